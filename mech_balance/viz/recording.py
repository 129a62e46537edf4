"""
Rerun recordings of a rig in motion: the original mechanism against its balanced design.

The only module of mech_balance that imports rerun.  It turns the core's results into an
``.rrd`` file that a person opens in the rerun viewer (``rerun FILE.rrd``), entity by entity:

* ``/info`` [info]: scene, design, RMS table and the scales (markdown);
* ``/rig/frame``, ``/rig/pivots`` [frame]: frame lines, slider guides, pivots (static);
* ``/rig/links`` [links]: one line strip per link;  ``/rig/joints`` [joints];
* ``/{variant}/mass_centres`` [mass_centres]: link mass centres and the system's G;
* ``/{variant}/point_masses`` [point_masses]: three equimomental masses per link (planar);
* ``/{variant}/shaking_force`` [shaking_force_arrow]: arrow at the crank pivot (RGGR: O);
* ``/{variant}/shaking_moment`` [shaking_moment_arc]: arc about the crank pivot (RGGR: a
  moment vector at O);
* ``/plots/shaking_force/{variant}`` [shaking_force_plot]: abs(shaking force), N;
* ``/plots/shaking_moment/{variant}`` [shaking_moment_plot]: shaking moment, N*m (RGGR: its
  norm);
* ``/plots/driving_torque/{variant}`` [driving_torque_plot]: driving torque, N*m.

The stream switch of each entity is in brackets.  ``variant`` is ``original`` or
``balanced`` (same geometry, other inertias, so the linkage itself is logged once).  Every
sample is indexed on two timelines: ``crank_angle``, the crank angle in whole degrees (the
assembly angle plus the degrees turned), and ``time``, seconds at the scene's crank speed
(live: on the rig's clock, from the first sample).  A scene switches streams off with
``recording: {streams: {...}}`` (:class:`mech_balance.scene.Recording`); streams whose
quantity the scene's ``outputs`` do not include are off as well, and nothing a disabled
stream alone needs is computed.

Geometry that never changes is logged once as static data; the styles of animated entities
(colours, radii, labels) are static too, and whole time series go out in bulk through
``send_columns``.  :func:`record` writes an offline file; :class:`LiveRecorder` writes the
same layout sample by sample for the rig node.
"""

import atexit
from dataclasses import dataclass
import math
import os
from pathlib import Path
import re
import threading
import time

from mech_balance import atomic, conventions, paths
from mech_balance.analysis import cycle as analysis
from mech_balance.conventions import normalize_force, normalize_moment, rms
from mech_balance.core import equimomental
from mech_balance.core.planar import dynamics
from mech_balance.schema.scene import FRAME, needs, Recording
import numpy as np
import rerun as rr
import rerun.blueprint as rrb

APPLICATION_ID = 'mech_balance'
"""Prefix of the rerun application id (the scene name follows, so layouts never clash)."""
RRD_SUFFIX = '.rrd'
"""What the name of a recording file ends in (rerun's format)."""
VARIANTS = ('original', 'balanced')
DEGREES_PER_TURN = 360
"""The ``crank_angle`` timeline counts whole degrees, so samples per turn divide 360."""

FORCE_ARROW_SHARE = 0.5
"""Automatic force scale: the longest shaking-force arrow is at most this share of the rig."""
MOMENT_ARC_MAX_DEG = 270.0
"""Automatic moment scale: the largest shaking moment sweeps at most this arc."""
MOMENT_ARC_LIMIT_DEG = 355.0
"""An arc never sweeps more than this (a scene's own scale may ask for more)."""
MOMENT_ARC_RADIUS_SHARE = 0.2
"""Radius of the shaking-moment arc, as a share of the rig's size."""
MOMENT_HEAD_SHARE = 0.35
"""Length of the arc's arrow head, as a share of the arc radius."""
ARC_POINTS = 33
"""Points of the polyline that draws the shaking-moment arc."""
BLOCK_SHARE = 0.035
"""Half-size of the square drawn for a one-point link (a slider), as a share of the rig."""
POINT_MASS_RADIUS_SHARE = 0.03
"""Radius of the largest point mass, as a share of the rig (disc area ~ abs(mass))."""
CENTRE_RADIUS_SHARE = 0.012
"""Radius of a link's mass-centre dot, as a share of the rig."""
BOUNDS_PAD_SHARE = 0.08
"""Margin around everything drawn, as a share of the rig, for the 2-D views' bounds."""
COLLINEAR_RTOL = 1e-9
"""A link's points are collinear (drawn open) below this relative cross product."""
LINE_RADIUS_UI = rr.components.Radius.ui_points(2.0)
JOINT_RADIUS_UI = rr.components.Radius.ui_points(4.5)
Y_UP_SCALE = (1.0, -1.0, 1.0)
"""Scale of the 2-D drawing roots that shows the scene's y axis upwards."""
CLOSE_TIMEOUT_S = 5.0
"""How long :meth:`LiveRecorder.close` waits for a logging call on another thread."""

# colours (RGB)
FRAME_COLOR = (150, 150, 150)
JOINT_COLOR = (235, 235, 235)
FORCE_COLOR = (255, 120, 30)
MOMENT_COLOR = (190, 110, 255)
POSITIVE_MASS_COLOR = (60, 150, 255)
NEGATIVE_MASS_COLOR = (235, 60, 60)
SYSTEM_CENTRE_COLOR = (255, 255, 255)
SERIES_COLORS = {'original': (250, 160, 50), 'balanced': (70, 200, 130)}
LINK_PALETTE = ((86, 180, 233), (0, 158, 115), (240, 228, 66), (204, 121, 167),
                (213, 94, 0), (0, 114, 178), (230, 159, 0), (160, 160, 255))

_SHAKING_STREAMS = ('shaking_force_arrow', 'shaking_moment_arc', 'shaking_force_plot',
                    'shaking_moment_plot')
_PLOTS = (('shaking_force_plot', 'shaking_force'), ('shaking_moment_plot', 'shaking_moment'),
          ('driving_torque_plot', 'driving_torque'))


# ------------------------------------------------------------------------------- summaries


@dataclass(frozen=True)
class RecordingSummary:
    """What :func:`record` wrote: the file, its size, rows per series and entity paths."""

    path: Path
    size_bytes: int
    samples_per_cycle: int
    cycles: int
    rows: int
    entity_paths: tuple
    variants: tuple
    seconds: float


@dataclass
class _Variant:
    """The per-design part of a batch of samples (arrays over samples first)."""

    name: str
    mass_centres: np.ndarray = None  # (p, k, d) m
    point_masses: np.ndarray = None  # (p, 3 n, d) m
    force_N: np.ndarray = None       # (p, d)
    moment_Nm: np.ndarray = None     # (p,) planar, (p, 3) spatial
    torque_Nm: np.ndarray = None     # (p,)


@dataclass
class _Motion:
    """A batch of samples: link polylines, joints and one :class:`_Variant` per design."""

    links: list          # per link: (p, k_i, d) m
    joints: np.ndarray   # (p, n_joints, d) m
    variants: list

    @property
    def size(self):
        """Return the number of samples."""
        return self.joints.shape[0]

    def tiled(self, cycles):
        """Return the motion repeated ``cycles`` times (the motion is periodic in the crank)."""
        if cycles == 1:
            return self

        def rep(a):
            return None if a is None else np.concatenate([a] * cycles, axis=0)
        return _Motion([rep(a) for a in self.links], rep(self.joints),
                       [_Variant(v.name, rep(v.mass_centres), rep(v.point_masses),
                                 rep(v.force_N), rep(v.moment_Nm), rep(v.torque_Nm))
                        for v in self.variants])


