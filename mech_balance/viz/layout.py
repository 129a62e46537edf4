"""Where things land on screen (no rerun): the default window, the views, the gauge, the inset."""

from dataclasses import dataclass, field, replace
import functools
import itertools
import math

from mech_balance.viz.labels import label_anchor, LABEL_PAD_PX, LABEL_TEXT_PX, place_labels
from mech_balance.viz.style import (
    CENTRE_RADIUS_SHARE, DIAL_OVER_ARROW, DIAL_SHARE, FORCE_ARROW_SHARE, GAUGE_GAP_SHARE,
    GAUGE_LABEL_DROP,
    MOMENT_ARC_MAX_DEG, MOMENT_HEAD_SHARE, POINT_MASS_RADIUS_SHARE, SCALE_BAR_SHARE
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
INSET_SHARE = 0.4
"""Share of the right column's height of the inset (a crowded core zoomed), plots below."""
INSET_TRIGGER = 0.1
"""A 2-D rig gets an inset when more than this share of its labels' places is not clean."""
INSET_MIN_ZOOM = 1.5
"""... and the inset shows the crowded labels' features at least this much larger."""
INSET_PAD_PX = 70.0
"""Room around the crowded features in the inset, for their labels."""
GAUGE_GRID = 15
"""Places per side of the grid over the rig's box where a free corner for the gauge is sought."""
GAUGE_CLEAR_POINTS = 9
"""Points per drawn segment checked for the gauge's clearance."""
VIEW_PAD_PX = 34.0
"""Margin of the 2-D bounds around everything drawn (room for labels at the edge)."""
FOV_Y_RAD = math.radians(55.0)
"""Vertical field of view of the viewer's 3-D eye (rerun's default)."""
EYE_DIRECTION = (1.0, -1.7, 0.9)
"""Direction from the look target towards the 3-D eye (frame axes, z up): front right above."""
GRID_MARGIN_LINES = 0
"""The 3-D grid reaches this many spacings beyond the rig (besides rounding out to a line)."""
EYE_FIT = 1.03
"""The 3-D eye stands this much further than the distance that just fits the drawing."""
EYE_CENTRING = 3
"""Times the look target is moved to centre the picture before the last fit."""


@dataclass(frozen=True)
class Screen:
    """
    Where a view's points land on screen at the default window (:data:`WINDOW_PX`).

    ``size_px`` of the drawing area; 2-D: ``bounds`` ((x0, x1), (y0, y1)), y up; 3-D: an eye.
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

    @functools.cached_property
    def axes(self):
        """Return the 3-D eye's ``(eye, forward, right, up)`` unit vectors (frame axes)."""
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
        eye, fwd, right, up = self.axes
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
        eye, fwd, right, up = self.axes
        depth = (np.asarray(points, dtype=float) - eye) @ fwd
        s = depth * 2.0 * math.tan(0.5 * FOV_Y_RAD) / self.size_px[1]
        return (d[..., 0:1] * right - d[..., 1:2] * up) * s[..., None]


@dataclass
class Layout:
    """Everything static of a recording: rigs, drawings, styles, scales, screens, text."""

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
    series: tuple
    has_added: bool
    has_point_masses: bool
    gauge_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    gauge_reach_m: float = 0.0   # radius of everything the gauge draws
    dial_radius_m: float = 0.0
    scale_bar: tuple = None      # ((k, 3) strip, label text, label point (3,))
    screens: dict = None
    plots: list = ()
    labels: list = ()
    text: str = ''
    live: bool = False
    grid_m: float = 0.0          # 3-D: spacing of the grid lines
    grid_text: str = ''
    grid_box: tuple = None       # 3-D: (x0, x1, y0, y1) of the grid drawn on z = 0
    marks: dict = None           # variant -> {'rings': [(body, (k, 3))], 'stalks': [...]}
    changes: dict = None         # variant -> [(body index, mass change kg)]
    inset: object = None         # a Screen zoomed on a crowded core, or None
    placed: dict = None          # view -> its labels at every sample (place_labels)

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
    """Return metres of arrow per unit (1 cm a round value, the longest <= ``share`` of rig)."""
    if not largest > 0.0:
        return 1.0
    return 0.01 / nice_ceil(largest * 0.01 / (share * size_m), steps)


def arc_scale(largest):
    """Return degrees of arc per N*m: 90 deg is a round moment, the largest sweeps <= 270."""
    if not largest > 0.0:
        return 1.0
    return 90.0 / nice_ceil(largest * 90.0 / MOMENT_ARC_MAX_DEG)


def window_px(n_views, n_plots, has_text, inset=None):
    """Return the drawing-area sizes (px) of a rig view and of a plot (under any inset)."""
    w, h = WINDOW_PX
    height = h - TOP_BAR_PX - TIME_PANEL_PX
    left = w * LEFT_SHARE if n_plots or inset is not None else w
    rig_h = (height * RIG_ROW_SHARE if has_text else height) - VIEW_TITLE_PX
    rig_w = left / max(n_views, 1) - 6.0
    plots_h = height * (1.0 - INSET_SHARE) if inset is not None else height
    plot = ((w - left) - 8.0, plots_h / max(n_plots, 1) - VIEW_TITLE_PX)
    return (float(rig_w), float(rig_h)), plot


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
        text = length_text(bar)
        lo = np.minimum(lo, strip.min(axis=0) - [0, tick, 0])
        if gauge and reach > 0.0:
            centre = _gauge_place(layout, motion, pts, radii, lo, hi, reach, gap, view_px)
            layout.gauge_m, layout.gauge_reach_m = centre, reach
            lo = np.minimum(lo, centre - reach)
            hi = np.maximum(hi, centre + reach)
        screen = fit_2d(lo, hi, view_px)
        label_at = 0.5 * (strip[1] + strip[2]) + screen.offset_m(
            strip[1], [0.0, 3.0 + 0.5 * (LABEL_TEXT_PX + LABEL_PAD_PX[1])])
        layout.scale_bar = (strip, text, label_at)
    else:
        reach = max(arrow, nmax * layout.moment_scale if layout.on('shaking_moment_arc')
                    else 0.0)
        # the grid under the rig alone (the gauge stands beside it, off the grid)
        layout.grid_box = grid_box(lo, hi, layout.grid_m)
        screen = _frame_3d(layout, motion, pts, lo, hi, reach if gauge else 0.0, gap, view_px)
    layout.screens = {v: screen for v in layout.variants}


def zoom_inset(layout, motion, placed):
    """
    Return the labels of an inset zoomed on the original view's crowded core, or None.

    Sets ``layout.inset`` and moves the crowded names there (`docs/recordings.md`, Inset).
    """
    tiers = placed['original'][4].reshape(motion.size, -1)
    if layout.dim != 2 or not np.mean(tiers >= 2) > INSET_TRIGGER:
        return None
    kinds = ('frame', 'joint', 'link')
    specs = [s for s in layout.labels if not s.members or 'original' in s.members]
    crowded = [s for s, t in zip(specs, tiers.T)
               if s.where in kinds and np.mean(t >= 2) > INSET_TRIGGER]
    points = [s for s in crowded if s.where != 'link'] or crowded   # the core's points
    if not points:
        return None
    pts = np.concatenate([label_anchor(layout, motion, s, 'original', None) for s in points])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    _, (w, h) = window_px(len(layout.variants), 1, False)
    screen = fit_2d(lo, hi, (w, (h + VIEW_TITLE_PX) * INSET_SHARE - VIEW_TITLE_PX),
                    (INSET_PAD_PX, INSET_PAD_PX))
    if layout.screens['original'].metres_per_px < INSET_MIN_ZOOM * screen.metres_per_px:
        return None
    layout.inset = screen
    (x0, x1), (y0, y1) = screen.bounds

    def inside(spec):
        a = label_anchor(layout, motion, spec, 'original', None)
        return np.all((a[:, 0] > x0) & (a[:, 0] < x1) & (a[:, 1] > y0) & (a[:, 1] < y1))
    named = [x for x in specs if x.where in kinds and inside(x)]
    zoomed = replace(layout, screens={'original': screen}, scale_bar=None, has_added=False,
                     streams=tuple(x for x in layout.streams if x != 'mass_centres'),
                     labels=named)
    moved = [x in crowded and x in named for x in specs]
    layout.labels = [x for x in layout.labels if not (x in crowded and x in named)]
    pos, texts, colors, counts, tiers = placed['original']
    keep = np.tile(~np.array(moved), motion.size)
    placed['original'] = (pos[keep], [t for t, k in zip(texts, keep) if k],
                          [c for c, k in zip(colors, keep) if k], counts - sum(moved), tiers[keep])
    return place_labels(zoomed, motion, 'original')


def grid_box(lo, hi, spacing):
    """Return the 3-D grid's ``(x0, x1, y0, y1)`` on z = 0: the rig's extent rounded out."""
    if not spacing > 0.0:
        return None
    m = GRID_MARGIN_LINES * spacing
    x0, y0 = (np.floor((lo[:2] - m) / spacing) * spacing).tolist()
    x1, y1 = (np.ceil((hi[:2] + m) / spacing) * spacing).tolist()
    return (x0, x1, y0, y1)


def fit_2d(lo, hi, view_px, pad_px=(VIEW_PAD_PX, VIEW_PAD_PX + LABEL_TEXT_PX)):
    """Return the 2-D :class:`Screen` of ``view_px`` that fits the box ``lo``-``hi``, centred."""
    w, h = view_px
    s = max((hi[0] - lo[0]) / (w - 2 * pad_px[0]), (hi[1] - lo[1]) / (h - 2 * pad_px[1]),
            1e-300)
    c = 0.5 * (np.asarray(lo, dtype=float) + hi)
    return Screen(view_px, bounds=((float(c[0] - 0.5 * w * s), float(c[0] + 0.5 * w * s)),
                                   (float(c[1] - 0.5 * h * s), float(c[1] + 0.5 * h * s))))


def length_text(length_m):
    """Return a round length as a person writes it (``5 cm``, ``2 mm``, ``1 m``)."""
    if length_m >= 1.0:
        return f'{length_m:g} m'
    return f'{length_m * 100:g} cm' if length_m >= 0.01 else f'{length_m * 1000:g} mm'


def _gauge_place(layout, motion, pts, radii, lo, hi, reach, gap, view_px):
    """
    Return the 2-D gauge's centre: where the rig, gauge and all fit the view the largest.

    Tried: beside, under and over the rig, and the free corners of its own box.
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
        grid = np.array([(x, y) for y in ys[::-1] for x in xs])
        free = np.ones(len(grid), dtype=bool)
        padded = pad > 0.0
        if not padded.all():          # the nearest bare point, column by column of the grid
            free &= _nearest(grid, cloud[~padded], reach + gap) >= reach + gap
        if padded.any():              # points drawn with a radius (mass centres, discs)
            d = np.linalg.norm(grid[:, None] - cloud[padded][None], axis=-1) - pad[padded]
            free &= d.min(axis=1) >= reach + gap
        places += [tuple(g) for g in grid[free]]
    best, best_s = None, math.inf
    for x, y in places:
        c = np.array([x, y, 0.0])
        s = fit_2d(np.minimum(lo, c - reach), np.maximum(hi, c + reach), view_px).metres_per_px
        if s < best_s * (1.0 - 1e-9):
            best, best_s = c, s
    return best


def _nearest(grid, cloud, within):
    """
    Return the distance from each grid point ``(g, 2)`` to its nearest cloud point.

    Exact where it is below ``within``; elsewhere at least ``within`` (``inf`` where no cloud
    point is within ``within`` in x): each grid column is held against the cloud points of
    its strip of x alone (numpy, no k-d tree: scipy.spatial costs more to import).
    """
    out = np.full(len(grid), np.inf)
    near_x = within * (1.0 + 1e-9)
    for x in np.unique(grid[:, 0]):
        rows = np.flatnonzero(grid[:, 0] == x)
        strip = cloud[np.abs(cloud[:, 0] - x) <= near_x]
        if len(strip):
            d = grid[rows, None, :] - strip[None]
            out[rows] = np.sqrt((d * d).sum(axis=-1)).min(axis=1)
    return out


def _gauge_tips(layout, motion):
    """Return the 3-D gauge's drawn points relative to its centre: arrow tips, label, centre."""
    tips = [np.zeros((1, 3))]
    for d in motion.data.values():
        if layout.on('shaking_force_arrow') and d.force_N is not None:
            tips.append(d.force_N * layout.force_scale_m_per_N)
        if layout.on('shaking_moment_arc') and d.moment_Nm is not None:
            tips.append(d.moment_Nm * layout.moment_scale)
    tips = np.concatenate(tips)
    return np.concatenate([tips, [[0.0, 0.0, -GAUGE_LABEL_DROP * layout.gauge_reach_m]]])


def _hull(points):
    """Return the distinct points of ``points`` ``(m, 3)``: those extreme on a screen too."""
    return np.unique(np.asarray(points, dtype=float), axis=0)


def _frame_3d(layout, motion, pts, lo, hi, reach, gap, view_px):
    """Return the 3-D screen: the eye fitted to the rig and its gauge, the gauge's place chosen."""
    d = np.asarray(EYE_DIRECTION, dtype=float)
    d = d / np.linalg.norm(d)
    right = np.cross(-d, (0.0, 0.0, 1.0))
    right = right / np.linalg.norm(right)
    back = np.cross(right, (0.0, 0.0, 1.0))
    up = np.array([0.0, 0.0, 1.0])
    rig = _hull(pts)
    centre = 0.5 * (lo + hi)
    if not reach > 0.0:
        return fit_eye(view_px, centre, d, rig)
    layout.gauge_reach_m = reach
    offsets = _hull(_gauge_tips(layout, motion))

    def beside(axis):
        return 0.5 * np.abs(hi - lo) @ np.abs(axis) + gap + reach
    best = None
    for a, b, c in itertools.product((1, -1, 0), (0, 1), (0, 1, -1)):
        if a == 0 and b == 0:
            continue            # in front of the rig or behind it
        gauge = centre + a * right * beside(right) + b * up * beside(up) + \
            c * back * beside(back)
        tips = gauge + offsets
        screen = fit_eye(view_px, centre, d, np.concatenate([rig, tips]))
        r, g = screen.px(rig), screen.px(tips)
        clear = np.any(g.min(axis=0) > r.max(axis=0)) or np.any(g.max(axis=0) < r.min(axis=0))
        dist = np.linalg.norm(np.subtract(screen.eye_m, screen.target_m))
        key = (not clear, dist)
        if best is None or key < best[0]:
            best = (key, gauge, screen)
    layout.gauge_m = best[1]
    return best[2]


def fit_eye(view_px, target, direction, corners):
    """Return a 3-D :class:`Screen` whose eye along ``direction`` sees every corner, centred."""
    target = np.asarray(target, dtype=float)
    corners = np.asarray(corners, dtype=float)
    d = np.asarray(direction, dtype=float)
    d = d / np.linalg.norm(d)
    w, h = view_px
    focal = 0.5 * h / math.tan(0.5 * FOV_Y_RAD)
    half = np.array([0.5 * w - VIEW_PAD_PX, 0.5 * h - VIEW_PAD_PX])
    probe = Screen(view_px, eye_m=tuple(target + d), target_m=tuple(target))
    _, fwd, right, up = probe.axes
    for step in range(EYE_CENTRING + 1):
        v = corners - target
        across = np.abs(np.stack([v @ right, v @ up], axis=-1))              # (m, 2)
        dist = float(np.max(np.max(focal * across / half, axis=1) - v @ fwd))
        dist = max(dist, float(np.max(-(v @ fwd))) + 1e-9, 1e-9)
        screen = Screen(view_px, eye_m=tuple(target + d * dist), target_m=tuple(target))
        if step == EYE_CENTRING:
            break
        px = screen.px(corners)
        mid = 0.5 * (px.min(axis=0) + px.max(axis=0)) - [0.5 * w, 0.5 * h]
        target = target + screen.offset_m(target, mid)
    return Screen(view_px, eye_m=tuple(target + d * dist * EYE_FIT), target_m=tuple(target))
