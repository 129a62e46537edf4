"""Logging a laid-out recording to rerun: the static geometry, then the samples."""

import math
import re

from mech_balance import paths
from mech_balance.viz.blueprint import blueprint
from mech_balance.viz.drawing import DEGREE_TIMELINE
from mech_balance.viz.labels import label_point_px, label_size_px, place_labels
from mech_balance.viz.plots import ANGLE_ROOT, furniture, plot_values
from mech_balance.viz.style import (
    ADDED_ALPHA, ADDED_DRAW_ORDER, ARC_POINTS, ARROW_3D_RADIUS_SHARE, CENTRE_RADIUS_SHARE,
    DIAL_COLOR, DIAL_POINTS, FORCE_COLOR, FRAME_COLOR, FRAME_RADIUS_3D_SHARE, FRAME_RADIUS_UI,
    GRID_COLOR, GRID_RADIUS_UI, JOINT_COLOR, JOINT_RADIUS_3D_SHARE, JOINT_RADIUS_UI,
    LINE_RADIUS_UI, LINK_RADIUS_3D_SHARE, MOMENT_ARC_LIMIT_DEG, MOMENT_COLOR, MOMENT_HEAD_SHARE,
    NEGATIVE_MASS_COLOR, PLANE_ALPHA, PLOT_GRID_COLOR, POINT_MASS_RADIUS_SHARE,
    POSITIVE_MASS_COLOR, SCALE_COLOR, SERIES_COLORS, SERIES_WIDTHS, SYSTEM_CENTRE_COLOR
)
import numpy as np
import rerun as rr


APPLICATION_ID = 'mech_balance'
"""Prefix of the rerun application id (the scene name follows, so layouts never clash)."""
RRD_SUFFIX = '.rrd'
"""What the name of a recording file ends in (rerun's format)."""
Y_UP_SCALE = (1.0, -1.0, 1.0)
"""Scale of the 2-D drawing roots that shows the scene's y axis upwards."""


def application_id(scene):
    """Return the rerun application id of a scene's recordings (its blueprint's key)."""
    return f'{APPLICATION_ID}_' + re.sub(r'[^A-Za-z0-9_-]+', '_', scene.name)


def check_output_path(path, field, create_dir=False):
    """Return the ``.rrd`` file ``path`` checked (:func:`mech_balance.paths.check_output_path`)."""
    return paths.check_output_path(path, field, (RRD_SUFFIX,), create_dir=create_dir)


def time_index(degrees, seconds):
    """Return the time columns of a batch: whole degrees turned (twice) and seconds."""
    return [rr.TimeColumn(DEGREE_TIMELINE, sequence=degrees),
            rr.TimeColumn('crank_angle', sequence=degrees),
            rr.TimeColumn('time', duration=seconds)]


def grid_strips(box, spacing):
    """Return the lines ``[(2, 3)]`` of a grid on z = 0 over ``box`` (x0, x1, y0, y1)."""
    x0, x1, y0, y1 = box
    xs = x0 + spacing * np.arange(round((x1 - x0) / spacing) + 1)
    ys = y0 + spacing * np.arange(round((y1 - y0) / spacing) + 1)
    return [np.array([[x, y0, 0.0], [x, y1, 0.0]]) for x in xs] + \
        [np.array([[x0, y, 0.0], [x1, y, 0.0]]) for y in ys]


def view_coords(layout, a):
    """Return points ``(..., 3)`` as the view's coordinates (2-D: x, y)."""
    a = np.asarray(a, dtype=float)
    return a[..., :2] if layout.dim == 2 else a


def uniform_strips(strips):
    """Return polylines ``[(p, k_i, d)]`` as one array ``(p * n, max k_i, d)``, end-padded."""
    k = max(s.shape[1] for s in strips)
    out = np.stack([np.concatenate([s, np.repeat(s[:, -1:], k - s.shape[1], axis=1)], axis=1)
                    for s in strips], axis=1)                     # (p, n, k, d)
    return out.reshape((-1,) + out.shape[2:])


def archetypes(dim):
    if dim == 2:
        return rr.Points2D, rr.LineStrips2D, rr.Arrows2D
    return rr.Points3D, rr.LineStrips3D, rr.Arrows3D


def line_radius(layout, share, ui):
    """Return a line or point radius: 2-D in ui points, 3-D in metres (tubes, spheres)."""
    return ui if layout.dim == 2 else share * layout.size_m