@dataclass
class _Layout:
    """Everything static: styles, scales, frame geometry, bounds, text and stream switches."""

    title: str
    dim: int
    streams: tuple
    variants: tuple
    size_m: float
    pivot_m: np.ndarray
    pivot_name: str
    link_names: list
    link_colors: list
    joint_names: list
    frame_strips: list
    frame_points: np.ndarray
    frame_labels: list
    centre_labels: list
    centre_colors: list
    centre_radii: list
    point_mass_kg: dict
    point_mass_radius_m: dict
    force_scale_m_per_N: float
    moment_scale: float          # deg per N*m (planar arc) or m per N*m (RGGR arrow)
    arc_radius_m: float
    bounds: tuple
    text: str = ''
    units: dict = None

    def on(self, stream):
        """Return whether ``stream`` is logged."""
        return stream in self.streams


# ------------------------------------------------------------------------------- helpers


def _c2(z):
    """Return complex points ``(...)`` as float ``(..., 2)`` (x, y)."""
    z = np.asarray(z)
    return np.stack([z.real, z.imag], axis=-1)


def _nice_ceil(x):
    """Return the smallest 1, 2 or 5 times a power of ten that is >= ``x`` (``x`` > 0)."""
    exp = math.floor(math.log10(x))
    for m in (1.0, 2.0, 5.0, 10.0):
        if m * 10.0 ** exp >= x * (1.0 - 1e-12):
            return m * 10.0 ** exp
    return 10.0 ** (exp + 1)


def _arrow_scale(size_m, largest):
    """
    Return metres of arrow per unit value (m per N, or m per N*m).

    1 cm of arrow is a round value and the longest arrow at most ``FORCE_ARROW_SHARE`` of
    the rig's size.
    """
    if not largest > 0.0:
        return 1.0
    return 0.01 / _nice_ceil(largest * 0.01 / (FORCE_ARROW_SHARE * size_m))


def _arc_scale(largest):
    """
    Return degrees of arc per N*m.

    90 deg of arc is a round moment and the largest moment sweeps at most
    ``MOMENT_ARC_MAX_DEG``.
    """
    if not largest > 0.0:
        return 1.0
    return 90.0 / _nice_ceil(largest * 90.0 / MOMENT_ARC_MAX_DEG)


def _fmt(x):
    return f'{x:.4g}'


def _markdown(lines):
    """Return markdown text: a literal ``*`` (as in N*m) is escaped, list bullets are kept."""
    out = []
    for line in lines:
        bullet = '* ' if line.startswith('* ') else ''
        out.append(bullet + line[len(bullet):].replace('*', '\\*'))
    return '\n'.join(out)


def _cell(text):
    """Return ``text`` safe inside a markdown table cell (pipes escaped)."""
    return str(text).replace('|', '\\|')


def _streams_for(scene, outputs_have):
    """Return the enabled stream names: the scene's switches, less what it does not compute."""
    rec = getattr(scene, 'recording', None) or Recording()
    streams = list(rec.streams)
    if 'accelerations' not in outputs_have:
        streams = [s for s in streams if s not in _SHAKING_STREAMS]
    if 'driving_torque' not in outputs_have:
        streams = [s for s in streams if s != 'driving_torque_plot']
    return tuple(streams)


def _check_samples(samples, cycles):
    if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) or samples < 4 \
            or DEGREES_PER_TURN % int(samples):
        raise ValueError(
            f'samples: got {samples!r}, expected a divisor of {DEGREES_PER_TURN} that is >= 4 '
            '(the crank_angle timeline counts whole degrees, one distinct tick per sample)')
    if isinstance(cycles, bool) or not isinstance(cycles, (int, np.integer)) or cycles < 1:
        raise ValueError(f'cycles: got {cycles!r}, expected an integer >= 1')
    if cycles > conventions.MAX_CYCLES:
        raise ValueError(f'cycles: got {cycles}, expected at most {conventions.MAX_CYCLES} '
                         'crank turns (conventions.MAX_CYCLES)')


def _psi_grid(psi0, speed, samples):
    """Return ``samples`` crank angles of one turn from ``psi0`` in the direction of rotation."""
    sign = 1.0 if speed >= 0.0 else -1.0
    return psi0 + sign * 2.0 * math.pi * np.arange(samples) / samples


def _ticks(psi0, speed, samples, cycles):
    """Return the ``crank_angle`` (whole degrees) and ``time`` (s) of every sample."""
    step = DEGREES_PER_TURN // samples
    k = np.arange(samples * cycles)
    degrees = int(round(math.degrees(psi0))) + step * k
    seconds = k * (2.0 * math.pi / samples) / abs(speed)
    return degrees.astype(np.int64), seconds


def _bounds(points, pad):
    """Return ((xmin, xmax), (ymin, ymax)) of ``(..., 2)`` points, padded."""
    pts = np.asarray(points).reshape(-1, 2)
    lo, hi = pts.min(axis=0) - pad, pts.max(axis=0) + pad
    return (float(lo[0]), float(hi[0])), (float(lo[1]), float(hi[1]))


# ------------------------------------------------------------------------------- planar


