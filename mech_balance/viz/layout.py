"""
Where things land on screen: the default window, label placement, view ranges, plot ticks.

Pure geometry of the picture (no rerun): the :class:`Screen` of a view at :data:`WINDOW_PX`,
the label boxes the viewer draws, the greedy placement of every label of a view, the gauge's
place, the 2-D bounds or 3-D eye fitted to the drawing, and the y ranges of the plots.
"""

from dataclasses import dataclass
import math

from mech_balance.schema.scene import series_stream
from mech_balance.viz.hits import distance_to_segments, first_passing, segments_hit_boxes
from mech_balance.viz.style import (
    CENTRE_RADIUS_SHARE, DIAL_OVER_ARROW, DIAL_SHARE, FORCE_ARROW_SHARE, FRAME_COLOR,
    GAUGE_GAP_SHARE, JOINT_COLOR, MOMENT_ARC_MAX_DEG, MOMENT_COLOR, MOMENT_HEAD_SHARE,
    POINT_MASS_RADIUS_SHARE, READOUT_COLOR, SAME_POINT_RTOL, SCALE_BAR_SHARE, SCALE_COLOR,
    series_label, SYSTEM_CENTRE_COLOR
)
import numpy as np


WINDOW_PX = (1900, 1040)
"""The viewer window the layout is designed for (the screenshot tool's default)."""
TOP_BAR_PX = 36
"""Height of the viewer's top bar."""
TIME_PANEL_PX = 44
"""Height of the collapsed time panel (the play bar)."""
VIEW_TITLE_PX = 30
"""Height of a view's title bar (and its borders)."""
LEFT_SHARE = 0.6
"""Share of the window width of the left column (rigs over the RMS table); plots right."""
RIG_ROW_SHARE = 0.66
"""Share of the left column's height of the rig views (the RMS table below)."""
LABEL_TEXT_PX = 13.0
"""Height of a label's text in the viewer."""
LABEL_CHAR_PX = {'upper': 10.0, 'digit': 7.0, 'other': 6.6}
"""Width of one character of a label (capitals, digits, the rest), measured on screenshots."""
LABEL_PAD_PX = (12.0, 9.0)
"""Padding of a label's box (width, height) around its text."""
LABEL_DROP_PX = 2.0
"""The viewer draws a point's label box this far below the point, centred on it."""
LABEL_GAP_PX = 3.0
"""Free space kept between two label boxes."""
LABEL_OFFSET_PX = 9.0
"""Distance from a feature to the nearest edge of its label box."""
LABEL_OFFSETS_PX = (LABEL_OFFSET_PX, 2.5 * LABEL_OFFSET_PX)
"""The rings of places tried around a feature (the nearer first; the farther clears a
slider's block or a crowded joint)."""
NEAR_MARGIN_PX = 2.0
"""A label is at least this much nearer its own feature than any other (points, links)."""
SAME_PLACE_PX = 1.0
"""Drawn points closer than this on screen are one place (a joint on a frame pivot)."""
LINK_LABEL_ALONG = (0.3, 0.7, 0.15, 0.85)
"""Besides its middle, a link's name may sit at these fractions of its first segment."""
GAUGE_GRID = 15
"""Places per side of the grid over the rig's box where a free corner for the gauge is sought."""
GAUGE_CLEAR_POINTS = 9
"""Points per drawn segment checked for the gauge's clearance."""
MARKER_PX = 6.0
"""Radius kept free around a drawn point (pivot, joint, mass centre) by the labels."""
VIEW_PAD_PX = 34.0
"""Margin of the 2-D bounds around everything drawn (room for labels at the edge)."""
FOV_Y_RAD = math.radians(55.0)
"""Vertical field of view of the viewer's 3-D eye (rerun's default)."""
EYE_DIRECTION = (1.0, -1.7, 0.9)
"""Direction from the look target towards the 3-D eye (frame axes, z up): front right above."""
GRID_MARGIN_LINES = 1
"""The 3-D grid reaches this many spacings beyond everything drawn."""
EYE_FIT = 1.05
"""The 3-D eye stands this much further than the distance that just fits the drawing."""
LEGEND_HEADROOM = 0.24
"""Share of a plot's height kept free above the curves for the legend (top right)."""
PLOT_MIN_TICKS = 3
"""A plot's y range holds at least this many labelled ticks."""
PLOT_EDGE_SHARE = 0.04
"""Share of a plot's range added beyond its end ticks, so that the viewer labels them."""
PLOT_TICK_PX = 24.0
"""Least distance between two labelled y ticks (the viewer hides denser labels: 23 px are
shown, 12 px are not, on screenshots of rerun 0.41)."""


