"""
The drawing adapter: the Rig protocol's ``rig.drawing`` posed by ``RigData.bodies``.

:func:`plan` lays out a recording (:class:`.layout.Layout`) from one reference turn;
:func:`motion_of` turns evaluated data into drawn positions.
"""

from dataclasses import dataclass
import math

from mech_balance import conventions
from mech_balance.core.rig import rig_for
from mech_balance.schema import registry
from mech_balance.schema.scene import needs, Recording, RECORDING_STREAMS, SERIES, \
    series_stream
from mech_balance.viz.labels import label_specs, place_labels
from mech_balance.viz.layout import (
    arc_scale, arrow_scale, Layout, length_text, nice_floor, place_views, zoom_inset
)
from mech_balance.viz.plots import plot_specs
from mech_balance.viz.style import (
    ARROW_3D_SHARE, AXIS_MARGIN_SHARE, BLOCK_SHARE, FORCE_ARROW_SHARE, LINK_PALETTE,
    SAME_POINT_RTOL, SCALE_BAR_SHARE
)
from mech_balance.viz.text import info_text
import numpy as np


VARIANTS = ('original', 'balanced')
MIN_SAMPLES = 4
"""Fewest samples per crank turn of a recording."""
ARROW_3D_STEPS = (1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0)
"""3-D: the round values of 1 cm of gauge arrow (finer than 1-2-5, so that the longest arrow
comes out near its share of the rig: in perspective a short arrow reads as nothing)."""
RING_POINTS = 49
"""Points of the ring that draws a counterweight's plane."""
PLANE_RING_SHARE = 1.25
"""A counterweight's plane ring has this times the disc's radius."""
MASS_KEPT_RTOL = 1e-6
"""A mass change below this share of the body's mass is none (the solver's round-off)."""
MOVED_RTOL = 1e-9
"""A body's mass centre (share of the rig) or mass (relative) changed beyond this."""
COLLINEAR_RTOL = 1e-9
"""A link's points are collinear (drawn open) below this relative cross product."""
GEOMETRY_ANGLES = 8
"""Crank angles at which a balanced design's poses are compared with the original's."""
GEOMETRY_RTOL = 1e-7
"""Poses of two designs of one geometry agree to this share of the rig."""
AXIS_NEAR_SHARE = 0.25
"""A fixed axis or guide is drawn over the points within this share of the rig from it."""
SHAKING_STREAMS = ('shaking_force_arrow', 'shaking_moment_arc', 'shaking_force_plot',
                   'shaking_moment_plot')


def check_samples(samples, cycles, links=1):
    if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) or \
            samples < MIN_SAMPLES:
        raise ValueError(f'samples: got {samples!r}, expected an integer >= {MIN_SAMPLES} '
                         'samples per crank turn')
    conventions.check_samples(int(samples), links=links)
    if isinstance(cycles, bool) or not isinstance(cycles, (int, np.integer)) or cycles < 1:
        raise ValueError(f'cycles: got {cycles!r}, expected an integer >= 1')
    if cycles > conventions.MAX_CYCLES:
        raise ValueError(f'cycles: got {cycles}, expected at most {conventions.MAX_CYCLES} '
                         'crank turns (a fixed limit of mech_balance)')
    if int(samples) * int(cycles) > conventions.MAX_RECORD_ROWS:
        raise ValueError(f'samples: got {int(samples)} per turn x {int(cycles)} turns = '
                         f'{int(samples) * int(cycles)} rows, expected at most '
                         f'{conventions.MAX_RECORD_ROWS} (a fixed limit of mech_balance); '
                         'use fewer samples or turns')


DEGREE_TIMELINE = 'crank_angle_deg'
"""The default timeline: whole degrees turned from crank angle 0 (``crank_angle``: the same)."""


def turn_angles(samples, speed_rad_s=1.0):
    """Return the crank angles of one recorded turn: from 0 in the direction of rotation."""
    sign = -1.0 if speed_rad_s < 0.0 else 1.0
    return sign * conventions.cycle_angles(samples)