class _PlanarModel:
    """A planar scene (and its balanced design) turned into drawable samples."""

    def __init__(self, scene, balanced=None, linkage=None):
        self.rig = analysis.Rig(scene, linkage)
        self.linkage = self.rig.linkage
        self.scenes = {'original': scene}
        if balanced is not None:
            self.scenes['balanced'] = align_design(scene, balanced)
        have = needs(scene.outputs)
        self.streams = _streams_for(scene, have)
        out = {'kinematics'}
        if any(s in self.streams for s in _SHAKING_STREAMS):
            out.add('shaking_wrench')
        if 'driving_torque_plot' in self.streams:
            out.add('driving_torque')
        self.stream_outputs = tuple(out)
        self.table_outputs = tuple(out | (set(scene.outputs) if 'info' in self.streams
                                          else set()))
        self.inertia = {v: dynamics.Inertia.from_links(sc.links) for v, sc in self.scenes.items()}
        self.body = {lk.name: self.linkage.body_names.index(lk.name) for lk in scene.links}
        self.point_models = {}
        if 'point_masses' in self.streams:
            self.point_models = {
                v: [equimomental.from_link(lk.mass_kg, lk.com_m, lk.inertia_origin_kg_m2)
                    for lk in sc.links] for v, sc in self.scenes.items()}
        self.joints = [(j.name, self.body_of(j.link_a),
                        complex(*self._point(j.link_a, j.point_a)))
                       for j in scene.joints if j.kind == 'revolute']
        self.templates = None  # link polylines in link frames, set by layout()

    def body_of(self, name):
        """Return the linkage body index of a link name (0 for the frame)."""
        return 0 if name == FRAME else self.body[name]

    def _point(self, link, point):
        sc = self.scenes['original']
        return sc.frame_points[point] if link == FRAME else sc.link(link).points[point]

    def evaluate(self, psi, outputs):
        """Return ``(state, {variant: wrenches or None})`` at crank angles ``psi``."""
        need = needs(outputs)
        state = self.linkage.solve(psi, need_acc='accelerations' in need)
        return state, self.wrenches(state, outputs)

    def wrenches(self, state, outputs, given=None):
        """Return the wrenches of every variant for a solved state (``given`` reused)."""
        need = needs(outputs)
        if 'accelerations' not in need:
            return dict.fromkeys(self.scenes)
        out = dict(given or {})
        for v in self.scenes:
            if out.get(v) is None:
                out[v] = dynamics.inverse_dynamics(self.linkage, state, self.inertia[v],
                                                   self.rig.gravity, need)
        return out

    def motion(self, state, wrenches):
        """Return the :class:`_Motion` of a solved state and its wrenches."""
        rot, origin = state.pose.rot, state.pose.origin
        links = []
        if 'links' in self.streams:
            for b, local in self.templates:
                links.append(_c2(origin[b][:, None] + rot[b][:, None] * local[None, :]))
        joints = np.zeros((state.size, 0, 2))
        if 'joints' in self.streams and self.joints:
            joints = _c2(np.stack([origin[b] + rot[b] * p for _, b, p in self.joints], axis=-1))
        variants = []
        for v, sc in self.scenes.items():
            var = _Variant(v)
            if 'mass_centres' in self.streams:
                bodies = [self.body[lk.name] for lk in sc.links]
                centres = [origin[b] + rot[b] * complex(*lk.com_m)
                           for b, lk in zip(bodies, sc.links)]
                masses = np.array([lk.mass_kg for lk in sc.links])
                system = np.tensordot(masses, np.array(centres), axes=1) / masses.sum()
                var.mass_centres = _c2(np.stack(centres + [system], axis=-1))
            if 'point_masses' in self.streams:
                pts = [origin[self.body[lk.name]][:, None] + rot[self.body[lk.name]][:, None]
                       * (pm.distance_m * equimomental.UNIT)[None, :]
                       for lk, pm in zip(sc.links, self.point_models[v])]
                var.point_masses = _c2(np.concatenate(pts, axis=1))
            w = wrenches.get(v)
            if w is not None:
                var.force_N = _c2(w.shaking_force)
                var.moment_Nm = np.asarray(w.shaking_moment, dtype=float)
                if w.driving_torque is not None:
                    var.torque_Nm = np.asarray(w.driving_torque, dtype=float)
            variants.append(var)
        return _Motion(links, joints, variants)

    def layout(self, state, wrenches, samples, balanced_source):
        """Return the :class:`_Layout` from a reference cycle (scales, bounds, text)."""
        sc = self.scenes['original']
        rot, origin = state.pose.rot, state.pose.origin
        every = [origin[self.body[lk.name]][:, None] + rot[self.body[lk.name]][:, None]
                 * np.array([complex(*p) for p in lk.points.values()])[None, :]
                 for lk in sc.links]
        frame_pts = np.array([complex(*p) for p in sc.frame_points.values()])
        cloud = np.concatenate([np.concatenate(every, axis=1).ravel(), frame_pts])
        span = max(np.ptp(cloud.real), np.ptp(cloud.imag))
        size = float(span) if span > 0.0 else 1.0
        self.templates = [(self.body[lk.name], _link_template(lk, size * BLOCK_SHARE))
                          for lk in sc.links]
        pivot = self.linkage.pivot
        crank = next(j for j in sc.joints if j.name == sc.crank_joint)
        pivot_name = crank.point_a if crank.link_a == FRAME else crank.point_b

        rec = sc.recording
        forces = [np.abs(w.shaking_force) for w in wrenches.values() if w is not None]
        moments = [np.abs(w.shaking_moment) for w in wrenches.values() if w is not None]
        fmax = max((float(f.max()) for f in forces), default=0.0)
        nmax = max((float(n.max()) for n in moments), default=0.0)
        fscale = rec.force_scale_m_per_N or _arrow_scale(size, fmax)
        mscale = rec.moment_scale_deg_per_Nm or _arc_scale(nmax)
        arc_r = MOMENT_ARC_RADIUS_SHARE * size

        extent = [cloud, pivot + arc_r * (1.0 + MOMENT_HEAD_SHARE) * np.exp(
            1j * np.linspace(0.0, 2.0 * math.pi, 16))]
        if 'shaking_force_arrow' in self.streams:
            extent += [pivot + fscale * f for f in
                       (w.shaking_force for w in wrenches.values() if w is not None)]
        bounds = _bounds(_c2(np.concatenate([np.ravel(e) for e in extent])),
                         BOUNDS_PAD_SHARE * size)

        frame_strips = _frame_strips(sc, self, state, size)
        names = [lk.name for lk in sc.links]
        pm_kg, pm_r = {}, {}
        if self.point_models:
            pm_kg = {v: np.concatenate([pm.masses_kg for pm in pms])
                     for v, pms in self.point_models.items()}
            mmax = max(float(np.max(np.abs(m))) for m in pm_kg.values()) or 1.0
            pm_r = {v: POINT_MASS_RADIUS_SHARE * size * np.sqrt(np.abs(m) / mmax)
                    for v, m in pm_kg.items()}
        layout = _Layout(
            title=sc.name, dim=2, streams=self.streams, variants=tuple(self.scenes),
            size_m=size, pivot_m=_c2(pivot), pivot_name=pivot_name, link_names=names,
            link_colors=[LINK_PALETTE[i % len(LINK_PALETTE)] for i in range(len(names))],
            joint_names=[n for n, _, _ in self.joints], frame_strips=frame_strips,
            frame_points=_c2(frame_pts), frame_labels=list(sc.frame_points),
            centre_labels=[f'G{i + 1}' for i in range(len(names))] + ['G'],
            centre_colors=[LINK_PALETTE[i % len(LINK_PALETTE)] for i in range(len(names))]
            + [SYSTEM_CENTRE_COLOR],
            centre_radii=[CENTRE_RADIUS_SHARE * size] * len(names)
            + [1.8 * CENTRE_RADIUS_SHARE * size],
            point_mass_kg=pm_kg, point_mass_radius_m=pm_r, force_scale_m_per_N=fscale,
            moment_scale=mscale, arc_radius_m=arc_r, bounds=bounds)
        if 'info' in self.streams:
            layout.text = _planar_text(self, layout, state, wrenches, samples, balanced_source)
        return layout


def _link_template(link, half_block):
    """Return the polyline of a link in its own frame (complex, closed when it is a plate)."""
    pts = np.array([complex(*p) for p in link.points.values()])
    if pts.size == 1:
        square = half_block * np.array([1 + 1j, -1 + 1j, -1 - 1j, 1 - 1j, 1 + 1j])
        return pts[0] + square
    rel = pts - pts[0]
    span = float(np.max(np.abs(rel)))
    cross = np.abs((np.conj(rel[1:, None]) * rel[None, 1:]).imag)
    if pts.size >= 3 and span > 0.0 and float(cross.max()) > COLLINEAR_RTOL * span ** 2:
        return np.concatenate([pts, pts[:1]])
    return pts


def _frame_strips(sc, model, state, size):
    """Return the frame's static polylines: the ground link and the prismatic guides."""
    pts = []
    for p in sc.frame_points.values():
        z = complex(*p)
        if not any(abs(z - q) <= 1e-12 * size for q in pts):
            pts.append(z)
    strips = [_c2(np.array(pts))] if len(pts) >= 2 else []
    for j in sc.joints:
        if j.kind != 'prismatic' or j.link_a != FRAME:
            continue
        base = complex(*sc.frame_points[j.point_a])
        axis = complex(*j.axis)
        b = model.body_of(j.link_b)
        local = complex(*sc.link(j.link_b).points[j.point_b])
        moving = state.pose.origin[b] + state.pose.rot[b] * local
        t = ((moving - base) * np.conj(axis)).real
        margin = 2.0 * BLOCK_SHARE * size
        strips.append(_c2(base + axis * np.array([t.min() - margin, t.max() + margin])))
    return strips


def align_design(original, balanced):
    """
    Return ``balanced`` with its links in the order of ``original``'s.

    Raises ValueError unless both scenes have the same geometry (frame points, link
    points, joints and crank joint; orders may differ) and so differ in inertias only.
    """
    if getattr(balanced, 'kind', 'planar') != getattr(original, 'kind', 'planar'):
        raise ValueError(f'design: got a {balanced.kind} scene, expected a {original.kind} one '
                         f'like {original.name!r}')
    if original.kind == 'rggr':
        if balanced.geometry != original.geometry or balanced.branch != original.branch:
            raise ValueError(f'design: scene {balanced.name!r} has another RGGR geometry or '
                             f'branch than {original.name!r}, expected the same')
        return balanced

    def shape(sc):
        return (sc.frame_points, {lk.name: lk.points for lk in sc.links}, set(sc.joints),
                sc.crank_joint)
    if shape(original) != shape(balanced):
        raise ValueError(
            f'design: scene {balanced.name!r} ({balanced.source}) has another geometry than '
            f'{original.name!r}, expected the same frame points, link points and joints '
            '(a balanced design changes inertias only)')
    return balanced.with_links([balanced.link(lk.name) for lk in original.links])


