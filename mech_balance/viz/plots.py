"""The plots of a recording (no rerun): each quantity over the crank angle, as a 2-D view."""

from dataclasses import dataclass
import math

from mech_balance.schema.scene import series_stream
from mech_balance.viz.labels import label_point_px, label_size_px
from mech_balance.viz.layout import nice_ceil, window_px
from mech_balance.viz.style import series_label
import numpy as np


ANGLE_ROOT = 'by_angle'
"""The entities of the plots over the crank angle (2-D views), one subtree per quantity."""
X_TICKS_DEG = (0, 90, 180, 270, 360)
"""The x axis's labelled ticks (deg)."""
Y_TICKS = (3, 6)
"""A plot's y axis has at least and at most this many labelled ticks."""
X_NAME_DEG = 225.0
"""The x axis's name stands in the row of its tick labels, between 180 and 270 deg."""
MARGIN_PX = (84.0, 24.0, 26.0, 28.0)
"""Room inside a plot's view (left, right, top, bottom) for its tick labels and legend."""


@dataclass
class Plot:
    """One plotted quantity: stream switch, entity, title, unit and the drawing over angle."""

    stream: str
    entity: str
    title: str
    unit: str
    axes: object = None
    curves: dict = None       # variant -> (n + 1, 2) pixel points over one turn, 0-360 deg


@dataclass
class AnglePlot:
    """Where a plot's values land in its 2-D view: pixel box, y ticks, the value->px map."""

    size_px: tuple            # (w, h) of the view's drawing area at the default window
    box_px: tuple             # (x0, y0, x1, y1) of the plotting area
    y_ticks: tuple            # tick values, in the quantity's unit

    def x(self, degrees):
        """Return the pixel x of crank angles (deg, reduced to a turn)."""
        x0, _, x1, _ = self.box_px
        return x0 + (x1 - x0) * np.asarray(degrees, dtype=float) / 360.0

    def y(self, values):
        """Return the pixel ordinates (down) of values."""
        _, y0, _, y1 = self.box_px
        lo, hi = self.y_ticks[0], self.y_ticks[-1]
        return y1 - (y1 - y0) * (np.asarray(values, dtype=float) - lo) / (hi - lo)

    def points(self, degrees, values):
        """Return the pixel points ``(n, 2)`` of values at crank angles (deg)."""
        return np.stack([self.x(degrees), self.y(values)], axis=-1)


def y_ticks(values):
    """Return :data:`Y_TICKS` round ticks (1, 2, 5 x 10^k apart) over ``values``, 0 if near."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    lo, hi = (float(v.min()), float(v.max())) if v.size else (0.0, 0.0)
    if lo >= 0.0 and lo < 0.5 * hi:
        lo = 0.0
    if hi <= 0.0 and hi > 0.5 * lo:
        hi = 0.0
    if not hi - lo > 1e-12 * max(abs(lo), abs(hi), 1e-300):
        pad = 0.5 * (abs(hi) or 1.0)
        lo, hi = lo - pad, hi + pad
    step = nice_ceil((hi - lo) / (Y_TICKS[1] - 1))
    while True:
        t0, t1 = math.floor(lo / step + 1e-9), math.ceil(hi / step - 1e-9)
        if t1 - t0 + 1 <= Y_TICKS[1]:
            break
        step = nice_ceil(step * 1.01)
    ticks = [k * step for k in range(t0, t1 + 1)]
    while len(ticks) < Y_TICKS[0]:
        ticks = ticks + [ticks[-1] + step] if hi > 0.0 or lo >= 0.0 else \
            [ticks[0] - step] + ticks
    return tuple(float(round(t / step) * step) for t in ticks)


def tick_text(value, unit):
    """Return a tick's label: the value and the unit (``0.5 N``, ``-1 N*m``)."""
    return f'{value:.4g} {unit}'.strip() if value else f'0 {unit}'.strip()


def furniture(axes, unit, x_name):
    """Return a plot's static drawing: ``(grid strips, axis strips, [(point, tick label)])``."""
    x0, y0, x1, y1 = axes.box_px
    grid = [np.array([[x, y0], [x, y1]]) for x in axes.x(X_TICKS_DEG)] + \
        [np.array([[x0, y], [x1, y]]) for y in axes.y(axes.y_ticks)]
    frame = [np.array([[x0, y0], [x0, y1], [x1, y1]])]
    if axes.y_ticks[0] < 0.0 < axes.y_ticks[-1]:
        frame.append(np.array([[x0, axes.y(0.0)], [x1, axes.y(0.0)]]))
    texts = []
    row = y1 + 3.0 + 0.5 * label_size_px('0')[1]            # the x tick labels' row
    for d in X_TICKS_DEG:
        texts.append((label_point_px((axes.x(d), row), f'{d}°'), f'{d}°'))
    texts.append((label_point_px((axes.x(X_NAME_DEG), row), x_name), x_name))
    for t in axes.y_ticks:
        text = tick_text(t, unit)
        w = label_size_px(text)[0]
        texts.append((label_point_px((x0 - 4.0 - 0.5 * w, axes.y(t)), text), text))
    return grid, frame, texts


def plot_specs(layout, motion):
    """Return the plots, each with its :class:`AnglePlot` (from the reference turn's data)."""
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
    _, (w, h) = window_px(len(layout.variants), len(specs), layout.on('info'), layout.inset)
    left, right, top, bottom = MARGIN_PX
    turned = 360.0 * np.arange(motion.size + 1) / motion.size       # from 0 deg, one turn
    plots = []
    for stream, entity, title, unit in specs:
        values = plot_values(layout, motion.data, entity)
        axes = AnglePlot((w, h), (left, top, w - right, h - bottom),
                         y_ticks(np.concatenate(list(values.values()))))
        curves = {v: axes.points(turned, np.append(x, x[:1])) for v, x in values.items()}
        plots.append(Plot(stream, entity, title, unit, axes, curves))
    return plots


def plot_values(layout, data, entity):
    """Return ``{variant: values}`` of one plotted quantity (``data``: variant -> RigData)."""
    if entity == 'shaking_force':
        return {v: np.linalg.norm(d.force_N, axis=1) for v, d in data.items()}
    if entity == 'shaking_moment' and layout.dim == 2:
        return {v: d.moment_Nm[:, 2] for v, d in data.items()}
    if entity == 'shaking_moment':
        return {v: np.linalg.norm(d.moment_Nm, axis=1) for v, d in data.items()}
    return {v: d.series[entity] for v, d in data.items() if entity in d.series}