def log_static(rec, layout):
    """Log the static geometry and styles of a recording."""
    points, strips, arrows = archetypes(layout.dim)
    size = layout.size_m
    thin = line_radius(layout, FRAME_RADIUS_3D_SHARE, FRAME_RADIUS_UI)
    joint = line_radius(layout, JOINT_RADIUS_3D_SHARE, JOINT_RADIUS_UI)

    def static(path, archetype):
        rec.log(path, archetype, static=True)
    if layout.dim == 3:
        static('/', rr.ViewCoordinates.RIGHT_HAND_Z_UP)
    else:       # rerun's 2-D views draw y down (rerun-io/rerun#1387): mirror the drawing
        for root in ('rig', 'inset') + layout.variants:
            static(root, rr.Transform3D(scale=Y_UP_SCALE))
    for view in layout.variants + (('inset',) if layout.inset is not None else ()):
        static(f'{view}/labels', points.from_fields(radii=[0.0], show_labels=True))
    if layout.grid_box is not None:
        static('rig/grid', strips(grid_strips(layout.grid_box, layout.grid_m),
                                  colors=[GRID_COLOR], radii=[GRID_RADIUS_UI]))
    if layout.on('info'):
        static('info', rr.TextDocument(layout.text, media_type=rr.MediaType.MARKDOWN))
    if layout.on('frame'):
        if layout.frame_strips:
            static('rig/frame', strips([view_coords(layout, s) for s in layout.frame_strips],
                                       colors=[FRAME_COLOR], radii=[thin]))
        static('rig/pivots', points(view_coords(layout, layout.frame_points),
                                    colors=[FRAME_COLOR], radii=[joint]))
    if layout.on('links'):
        static('rig/links', strips.from_fields(colors=layout.link_colors, radii=[
            line_radius(layout, LINK_RADIUS_3D_SHARE, LINE_RADIUS_UI)]))
    if layout.on('joints'):
        static('rig/joints', points.from_fields(colors=[JOINT_COLOR], radii=[joint]))
    if layout.scale_bar is not None:
        static('rig/scale', strips([view_coords(layout, layout.scale_bar[0])],
                                   colors=[SCALE_COLOR], radii=[FRAME_RADIUS_UI]))
    if layout.dim == 2 and layout.dial_radius_m > 0.0:
        t = np.linspace(0.0, 2.0 * math.pi, DIAL_POINTS)
        circle = layout.gauge_m[:2] + layout.dial_radius_m * np.stack([np.cos(t), np.sin(t)],
                                                                      axis=-1)
        static('rig/gauge', rr.LineStrips2D([circle], colors=[DIAL_COLOR],
                                            radii=[FRAME_RADIUS_UI]))
    for v in layout.variants:
        if layout.on('mass_centres'):
            n = len(layout.link_names)
            static(f'{v}/mass_centres', points.from_fields(
                colors=list(layout.link_colors) + [SYSTEM_CENTRE_COLOR],
                radii=[CENTRE_RADIUS_SHARE * size] * n + [1.8 * CENTRE_RADIUS_SHARE * size]))
        added = [(i, a) for i, b in enumerate(layout.drawings[v].bodies) for a in b.added]
        behind = {'draw_order': ADDED_DRAW_ORDER} if layout.dim == 2 else {}
        if layout.has_added and added:      # see-through discs in their link's colour
            static(f'{v}/counterweights', points.from_fields(
                radii=[a.radius_m for _, a in added],
                colors=[layout.link_colors[i] + (ADDED_ALPHA,) for i, _ in added],
                labels=[f'{a.name}: {a.mass_kg:.3g} kg' for _, a in added], show_labels=False,
                **behind))
            static(f'{v}/counterweight_planes', strips.from_fields(
                colors=[layout.link_colors[i] + (PLANE_ALPHA,) for i, _ in added],
                radii=[thin], **behind))
        moved = (layout.changes or {}).get(v, [])
        if layout.on('links') and moved:
            static(f'{v}/mass_changes', strips.from_fields(
                colors=[layout.link_colors[i] for i, _ in moved], radii=[thin]))
        if layout.has_point_masses:
            kg = np.array([m for b in layout.drawings[v].bodies for m, _ in b.point_masses])
            mmax = max(max(abs(m) for dr in layout.drawings.values() for b in dr.bodies
                           for m, _ in b.point_masses), 1e-300)
            static(f'{v}/point_masses', points.from_fields(
                radii=POINT_MASS_RADIUS_SHARE * size * np.sqrt(np.abs(kg) / mmax),
                colors=[POSITIVE_MASS_COLOR if m >= 0.0 else NEGATIVE_MASS_COLOR for m in kg],
                labels=[f'{m * 1e3:+.4g} g' for m in kg], show_labels=False))
        if layout.on('shaking_force_arrow'):
            static(f'{v}/shaking_force', arrows.from_fields(
                origins=[view_coords(layout, layout.gauge_m)], colors=[FORCE_COLOR],
                radii=[line_radius(layout, ARROW_3D_RADIUS_SHARE, LINE_RADIUS_UI)]))
        if layout.on('shaking_moment_arc') and layout.dim == 2:
            static(f'{v}/shaking_moment', rr.LineStrips2D.from_fields(
                colors=[MOMENT_COLOR], radii=[LINE_RADIUS_UI]))
        elif layout.on('shaking_moment_arc'):
            static(f'{v}/shaking_moment', rr.Arrows3D.from_fields(
                origins=[layout.gauge_m], colors=[MOMENT_COLOR],
                radii=[ARROW_3D_RADIUS_SHARE * size]))
    for p in layout.plots:
        for v in layout.variants:
            static(f'plots/{p.entity}/{v}', rr.SeriesLines(
                colors=[SERIES_COLORS[v]], names=[v], widths=[SERIES_WIDTHS[v]]))
        if not layout.live:
            log_angle_plot(rec, layout, p)