def _design_rows(sc, norm):
    """Return the seed-001 design vector (eq. 45) of a scene per link, normalized if given."""
    x = equimomental.design_vector(sc).reshape(-1, 4)
    if norm is not None:
        x = x / np.array([norm.mass_kg] * 3 + [norm.length_m])
    return x


def _planar_text(model, layout, state, wrenches, samples, balanced_source):
    sc = model.scenes['original']
    norm = sc.normalization
    both = 'balanced' in model.scenes
    rpm = sc.crank_speed_rad_s * 60.0 / (2.0 * math.pi)
    lines = [f'# {sc.name}: ' + ('original vs balanced' if both else 'original'), '',
             sc.description, '',
             f'Scene file `{sc.source}`; crank joint {sc.crank_joint} at '
             f'{_fmt(sc.crank_speed_rad_s)} rad/s ({_fmt(rpm)} rpm); {samples} samples per '
             'crank turn.']
    if both:
        lines.append(f'Balanced design: {balanced_source or model.scenes["balanced"].source}.')
    lines += ['', '## How to read the views', '']
    if both:
        lines.append('* Left: the original rig; right: the balanced rig. They move alike (same '
                     'geometry); only the mass distribution differs.')
    lines.append('* Grey: the frame and its pivots; coloured lines: the links; white dots: '
                 'the joints.')
    if layout.on('mass_centres'):
        lines.append('* Small dots G1, G2, ...: link mass centres; large white dot G: the mass '
                     'centre of all moving links (it stands still when the rig is force '
                     'balanced).')
    if layout.on('point_masses'):
        lines.append('* Blue and red discs: the three equimomental point masses of each link '
                     '(seed 001 eqs. 13-15); disc area proportional to the mass, blue '
                     'positive, red negative.')
    if layout.on('shaking_force_arrow'):
        lines.append(f'* Orange arrow at {layout.pivot_name}: the shaking force on the frame; '
                     f'scale {_fmt(layout.force_scale_m_per_N)} m per N, i.e. 1 cm of arrow '
                     f'= {_fmt(0.01 / layout.force_scale_m_per_N)} N.')
    if layout.on('shaking_moment_arc'):
        lines.append(f'* Purple arc about {layout.pivot_name}: the shaking moment about '
                     f'{layout.pivot_name}, counter-clockwise positive, starting at 12 '
                     f"o'clock; 90 deg of arc = {_fmt(90.0 / layout.moment_scale)} N*m.")
    if any(layout.on(s) for s, _ in _PLOTS):
        lines.append('* Plots: ' + ', '.join(
            t for s, t in zip([p for p, _ in _PLOTS],
                              ('|shaking force| (N)', f'shaking moment about '
                               f'{layout.pivot_name} (N*m)', 'driving torque (N*m)'))
            if layout.on(s)) + '; orange = original, green = balanced.')
    lines.append(f'* Timelines: `crank_angle` = crank angle in whole degrees (assembly angle '
                 f'{_fmt(math.degrees(sc.assembly_crank_angle_rad))} deg plus the degrees '
                 f'turned), `time` = seconds at {_fmt(abs(sc.crank_speed_rad_s))} rad/s.')

    unit = (f'masses in m1 = {_fmt(norm.mass_kg)} kg, distances in a1 = '
            f'{_fmt(norm.length_m)} m') if norm is not None else 'SI: kg and m'
    lines += ['', f'## Design: equimomental point masses (seed 001 eq. 45; {unit})', '',
              '| link | design | m_i1 | m_i2 | m_i3 | l_i1 |', '|---|---|---:|---:|---:|---:|']
    rows = {v: _design_rows(s, norm) for v, s in model.scenes.items()}
    for i, lk in enumerate(sc.links):
        for v in model.scenes:
            lines.append(f'| {lk.name} | {v} | ' + ' | '.join(_fmt(x) for x in rows[v][i])
                         + ' |')

    psi = state.psi
    tables = {}
    for v, s in model.scenes.items():
        cycle = analysis.Cycle(model.rig.with_scene(s), psi, state, wrenches.get(v), 0.0)
        tables[v] = {False: analysis.summarize(cycle, False)}
        if norm is not None:
            tables[v][True] = analysis.summarize(cycle, True)
    views = [False] + ([True] if norm is not None else [])
    for normalized in views:
        head = 'normalized by m1, a1, omega (seed 001 sec. 3.4)' if normalized else 'SI'
        lines += ['', f'## RMS over one crank turn ({head}; true RMS, '
                  'mech_balance.conventions)', '']
        cols = '| quantity | unit | original |' + (' balanced | balanced / original |'
                                                   if both else '')
        lines += [cols, '|---|---|---:|' + ('---:|---:|' if both else '')]
        for k, row in enumerate(tables['original'][normalized]):
            text = f'| {_cell(row.quantity)} | {row.unit} | {_fmt(row.rms)} |'
            if both:
                other = tables['balanced'][normalized][k]
                ratio = other.rms / row.rms if row.rms > 0.0 else float('nan')
                text += f' {_fmt(other.rms)} | {_fmt(ratio)} |'
            lines.append(text)
    return _markdown(lines)


# ------------------------------------------------------------------------------- RGGR


def _rggr_pivots(geometry):
    """Return Q1 = (0, l2, l1) and Q3 = l3 (sin beta, 0, cos beta) (seed 002 eqs. 15-19)."""
    sb, cb = math.sin(geometry.beta_rad), math.cos(geometry.beta_rad)
    return (np.array([0.0, geometry.l2_m, geometry.l1_m]),
            geometry.l3_m * np.array([sb, 0.0, cb]))