def turn_ticks(samples, speed_rad_s, cycles=1):
    """Return the ``crank_angle`` ticks (whole degrees turned) and ``time`` (s) of a record."""
    k = np.arange(samples * cycles)
    turn, j = np.divmod(k, samples)
    degrees = np.round(360.0 * j / samples).astype(np.int64) + 360 * turn
    return degrees, k * (2.0 * math.pi / samples) / abs(speed_rad_s)


def world_points(poses, body, local):
    """Return ``(n, k, 3)`` frame coordinates of points ``(k, 3)`` fixed in ``body``."""
    k = poses.names.index(body)
    local = np.asarray(local, dtype=float).reshape(-1, 3)
    return poses.origin_m[:, k, None, :] + np.einsum('nij,kj->nki', poses.rotation[:, k],
                                                     local)


def streams_for(scene, rig):
    """Return the enabled stream names: the scene's switches, less what it does not compute."""
    rec = getattr(scene, 'recording', None) or Recording()
    have = needs(rig.outputs)
    streams = list(rec.streams)
    if 'accelerations' not in have:
        streams = [s for s in streams if s not in SHAKING_STREAMS]
    if 'driving_torque' not in have:
        streams = [s for s in streams if s != 'driving_torque_plot']
    return tuple(streams)


def series_on(name, streams):
    """Return whether the plot of series ``name`` is switched on (``series_stream``)."""
    stream = series_stream(name)
    return stream not in RECORDING_STREAMS or stream in streams


def outputs_for(rig, streams):
    """Return the outputs the enabled streams need (nothing a disabled stream alone needs)."""
    out = ['kinematics']
    if any(s in streams for s in SHAKING_STREAMS):
        out.append('shaking_wrench')
    for o in rig.outputs:
        if o not in ('kinematics', 'shaking_wrench', 'bearing_reactions') and \
                series_on(o, streams) and o not in out:
            out.append(o)
    return tuple(out)


def poses_signature(rig, psi):
    data = rig.at(psi, outputs=('kinematics',))
    order = np.argsort(np.array(data.bodies.names))
    return data.bodies.origin_m[:, order], data.bodies.rotation[:, order]


def drawing_shape(drawing):
    return (drawing.dimension, sorted(drawing.frame.items()),
            sorted((b.name, tuple(sorted(b.points.items()))) for b in drawing.bodies),
            sorted(drawing.joints), sorted(drawing.axes))


def align_design(original, balanced):
    """
    Return ``balanced`` with its bodies in the order of ``original``'s.

    Raises ValueError unless both have one kind, drawing and poses over a turn.
    """
    ko, kb = registry.kind_of(original), registry.kind_of(balanced)
    if kb is not ko:
        raise ValueError(f'design: got a {kb.name} scene, expected a {ko.name} one like '
                         f'{original.name!r}')
    ro, rb = rig_for(original), rig_for(balanced)
    same = drawing_shape(ro.drawing) == drawing_shape(rb.drawing) and \
        set(ro.joint_names) == set(rb.joint_names) and ro.crank_joint == rb.crank_joint
    if same:
        psi = conventions.cycle_angles(GEOMETRY_ANGLES)
        (oo, rot_o), (ob, rot_b) = poses_signature(ro, psi), poses_signature(rb, psi)
        size = max(float(np.ptp(oo)), 1e-12)
        same = np.allclose(oo, ob, rtol=0.0, atol=GEOMETRY_RTOL * size) and \
            np.allclose(rot_o, rot_b, rtol=0.0, atol=GEOMETRY_RTOL)
    if not same:
        raise ValueError(
            f'design: scene {balanced.name!r} ({getattr(balanced, "source", "?")}) has another '
            f'geometry than {original.name!r}, expected the same frame points, link points, '
            'joints and assembly (a balanced design changes inertias only)')
    if hasattr(balanced, 'with_links'):
        order = [b.name for b in ro.drawing.bodies]
        by_name = {lk.name: lk for lk in balanced.links}
        return balanced.with_links([by_name[n] for n in order])
    return balanced