@dataclass(frozen=True)
class Screen:
    """
    Where a view's points land on screen at the default window (:data:`WINDOW_PX`).

    ``size_px`` (w, h) of the view's drawing area; 2-D: ``bounds`` ((x0, x1), (y0, y1)) in
    the scene's frame (y up), fitted exactly; 3-D: an eye at ``eye_m`` looking at
    ``target_m`` with ``up`` and :data:`FOV_Y_RAD`.
    """

    size_px: tuple
    bounds: tuple = None
    eye_m: tuple = None
    target_m: tuple = None
    up: tuple = (0.0, 0.0, 1.0)

    @property
    def metres_per_px(self):
        """Return the 2-D scale (m per pixel)."""
        (x0, x1), _ = self.bounds
        return (x1 - x0) / self.size_px[0]

    def _axes(self):
        eye, target = np.asarray(self.eye_m), np.asarray(self.target_m)
        fwd = target - eye
        fwd = fwd / np.linalg.norm(fwd)
        right = np.cross(fwd, self.up)
        right = right / np.linalg.norm(right)
        return eye, fwd, right, np.cross(right, fwd)

    def px(self, points):
        """Return the pixel coordinates ``(..., 2)`` (x right, y down) of points ``(..., 3)``."""
        p = np.asarray(points, dtype=float)
        w, h = self.size_px
        if self.bounds is not None:
            (x0, _), (_, y1) = self.bounds
            s = self.metres_per_px
            return np.stack([(p[..., 0] - x0) / s, (y1 - p[..., 1]) / s], axis=-1)
        eye, fwd, right, up = self._axes()
        v = p - eye
        depth = np.maximum(v @ fwd, 1e-12)
        f = 0.5 * h / math.tan(0.5 * FOV_Y_RAD)
        return np.stack([0.5 * w + f * (v @ right) / depth, 0.5 * h - f * (v @ up) / depth],
                        axis=-1)

    def offset_m(self, points, d_px):
        """Return the scene vectors ``(..., 3)`` that move points by ``d_px`` pixels."""
        d = np.asarray(d_px, dtype=float)
        if self.bounds is not None:
            s = self.metres_per_px
            return np.stack([d[..., 0] * s, -d[..., 1] * s, np.zeros(d.shape[:-1])], axis=-1)
        eye, fwd, right, up = self._axes()
        depth = (np.asarray(points, dtype=float) - eye) @ fwd
        s = depth * 2.0 * math.tan(0.5 * FOV_Y_RAD) / self.size_px[1]
        return (d[..., 0:1] * right - d[..., 1:2] * up) * s[..., None]


def label_size_px(text):
    """Return the (width, height) in pixels of the box of a label with ``text``."""
    w = sum(LABEL_CHAR_PX['upper'] if c.isupper() else LABEL_CHAR_PX['digit'] if c.isdigit()
            else LABEL_CHAR_PX['other'] for c in text)
    return w + LABEL_PAD_PX[0], LABEL_TEXT_PX + LABEL_PAD_PX[1]


def label_box_px(anchor_px, text):
    """
    Return the box ``(x0, y0, x1, y1)`` (pixels) that a label at ``anchor_px`` covers.

    The viewer draws a point's label centred under it, :data:`LABEL_DROP_PX` below.
    """
    a = np.asarray(anchor_px, dtype=float)
    w, h = label_size_px(text)
    top = a[..., 1] + LABEL_DROP_PX
    return np.array([a[..., 0] - w / 2, top, a[..., 0] + w / 2, top + h])


@dataclass
class Plot:
    """One time-series view: entity, title, values per variant (reference turn), y range."""

    stream: str
    entity: str
    title: str
    unit: str
    y_range: tuple = None
    tick_step: float = None


@dataclass
class Label:
    """A label of a view: text (or texts per sample), colour, the feature it names."""

    text: object          # str, or a function of the sample's crank angle (deg)
    color: tuple
    where: str            # 'frame', 'joint', 'centre', 'link', 'fixed'
    index: int = 0
    members: tuple = ()   # the variants it belongs to (all if empty)


@dataclass
class Layout:
    """Everything static of a recording: rigs, drawings, styles, scales, screens, text."""

    title: str
    dim: int
    streams: tuple
    variants: tuple
    rigs: dict
    drawings: dict
    stream_outputs: tuple
    size_m: float
    templates: list              # per body: (body name, (k, 3) local outline)
    link_names: list
    link_colors: list
    joint_names: list
    frame_names: list
    frame_points: np.ndarray     # (f, 3)
    frame_strips: list           # (k, 3) each
    pivot_name: str
    force_scale_m_per_N: float
    moment_scale: float          # deg per N*m (2-D arc) or m per N*m (3-D arrow)
    gauge_m: np.ndarray          # (3,)
    gauge_reach_m: float         # radius of everything the gauge draws
    dial_radius_m: float
    scale_bar: tuple             # ((k, 3) strip, label text, label point (3,)) or None
    screens: dict
    plots: list
    labels: list
    series: tuple
    has_added: bool
    has_point_masses: bool
    text: str = ''
    live: bool = False
    grid_m: float = 0.0          # 3-D: spacing of the grid lines
    grid_text: str = ''
    grid_box: tuple = None       # 3-D: (x0, x1, y0, y1) of the grid drawn on z = 0
    marks: dict = None           # variant -> {'rings': [(body, (k, 3))], 'stalks': [...]}
    changes: dict = None         # variant -> [(body index, mass change kg)]

    def on(self, stream):
        """Return whether ``stream`` is logged."""
        return stream in self.streams


