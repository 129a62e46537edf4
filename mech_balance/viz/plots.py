"""
The time-series views of a recording: which quantities, their values, their y ranges.

Pure numbers (no rerun): the y range of a plot on the viewer's decade ticks, chosen from the
reference turn's data so that each plot shows at least :data:`PLOT_MIN_TICKS` labelled ticks.
"""

from dataclasses import dataclass
import math

from mech_balance.schema.scene import series_stream
from mech_balance.viz.layout import window_px
from mech_balance.viz.style import series_label
import numpy as np


LEGEND_HEADROOM = 0.24
"""Share of a plot's height kept free above the curves for the legend (top right)."""
PLOT_MIN_TICKS = 3
"""A plot's y range holds at least this many labelled ticks."""
PLOT_EDGE_SHARE = 0.04
"""Share of a plot's range added beyond its end ticks, so that the viewer labels them."""
PLOT_TICK_PX = 24.0
"""Least distance between two labelled y ticks (the viewer hides denser labels: 23 px are
shown, 12 px are not, on screenshots of rerun 0.41)."""


@dataclass
class Plot:
    """One time-series view: entity, title, values per variant (reference turn), y range."""

    stream: str
    entity: str
    title: str
    unit: str
    y_range: tuple = None
    tick_step: float = None


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