class _RggrModel:
    """An RGGR scene (and its balanced design) turned into drawable 3-D samples."""

    def __init__(self, scene, balanced=None):
        from mech_balance.core import rggr
        self.rggr = rggr
        self.scenes = {'original': scene}
        if balanced is not None:
            self.scenes['balanced'] = align_design(scene, balanced)
        self.streams = tuple(s for s in _streams_for(scene, needs(('driving_torque',)))
                             if s != 'point_masses')
        self.stream_outputs = self.table_outputs = ('driving_torque',)

    def evaluate(self, psi, outputs=None):
        """Return ``(None, {variant: RggrDynamics})`` at crank angles ``psi``."""
        return None, {v: self.rggr.dynamics(sc, psi) for v, sc in self.scenes.items()}

    def motion(self, state, dyns):
        """Return the :class:`_Motion` of the dynamics of every variant."""
        kin = dyns['original'].kinematics
        q1, q3 = _rggr_pivots(self.scenes['original'].geometry)
        n = kin.pin_b_m.shape[0]
        links = []
        if 'links' in self.streams:
            links = [np.stack([np.broadcast_to(q1, (n, 3)), kin.pin_b_m], axis=1),
                     np.stack([kin.pin_b_m, kin.pin_c_m], axis=1),
                     np.stack([np.broadcast_to(q3, (n, 3)), kin.pin_c_m], axis=1)]
        joints = np.zeros((n, 0, 3))
        if 'joints' in self.streams:
            joints = np.stack([kin.pin_b_m, kin.pin_c_m], axis=1)
        variants = []
        for v, sc in self.scenes.items():
            d = dyns[v]
            var = _Variant(v, force_N=d.shaking_force_N, moment_Nm=d.shaking_moment_Nm,
                           torque_Nm=d.driving_torque_Nm)
            if 'mass_centres' in self.streams:
                k = d.kinematics
                m = np.array([sc.crank_total().mass_kg, sc.coupler.mass_kg,
                              sc.output_total().mass_kg])
                c = np.stack([k.crank_centre_m, k.coupler_centre_m, k.output_centre_m], axis=1)
                system = np.einsum('k,pkd->pd', m, c) / m.sum()
                var.mass_centres = np.concatenate([c, system[:, None]], axis=1)
            variants.append(var)
        return _Motion(links, joints, variants)

    def layout(self, state, dyns, samples, balanced_source):
        """Return the 3-D :class:`_Layout` from a reference cycle."""
        sc = self.scenes['original']
        g = sc.geometry
        q1, q3 = _rggr_pivots(g)
        kin = dyns['original'].kinematics
        e = np.array([0.0, g.l2_m, 0.0])
        w3 = np.array([math.sin(g.beta_rad), 0.0, math.cos(g.beta_rad)])
        cloud = np.concatenate([kin.pin_b_m, kin.pin_c_m, [np.zeros(3), e, q1, q3]])
        size = float(np.max(np.ptp(cloud, axis=0))) or 1.0
        fmax = max(float(np.max(np.linalg.norm(d.shaking_force_N, axis=1)))
                   for d in dyns.values())
        nmax = max(float(np.max(np.linalg.norm(d.shaking_moment_Nm, axis=1)))
                   for d in dyns.values())
        fscale, mscale = _arrow_scale(size, fmax), _arrow_scale(size, nmax)
        ext = 0.25 * g.a1_m
        lo1, hi1 = min(0.0, g.l1_m) - ext, max(0.0, g.l1_m) + ext
        lo3, hi3 = min(0.0, g.l3_m) - ext, max(0.0, g.l3_m) + ext
        frame_strips = [np.array([np.zeros(3), e]),
                        np.array([e + [0.0, 0.0, lo1], e + [0.0, 0.0, hi1]]),
                        np.array([lo3 * w3, hi3 * w3])]
        names = ['crank', 'coupler', 'output']
        layout = _Layout(
            title=sc.name, dim=3, streams=self.streams, variants=tuple(self.scenes),
            size_m=size, pivot_m=np.zeros(3), pivot_name='O', link_names=names,
            link_colors=list(LINK_PALETTE[:3]), joint_names=['B', 'C'],
            frame_strips=frame_strips, frame_points=np.array([np.zeros(3), e, q1, q3]),
            frame_labels=['O', 'E', 'Q1', 'Q3'],
            centre_labels=['G1', 'G2', 'G3', 'G'],
            centre_colors=list(LINK_PALETTE[:3]) + [SYSTEM_CENTRE_COLOR],
            centre_radii=[CENTRE_RADIUS_SHARE * size] * 3 + [1.8 * CENTRE_RADIUS_SHARE * size],
            point_mass_kg={}, point_mass_radius_m={}, force_scale_m_per_N=fscale,
            moment_scale=mscale, arc_radius_m=0.0, bounds=None)
        if 'info' in self.streams:
            layout.text = _rggr_text(self, layout, dyns, samples, balanced_source)
        return layout


def _rggr_text(model, layout, dyns, samples, balanced_source):
    sc = model.scenes['original']
    both = 'balanced' in model.scenes
    norm = sc.normalization
    lines = [f'# {sc.name}: ' + ('original vs balanced' if both else 'original'), '',
             sc.description, '',
             f'Scene file `{sc.source}`; RGGR spatial four-bar (seed 002), crank at '
             f'{_fmt(sc.crank_speed_rad_s)} rad/s, assembly branch {sc.branch:+d}; {samples} '
             'samples per crank turn.']
    if both:
        lines.append(f'Balanced design: {balanced_source or model.scenes["balanced"].source}.')
    lines += ['', '## How to read the views', '',
              '* 3-D views, z up. Grey: the frame (common normal OE, crank axis through E, '
              'output axis through O); coloured lines: crank Q1-B, coupler B-C, output Q3-C.']
    if layout.on('mass_centres'):
        lines.append('* Dots G1, G2, G3: mass centres of crank (with its weight), coupler and '
                     'output link (with its weight); white G: the system mass centre.')
    if layout.on('shaking_force_arrow'):
        lines.append(f'* Orange arrow at O: the shaking force; {_fmt(layout.force_scale_m_per_N)}'
                     f' m per N (1 cm = {_fmt(0.01 / layout.force_scale_m_per_N)} N).')
    if layout.on('shaking_moment_arc'):
        lines.append(f'* Purple arrow at O: the shaking moment vector about O; '
                     f'{_fmt(layout.moment_scale)} m per N*m (1 cm = '
                     f'{_fmt(0.01 / layout.moment_scale)} N*m).')
    lines.append('* Plots: |shaking force| (N), |shaking moment| about O (N*m), driving torque '
                 '(N*m); orange = original, green = balanced. Timelines: `crank_angle` in whole '
                 f'degrees, `time` in seconds at {_fmt(abs(sc.crank_speed_rad_s))} rad/s.')
    lines += ['', '## Design (links with their balancing weights, about Q1 and Q3, SI)', '',
              '| design | crank mass kg | crank centre uvw m | output mass kg | '
              'output centre uvw m | I_1wu, I_1vw, I_3wu, I_3vw kg m^2 |',
              '|---|---:|---|---:|---|---|']
    for v, s in model.scenes.items():
        c, o = s.crank_total(), s.output_total()
        lines.append(f'| {v} | {_fmt(c.mass_kg)} | '
                     + ', '.join(_fmt(x) for x in c.centre_uvw_m) + f' | {_fmt(o.mass_kg)} | '
                     + ', '.join(_fmt(x) for x in o.centre_uvw_m) + ' | '
                     + ', '.join(_fmt(x) for x in s.inertia_parameters_kg_m2()) + ' |')
    quantities = (('|shaking force|', 'N', 'm_o1 a1 omega^2',
                   lambda d: d.shaking_force_N, normalize_force),
                  ('|shaking moment| about O', 'N*m', 'm_o1 a1^2 omega^2',
                   lambda d: d.shaking_moment_Nm, normalize_moment),
                  ('driving torque', 'N*m', 'm_o1 a1^2 omega^2',
                   lambda d: d.driving_torque_Nm, normalize_moment))
    head = '| quantity | unit | original |' + (
        ' balanced | balanced / original |' if both else '')
    lines += ['', '## RMS over one crank turn (true RMS, mech_balance.conventions)', '',
              head, '|---|---|---:|' + ('---:|---:|' if both else '')]
    for normalized in (False, True):
        for name, si, paper, get, scale in quantities:
            vals = {}
            for v in model.scenes:
                x = get(dyns[v])
                if normalized:
                    x = scale(x, norm['mass_kg'], norm['length_m'], norm['omega_rad_s'])
                vals[v] = float(rms(x))
            text = (f'| {_cell(name)} | {paper if normalized else si} | '
                    f'{_fmt(vals["original"])} |')
            if both:
                ratio = vals['balanced'] / vals['original'] if vals['original'] else float('nan')
                text += f' {_fmt(vals["balanced"])} | {_fmt(ratio)} |'
            lines.append(text)
    return _markdown(lines)


def _model_for(scene, balanced):
    if getattr(scene, 'kind', 'planar') == 'rggr':
        return _RggrModel(scene, balanced)
    return _PlanarModel(scene, balanced)


# ------------------------------------------------------------------------------- logging


def _index(degrees, seconds):
    return [rr.TimeColumn('crank_angle', sequence=degrees),
            rr.TimeColumn('time', duration=seconds)]


def _archetypes(dim):
    if dim == 2:
        return rr.Points2D, rr.LineStrips2D, rr.Arrows2D
    return rr.Points3D, rr.LineStrips3D, rr.Arrows3D


def _log_info(rec, layout, motion=None, index=None):
    if motion is None:
        rec.log('info', rr.TextDocument(layout.text, media_type=rr.MediaType.MARKDOWN),
                static=True)