def outline(body, half_block):
    """Return a body's polyline ``(k, 3)``: closed for a plate, a square for a slider block."""
    pts = np.array([body.points[n] for n in body.outline], dtype=float).reshape(-1, 3)
    if len(pts) == 1:
        square = half_block * np.array([[1, 1, 0], [-1, 1, 0], [-1, -1, 0], [1, -1, 0],
                                        [1, 1, 0]], dtype=float)
        return pts[0] + square
    rel = pts - pts[0]
    span = float(np.max(np.linalg.norm(rel, axis=1)))
    cross = np.linalg.norm(np.cross(rel[1:, None], rel[None, 1:]), axis=-1)
    if len(pts) >= 3 and span > 0.0 and float(cross.max()) > COLLINEAR_RTOL * span ** 2:
        return np.concatenate([pts, pts[:1]])
    return pts


@dataclass
class Motion:
    """A batch of samples: drawn positions (frame coordinates, 3-D) and every variant's data."""

    links: list           # per body (p, k, 3)
    joints: np.ndarray    # (p, J, 3)
    centres: dict         # variant -> (p, nb + 1, 3), the system's last
    added: dict           # variant -> (p, A, 3)
    point_masses: dict    # variant -> (p, 3 nb, 3)
    data: dict            # variant -> RigData
    degrees: np.ndarray   # (p,) crank angle shown (deg, reduced to [0, 360))
    marks: dict = None    # variant -> {'rings': (p, R, k, 3), 'stalks': (p, S, 2, 3)}

    @property
    def size(self):
        """Return the number of samples."""
        return self.joints.shape[0]


def motion_of(layout, data):
    """Return the :class:`Motion` of evaluated data ``{variant: RigData}``."""
    ref = data['original']
    poses = ref.bodies
    links = [world_points(poses, name, local) for name, local in layout.templates]
    drawing = layout.drawings['original']
    joints = np.zeros((len(ref), 0, 3))
    if drawing.joints:
        joints = np.concatenate([world_points(poses, body, [body_point(drawing, body, point)])
                                 for _, body, point in drawing.joints], axis=1)
    centres, added, point_masses = {}, {}, {}
    for v, d in data.items():
        dr = layout.drawings[v]
        c = np.concatenate([world_points(d.bodies, b.name, [b.mass_centre_m]) for b in dr.bodies],
                           axis=1)
        m = np.array([b.mass_kg or 0.0 for b in dr.bodies])
        system = np.einsum('k,nkd->nd', m, c) / m.sum() if m.sum() > 0 else c.mean(axis=1)
        centres[v] = np.concatenate([c, system[:, None]], axis=1)
        parts = [world_points(d.bodies, b.name, [a.centre_m for a in b.added])
                 for b in dr.bodies if b.added]
        added[v] = np.concatenate(parts, axis=1) if parts else np.zeros((len(d), 0, 3))
        if layout.has_point_masses:
            pm = [world_points(d.bodies, b.name, [p for _, p in b.point_masses])
                  for b in dr.bodies if b.point_masses]
            point_masses[v] = np.concatenate(pm, axis=1)
    degrees = np.mod(np.degrees(ref.crank_angle_rad), 360.0)
    marks = {}
    for v, d in data.items():
        marks[v] = {}
        for kind, templates in (layout.marks or {}).get(v, {}).items():
            parts = [world_points(d.bodies, body, local)[:, None] for body, local in templates]
            marks[v][kind] = np.concatenate(parts, axis=1) if parts else None
    return Motion(links, joints, centres, added, point_masses, data, degrees, marks)