def log_angle_plot(rec, layout, plot):
    """Log a plot's static 2-D drawing over the crank angle (:mod:`.plots`)."""
    root = f'{ANGLE_ROOT}/{plot.entity}'
    grid, frame, texts = furniture(plot.axes, plot.unit, angle_name(layout))
    rec.log(f'{root}/grid', rr.LineStrips2D(grid, colors=[PLOT_GRID_COLOR], radii=[
        GRID_RADIUS_UI], draw_order=1.0), static=True)
    rec.log(f'{root}/axes', rr.LineStrips2D(frame, colors=[SCALE_COLOR], radii=[
        GRID_RADIUS_UI], draw_order=2.0), static=True)
    colors = [SCALE_COLOR] * len(texts)
    if len(layout.variants) > 1:        # a legend in the top margin, right
        x = plot.axes.box_px[2]
        for v in layout.variants[::-1]:
            w = label_size_px(v)[0]
            texts.append((label_point_px((x - 0.5 * w, 12.0), v), v))
            colors.append(SERIES_COLORS[v])
            x -= w + 8.0
    rec.log(f'{root}/labels', rr.Points2D([t[0] for t in texts], labels=[t[1] for t in texts],
                                          colors=colors, radii=[0.0], show_labels=True),
            static=True)
    for order, v in enumerate(('balanced', 'original')):     # the thin original on top
        if v in plot.curves:
            rec.log(f'{root}/{v}', rr.LineStrips2D(
                [plot.curves[v]], colors=[SERIES_COLORS[v]], draw_order=10.0 + order,
                radii=[rr.components.Radius.ui_points(0.5 * SERIES_WIDTHS[v])]), static=True)
    rec.log(f'{root}/cursor', rr.LineStrips2D.from_fields(
        colors=[SCALE_COLOR], radii=[FRAME_RADIUS_UI], draw_order=20.0), static=True)
    rec.log(f'{root}/values', rr.Points2D.from_fields(
        colors=[SERIES_COLORS[v] for v in layout.variants],
        radii=[rr.components.Radius.ui_points(4.0)], draw_order=21.0), static=True)


def angle_name(layout):
    """Return the name of a plot's x axis: the crank angle, or a prismatic input's phase."""
    stroke = getattr(layout.rigs['original'].scene, 'crank_stroke_m', None)
    return 'crank angle (deg)' if stroke is None else 'input phase (deg)'


def log_cursor(rec, layout, motion, index, values):
    """
    Log each plot's cursor: a line at the sample's crank angle, a dot on each curve.

    ``values``: per plot, its :func:`.plots.plot_values` at these samples.
    """
    sign = -1.0 if layout.rigs['original'].scene.crank_speed_rad_s < 0.0 else 1.0
    turned = np.mod(sign * motion.degrees, 360.0)
    p, n = motion.size, len(layout.variants)
    for plot, by_variant in zip(layout.plots, values):
        root = f'{ANGLE_ROOT}/{plot.entity}'
        x = plot.axes.x(turned)
        _, y0, _, y1 = plot.axes.box_px
        lines = np.stack([np.stack([x, np.full(p, y0)], -1), np.stack([x, np.full(p, y1)], -1)],
                         axis=1)
        rec.send_columns(f'{root}/cursor', index, rr.LineStrips2D.columns(strips=lines))
        dots = np.stack([plot.axes.points(turned, v) for v in by_variant.values()], axis=1)
        rec.send_columns(f'{root}/values', index, rr.Points2D.columns(
            positions=dots.reshape(-1, 2)).partition(np.full(p, n)))