def _log_frame(rec, layout, motion=None, index=None):
    if motion is not None:
        return
    points, strips, _ = _archetypes(layout.dim)
    if layout.frame_strips:
        rec.log('rig/frame', strips(layout.frame_strips, colors=[FRAME_COLOR],
                                    radii=[LINE_RADIUS_UI]), static=True)
    rec.log('rig/pivots', points(layout.frame_points, labels=layout.frame_labels,
                                 colors=[FRAME_COLOR], radii=[JOINT_RADIUS_UI]), static=True)


def _log_links(rec, layout, motion=None, index=None):
    _, strips, _ = _archetypes(layout.dim)
    if motion is None:
        rec.log('rig/links', strips.from_fields(colors=layout.link_colors,
                                                labels=layout.link_names,
                                                radii=[LINE_RADIUS_UI]), static=True)
        return
    n = len(motion.links)
    flat = [motion.links[i][k] for k in range(motion.size) for i in range(n)]
    rec.send_columns('rig/links', index,
                     strips.columns(strips=flat).partition(np.full(motion.size, n)))


def _log_joints(rec, layout, motion=None, index=None):
    points, _, _ = _archetypes(layout.dim)
    if motion is None:
        rec.log('rig/joints', points.from_fields(colors=[JOINT_COLOR], radii=[JOINT_RADIUS_UI]),
                static=True)
        return
    n = motion.joints.shape[1]
    rec.send_columns('rig/joints', index, points.columns(
        positions=motion.joints.reshape(-1, layout.dim)).partition(np.full(motion.size, n)))


def _log_mass_centres(rec, layout, motion=None, index=None):
    points, _, _ = _archetypes(layout.dim)
    for v in (motion.variants if motion is not None else layout.variants):
        path = f'{v if motion is None else v.name}/mass_centres'
        if motion is None:
            rec.log(path, points.from_fields(colors=layout.centre_colors,
                                             labels=layout.centre_labels,
                                             radii=layout.centre_radii), static=True)
            continue
        k = v.mass_centres.shape[1]
        rec.send_columns(path, index, points.columns(
            positions=v.mass_centres.reshape(-1, layout.dim)).partition(
                np.full(motion.size, k)))


def _log_point_masses(rec, layout, motion=None, index=None):
    if layout.dim != 2:
        return
    for v in (motion.variants if motion is not None else layout.variants):
        if motion is None:
            kg = layout.point_mass_kg[v]
            rec.log(f'{v}/point_masses', rr.Points2D.from_fields(
                radii=layout.point_mass_radius_m[v],
                colors=[POSITIVE_MASS_COLOR if m >= 0.0 else NEGATIVE_MASS_COLOR for m in kg],
                labels=[f'{m * 1e3:+.4g} g' for m in kg], show_labels=False), static=True)
            continue
        k = v.point_masses.shape[1]
        rec.send_columns(f'{v.name}/point_masses', index, rr.Points2D.columns(
            positions=v.point_masses.reshape(-1, 2)).partition(np.full(motion.size, k)))


def _log_shaking_force_arrow(rec, layout, motion=None, index=None):
    _, _, arrows = _archetypes(layout.dim)
    for v in (motion.variants if motion is not None else layout.variants):
        if motion is None:
            rec.log(f'{v}/shaking_force', arrows.from_fields(
                origins=[layout.pivot_m], colors=[FORCE_COLOR], radii=[LINE_RADIUS_UI]),
                static=True)
            continue
        rec.send_columns(f'{v.name}/shaking_force', index, arrows.columns(
            vectors=v.force_N * layout.force_scale_m_per_N))


def _moment_arc(pivot, moment_Nm, scale_deg_per_Nm, radius):
    """Return the arc ``(p, ARC_POINTS, 2)`` and arrow head ``(p, 3, 2)`` of planar moments."""
    limit = math.radians(MOMENT_ARC_LIMIT_DEG)
    sweep = np.clip(np.radians(moment_Nm * scale_deg_per_Nm), -limit, limit)
    start = 0.5 * math.pi
    t = np.linspace(0.0, 1.0, ARC_POINTS)
    centre = complex(pivot[0], pivot[1])
    arc = centre + radius * np.exp(1j * (start + sweep[:, None] * t[None, :]))
    tip_dir = np.exp(1j * (start + sweep))
    tangent = np.sign(sweep) * 1j * tip_dir
    head = MOMENT_HEAD_SHARE * radius * np.minimum(1.0, np.abs(sweep) / 0.5)
    tip = centre + radius * tip_dir
    barbs = [tip - head * tangent * np.exp(1j * math.radians(a)) for a in (30.0, -30.0)]
    return _c2(arc), _c2(np.stack([barbs[0], tip, barbs[1]], axis=1))


def _log_shaking_moment_arc(rec, layout, motion=None, index=None):
    for v in (motion.variants if motion is not None else layout.variants):
        path = f'{v if motion is None else v.name}/shaking_moment'
        if layout.dim == 3:
            if motion is None:
                rec.log(path, rr.Arrows3D.from_fields(origins=[layout.pivot_m],
                                                      colors=[MOMENT_COLOR],
                                                      radii=[LINE_RADIUS_UI]), static=True)
            else:
                rec.send_columns(path, index, rr.Arrows3D.columns(
                    vectors=v.moment_Nm * layout.moment_scale))
            continue
        if motion is None:
            rec.log(path, rr.LineStrips2D.from_fields(colors=[MOMENT_COLOR],
                                                      radii=[LINE_RADIUS_UI]), static=True)
            continue
        arc, head = _moment_arc(layout.pivot_m, v.moment_Nm, layout.moment_scale,
                                layout.arc_radius_m)
        flat = [s for k in range(motion.size) for s in (arc[k], head[k])]
        rec.send_columns(path, index, rr.LineStrips2D.columns(strips=flat).partition(
            np.full(motion.size, 2)))


def _series(layout, motion, stream):
    for v in motion.variants:
        if stream == 'shaking_force_plot':
            yield v.name, np.linalg.norm(v.force_N, axis=1)
        elif stream == 'shaking_moment_plot':
            m = v.moment_Nm
            yield v.name, np.linalg.norm(m, axis=1) if m.ndim == 2 else m
        elif v.torque_Nm is not None:
            yield v.name, v.torque_Nm


def _log_plot(stream, rec, layout, motion=None, index=None):
    entity = dict(_PLOTS)[stream]
    if motion is None:
        for v in layout.variants:
            rec.log(f'plots/{entity}/{v}', rr.SeriesLines(colors=[SERIES_COLORS[v]], names=[v],
                                                          widths=[2.0]), static=True)
        return
    for v, values in _series(layout, motion, stream):
        rec.send_columns(f'plots/{entity}/{v}', index,
                         rr.Scalars.columns(scalars=np.asarray(values, dtype=np.float64)))


def _log_shaking_force_plot(rec, layout, motion=None, index=None):
    _log_plot('shaking_force_plot', rec, layout, motion, index)


def _log_shaking_moment_plot(rec, layout, motion=None, index=None):
    _log_plot('shaking_moment_plot', rec, layout, motion, index)


def _log_driving_torque_plot(rec, layout, motion=None, index=None):
    _log_plot('driving_torque_plot', rec, layout, motion, index)


_LOGGERS = {
    'info': _log_info, 'frame': _log_frame, 'links': _log_links, 'joints': _log_joints,
    'mass_centres': _log_mass_centres, 'point_masses': _log_point_masses,
    'shaking_force_arrow': _log_shaking_force_arrow,
    'shaking_moment_arc': _log_shaking_moment_arc,
    'shaking_force_plot': _log_shaking_force_plot,
    'shaking_moment_plot': _log_shaking_moment_plot,
    'driving_torque_plot': _log_driving_torque_plot,
}
"""One ``_log_<stream>(rec, layout, motion=None, index=None)`` per stream: without a motion
it logs the stream's static part, with one it sends the motion's columns."""