def design_marks(drawings, templates, size):
    """
    Return what a design changed, to draw: ``({variant: marks}, {variant: changes})``.

    ``rings`` in each added body's plane; ``stalks`` to a moved mass centre; ``changes``:
    ``[(body index, mass change kg)]``.
    """
    marks, changes = {}, {}
    original = {b.name: b for b in drawings['original'].bodies}
    t = np.linspace(0.0, 2.0 * math.pi, RING_POINTS)
    circle = np.stack([np.cos(t), np.sin(t), np.zeros_like(t)], axis=-1)
    outlines = dict(templates)
    for v, dr in drawings.items():
        rings, stalks, moved = [], [], []
        for i, b in enumerate(dr.bodies):
            for a in b.added:
                rings.append((b.name, np.asarray(a.centre_m, dtype=float)
                              + PLANE_RING_SHARE * a.radius_m * circle))
            o = original[b.name]
            c_new = np.asarray(b.mass_centre_m, dtype=float)
            c_old = np.asarray(o.mass_centre_m, dtype=float)
            dm = (b.mass_kg or 0.0) - (o.mass_kg or 0.0)
            if v == 'original' or b.added or (
                    np.linalg.norm(c_new - c_old) <= MOVED_RTOL * size and
                    abs(dm) <= MOVED_RTOL * max(o.mass_kg or 0.0, 1e-300)):
                continue
            outline = outlines[b.name]
            foot = _nearest_on_polyline(c_new, outline)
            stalks.append((b.name, np.stack([foot, c_new])))
            kept = abs(dm) <= MASS_KEPT_RTOL * max(o.mass_kg or 0.0, b.mass_kg or 0.0)
            moved.append((i, 0.0 if kept else dm))
        marks[v] = {'rings': rings, 'stalks': stalks}
        changes[v] = moved
    return marks, changes


def _nearest_on_polyline(q, strip):
    """Return the point of polyline ``strip`` ``(k, 3)`` nearest ``q`` ``(3,)``."""
    if len(strip) == 1:
        return strip[0]
    a, b = strip[:-1], strip[1:]
    ab = b - a
    t = np.clip(np.einsum('ij,ij->i', q - a, ab) / np.maximum(np.einsum('ij,ij->i', ab, ab),
                                                              1e-300), 0.0, 1.0)
    feet = a + t[:, None] * ab
    return feet[np.argmin(np.linalg.norm(feet - q, axis=1))]


def body_point(drawing, body, point):
    if body == 'frame':
        return drawing.frame[point]
    return next(b for b in drawing.bodies if b.name == body).points[point]


def frame_strips_of(drawing, moving, size):
    """Return the frame's polylines: the ground link, each fixed axis or guide over its part."""
    frame = {n: np.asarray(p, dtype=float) for n, p in drawing.frame.items()}
    tol = SAME_POINT_RTOL * size
    on_axis = set()
    lines = []
    cloud = np.concatenate([moving.reshape(-1, 3), np.array(list(frame.values()))])
    for _, point, direction in drawing.axes:
        p, d = np.asarray(point, dtype=float), np.asarray(direction, dtype=float)
        d = d / np.linalg.norm(d)
        for n, q in frame.items():
            if np.linalg.norm(np.cross(q - p, d)) <= tol:
                on_axis.add(n)
        # over what moves along it (a slider's travel) or turns about it (a shaft's joint),
        # not the projection of the whole rig: far points are left out
        near = np.linalg.norm(np.cross(cloud - p, d), axis=1) <= AXIS_NEAR_SHARE * size
        t = np.append((cloud[near] - p) @ d, 0.0)
        margin = AXIS_MARGIN_SHARE * size
        lines.append(p + np.outer([t.min() - margin, t.max() + margin], d))
    ground = []
    for n, q in frame.items():
        if n not in on_axis and not any(np.linalg.norm(q - g) <= tol for g in ground):
            ground.append(q)
    for _, point, _ in drawing.axes:
        q = np.asarray(point, dtype=float)
        if not any(np.linalg.norm(q - g) <= tol for g in ground):
            ground.append(q)
    strips = [np.array(ground)] if len(ground) >= 2 else []
    return strips + lines


def pivot_label(layout, rig):
    """Return the name of the frame point the shaking moment is reduced to, or its words."""
    at = np.asarray(rig.moment_point_m, dtype=float)
    for name, q in zip(layout.frame_names, layout.frame_points):
        if np.linalg.norm(at - q) <= SAME_POINT_RTOL * layout.size_m:
            return name
    return rig.moment_point