def nice_ceil(x, steps=(1.0, 2.0, 5.0)):
    """Return the smallest of ``steps`` times a power of ten that is >= ``x`` (``x`` > 0)."""
    exp = math.floor(math.log10(x))
    for m in tuple(steps) + (10.0,):
        if m * 10.0 ** exp >= x * (1.0 - 1e-12):
            return m * 10.0 ** exp
    return 10.0 ** (exp + 1)


def nice_floor(x):
    """Return the largest 1, 2 or 5 times a power of ten that is <= ``x`` (``x`` > 0)."""
    exp = math.floor(math.log10(x))
    for m in (5.0, 2.0, 1.0):
        if m * 10.0 ** exp <= x * (1.0 + 1e-12):
            return m * 10.0 ** exp
    return 10.0 ** (exp - 1)


def arrow_scale(size_m, largest, share=FORCE_ARROW_SHARE, steps=(1.0, 2.0, 5.0)):
    """
    Return metres of arrow per unit value (m per N, or m per N*m).

    1 cm of arrow is a round value (``steps`` times a power of ten) and the longest arrow at
    most ``share`` of the rig's size.
    """
    if not largest > 0.0:
        return 1.0
    return 0.01 / nice_ceil(largest * 0.01 / (share * size_m), steps)


def arc_scale(largest):
    """Return degrees of arc per N*m: 90 deg is a round moment, the largest sweeps <= 270."""
    if not largest > 0.0:
        return 1.0
    return 90.0 / nice_ceil(largest * 90.0 / MOMENT_ARC_MAX_DEG)


def plot_range(values, height_px):
    """
    Return ``(lo, hi, step)``: a y range on round ticks that covers ``values``.

    The viewer labels a plot's y axis at powers of ten only (egui_plot's decade grid), and
    only where two labels are at least :data:`PLOT_TICK_PX` apart: ``step`` is the smallest
    power of ten that is, so a plot ``height_px`` tall shows at least
    :data:`PLOT_MIN_TICKS` labelled ticks.  0 is inside when the data do not keep away from
    it, and :data:`LEGEND_HEADROOM` of the height is free above the data for the legend.
    """
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    lo, hi = (float(v.min()), float(v.max())) if v.size else (0.0, 0.0)
    if lo >= 0.0 and lo < 0.5 * hi:
        lo = 0.0
    if hi <= 0.0 and hi > 0.5 * lo:
        hi = 0.0
    span = hi - lo
    if not span > 1e-300:
        span = abs(hi) or 1.0
        lo, hi = lo - 0.5 * span, hi + 0.5 * span
        span = hi - lo
    top = hi + span * LEGEND_HEADROOM / (1.0 - LEGEND_HEADROOM)
    step = 10.0 ** math.floor(math.log10(top - lo) - 3.0)
    while True:
        y0 = math.floor(lo / step + 1e-9) * step
        y1 = math.ceil(top / step - 1e-9) * step
        steps = round((y1 - y0) / step)
        if height_px / ((1.0 + 2.0 * PLOT_EDGE_SHARE) * max(steps, 1)) >= PLOT_TICK_PX:
            break
        step *= 10.0
    while round((y1 - y0) / step) < PLOT_MIN_TICKS - 1:
        y0 -= step if lo < 0.0 or y0 > 0.0 else 0.0
        if round((y1 - y0) / step) < PLOT_MIN_TICKS - 1:
            y1 += step
    # the viewer does not label a tick on the very edge: keep the end ticks inside
    margin = PLOT_EDGE_SHARE * (y1 - y0)
    return float(y0 - margin), float(y1 + margin), float(step)


def window_px(n_views, n_plots, has_text):
    """Return the drawing-area sizes (px) of a rig view and of a plot at :data:`WINDOW_PX`."""
    w, h = WINDOW_PX
    height = h - TOP_BAR_PX - TIME_PANEL_PX
    left = w * LEFT_SHARE if n_plots else w
    rig_h = (height * RIG_ROW_SHARE if has_text else height) - VIEW_TITLE_PX
    rig_w = left / max(n_views, 1) - 6.0
    plot = ((w - left) - 60.0, height / max(n_plots, 1) - VIEW_TITLE_PX - 24.0)
    return (float(rig_w), float(rig_h)), plot


def merged_names(names, positions, size):
    """Return ``[(label, [indices])]``: names at one place (at every sample) merged."""
    tol = SAME_POINT_RTOL * size * 1e3
    groups = []
    for i, name in enumerate(names):
        for g in groups:
            if np.max(np.linalg.norm(positions[:, i] - positions[:, g[1][0]], axis=-1)) <= tol:
                g[1].append(i)
                if name not in g[0]:
                    g[0].append(name)
                break
        else:
            groups.append(([name], [i]))
    return [('/'.join(n), idx) for n, idx in groups]


def drawn_extent(layout, motion):
    """Return every drawn point of the rig over the turn ``(m, 3)``, and radii around them."""
    pts = [np.concatenate(motion.links, axis=1).reshape(-1, 3), layout.frame_points]
    pts += list(layout.frame_strips)
    radii = [np.zeros(len(p)) for p in pts]
    if layout.on('mass_centres'):
        for c in motion.centres.values():
            pts.append(c.reshape(-1, 3))
            radii.append(np.full(len(pts[-1]), 1.8 * CENTRE_RADIUS_SHARE * layout.size_m))
    for v, a in motion.added.items():
        if layout.has_added and a.shape[1]:
            r = np.array([x.radius_m for b in layout.drawings[v].bodies for x in b.added])
            pts.append(a.reshape(-1, 3))
            radii.append(np.tile(r, a.shape[0]))
    for v, p in motion.point_masses.items():
        pts.append(p.reshape(-1, 3))
        radii.append(np.full(len(pts[-1]), POINT_MASS_RADIUS_SHARE * layout.size_m))
    return np.concatenate(pts), np.concatenate(radii)