def _log_static(rec, layout):
    if layout.dim == 3:
        rec.log('/', rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    else:
        # rerun's 2-D views draw y downwards (rerun-io/rerun#1387): mirror the drawing so
        # that the scene's y axis points up; the logged data stay in the scene's frame.
        for root in ('rig',) + layout.variants:
            rec.log(root, rr.Transform3D(scale=Y_UP_SCALE), static=True)
    for s in layout.streams:
        _LOGGERS[s](rec, layout)


def _log_motion(rec, layout, motion, degrees, seconds):
    index = _index(degrees, seconds)
    for s in layout.streams:
        _LOGGERS[s](rec, layout, motion, index)


# ------------------------------------------------------------------------------- blueprint


def _spatial_name(layout, variant):
    parts = [variant]
    if layout.on('shaking_force_arrow'):
        parts.append(f'force arrow 1 cm = {_fmt(0.01 / layout.force_scale_m_per_N)} N')
    if layout.on('shaking_moment_arc'):
        parts.append(f'moment arc 90 deg = {_fmt(90.0 / layout.moment_scale)} N*m'
                     if layout.dim == 2 else
                     f'moment arrow 1 cm = {_fmt(0.01 / layout.moment_scale)} N*m')
    return ' | '.join(parts)


def blueprint(layout):
    """Return the default blueprint: rigs side by side, text below, plots on the right."""
    spatial = []
    shown = {'frame', 'links', 'joints', 'mass_centres', 'point_masses',
             'shaking_force_arrow', 'shaking_moment_arc'}
    if shown & set(layout.streams):
        for v in layout.variants:
            contents = ['/rig/**', f'/{v}/**']
            if layout.dim == 2:
                (x0, x1), (y0, y1) = layout.bounds
                spatial.append(rrb.Spatial2DView(
                    origin='/', contents=contents, name=_spatial_name(layout, v),
                    visual_bounds=rrb.VisualBounds2D(x_range=[x0, x1], y_range=[-y1, -y0])))
            else:
                spatial.append(rrb.Spatial3DView(origin='/', contents=contents,
                                                 name=_spatial_name(layout, v)))
    moment = ('|shaking moment| about O (N*m)' if layout.dim == 3 else
              f'shaking moment about {layout.pivot_name} (N*m)')
    titles = {'shaking_force_plot': '|shaking force| (N)', 'shaking_moment_plot': moment,
              'driving_torque_plot': 'driving torque (N*m)'}
    plots = [rrb.TimeSeriesView(origin=f'/plots/{entity}', name=titles[s],
                                plot_legend=rrb.PlotLegend(visible=True))
             for s, entity in _PLOTS if layout.on(s)]
    left = []
    if spatial:
        left.append(rrb.Horizontal(*spatial) if len(spatial) > 1 else spatial[0])
    if layout.on('info'):
        left.append(rrb.TextDocumentView(origin='/info', name='scene, design and RMS'))
    columns = []
    if left:
        columns.append(rrb.Vertical(*left, row_shares=[3, 2][:len(left)])
                       if len(left) > 1 else left[0])
    if plots:
        columns.append(rrb.Vertical(*plots))
    root = rrb.Horizontal(*columns, column_shares=[3, 2][:len(columns)])
    return rrb.Blueprint(
        root, rrb.BlueprintPanel(state='collapsed'), rrb.SelectionPanel(state='collapsed'),
        rrb.TimePanel(state='expanded', timeline='crank_angle', play_state='playing',
                      loop_mode='all'))


def application_id(scene):
    """Return the rerun application id of a scene's recordings (its blueprint's key)."""
    return f'{APPLICATION_ID}_' + re.sub(r'[^A-Za-z0-9_-]+', '_', scene.name)


def check_output_path(path, field, create_dir=False):
    """
    Return the recording file ``path`` as a ``Path``, checked before anything is computed.

    :func:`mech_balance.paths.check_output_path` with the suffix :data:`RRD_SUFFIX`; ``field``
    names the caller's option or parameter (``--out``, ``recording_path``) in the error.
    """
    return paths.check_output_path(path, field, (RRD_SUFFIX,), create_dir=create_dir)


def _open(path, scene, layout):
    rec = rr.RecordingStream(application_id(scene))
    rec.save(str(path))
    _start(rec, scene, layout)
    return rec


def _start(rec, scene, layout):
    """Send the blueprint, the recording's name and the static geometry."""
    rec.send_blueprint(blueprint(layout), make_active=True, make_default=True)
    rec.send_recording_name(f'{scene.name}: ' + ' vs '.join(layout.variants))
    _log_static(rec, layout)


# ------------------------------------------------------------------------------- offline


def record(path, scene, balanced=None, cycles=1, samples=None, balanced_source=None, *,
           field='path'):
    """
    Write an offline recording of ``scene`` (and ``balanced``) to ``path`` (``.rrd``).

    ``balanced`` is a scene with the same geometry and other inertias (or None for the
    original alone); ``samples`` per crank turn (a divisor of 360, default the scene's) over
    ``cycles`` turns.  One turn is computed and repeated, since the rig's motion is periodic
    in the crank angle.  ``path`` is checked first by :func:`check_output_path` (its errors
    name ``field``).  Returns a :class:`RecordingSummary`.
    """
    t0 = time.perf_counter()
    path = check_output_path(path, field)
    samples = getattr(scene, 'samples', 360) if samples is None else samples
    _check_samples(samples, cycles)
    model = _model_for(scene, balanced)
    psi0 = getattr(scene, 'assembly_crank_angle_rad', 0.0)
    psi = _psi_grid(psi0, scene.crank_speed_rad_s, int(samples))
    state, wrenches = model.evaluate(psi, model.table_outputs)
    layout = model.layout(state, wrenches, int(samples), balanced_source)
    motion = model.motion(state, wrenches).tiled(int(cycles))
    degrees, seconds = _ticks(psi0, scene.crank_speed_rad_s, int(samples), int(cycles))
    # Encoded into one binary stream (its reads do not concatenate: read it once, at the end)
    # that this process writes atomically (atomic.py): a write error is raised here (rerun's
    # own file sink blocks on one) and an existing file survives any failure, SIGKILL too.
    rec = rr.RecordingStream(application_id(scene))
    stream = rec.binary_stream()
    try:
        _start(rec, scene, layout)
        _log_motion(rec, layout, motion, degrees, seconds)
        data = stream.read(flush=True) or b''
    finally:
        rec.disconnect()
    atomic.write_bytes_atomic(path, data)
    return RecordingSummary(
        path=Path(path), size_bytes=os.path.getsize(path), samples_per_cycle=int(samples),
        cycles=int(cycles), rows=int(samples) * int(cycles),
        entity_paths=tuple(entity_paths(layout)), variants=layout.variants,
        seconds=time.perf_counter() - t0)


def entity_paths(layout):
    """Return the entity paths a layout logs (static and animated), sorted."""
    paths = set()
    per_variant = {'mass_centres': 'mass_centres', 'point_masses': 'point_masses',
                   'shaking_force_arrow': 'shaking_force',
                   'shaking_moment_arc': 'shaking_moment'}
    for s in layout.streams:
        if s == 'info':
            paths.add('/info')
        elif s == 'frame':
            paths |= {'/rig/pivots'} | ({'/rig/frame'} if layout.frame_strips else set())
        elif s in ('links', 'joints'):
            paths.add(f'/rig/{s}')
        elif s in per_variant:
            if s == 'point_masses' and layout.dim != 2:
                continue
            paths |= {f'/{v}/{per_variant[s]}' for v in layout.variants}
        else:
            paths |= {f'/plots/{dict(_PLOTS)[s]}/{v}' for v in layout.variants}
    return sorted(paths)


# ------------------------------------------------------------------------------- live


class LiveRecorder:
    """
    Write the recording of a running rig sample by sample (used by the rig node).

    ``LiveRecorder(path, scene, balanced=None)`` opens ``path`` (``.rrd``, checked by
    :func:`check_output_path`, whose errors name ``field``), lays it out and logs the static
    geometry, the blueprint and the text panel from one reference turn
    (``scene.samples`` angles).  :meth:`log_sample` appends samples; :meth:`close` (also run
    at interpreter exit) flushes and closes the file, is idempotent and safe to call from a
    signal handler or another thread.  Until then the samples go to ``.NAME.partial-XXXXXXXX``
    next to ``path`` (:mod:`mech_balance.atomic`); :meth:`close` renames it over ``path``, so
    an existing recording is replaced only by a complete one.
    """

    def __init__(self, path, scene, balanced=None, balanced_source=None, *, field='path'):
        self.path = check_output_path(path, field)
        self.scene = scene
        self._model = _model_for(scene, balanced)
        samples = getattr(scene, 'samples', 360)
        psi0 = getattr(scene, 'assembly_crank_angle_rad', 0.0)
        psi = _psi_grid(psi0, scene.crank_speed_rad_s, samples)
        state, wrenches = self._model.evaluate(psi, self._model.table_outputs)
        self.layout = self._model.layout(state, wrenches, samples, balanced_source)
        self._lock = threading.Lock()
        self._owner = None
        self._closed = False
        self._close_requested = False
        self.samples_logged = 0
        self._t0 = None
        # visibly partial (.NAME.partial-XXXXXXXX) until close() renames it over the path
        self._partial = atomic.partial_path(self.path)
        try:
            self._rec = _open(self._partial, scene, self.layout)
        except BaseException:
            atomic.discard(self._partial)
            raise
        atexit.register(self.close)

    @property
    def closed(self):
        """Return whether the file has been closed."""
        return self._closed

    def log_sample(self, time_s, crank_angle_rad, state=None, wrenches=None,
                   balanced_wrenches=None):
        """
        Append one sample (scalars) or a batch ``(p,)`` of samples; return the count logged.

        ``crank_angle_rad`` is the cumulative crank angle (the ``crank_angle`` timeline shows
        it rounded to whole degrees), ``time_s`` the rig's clock in seconds (the ``time``
        timeline counts from the first sample logged).  For a planar scene,
        ``state`` (a :class:`~mech_balance.kinematics.KinematicState` at those angles) and
        the original's ``wrenches`` may be passed to save recomputing them; whatever is
        missing (the balanced wrenches too) is computed here.  RGGR scenes compute their
        closed-form dynamics here and take no state.  After :meth:`close` nothing is logged
        and 0 is returned.
        """
        t = np.atleast_1d(np.asarray(time_s, dtype=float)).ravel()
        psi = np.atleast_1d(np.asarray(crank_angle_rad, dtype=float)).ravel()
        if t.shape != psi.shape or t.size == 0:
            raise ValueError(f'time_s: got shape {t.shape}, expected the shape of '
                             f'crank_angle_rad {psi.shape} (one time per angle, >= 1)')
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(psi))):
            raise ValueError('time_s, crank_angle_rad: got non-finite values, expected finite')
        if state is not None and state.size != psi.size:
            raise ValueError(f'state: got {state.size} angles, expected {psi.size}')
        if self._closed or self._close_requested:
            return 0
        model = self._model
        if isinstance(model, _RggrModel):
            state, wr = model.evaluate(psi)
        else:
            if state is None:
                psi0 = self.scene.assembly_crank_angle_rad
                state = model.linkage.solve(
                    psi0 + np.mod(psi - psi0, 2.0 * math.pi),
                    need_acc='accelerations' in needs(model.stream_outputs))
            wr = model.wrenches(state, model.stream_outputs,
                                {'original': wrenches, 'balanced': balanced_wrenches})
        motion = model.motion(state, wr)
        degrees = np.round(np.degrees(psi)).astype(np.int64)
        if not self._lock.acquire(timeout=CLOSE_TIMEOUT_S):
            return 0
        self._owner = threading.get_ident()
        try:
            if self._closed:
                return 0
            if self._t0 is None:
                self._t0 = float(t[0])
            _log_motion(self._rec, self.layout, motion, degrees, t - self._t0)
            self.samples_logged += psi.size
        finally:
            self._owner = None
            self._lock.release()
        if self._close_requested:
            self.close()
        return psi.size

    def close(self):
        """Flush and close the file (idempotent; safe from signal handlers and atexit)."""
        if self._closed:
            return
        self._close_requested = True
        if self._owner == threading.get_ident():
            return  # interrupted a log call on this thread: it closes the file when done
        if not self._lock.acquire(timeout=CLOSE_TIMEOUT_S):
            return
        try:
            if not self._closed:
                self._closed = True
                try:
                    self._rec.flush(timeout_sec=CLOSE_TIMEOUT_S)
                finally:
                    self._rec.disconnect()
                    atexit.unregister(self.close)
                # complete: replace the target (a failed flush leaves the .partial file)
                atomic.commit(self._partial, self.path)
        finally:
            self._lock.release()

    def __enter__(self):
        """Return the recorder (``with LiveRecorder(...) as rec:``)."""
        return self

    def __exit__(self, *exc):
        """Close the file."""
        self.close()