def plan(scene, balanced, samples, balanced_source, live=False):
    """Return ``(layout, reference motion)`` from one turn of ``samples`` angles."""
    rig = rig_for(scene)
    rigs = {'original': rig}
    if balanced is not None:
        rigs['balanced'] = rig.with_scene(align_design(scene, balanced))
    drawings = {v: r.drawing for v, r in rigs.items()}
    drawing = drawings['original']
    dim = drawing.dimension
    streams = streams_for(scene, rig)
    stream_outputs = outputs_for(rig, streams)
    asked = tuple(rig.outputs) if 'info' in streams else ()
    table_outputs = tuple(dict.fromkeys(stream_outputs + asked))
    psi = turn_angles(samples, scene.crank_speed_rad_s)
    data = {v: r.at(psi, outputs=table_outputs) for v, r in rigs.items()}
    ref = data['original']
    if ref.force_N is None:
        streams = tuple(s for s in streams if s not in SHAKING_STREAMS)
    series = tuple(dict.fromkeys(k for k in list(SERIES) + sorted(ref.series)
                                 if k in ref.series and series_on(k, streams)))
    has_pm = 'point_masses' in streams and all(
        b.point_masses for dr in drawings.values() for b in dr.bodies)
    if not has_pm:
        streams = tuple(s for s in streams if s != 'point_masses')
    has_added = 'links' in streams and any(b.added for dr in drawings.values()
                                           for b in dr.bodies)

    # size of the rig: everything that moves over the turn and the frame
    bodies = [world_points(ref.bodies, b.name, list(b.points.values())) for b in drawing.bodies]
    frame_pts = np.array(list(drawing.frame.values()), dtype=float).reshape(-1, 3)
    moving = np.concatenate(bodies, axis=1)
    cloud = np.concatenate([moving.reshape(-1, 3), frame_pts])
    span = float(np.max(np.ptp(cloud, axis=0)))
    size = span if span > 0.0 else 1.0
    templates = [(b.name, outline(b, size * BLOCK_SHARE)) for b in drawing.bodies]
    names = [b.name for b in drawing.bodies]
    colors = [LINK_PALETTE[i % len(LINK_PALETTE)] for i in range(len(names))]
    frame_strips = frame_strips_of(drawing, moving, size) if 'frame' in streams else []

    rec = getattr(scene, 'recording', None) or Recording()
    fmax = max((float(np.max(np.linalg.norm(d.force_N, axis=1))) for d in data.values()
                if d.force_N is not None), default=0.0)
    nmax = max((float(np.max(np.linalg.norm(d.moment_Nm, axis=1))) for d in data.values()
                if d.moment_Nm is not None), default=0.0)
    share = FORCE_ARROW_SHARE if dim == 2 else ARROW_3D_SHARE
    steps = (1.0, 2.0, 5.0) if dim == 2 else ARROW_3D_STEPS    # 3-D: lengths matter more
    fscale = rec.force_scale_m_per_N or arrow_scale(size, fmax, share, steps)
    mscale = (rec.moment_scale_deg_per_Nm or arc_scale(nmax)) if dim == 2 else \
        arrow_scale(size, nmax, share, steps)

    layout = Layout(
        dim=dim, streams=streams, variants=tuple(rigs), rigs=rigs, drawings=drawings,
        stream_outputs=stream_outputs, size_m=size, templates=templates, link_names=names,
        link_colors=colors, joint_names=[j[0] for j in drawing.joints],
        frame_names=list(drawing.frame), frame_points=frame_pts, frame_strips=frame_strips,
        pivot_name=rig.moment_point, force_scale_m_per_N=fscale, moment_scale=mscale,
        series=series, has_added=has_added, has_point_masses=has_pm, live=live,
        grid_m=nice_floor(SCALE_BAR_SHARE * size))
    layout.marks, layout.changes = design_marks(drawings, templates, size)
    layout.grid_text = length_text(layout.grid_m)
    layout.pivot_name = pivot_label(layout, rig)
    motion = motion_of(layout, data)
    place_views(layout, motion, fmax, nmax, len(series))
    layout.labels = label_specs(layout, motion)
    if not live:        # a live view places its labels batch by batch
        layout.placed = {'original': place_labels(layout, motion, 'original')}
        inset = zoom_inset(layout, motion, layout.placed)
        if inset is not None:       # the crowded core's names moved to the inset
            layout.placed['inset'] = inset
        layout.placed.update({v: place_labels(layout, motion, v) for v in layout.variants
                              if v not in layout.placed})
    layout.plots = plot_specs(layout, motion)
    if 'info' in streams:
        layout.text = info_text(layout, scene, data, samples, balanced_source)
    return layout, motion