def place_views(layout, motion, fmax, nmax, n_series):
    """Choose the gauge's place, the scale bar and the screens (2-D bounds or 3-D eye)."""
    size = layout.size_m
    pts, radii = drawn_extent(layout, motion)
    lo = np.min(pts - radii[:, None], axis=0)
    hi = np.max(pts + radii[:, None], axis=0)
    n_plots = int(layout.on('shaking_force_plot')) + int(layout.on('shaking_moment_plot')) + \
        n_series
    view_px, _ = window_px(len(layout.variants), n_plots, layout.on('info'))
    arrow = fmax * layout.force_scale_m_per_N if layout.on('shaking_force_arrow') else 0.0
    gauge = layout.on('shaking_force_arrow') or layout.on('shaking_moment_arc')
    gap = GAUGE_GAP_SHARE * size
    if layout.dim == 2:
        dial = 0.0
        if layout.on('shaking_moment_arc'):
            dial = max(DIAL_SHARE * size, DIAL_OVER_ARROW * arrow)
        reach = dial * (1.0 + MOMENT_HEAD_SHARE) if dial else arrow
        layout.dial_radius_m = dial
        # the scale bar under the rig, at its left
        bar = nice_floor(SCALE_BAR_SHARE * size)
        tick = 0.04 * size
        y_bar = lo[1] - 0.6 * gap
        x_bar = lo[0]
        strip = np.array([[x_bar, y_bar + tick, 0], [x_bar, y_bar, 0],
                          [x_bar + bar, y_bar, 0], [x_bar + bar, y_bar + tick, 0]])
        text = f'{bar * 100:g} cm' if bar >= 0.01 else f'{bar * 1000:g} mm'
        lo = np.minimum(lo, strip.min(axis=0) - [0, tick, 0])
        if gauge and reach > 0.0:
            centre = _gauge_place(layout, motion, pts, radii, lo, hi, reach, gap, view_px)
            layout.gauge_m, layout.gauge_reach_m = centre, reach
            lo = np.minimum(lo, centre - reach)
            hi = np.maximum(hi, centre + reach)
        # the bounds: the view's aspect, everything drawn inside with a margin
        w_px, h_px = view_px
        s = max((hi[0] - lo[0]) / (w_px - 2 * VIEW_PAD_PX),
                (hi[1] - lo[1]) / (h_px - 2 * VIEW_PAD_PX - 2 * LABEL_TEXT_PX))
        cx, cy = 0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])
        bounds = ((float(cx - 0.5 * w_px * s), float(cx + 0.5 * w_px * s)),
                  (float(cy - 0.5 * h_px * s), float(cy + 0.5 * h_px * s)))
        screen = Screen(view_px, bounds=bounds)
        label_at = 0.5 * (strip[1] + strip[2]) + screen.offset_m(
            strip[1], [0.0, 3.0 + 0.5 * (LABEL_TEXT_PX + LABEL_PAD_PX[1])])
        layout.scale_bar = (strip, text, label_at)
    else:
        reach = max(arrow, nmax * layout.moment_scale if layout.on('shaking_moment_arc')
                    else 0.0)
        d = np.asarray(EYE_DIRECTION, dtype=float)
        d = d / np.linalg.norm(d)
        right = np.cross(-d, (0.0, 0.0, 1.0))
        right = right / np.linalg.norm(right)
        centre = 0.5 * (lo + hi)
        if gauge and reach > 0.0:
            half = 0.5 * np.abs(hi - lo) @ np.abs(right)
            layout.gauge_m = centre + right * (half + gap + reach)
            layout.gauge_reach_m = reach
            lo = np.minimum(lo, layout.gauge_m - reach)
            hi = np.maximum(hi, layout.gauge_m + reach)
        layout.grid_box = grid_box(lo, hi, layout.grid_m)
        target = 0.5 * (lo + hi)
        drawn = pts[::max(1, len(pts) // 4000)]
        if layout.gauge_reach_m:
            drawn = np.concatenate([drawn, layout.gauge_m + layout.gauge_reach_m * np.array(
                [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]])])
        screen = fit_eye(view_px, target, d, drawn)
    layout.screens = {v: screen for v in layout.variants}


def grid_box(lo, hi, spacing):
    """
    Return the 3-D grid's ``(x0, x1, y0, y1)``: what is drawn, one line beyond, on the lines.

    The grid lies on z = 0 under (or through) the rig and covers its extent over the turn and
    the gauge plus :data:`GRID_MARGIN_LINES` spacings, so that it frames the rig instead of
    filling the view to the horizon.
    """
    if not spacing > 0.0:
        return None
    m = GRID_MARGIN_LINES * spacing
    x0, y0 = (np.floor((lo[:2] - m) / spacing) * spacing).tolist()
    x1, y1 = (np.ceil((hi[:2] + m) / spacing) * spacing).tolist()
    return (x0, x1, y0, y1)


def _scale_2d(lo, hi, view_px):
    """Return the metres per pixel at which the box ``lo``-``hi`` fits a 2-D view."""
    w_px, h_px = view_px
    return max((hi[0] - lo[0]) / (w_px - 2 * VIEW_PAD_PX),
               (hi[1] - lo[1]) / (h_px - 2 * VIEW_PAD_PX - 2 * LABEL_TEXT_PX))


def _gauge_place(layout, motion, pts, radii, lo, hi, reach, gap, view_px):
    """
    Return the 2-D gauge's centre: where the rig, gauge and all fit the view the largest.

    Tried: beside the rig (right, left), under and over it, and every place of a grid over
    the rig's own box where nothing of the rig comes within ``gap`` of the gauge over the
    whole turn (a free corner); the first of the best is taken.
    """
    cx, cy = 0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])
    places = [(hi[0] + gap + reach, cy), (cx, lo[1] - gap - reach),
              (lo[0] - gap - reach, cy), (cx, hi[1] + gap + reach)]
    dense = [pts[:, :2]]
    t = np.linspace(0.0, 1.0, GAUGE_CLEAR_POINTS)[None, None, :, None]
    for strip in motion.links:
        if strip.shape[1] >= 2:
            a, b = strip[:, :-1, None, :2], strip[:, 1:, None, :2]
            dense.append((a + t * (b - a)).reshape(-1, 2))
    for strip in layout.frame_strips:
        a, b = strip[:-1, None, :2], strip[1:, None, :2]
        dense.append((a + t[0] * (b - a)).reshape(-1, 2))
    cloud = np.concatenate(dense)
    pad = np.concatenate([radii, np.zeros(len(cloud) - len(radii))])
    cloud, pad = cloud[::max(1, len(cloud) // 20000)], pad[::max(1, len(cloud) // 20000)]
    xs = np.linspace(lo[0] + reach, hi[0] - reach, GAUGE_GRID)
    ys = np.linspace(lo[1] + reach, hi[1] - reach, GAUGE_GRID)
    if hi[0] - lo[0] > 2 * reach and hi[1] - lo[1] > 2 * reach:
        for y in ys[::-1]:
            for x in xs:
                d = np.linalg.norm(cloud - [x, y], axis=1) - pad
                if d.min() >= reach + gap:
                    places.append((x, y))
    best, best_s = None, math.inf
    for x, y in places:
        c = np.array([x, y, 0.0])
        s = _scale_2d(np.minimum(lo, c - reach), np.maximum(hi, c + reach), view_px)
        if s < best_s * (1.0 - 1e-9):
            best, best_s = c, s
    return best


def fit_eye(view_px, target, direction, corners):
    """Return a 3-D :class:`Screen` whose eye sees every corner inside the view's margins."""
    dist = 0.3 * float(np.max(np.linalg.norm(corners - target, axis=1))) or 1.0
    for _ in range(80):
        screen = Screen(view_px, eye_m=tuple(target + direction * dist),
                        target_m=tuple(target))
        px = screen.px(corners)
        pad = VIEW_PAD_PX
        if np.all(px[:, 0] >= pad) and np.all(px[:, 0] <= view_px[0] - pad) and \
                np.all(px[:, 1] >= pad) and np.all(px[:, 1] <= view_px[1] - pad):
            return Screen(view_px, eye_m=tuple(target + direction * dist * EYE_FIT),
                          target_m=tuple(target))
        dist *= 1.05
    return screen


def plot_specs(layout, motion):
    """Return the time-series views with their y ranges (from the reference turn's data)."""
    specs = []
    if layout.on('shaking_force_plot'):
        specs.append(('shaking_force_plot', 'shaking_force', '|shaking force| (N)', 'N'))
    if layout.on('shaking_moment_plot'):
        where = layout.pivot_name
        title = (f'shaking moment about {where} (N*m)' if layout.dim == 2 else
                 f'|shaking moment| about {where} (N*m)')
        specs.append(('shaking_moment_plot', 'shaking_moment', title, 'N*m'))
    for k in layout.series:
        label, unit, _ = series_label(k)
        specs.append((series_stream(k), k, label + (f' ({unit})' if unit else ''), unit))
    plots = []
    _, plot_px = window_px(len(layout.variants), len(specs), layout.on('info'))
    for stream, entity, title, unit in specs:
        values = np.concatenate([v for _, v in plot_values(layout, motion, entity)])
        y0, y1, step = plot_range(values, plot_px[1])
        plots.append(Plot(stream, entity, title, unit, (y0, y1), step))
    return plots


def plot_values(layout, motion, entity):
    """Yield ``(variant, values)`` of one plotted quantity."""
    for v in layout.variants:
        d = motion.data[v]
        if entity == 'shaking_force':
            yield v, np.linalg.norm(d.force_N, axis=1)
        elif entity == 'shaking_moment':
            norm = np.linalg.norm(d.moment_Nm, axis=1)
            yield v, d.moment_Nm[:, 2] if layout.dim == 2 else norm
        elif entity in d.series:
            yield v, d.series[entity]


def moved_text(layout, variant, i):
    """Return the label of a body whose mass is kept and whose mass centre moved: how far."""
    moved = np.linalg.norm(np.subtract(layout.drawings[variant].bodies[i].mass_centre_m,
                                       layout.drawings['original'].bodies[i].mass_centre_m))
    return f'moved {moved * 1e3:.0f} mm'


def slide_readout(stroke_m, motion, variant):
    """
    Return the readout of a prismatic input: ``deg -> 'slide 30.0 mm, force +12.3 N'``.

    The slide follows the input's stroke law at the cycle angle; the driving force is the
    design's at the recorded samples (a live view's new angles show the slide alone).
    """
    from mech_balance.schema.spatial import stroke_law
    data = (motion.data or {}).get(variant)
    force = getattr(data, 'series', {}).get('driving_force') if data is not None else None
    at = {} if force is None else {round(float(d), 9): float(f)
                                   for d, f in zip(motion.degrees, force)}

    def text(deg):
        slide = float(stroke_law(stroke_m, math.radians(deg))[0])
        f = at.get(round(float(deg), 9))
        return f'slide {slide * 1e3:.1f} mm' + ('' if f is None else f', force {f:+.3g} N')
    return text


def label_specs(layout, motion):
    """Return the labels of a rig view, most important first."""
    stroke = getattr(layout.rigs['original'].scene, 'crank_stroke_m', None)
    if stroke is None:
        specs = [Label(lambda deg: f'crank {deg:.1f} deg', READOUT_COLOR, 'readout')]
    else:   # a prismatic input: its slide and the driving force of each design
        specs = [Label(slide_readout(stroke, motion, v), READOUT_COLOR, 'readout', 0, (v,))
                 for v in layout.variants]
    if layout.scale_bar is not None:
        specs.append(Label(layout.scale_bar[1], SCALE_COLOR, 'scale'))
    if layout.on('shaking_force_arrow') or layout.on('shaking_moment_arc'):
        specs.append(Label('shaking force, moment', MOMENT_COLOR, 'gauge'))
    if layout.on('frame'):
        f = np.broadcast_to(layout.frame_points, (1,) + layout.frame_points.shape)
        for text, idx in merged_names(layout.frame_names, f, layout.size_m):
            specs.append(Label(text, FRAME_COLOR, 'frame', idx[0]))
    if layout.on('mass_centres'):
        specs.append(Label('CoM', SYSTEM_CENTRE_COLOR, 'centre', -1))
    if layout.on('joints') and motion.joints.shape[1]:
        fixed = np.ptp(motion.joints, axis=0).max(axis=-1) <= SAME_POINT_RTOL * layout.size_m
        moving = [i for i in range(motion.joints.shape[1]) if not fixed[i]]
        names = [layout.joint_names[i] for i in moving]
        for text, idx in merged_names(names, motion.joints[:, moving], layout.size_m):
            specs.append(Label(text, JOINT_COLOR, 'joint', moving[idx[0]]))
    if layout.on('links'):
        for i, name in enumerate(layout.link_names):
            specs.append(Label(name, layout.link_colors[i], 'link', i))
    for v in layout.variants:
        added = [(i, a) for i, b in enumerate(layout.drawings[v].bodies) for a in b.added]
        planes = any(abs(a.centre_m[2]) > 0.0 for _, a in added) and layout.dim == 2
        for j, (i, a) in enumerate(added if layout.has_added else ()):
            text = f'{a.mass_kg:.3g} kg' + (f', z {a.centre_m[2] * 1e3:+.3g} mm' if planes
                                            else '')
            specs.append(Label(text, layout.link_colors[i], 'added', j, (v,)))
        if layout.on('links') and layout.on('mass_centres'):
            for i, dm in (layout.changes or {}).get(v, []):
                text = f'{dm:+.3g} kg' if dm else moved_text(layout, v, i)
                specs.append(Label(text, layout.link_colors[i], 'change', i, (v,)))
    return specs


def candidates(w, h):
    """
    Return label-box centre offsets (px) around a feature: above, right, below, left, ...

    The four sides and four corners first, then eight places between them on the ellipse
    through the sides (a box there keeps about its offset from the feature), for each of
    :data:`LABEL_OFFSETS_PX` in turn.
    """
    out = []
    for offset in LABEL_OFFSETS_PX:
        dx, dy = 0.5 * w + offset, 0.5 * h + offset
        out += [[0, -dy], [dx, 0], [0, dy], [-dx, 0], [dx, -dy], [-dx, -dy], [dx, dy],
                [-dx, dy]]
        out += [[dx * math.cos(a), dy * math.sin(a)]
                for a in np.radians([-67.5, -22.5, 22.5, 67.5, 112.5, 157.5, 202.5, 247.5])]
    return np.array(out, dtype=float)


def label_anchor(layout, motion, spec, variant, screen):
    """Return the feature ``(p, 3)`` a label names, or None."""
    p = motion.size
    if spec.where == 'frame':
        return np.broadcast_to(layout.frame_points[spec.index], (p, 3))
    if spec.where == 'joint':
        return motion.joints[:, spec.index]
    if spec.where in ('centre', 'change'):
        return motion.centres[variant][:, spec.index]
    if spec.where == 'added':
        return motion.added[variant][:, spec.index]
    if spec.where == 'link':
        strip = motion.links[spec.index]
        k = strip.shape[1]
        return strip[:, :max(k - 1, 1)].mean(axis=1) if k > 2 else strip.mean(axis=1)
    if spec.where == 'link_along':
        strip = motion.links[spec.index]
        if strip.shape[1] < 2:
            return None
        return [strip[:, 0] + t * (strip[:, 1] - strip[:, 0]) for t in LINK_LABEL_ALONG]
    if spec.where == 'gauge':
        below = np.array([0.0, layout.gauge_reach_m, 0.0] if layout.dim == 2 else
                         [0.0, 0.0, 1.15 * layout.gauge_reach_m])     # 3-D: under the arrows
        return np.broadcast_to(layout.gauge_m - below, (p, 3))
    if spec.where == 'scale':
        return np.broadcast_to(layout.scale_bar[2], (p, 3))
    return None


def link_segments_px(motion, screen):
    """Return per link its segments ``(p, k - 1, 2, 2)`` on screen (a one-point link: none)."""
    out = []
    for strip in motion.links:
        px = screen.px(strip)                                       # (p, k, 2)
        out.append(np.stack([px[:, :-1], px[:, 1:]], axis=2))
    return out


def segments_px(layout, motion, screen, variant=None):
    """
    Return every drawn line segment of a view ``(p, m, 2, 2)`` on screen.

    The links and the frame; with ``variant``, also that design's marks as drawn: the
    counterweight plane rings and the stalks to moved mass centres (:func:`design_marks`).
    """
    segs = [s for s in link_segments_px(motion, screen) if s.shape[1]]
    for strip in layout.frame_strips:
        px = screen.px(strip)
        seg = np.stack([px[:-1], px[1:]], axis=1)
        segs.append(np.broadcast_to(seg, (motion.size,) + seg.shape))
    marks = (motion.marks or {}).get(variant, {}) if variant is not None else {}
    drawn = {'rings': layout.has_added, 'stalks': layout.on('links')}
    for kind in ('rings', 'stalks'):
        m = marks.get(kind)
        if m is None or not drawn[kind] or not np.size(m):
            continue
        px = screen.px(np.asarray(m, dtype=float))                  # (p, r, k, 2)
        seg = np.stack([px[:, :, :-1], px[:, :, 1:]], axis=3)       # (p, r, k - 1, 2, 2)
        segs.append(seg.reshape(motion.size, -1, 2, 2))
    if not segs:
        return np.zeros((motion.size, 0, 2, 2))
    return np.concatenate(segs, axis=1)


def place_labels(layout, motion, variant):
    """
    Return ``(positions (q, 3), texts, colours, counts (p,))``: the labels of one view.

    Greedy, most important label first, at each sample: each label takes the first place
    around its feature whose box keeps clear of the boxes already placed, of every drawn
    point and of every drawn line, inside the view, and that is nearer its own feature than
    any other (:func:`_nearest_own`); else it is left out at that sample.  So no two labels
    ever overlap, no line crosses a label and no label names a neighbour's point at the
    default window.
    """
    screen = layout.screens[variant]
    p = motion.size
    w_px, h_px = screen.size_px
    points = []
    if layout.on('frame'):
        points.append(screen.px(np.broadcast_to(layout.frame_points,
                                                (p,) + layout.frame_points.shape)))
    if layout.on('joints') and motion.joints.shape[1]:
        points.append(screen.px(motion.joints))
    if layout.on('mass_centres'):
        points.append(screen.px(motion.centres[variant]))
    markers = np.concatenate(points, axis=1) if points else np.zeros((p, 0, 2))
    lines = segments_px(layout, motion, screen, variant)
    links_px = link_segments_px(motion, screen)
    placed = []      # (p, 4) boxes with (p,) masks
    out = []         # per spec: (p, 3) anchors, mask, texts
    h = LABEL_TEXT_PX + LABEL_PAD_PX[1]
    for spec in layout.labels:
        if spec.members and variant not in spec.members:
            continue                    # a label of the other design (its discs, changes)
        texts = [spec.text(d) for d in motion.degrees] if callable(spec.text) else None
        w = max(label_size_px(t)[0] for t in (texts or [spec.text]))
        if spec.where in ('readout', 'scale'):
            corner = np.array([LABEL_GAP_PX + 0.5 * w, LABEL_GAP_PX + 0.5 * h])
            if spec.where == 'scale':
                corner = screen.px(layout.scale_bar[2])
            box = np.broadcast_to(np.array([corner[0] - w / 2, corner[1] - h / 2,
                                            corner[0] + w / 2, corner[1] + h / 2]), (p, 4))
            ok = np.ones(p, dtype=bool)
            centre_px = np.broadcast_to(corner, (p, 2))
            base = unproject(screen, centre_px - [0.0, LABEL_DROP_PX + 0.5 * h], layout,
                             motion)
            placed.append((box, ok))
            out.append((base, ok, texts or [spec.text] * p, spec.color))
            continue
        feature = label_anchor(layout, motion, spec, variant, screen)
        features = [feature]
        if spec.where == 'link':
            features += label_anchor(layout, motion, Label('', (), 'link_along', spec.index),
                                     variant, screen) or []
        offs = candidates(w, h)                                     # (c, 2)
        if spec.where == 'gauge':
            offs = offs[[2, 6, 7, 1, 3, 0, 4, 5] + list(range(8, len(offs)))]
        f_px = np.stack([screen.px(f) for f in features], axis=1)  # (p, a, 2)
        centres = (f_px[:, :, None, :] + offs[None, None]).reshape(p, -1, 2)   # (p, a c, 2)
        which = np.repeat(np.arange(len(features)), len(offs))     # anchor of each place
        boxes = np.stack([centres[..., 0] - w / 2, centres[..., 1] - h / 2,
                          centres[..., 0] + w / 2, centres[..., 1] + h / 2], axis=-1)
        ok = (boxes[..., 0] >= 0) & (boxes[..., 1] >= 0) & (boxes[..., 2] <= w_px) & \
            (boxes[..., 3] <= h_px)
        for other, mask in placed:
            g = LABEL_GAP_PX
            hit = (boxes[..., 0] < other[:, None, 2] + g) & \
                (boxes[..., 2] > other[:, None, 0] - g) & \
                (boxes[..., 1] < other[:, None, 3] + g) & (boxes[..., 3] > other[:, None, 1] - g)
            ok &= ~(hit & mask[:, None])
        if markers.shape[1]:
            mx, my = markers[:, None, :, 0], markers[:, None, :, 1]
            m = MARKER_PX
            hit = (mx > boxes[..., 0, None] - m) & (mx < boxes[..., 2, None] + m) & \
                (my > boxes[..., 1, None] - m) & (my < boxes[..., 3, None] + m)
            ok &= ~hit.any(axis=-1)
        # no line crosses a label, and it names its own feature: the costly tests, run only
        # where the cheap ones passed and only until each sample's first place is found
        ok = first_passing(ok, lambda rows, cols: ~segments_hit_boxes(
            lines[rows], boxes[rows, cols]) & _nearest_own(
            spec, f_px[rows, 0], centres[rows, cols], markers[rows],
            [s[rows] for s in links_px]))
        found = ok.any(axis=1)
        first = np.argmax(ok, axis=1)
        rows = np.arange(p)
        box = boxes[rows, first]
        centre_px = centres[rows, first]
        placed.append((box, found))
        chosen = np.stack(features, axis=1)[rows, which[first]]    # (p, 3)
        base = unproject(screen, centre_px - [0.0, LABEL_DROP_PX + 0.5 * h], layout, motion,
                         chosen)
        out.append((base, found, texts or [spec.text] * p, spec.color))
    positions, labels, colors, counts = [], [], [], np.zeros(p, dtype=np.int64)
    for k in range(p):
        for base, mask, texts, color in out:
            if mask[k]:
                positions.append(base[k])
                labels.append(texts[k])
                colors.append(color)
                counts[k] += 1
    return (np.array(positions).reshape(-1, 3), labels, colors, counts)


def _nearest_own(spec, feature_px, centres, markers, links_px):
    """
    Return ``(p, c)``: whether a label box centred at ``centres`` names its own feature.

    A point's label (frame, joint, mass centre) is nearer its point than any other drawn
    point (points at its place excepted), by :data:`NEAR_MARGIN_PX`; a link's name nearer
    its link than any other link.
    """
    if spec.where == 'link':
        own = links_px[spec.index]
        if own.shape[1] == 0:
            return np.ones(centres.shape[:2], dtype=bool)
        mine = distance_to_segments(centres, own)
        others = [distance_to_segments(centres, s) for i, s in enumerate(links_px)
                  if i != spec.index and s.shape[1]]
        return mine + NEAR_MARGIN_PX < np.min(others, axis=0) if others else \
            np.ones(centres.shape[:2], dtype=bool)
    if spec.where not in ('frame', 'joint', 'centre', 'change') or markers.shape[1] == 0:
        return np.ones(centres.shape[:2], dtype=bool)
    mine = np.linalg.norm(centres - feature_px[:, None], axis=-1)              # (p, c)
    same = np.linalg.norm(markers - feature_px[:, None], axis=-1) <= SAME_PLACE_PX
    d = np.linalg.norm(centres[:, :, None] - markers[:, None], axis=-1)        # (p, c, M)
    d = np.where(same[:, None], np.inf, d)
    return mine + NEAR_MARGIN_PX < d.min(axis=-1)


def unproject(screen, centre_px, layout, motion, feature=None):
    """Return scene points ``(p, 3)`` drawn at pixel centres ``(p, 2)``."""
    if screen.bounds is not None:
        (x0, _), (_, y1) = screen.bounds
        s = screen.metres_per_px
        return np.stack([x0 + centre_px[:, 0] * s, y1 - centre_px[:, 1] * s,
                         np.zeros(len(centre_px))], axis=-1)
    if feature is None:
        feature = np.broadcast_to(np.asarray(screen.target_m), (len(centre_px), 3))
    return feature + screen.offset_m(feature, centre_px - screen.px(feature))