# ------------------------------------------------------------------------------- reading


@dataclass
class EntityData:
    """
    One entity of a recording read back: its static components and its time series.

    ``static`` maps a component (``'Points2D:colors'``) to its value (a list);
    ``columns`` maps a component to one value per logged row; ``index`` maps a timeline to
    its values per row (``crank_angle``: int degrees, ``time``: float seconds).  Rows are
    in time order.
    """

    static: dict
    columns: dict
    index: dict

    @property
    def rows(self):
        """Return the number of logged (non-static) rows."""
        return len(next(iter(self.index.values()))) if self.index else 0


def read_recording(path):
    """
    Return ``{entity_path: EntityData}`` of the recording in an ``.rrd`` file.

    Uses rerun's own loader (``rerun.chunk.RrdReader``), so a file that this returns is one
    the viewer reads.
    """
    from rerun.chunk import RrdReader
    entities = {}
    for chunk in RrdReader(str(path)).stream():
        batch = chunk.to_record_batch()
        data = entities.setdefault(chunk.entity_path, EntityData({}, {}, {}))
        names = [n for n in batch.schema.names if not n.startswith('rerun.controls')]
        if chunk.is_static:
            for n in names:
                data.static[n] = batch.column(n).to_pylist()[-1]
            continue
        timelines = set(chunk.timeline_names)
        for n in names:
            col = batch.column(n)
            if n in timelines:
                values = col.to_numpy()
                if values.dtype.kind == 'm':
                    values = values.astype('timedelta64[ns]').astype(np.int64) * 1e-9
                data.index.setdefault(n, []).append(np.asarray(values))
            else:
                data.columns.setdefault(n, []).extend(col.to_pylist())
    for data in entities.values():
        data.index = {k: np.concatenate(v) for k, v in data.index.items()}
        key = data.index.get('time', data.index.get('crank_angle'))
        if key is not None and np.any(np.diff(key) < 0):
            order = np.argsort(key, kind='stable')
            data.index = {k: v[order] for k, v in data.index.items()}
            data.columns = {k: [v[i] for i in order] for k, v in data.columns.items()}
    return entities


def read_blueprint_views(path):
    """Return ``[(kind, name, origin)]`` of the views in an ``.rrd`` file's blueprint."""
    from rerun.chunk import RrdReader
    reader = RrdReader(str(path))
    views = []
    for store in reader.blueprints():
        for chunk in reader.stream(store=store):
            batch = chunk.to_record_batch()
            if 'ViewBlueprint:class_identifier' not in batch.schema.names:
                continue
            for kind, name, origin in zip(
                    batch.column('ViewBlueprint:class_identifier').to_pylist(),
                    batch.column('ViewBlueprint:display_name').to_pylist(),
                    batch.column('ViewBlueprint:space_origin').to_pylist()):
                views.append((kind[0], name[0] if name else '', origin[0] if origin else ''))
    return sorted(views)