def concat_motions(motions):
    """Return one :class:`Motion` of several, sample after sample."""
    if len(motions) == 1:
        return motions[0]

    def cat(arrays):
        return np.concatenate(arrays, axis=0)

    def cat_data(ds):
        from mech_balance.core.rig import BodyPoses
        b = ds[0].bodies
        return MotionData(BodyPoses(b.names, cat([d.bodies.origin_m for d in ds]),
                                    cat([d.bodies.rotation for d in ds])),
                          cat([d.crank_angle_rad for d in ds]),
                          None if ds[0].force_N is None else cat([d.force_N for d in ds]),
                          None if ds[0].moment_Nm is None else cat([d.moment_Nm for d in ds]),
                          {k: cat([d.series[k] for d in ds]) for k in ds[0].series})
    m0 = motions[0]
    return Motion([cat([m.links[i] for m in motions]) for i in range(len(m0.links))],
                  cat([m.joints for m in motions]),
                  {v: cat([m.centres[v] for m in motions]) for v in m0.centres},
                  {v: cat([m.added[v] for m in motions]) for v in m0.added},
                  {v: cat([m.point_masses[v] for m in motions]) for v in m0.point_masses},
                  {v: cat_data([m.data[v] for m in motions]) for v in m0.data},
                  cat([m.degrees for m in motions]),
                  {v: {k: None if a is None else cat([m.marks[v][k] for m in motions])
                       for k, a in marks.items()} for v, marks in (m0.marks or {}).items()})


class MotionData:
    """What :func:`motion_of` reads of a RigData: poses, angles, wrench and series."""

    def __init__(self, bodies, crank_angle_rad, force_N, moment_Nm, series):
        self.bodies, self.crank_angle_rad = bodies, crank_angle_rad
        self.force_N, self.moment_Nm, self.series = force_N, moment_Nm, series

    def __len__(self):
        """Return the number of samples."""
        return self.crank_angle_rad.shape[0]


def live_motion(layout, psi, data, keep=None):
    """Return the motion of live samples: the original's data (given or computed), the rest."""
    from mech_balance.core.rig import BodyPoses
    sel = slice(None) if keep is None else keep
    speed = accel = None
    if data is not None:
        speed, accel = data.crank_speed_rad_s[sel], data.crank_accel_rad_s2[sel]
        data = MotionData(BodyPoses(data.bodies.names, data.bodies.origin_m[sel],
                                    data.bodies.rotation[sel]), data.crank_angle_rad[sel],
                          None if data.force_N is None else data.force_N[sel],
                          None if data.moment_Nm is None else data.moment_Nm[sel],
                          {k: s[sel] for k, s in data.series.items()})
        if (data.force_N is None and 'shaking_wrench' in layout.stream_outputs) or \
                any(k not in data.series for k in layout.series):
            data = None
    reduced = np.mod(psi, 2.0 * math.pi)
    evaluated = {}
    for v, rig in layout.rigs.items():
        d = data if v == 'original' else None
        evaluated[v] = d if d is not None else rig.at(reduced, speed, accel,
                                                      outputs=layout.stream_outputs)
    return motion_of(layout, evaluated)