def moment_arc(centre, moment_Nm, scale_deg_per_Nm, radius):
    """Return the arc ``(p, ARC_POINTS, 2)`` and arrow head ``(p, 3, 2)`` of planar moments."""
    limit = math.radians(MOMENT_ARC_LIMIT_DEG)
    sweep = np.clip(np.radians(moment_Nm * scale_deg_per_Nm), -limit, limit)
    start = 0.5 * math.pi
    t = np.linspace(0.0, 1.0, ARC_POINTS)
    c = complex(centre[0], centre[1])
    arc = c + radius * np.exp(1j * (start + sweep[:, None] * t[None, :]))
    tip_dir = np.exp(1j * (start + sweep))
    tangent = np.sign(sweep) * 1j * tip_dir
    head = MOMENT_HEAD_SHARE * radius * np.minimum(1.0, np.abs(sweep) / 0.5)
    tip = c + radius * tip_dir
    barbs = [tip - head * tangent * np.exp(1j * math.radians(a)) for a in (30.0, -30.0)]

    def c2(z):
        return np.stack([z.real, z.imag], axis=-1)
    return c2(arc), c2(np.stack([barbs[0], tip, barbs[1]], axis=1))


def log_motion(rec, layout, motion, degrees, seconds, labels=None):
    """Send the columns of a batch of samples (``labels``: placed per view beforehand)."""
    index = time_index(degrees, seconds)
    points, strips, arrows = archetypes(layout.dim)
    p = motion.size

    def send_points(path, pts, counts=None, **fields):     # (p, n, 3): n points per sample
        rec.send_columns(path, index, points.columns(
            positions=view_coords(layout, pts).reshape(-1, layout.dim), **fields).partition(
                np.full(p, pts.shape[1]) if counts is None else counts))
    if layout.on('links'):
        flat = uniform_strips([view_coords(layout, s) for s in motion.links])
        rec.send_columns('rig/links', index, strips.columns(strips=flat).partition(
            np.full(p, len(motion.links))))
    if layout.on('joints') and motion.joints.shape[1]:
        send_points('rig/joints', motion.joints)
    for v in layout.variants:
        data = motion.data[v]
        if layout.on('mass_centres'):
            send_points(f'{v}/mass_centres', motion.centres[v])
        if layout.has_added and motion.added[v].shape[1]:
            send_points(f'{v}/counterweights', motion.added[v])
        marks = (motion.marks or {}).get(v, {})
        drawn = {'rings': layout.has_added, 'stalks': layout.on('links')}
        for kind, path in (('rings', 'counterweight_planes'), ('stalks', 'mass_changes')):
            m = marks.get(kind)
            if m is not None and drawn[kind]:
                flat = view_coords(layout, m).reshape((-1,) + m.shape[2:3] + (layout.dim,))
                rec.send_columns(f'{v}/{path}', index, strips.columns(strips=flat).partition(
                    np.full(p, m.shape[1])))
        if layout.has_point_masses:
            send_points(f'{v}/point_masses', motion.point_masses[v])
        if layout.on('shaking_force_arrow'):
            rec.send_columns(f'{v}/shaking_force', index, arrows.columns(
                vectors=view_coords(layout, data.force_N * layout.force_scale_m_per_N)))
        if layout.on('shaking_moment_arc') and layout.dim == 2:
            flat = uniform_strips(list(moment_arc(layout.gauge_m, data.moment_Nm[:, 2],
                                                  layout.moment_scale, layout.dial_radius_m)))
            rec.send_columns(f'{v}/shaking_moment', index,
                             rr.LineStrips2D.columns(strips=flat).partition(np.full(p, 2)))
        elif layout.on('shaking_moment_arc'):
            rec.send_columns(f'{v}/shaking_moment', index, rr.Arrows3D.columns(
                vectors=data.moment_Nm * layout.moment_scale))
    for view in layout.variants + (('inset',) if labels and 'inset' in labels else ()):
        pos, texts, colors, counts = (labels[view] if labels else
                                      place_labels(layout, motion, view))[:4]
        send_points(f'{view}/labels', pos[None], labels=texts, colors=colors, counts=counts)
    values = [plot_values(layout, motion.data, plot.entity) for plot in layout.plots]
    for plot, by_variant in zip(layout.plots, values):
        for v, x in by_variant.items():
            rec.send_columns(f'plots/{plot.entity}/{v}', index,
                             rr.Scalars.columns(scalars=np.asarray(x, dtype=np.float64)))
    if layout.plots and not layout.live:
        log_cursor(rec, layout, motion, index, values)


def start_stream(rec, scene, layout):
    """Send the blueprint, the recording's name and the static geometry."""
    rec.send_blueprint(blueprint(layout), make_active=True, make_default=True)
    rec.send_recording_name(f'{scene.name}: ' + ' vs '.join(layout.variants))
    log_static(rec, layout)
