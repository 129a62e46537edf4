"""
Rerun recordings of a rig in motion: the original mechanism against its balanced design.

The only module of mech_balance that imports rerun.  It is one drawing adapter of the Rig
protocol (:mod:`mech_balance.core.rig`): the picture comes from ``rig.drawing`` (frame
points, bodies with their outlines, mass centres, added bodies and point masses, joints,
fixed axes) posed by ``rig.at(...).bodies``, the numbers from ``rig.at(...)`` (the shaking
wrench and every scalar in ``RigData.series``).  It never asks which kind of rig it draws;
where a 2-D and a 3-D picture differ it asks ``drawing.dimension``.

Entities (the stream switch of the scene's ``recording: {streams: ...}`` in brackets;
``variant`` is ``original`` or ``balanced``):

* ``/info`` [info]: the RMS table first, then the design and how to read the views;
* ``/rig/frame``, ``/rig/pivots`` [frame]: the ground link, fixed joint axes and guides,
  the frame points;  ``/rig/links`` [links];  ``/rig/joints`` [joints];
* ``/{variant}/mass_centres`` [mass_centres]: body mass centres, the system's last;
* ``/{variant}/counterweights`` [links]: the design's added bodies (counterweight discs,
  balancing weights) at true size, on their bodies;
* ``/{variant}/point_masses`` [point_masses, off unless a scene asks]: the equimomental
  point masses of the bodies, where the rig has them;
* ``/{variant}/shaking_force`` [shaking_force_arrow] and ``/{variant}/shaking_moment``
  [shaking_moment_arc]: a gauge beside the rig (2-D: an arrow inside a dial whose arc is
  the moment; 3-D: two arrows);
* ``/plots/{quantity}/{variant}`` [``{quantity}_plot``]: |shaking force| (N), shaking
  moment (N*m, 3-D: its norm) and every series of ``RigData.series`` (driving torque,
  kinetic energy, ...: :data:`mech_balance.schema.scene.SERIES`).

View furniture, not switchable: ``/{variant}/labels`` (every label of that view, placed so
that none overlaps another at the default window, :data:`WINDOW_PX`), ``/rig/scale`` (2-D
scale bar), ``/rig/gauge`` (the moment dial).

Timelines: ``crank_angle``, the crank angle turned from 0 in whole degrees (offline: a turn
starts at 0 deg, sample k of n at round(360 k / n), any n; live: the rig's cumulative
angle), and ``time``, seconds (offline at the scene's crank speed; live on the rig's
clock).  The exact angle is written in every rig view.  Geometry and styles are static;
whole time series go out through ``send_columns``.  :func:`record` writes a file;
:class:`LiveRecorder` the same views sample by sample, to a file and/or to a running viewer
(``url``), the viewer throttled to :data:`LIVE_MAX_RATE_HZ` on a thread of its own.
"""

import atexit
from collections import deque
from dataclasses import dataclass
import math
import os
from pathlib import Path
import re
import threading
import time

from mech_balance import atomic, conventions, paths
from mech_balance.conventions import rms
from mech_balance.core.rig import rig_for
from mech_balance.schema import registry
from mech_balance.schema.scene import needs, Recording, RECORDING_STREAMS, SERIES
import numpy as np
import rerun as rr
import rerun.blueprint as rrb

APPLICATION_ID = 'mech_balance'
"""Prefix of the rerun application id (the scene name follows, so layouts never clash)."""
RRD_SUFFIX = '.rrd'
"""What the name of a recording file ends in (rerun's format)."""
VARIANTS = ('original', 'balanced')
MIN_SAMPLES = 4
"""Fewest samples per crank turn of a recording."""

# ----------------------------------------------------------------- the screen it is made for
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
MARKER_PX = 6.0
"""Radius kept free around a drawn point (pivot, joint, mass centre) by the labels."""
VIEW_PAD_PX = 34.0
"""Margin of the 2-D bounds around everything drawn (room for labels at the edge)."""
FOV_Y_RAD = math.radians(55.0)
"""Vertical field of view of the viewer's 3-D eye (rerun's default)."""
EYE_DIRECTION = (1.0, -1.7, 0.9)
"""Direction from the look target towards the 3-D eye (frame axes, z up): front right above."""
EYE_FIT = 1.15
"""The 3-D eye stands this much further than the distance that just fits the drawing."""

# ----------------------------------------------------------------- sizes, shares of the rig
FORCE_ARROW_SHARE = 0.14
"""Automatic force scale: the longest shaking-force arrow is at most this share of the rig."""
ARROW_3D_SHARE = 0.3
"""3-D: the longest shaking-force (and moment) arrow is at most this share of the rig."""
ARROW_3D_RADIUS_SHARE = 0.012
"""3-D: radius of the gauge's arrows, as a share of the rig."""
MOMENT_ARC_MAX_DEG = 270.0
"""Automatic moment scale: the largest shaking moment sweeps at most this arc."""
MOMENT_ARC_LIMIT_DEG = 355.0
"""An arc never sweeps more than this (a scene's own scale may ask for more)."""
DIAL_SHARE = 0.12
"""Least radius of the moment dial, as a share of the rig's size."""
DIAL_OVER_ARROW = 1.15
"""The dial's radius is at least this times the longest force arrow (arrows stay inside)."""
MOMENT_HEAD_SHARE = 0.3
"""Length of the arc's arrow head, as a share of the dial radius."""
ARC_POINTS = 33
"""Points of the polyline that draws the shaking-moment arc."""
DIAL_POINTS = 65
"""Points of the dial circle."""
GAUGE_GAP_SHARE = 0.12
"""Gap between the rig and its gauge, as a share of the rig's size."""
BLOCK_SHARE = 0.035
"""Half-size of the square drawn for a one-point link (a slider), as a share of the rig."""
POINT_MASS_RADIUS_SHARE = 0.03
"""Radius of the largest point mass, as a share of the rig (disc area ~ abs(mass))."""
CENTRE_RADIUS_SHARE = 0.012
"""Radius of a body's mass-centre dot, as a share of the rig (the system's: 1.8 times)."""
AXIS_MARGIN_SHARE = 0.12
"""A fixed axis or guide extends this share of the rig beyond what moves along it."""
SCALE_BAR_SHARE = 0.3
"""The scale bar is the roundest length at most this share of the rig."""
LINK_RADIUS_3D_SHARE = 0.014
"""3-D: radius of a link's tube, as a share of the rig."""
FRAME_RADIUS_3D_SHARE = 0.005
"""3-D: radius of the frame's lines and axes, as a share of the rig."""
JOINT_RADIUS_3D_SHARE = 0.026
"""3-D: radius of a joint's sphere, as a share of the rig."""
COLLINEAR_RTOL = 1e-9
"""A link's points are collinear (drawn open) below this relative cross product."""
SAME_POINT_RTOL = 1e-9
"""Two points closer than this share of the rig are one place (their labels merge)."""
GEOMETRY_ANGLES = 8
"""Crank angles at which a balanced design's poses are compared with the original's."""
GEOMETRY_RTOL = 1e-7
"""Poses of two designs of one geometry agree to this share of the rig."""
LEGEND_HEADROOM = 0.24
"""Share of a plot's height kept free above the curves for the legend (top right)."""
PLOT_MIN_TICKS = 3
"""A plot's y range holds at least this many labelled ticks."""
PLOT_EDGE_SHARE = 0.04
"""Share of a plot's range added beyond its end ticks, so that the viewer labels them."""
PLOT_TICK_PX = 24.0
"""Least distance between two labelled y ticks (the viewer hides denser labels: 23 px are
shown, 12 px are not, on screenshots of rerun 0.41)."""
LINE_RADIUS_UI = rr.components.Radius.ui_points(2.0)
FRAME_RADIUS_UI = rr.components.Radius.ui_points(1.5)
JOINT_RADIUS_UI = rr.components.Radius.ui_points(4.5)
Y_UP_SCALE = (1.0, -1.0, 1.0)
"""Scale of the 2-D drawing roots that shows the scene's y axis upwards."""
CLOSE_TIMEOUT_S = 5.0
"""How long :meth:`LiveRecorder.close` waits for a logging call on another thread."""
LIVE_MAX_RATE_HZ = 30.0
"""The live view logs at most this many samples per second of the rig's clock."""
LIVE_FLUSH_HZ = 5.0
"""The live view's thread sends what it kept at most this often (per second of the rig's
clock): a send costs ~15 ms of Python whatever its size, which the publishing thread waits
for in slices of the node's switch interval."""
LIVE_QUEUE = 256
"""Batches waiting for the live view's thread; when full the oldest is dropped."""

# ----------------------------------------------------------------- colour roles (RGB)
FRAME_COLOR = (150, 150, 150)
JOINT_COLOR = (235, 235, 235)
FORCE_COLOR = (240, 70, 70)
MOMENT_COLOR = (200, 110, 255)
DIAL_COLOR = (90, 90, 100)
SCALE_COLOR = (200, 200, 200)
ADDED_COLOR = (175, 180, 195, 120)
"""Added bodies: see-through, so that the link under a disc shows."""
ADDED_DRAW_ORDER = 5.0
"""2-D draw order of the added bodies: behind the links (20) and points (30)."""
POSITIVE_MASS_COLOR = (225, 225, 225)
NEGATIVE_MASS_COLOR = (255, 105, 180)
SYSTEM_CENTRE_COLOR = (255, 255, 255)
READOUT_COLOR = (255, 255, 255)
SERIES_COLORS = {'original': (255, 150, 40), 'balanced': (70, 165, 255)}
"""Orange and blue mean original and balanced in the plots, and nothing else anywhere."""
LINK_PALETTE = ((27, 158, 119), (166, 216, 84), (255, 217, 47), (229, 196, 148),
                (141, 211, 199), (188, 189, 34), (166, 118, 29), (178, 223, 138))
"""Link colours: greens, yellows and browns (none is a plot, arrow or mass colour)."""

UNITS = {'force': 'N', 'moment': 'N*m', 'energy': 'J'}
"""SI unit of each dimension of :data:`mech_balance.schema.scene.SERIES`."""


def series_label(name):
    """Return ``(label, SI unit, dimension)`` of a series (its name alone if not listed)."""
    label, dim = SERIES.get(name, (name.replace('_', ' '), ''))
    return label, UNITS.get(dim, ''), dim


_SHAKING_STREAMS = ('shaking_force_arrow', 'shaking_moment_arc', 'shaking_force_plot',
                    'shaking_moment_plot')
_DRAWN_STREAMS = ('frame', 'links', 'joints', 'mass_centres', 'point_masses',
                  'shaking_force_arrow', 'shaking_moment_arc')


# ------------------------------------------------------------------------------- summaries


@dataclass(frozen=True)
class RecordingSummary:
    """What :func:`record` wrote: the file, its size, rows per series, entities and layout."""

    path: Path
    size_bytes: int
    samples_per_cycle: int
    cycles: int
    rows: int
    entity_paths: tuple
    variants: tuple
    seconds: float
    layout: object = None


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
class _Plot:
    """One time-series view: entity, title, values per variant (reference turn), y range."""

    stream: str
    entity: str
    title: str
    unit: str
    y_range: tuple = None
    tick_step: float = None


@dataclass
class _Label:
    """A label of a view: text (or texts per sample), colour, the feature it names."""

    text: object          # str, or a function of the sample's crank angle (deg)
    color: tuple
    where: str            # 'frame', 'joint', 'centre', 'link', 'fixed'
    index: int = 0
    members: tuple = ()   # joint indices merged into this label


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

    def on(self, stream):
        """Return whether ``stream`` is logged."""
        return stream in self.streams


# ------------------------------------------------------------------------------- helpers


def _nice_ceil(x):
    """Return the smallest 1, 2 or 5 times a power of ten that is >= ``x`` (``x`` > 0)."""
    exp = math.floor(math.log10(x))
    for m in (1.0, 2.0, 5.0, 10.0):
        if m * 10.0 ** exp >= x * (1.0 - 1e-12):
            return m * 10.0 ** exp
    return 10.0 ** (exp + 1)


def _nice_floor(x):
    """Return the largest 1, 2 or 5 times a power of ten that is <= ``x`` (``x`` > 0)."""
    exp = math.floor(math.log10(x))
    for m in (5.0, 2.0, 1.0):
        if m * 10.0 ** exp <= x * (1.0 + 1e-12):
            return m * 10.0 ** exp
    return 10.0 ** (exp - 1)


def _arrow_scale(size_m, largest, share=FORCE_ARROW_SHARE):
    """
    Return metres of arrow per unit value (m per N, or m per N*m).

    1 cm of arrow is a round value and the longest arrow at most ``share`` of the rig's size.
    """
    if not largest > 0.0:
        return 1.0
    return 0.01 / _nice_ceil(largest * 0.01 / (share * size_m))


def _arc_scale(largest):
    """Return degrees of arc per N*m: 90 deg is a round moment, the largest sweeps <= 270."""
    if not largest > 0.0:
        return 1.0
    return 90.0 / _nice_ceil(largest * 90.0 / MOMENT_ARC_MAX_DEG)


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


def _check_samples(samples, cycles, links=1):
    if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) or \
            samples < MIN_SAMPLES:
        raise ValueError(f'samples: got {samples!r}, expected an integer >= {MIN_SAMPLES} '
                         'samples per crank turn')
    conventions.check_samples(int(samples), links=links)
    if isinstance(cycles, bool) or not isinstance(cycles, (int, np.integer)) or cycles < 1:
        raise ValueError(f'cycles: got {cycles!r}, expected an integer >= 1')
    if cycles > conventions.MAX_CYCLES:
        raise ValueError(f'cycles: got {cycles}, expected at most {conventions.MAX_CYCLES} '
                         'crank turns (conventions.MAX_CYCLES)')


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


def _world(poses, body, local):
    """Return ``(n, k, 3)`` frame coordinates of points ``(k, 3)`` fixed in ``body``."""
    k = poses.names.index(body)
    local = np.asarray(local, dtype=float).reshape(-1, 3)
    return poses.origin_m[:, k, None, :] + np.einsum('nij,kj->nki', poses.rotation[:, k],
                                                     local)


def _streams_for(scene, rig):
    """Return the enabled stream names: the scene's switches, less what it does not compute."""
    rec = getattr(scene, 'recording', None) or Recording()
    have = needs(rig.outputs)
    streams = list(rec.streams)
    if 'accelerations' not in have:
        streams = [s for s in streams if s not in _SHAKING_STREAMS]
    if 'driving_torque' not in have:
        streams = [s for s in streams if s != 'driving_torque_plot']
    return tuple(streams)


def _series_on(name, streams):
    """Return whether the plot of series ``name`` is switched on."""
    stream = f'{name}_plot'
    return stream not in RECORDING_STREAMS or stream in streams


def _stream_outputs(rig, streams):
    """Return the outputs the enabled streams need (nothing a disabled stream alone needs)."""
    out = ['kinematics']
    if any(s in streams for s in _SHAKING_STREAMS):
        out.append('shaking_wrench')
    for o in rig.outputs:
        if o not in ('kinematics', 'shaking_wrench', 'bearing_reactions') and \
                _series_on(o, streams) and o not in out:
            out.append(o)
    return tuple(out)


# ------------------------------------------------------------------------------- designs


def _poses_signature(rig, psi):
    data = rig.at(psi, outputs=('kinematics',))
    order = np.argsort(np.array(data.bodies.names))
    return data.bodies.origin_m[:, order], data.bodies.rotation[:, order]


def _shape(drawing):
    return (drawing.dimension, sorted(drawing.frame.items()),
            sorted((b.name, tuple(sorted(b.points.items()))) for b in drawing.bodies),
            sorted(drawing.joints), sorted(drawing.axes))


def align_design(original, balanced):
    """
    Return ``balanced`` with its bodies in the order of ``original``'s.

    Raises ValueError unless both scenes are of one kind and have the same geometry: the
    same drawing (frame points, body points, joints, axes) and the same poses over a turn
    (the same assembly branch), so that they differ in inertias only.
    """
    ko, kb = registry.kind_of(original), registry.kind_of(balanced)
    if kb is not ko:
        raise ValueError(f'design: got a {kb.name} scene, expected a {ko.name} one like '
                         f'{original.name!r}')
    ro, rb = rig_for(original), rig_for(balanced)
    same = _shape(ro.drawing) == _shape(rb.drawing) and \
        set(ro.joint_names) == set(rb.joint_names) and ro.crank_joint == rb.crank_joint
    if same:
        psi = conventions.cycle_angles(GEOMETRY_ANGLES)
        (oo, rot_o), (ob, rot_b) = _poses_signature(ro, psi), _poses_signature(rb, psi)
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


# ------------------------------------------------------------------------------- geometry


def _outline(body, half_block):
    """
    Return a body's polyline in its own frame ``(k, 3)``.

    Closed for a plate, a square for a one-point body (a slider block).
    """
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
class _Motion:
    """A batch of samples: drawn positions (frame coordinates, 3-D) and every variant's data."""

    links: list           # per body (p, k, 3)
    joints: np.ndarray    # (p, J, 3)
    centres: dict         # variant -> (p, nb + 1, 3), the system's last
    added: dict           # variant -> (p, A, 3)
    point_masses: dict    # variant -> (p, 3 nb, 3)
    data: dict            # variant -> RigData
    degrees: np.ndarray   # (p,) crank angle shown (deg, reduced to [0, 360))

    @property
    def size(self):
        """Return the number of samples."""
        return self.joints.shape[0]


def _motion(layout, data):
    """Return the :class:`_Motion` of evaluated data ``{variant: RigData}``."""
    ref = data['original']
    poses = ref.bodies
    links = [_world(poses, name, local) for name, local in layout.templates]
    drawing = layout.drawings['original']
    joints = np.zeros((len(ref), 0, 3))
    if drawing.joints:
        joints = np.concatenate([_world(poses, body, [_body_point(drawing, body, point)])
                                 for _, body, point in drawing.joints], axis=1)
    centres, added, point_masses = {}, {}, {}
    for v, d in data.items():
        dr = layout.drawings[v]
        c = np.concatenate([_world(d.bodies, b.name, [b.mass_centre_m]) for b in dr.bodies],
                           axis=1)
        m = np.array([b.mass_kg or 0.0 for b in dr.bodies])
        system = np.einsum('k,nkd->nd', m, c) / m.sum() if m.sum() > 0 else c.mean(axis=1)
        centres[v] = np.concatenate([c, system[:, None]], axis=1)
        parts = [_world(d.bodies, b.name, [a.centre_m for a in b.added])
                 for b in dr.bodies if b.added]
        added[v] = np.concatenate(parts, axis=1) if parts else np.zeros((len(d), 0, 3))
        if layout.has_point_masses:
            pm = [_world(d.bodies, b.name, [p for _, p in b.point_masses])
                  for b in dr.bodies if b.point_masses]
            point_masses[v] = np.concatenate(pm, axis=1)
    degrees = np.mod(np.degrees(ref.crank_angle_rad), 360.0)
    return _Motion(links, joints, centres, added, point_masses, data, degrees)


def _body_point(drawing, body, point):
    if body == 'frame':
        return drawing.frame[point]
    return next(b for b in drawing.bodies if b.name == body).points[point]


def _tile(motion, cycles):
    """Return the motion repeated ``cycles`` times (periodic in the crank angle)."""
    if cycles == 1:
        return motion

    def rep(a):
        return np.concatenate([a] * cycles, axis=0)
    return _Motion([rep(a) for a in motion.links], rep(motion.joints),
                   {v: rep(a) for v, a in motion.centres.items()},
                   {v: rep(a) for v, a in motion.added.items()},
                   {v: rep(a) for v, a in motion.point_masses.items()},
                   {v: _TiledData(d, cycles) for v, d in motion.data.items()},
                   rep(motion.degrees))


class _TiledData:
    """The wrench and series of a RigData repeated over several turns (logging only)."""

    def __init__(self, data, cycles):
        def rep(a):
            return None if a is None else np.concatenate([a] * cycles, axis=0)
        self.force_N, self.moment_Nm = rep(data.force_N), rep(data.moment_Nm)
        self.series = {k: rep(v) for k, v in data.series.items()}


# ------------------------------------------------------------------------------- layout


def window_px(n_views, n_plots, has_text):
    """Return the drawing-area sizes (px) of a rig view and of a plot at :data:`WINDOW_PX`."""
    w, h = WINDOW_PX
    height = h - TOP_BAR_PX - TIME_PANEL_PX
    left = w * LEFT_SHARE if n_plots else w
    rig_h = (height * RIG_ROW_SHARE if has_text else height) - VIEW_TITLE_PX
    rig_w = left / max(n_views, 1) - 6.0
    plot = ((w - left) - 60.0, height / max(n_plots, 1) - VIEW_TITLE_PX - 24.0)
    return (float(rig_w), float(rig_h)), plot


def _frame_strips(drawing, moving, size):
    """Return the frame's polylines: the ground link, and each fixed axis or guide."""
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
        t = (cloud - p) @ d
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


def _merged_names(names, positions, size):
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


def _pivot_name(layout, rig):
    """Return the name of the frame point the shaking moment is reduced to, or its words."""
    at = np.asarray(rig.moment_point_m, dtype=float)
    for name, q in zip(layout.frame_names, layout.frame_points):
        if np.linalg.norm(at - q) <= SAME_POINT_RTOL * layout.size_m:
            return name
    return rig.moment_point


def _plan(scene, balanced, samples, balanced_source, live=False):
    """Return ``(layout, reference motion)`` from one turn of ``samples`` angles."""
    rig = rig_for(scene)
    rigs = {'original': rig}
    if balanced is not None:
        rigs['balanced'] = rig.with_scene(align_design(scene, balanced))
    drawings = {v: r.drawing for v, r in rigs.items()}
    drawing = drawings['original']
    dim = drawing.dimension
    streams = _streams_for(scene, rig)
    stream_outputs = _stream_outputs(rig, streams)
    asked = tuple(rig.outputs) if 'info' in streams else ()
    table_outputs = tuple(dict.fromkeys(stream_outputs + asked))
    psi = turn_angles(samples, scene.crank_speed_rad_s)
    data = {v: r.at(psi, outputs=table_outputs) for v, r in rigs.items()}
    ref = data['original']
    has_wrench = ref.force_N is not None
    if not has_wrench:
        streams = tuple(s for s in streams if s not in _SHAKING_STREAMS)
    series = tuple(k for k in list(SERIES) + sorted(ref.series)
                   if k in ref.series and _series_on(k, streams))
    series = tuple(dict.fromkeys(series))
    has_pm = 'point_masses' in streams and all(
        b.point_masses for dr in drawings.values() for b in dr.bodies)
    if not has_pm:
        streams = tuple(s for s in streams if s != 'point_masses')
    has_added = 'links' in streams and any(b.added for dr in drawings.values()
                                           for b in dr.bodies)

    # size of the rig: everything that moves over the turn and the frame
    bodies = [_world(ref.bodies, b.name, list(b.points.values())) for b in drawing.bodies]
    frame_pts = np.array(list(drawing.frame.values()), dtype=float).reshape(-1, 3)
    moving = np.concatenate(bodies, axis=1)
    cloud = np.concatenate([moving.reshape(-1, 3), frame_pts])
    span = float(np.max(np.ptp(cloud, axis=0)))
    size = span if span > 0.0 else 1.0
    templates = [(b.name, _outline(b, size * BLOCK_SHARE)) for b in drawing.bodies]
    names = [b.name for b in drawing.bodies]
    colors = [LINK_PALETTE[i % len(LINK_PALETTE)] for i in range(len(names))]
    frame_strips = _frame_strips(drawing, moving, size) if 'frame' in streams else []

    rec = getattr(scene, 'recording', None) or Recording()
    fmax = max((float(np.max(np.linalg.norm(d.force_N, axis=1))) for d in data.values()
                if d.force_N is not None), default=0.0)
    nmax = max((float(np.max(np.linalg.norm(d.moment_Nm, axis=1))) for d in data.values()
                if d.moment_Nm is not None), default=0.0)
    share = FORCE_ARROW_SHARE if dim == 2 else ARROW_3D_SHARE
    fscale = rec.force_scale_m_per_N or _arrow_scale(size, fmax, share)
    if dim == 2:
        mscale = rec.moment_scale_deg_per_Nm or _arc_scale(nmax)
    else:
        mscale = _arrow_scale(size, nmax, share)

    layout = Layout(
        title=scene.name, dim=dim, streams=streams, variants=tuple(rigs), rigs=rigs,
        drawings=drawings, stream_outputs=stream_outputs, size_m=size, templates=templates,
        link_names=names, link_colors=colors,
        joint_names=[j[0] for j in drawing.joints], frame_names=list(drawing.frame),
        frame_points=frame_pts, frame_strips=frame_strips,
        pivot_name=rig.moment_point, force_scale_m_per_N=fscale,
        moment_scale=mscale, gauge_m=np.zeros(3), gauge_reach_m=0.0, dial_radius_m=0.0,
        scale_bar=None,
        screens={}, plots=[], labels=[], series=series, has_added=has_added,
        has_point_masses=has_pm, live=live)
    motion = _motion(layout, data)
    layout.pivot_name = _pivot_name(layout, rig)
    _place_views(layout, motion, fmax, nmax, len(series))
    layout.labels = _label_specs(layout, motion)
    layout.plots = _plots(layout, motion)
    if 'info' in streams:
        layout.text = _text(layout, scene, data, samples, balanced_source)
    return layout, motion


def _drawn_extent(layout, motion):
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


def _place_views(layout, motion, fmax, nmax, n_series):
    """Choose the gauge's place, the scale bar and the screens (2-D bounds or 3-D eye)."""
    size = layout.size_m
    pts, radii = _drawn_extent(layout, motion)
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
        bar = _nice_floor(SCALE_BAR_SHARE * size)
        tick = 0.04 * size
        y_bar = lo[1] - 0.6 * gap
        x_bar = lo[0]
        strip = np.array([[x_bar, y_bar + tick, 0], [x_bar, y_bar, 0],
                          [x_bar + bar, y_bar, 0], [x_bar + bar, y_bar + tick, 0]])
        text = f'{bar * 100:g} cm' if bar >= 0.01 else f'{bar * 1000:g} mm'
        lo = np.minimum(lo, strip.min(axis=0) - [0, tick, 0])
        if gauge and reach > 0.0:
            w, h = hi[0] - lo[0], hi[1] - lo[1]
            aspect = view_px[0] / view_px[1]
            right = min(view_px[0] / (w + gap + 2 * reach), view_px[1] / max(h, 2 * reach))
            below = min(view_px[0] / max(w, 2 * reach), view_px[1] / (h + gap + 2 * reach))
            if right * aspect >= below * aspect:
                centre = np.array([hi[0] + gap + reach, 0.5 * (lo[1] + hi[1]), 0.0])
            else:
                centre = np.array([0.5 * (lo[0] + hi[0]), lo[1] - gap - reach, 0.0])
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
        target = 0.5 * (lo + hi)
        drawn = pts[::max(1, len(pts) // 4000)]
        if layout.gauge_reach_m:
            drawn = np.concatenate([drawn, layout.gauge_m + layout.gauge_reach_m * np.array(
                [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]])])
        screen = _fit_eye(view_px, target, d, drawn)
    layout.screens = {v: screen for v in layout.variants}


def _fit_eye(view_px, target, direction, corners):
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


def _plots(layout, motion):
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
        specs.append((f'{k}_plot', k, label + (f' ({unit})' if unit else ''), unit))
    plots = []
    _, plot_px = window_px(len(layout.variants), len(specs), layout.on('info'))
    for stream, entity, title, unit in specs:
        values = np.concatenate([v for _, v in _plot_values(layout, motion, entity)])
        y0, y1, step = plot_range(values, plot_px[1])
        plots.append(_Plot(stream, entity, title, unit, (y0, y1), step))
    return plots


def _plot_values(layout, motion, entity):
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


# ------------------------------------------------------------------------------- labels


def _label_specs(layout, motion):
    """Return the labels of a rig view, most important first."""
    specs = [_Label(lambda deg: f'crank {deg:.1f} deg', READOUT_COLOR, 'readout')]
    if layout.scale_bar is not None:
        specs.append(_Label(layout.scale_bar[1], SCALE_COLOR, 'scale'))
    if layout.on('shaking_force_arrow') or layout.on('shaking_moment_arc'):
        specs.append(_Label('shaking force, moment', MOMENT_COLOR, 'gauge'))
    if layout.on('frame'):
        f = np.broadcast_to(layout.frame_points, (1,) + layout.frame_points.shape)
        for text, idx in _merged_names(layout.frame_names, f, layout.size_m):
            specs.append(_Label(text, FRAME_COLOR, 'frame', idx[0]))
    if layout.on('mass_centres'):
        specs.append(_Label('CoM', SYSTEM_CENTRE_COLOR, 'centre', -1))
    if layout.on('joints') and motion.joints.shape[1]:
        fixed = np.ptp(motion.joints, axis=0).max(axis=-1) <= SAME_POINT_RTOL * layout.size_m
        moving = [i for i in range(motion.joints.shape[1]) if not fixed[i]]
        names = [layout.joint_names[i] for i in moving]
        for text, idx in _merged_names(names, motion.joints[:, moving], layout.size_m):
            specs.append(_Label(text, JOINT_COLOR, 'joint', moving[idx[0]]))
    if layout.on('links'):
        for i, name in enumerate(layout.link_names):
            specs.append(_Label(name, layout.link_colors[i], 'link', i))
    return specs


def _candidates(w, h):
    """Return label-box centre offsets (px) around a feature: above, right, below, left, ..."""
    dx, dy = 0.5 * w + LABEL_OFFSET_PX, 0.5 * h + LABEL_OFFSET_PX
    return np.array([[0, -dy], [dx, 0], [0, dy], [-dx, 0], [dx, -dy], [-dx, -dy], [dx, dy],
                     [-dx, dy]], dtype=float)


def _label_anchor(layout, motion, spec, variant, screen):
    """Return the feature ``(p, 3)`` a label names, or None."""
    p = motion.size
    if spec.where == 'frame':
        return np.broadcast_to(layout.frame_points[spec.index], (p, 3))
    if spec.where == 'joint':
        return motion.joints[:, spec.index]
    if spec.where == 'centre':
        return motion.centres[variant][:, spec.index]
    if spec.where == 'link':
        strip = motion.links[spec.index]
        k = strip.shape[1]
        return strip[:, :max(k - 1, 1)].mean(axis=1) if k > 2 else strip.mean(axis=1)
    if spec.where == 'gauge':
        below = np.array([0.0, layout.gauge_reach_m if layout.dim == 2 else 0.0, 0.0])
        return np.broadcast_to(layout.gauge_m - below, (p, 3))
    if spec.where == 'scale':
        return np.broadcast_to(layout.scale_bar[2], (p, 3))
    return None


def _segments_px(layout, motion, screen):
    """Return sample points ``(p, m, 2)`` along every drawn line of the rig, px."""
    pts = []
    t = np.linspace(0.0, 1.0, 9)[None, None, :, None]
    for strip in motion.links:
        if strip.shape[1] >= 2:
            a, b = strip[:, :-1, None, :], strip[:, 1:, None, :]
            pts.append((a + t * (b - a)).reshape(strip.shape[0], -1, 3))
    for strip in layout.frame_strips:
        a, b = strip[:-1, None, :], strip[1:, None, :]
        seg = (a + t[0] * (b - a)).reshape(-1, 3)
        pts.append(np.broadcast_to(seg, (motion.size,) + seg.shape))
    if not pts:
        return np.zeros((motion.size, 0, 2))
    return screen.px(np.concatenate(pts, axis=1))


def _place_labels(layout, motion, variant):
    """
    Return ``(positions (q, 3), texts, colours, counts (p,))``: the labels of one view.

    Greedy, most important label first, at each sample: each label takes the first place
    around its feature whose box keeps clear of the boxes already placed, of every drawn
    point and (if it can) of every drawn line, inside the view; else it is left out at that
    sample.  So no two labels ever overlap at the default window.
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
    lines = _segments_px(layout, motion, screen)
    placed = []      # (p, 4) boxes with (p,) masks
    out = []         # per spec: (p, 3) anchors, mask, texts
    h = LABEL_TEXT_PX + LABEL_PAD_PX[1]
    for spec in layout.labels:
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
            base = _unproject(screen, centre_px - [0.0, LABEL_DROP_PX + 0.5 * h], layout,
                              motion)
            placed.append((box, ok))
            out.append((base, ok, texts or [spec.text] * p, spec.color))
            continue
        feature = _label_anchor(layout, motion, spec, variant, screen)
        f_px = screen.px(feature)                                   # (p, 2)
        offs = _candidates(w, h)                                    # (c, 2)
        if spec.where == 'gauge':
            offs = offs[[2, 6, 7, 1, 3, 0, 4, 5]]                   # below the gauge first
        centres = f_px[:, None, :] + offs[None]                     # (p, c, 2)
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
        clear = ok.copy()
        if lines.shape[1]:
            lx, ly = lines[:, None, :, 0], lines[:, None, :, 1]
            hit = (lx > boxes[..., 0, None]) & (lx < boxes[..., 2, None]) & \
                (ly > boxes[..., 1, None]) & (ly < boxes[..., 3, None])
            clear &= ~hit.any(axis=-1)
        use_clear = clear.any(axis=1)
        choice_ok = np.where(use_clear[:, None], clear, ok)
        found = choice_ok.any(axis=1)
        first = np.argmax(choice_ok, axis=1)
        rows = np.arange(p)
        box = boxes[rows, first]
        centre_px = centres[rows, first]
        placed.append((box, found))
        base = _unproject(screen, centre_px - [0.0, LABEL_DROP_PX + 0.5 * h], layout, motion,
                          feature)
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


def _unproject(screen, centre_px, layout, motion, feature=None):
    """Return scene points ``(p, 3)`` drawn at pixel centres ``(p, 2)``."""
    if screen.bounds is not None:
        (x0, _), (_, y1) = screen.bounds
        s = screen.metres_per_px
        return np.stack([x0 + centre_px[:, 0] * s, y1 - centre_px[:, 1] * s,
                         np.zeros(len(centre_px))], axis=-1)
    if feature is None:
        feature = np.broadcast_to(np.asarray(screen.target_m), (len(centre_px), 3))
    return feature + screen.offset_m(feature, centre_px - screen.px(feature))


# ------------------------------------------------------------------------------- text


def _rms_rows(layout, data):
    """Return ``[(quantity, si unit, kind, {variant: values})]`` of the RMS table."""
    rows = []
    ref = data['original']
    if ref.force_N is not None:
        rows.append(('shaking force |f_sh|', 'N', 'force',
                     {v: np.linalg.norm(d.force_N, axis=1) for v, d in data.items()}))
        where = layout.pivot_name
        if layout.dim == 2:
            rows.append((f'shaking moment n_sh about {where}', 'N*m', 'moment',
                         {v: d.moment_Nm[:, 2] for v, d in data.items()}))
        else:
            rows.append((f'|shaking moment| about {where}', 'N*m', 'moment',
                         {v: np.linalg.norm(d.moment_Nm, axis=1) for v, d in data.items()}))
    for k in dict.fromkeys(list(SERIES) + sorted(ref.series)):
        if k in ref.series:
            label, unit, dim = series_label(k)
            rows.append((label, unit, 'force' if dim == 'force' else 'moment',
                         {v: d.series[k] for v, d in data.items()}))
    if ref.reactions:
        scale = max([float(np.max(np.abs(r[3]['original']))) for r in rows if r[2] == 'moment']
                    or [0.0])
        for name in ref.reactions:
            rows.append((f'bearing {name} |f|', 'N', 'force',
                         {v: np.linalg.norm(d.reactions[name][0], axis=1)
                          for v, d in data.items()}))
            moment = {v: np.linalg.norm(d.reactions[name][1], axis=1) for v, d in data.items()}
            if name != layout.rigs['original'].crank_joint and \
                    np.max(moment['original']) > 1e-12 * max(scale, 1e-300):
                rows.append((f'bearing {name} moment', 'N*m', 'moment', moment))
    return rows


def _text(layout, scene, data, samples, balanced_source):
    both = 'balanced' in data
    norm = getattr(scene, 'normalization', None)
    rig = layout.rigs['original']
    lines = [f'# {scene.name}: ' + ('original vs balanced' if both else 'original'), '']
    rows = _rms_rows(layout, data)
    if rows:
        more = ' balanced | balanced / original |' if both else ''
        head = '| RMS over one turn | SI | original |' + more
        sep = '|---|---|---:|' + ('---:|---:|' if both else '')
        if norm is not None:
            head += ' normalized | original |' + (' balanced |' if both else '')
            sep += '---|---:|' + ('---:|' if both else '')
        lines += [head, sep]
        for quantity, unit, dimension, values in rows:
            r = {v: float(rms(x)) for v, x in values.items()}
            text = f'| {_cell(quantity)} | {unit or "-"} | {_fmt(r["original"])} |'
            if both:
                ratio = r['balanced'] / r['original'] if r['original'] > 0 else float('nan')
                text += f' {_fmt(r["balanced"])} | {_fmt(ratio)} |'
            if norm is not None:
                f = norm.force if dimension == 'force' else norm.moment
                nunit = 'm1*a1*w^2' if dimension == 'force' else 'm1*a1^2*w^2'
                text += f' {nunit} | {_fmt(float(f(r["original"])))} |'
                if both:
                    text += f' {_fmt(float(f(r["balanced"])))} |'
            lines.append(text)
        lines += ['', 'True RMS (mech_balance.conventions); normalized by m1, a1, omega '
                  '(seed 001 sec. 3.4).' if norm is not None else
                  'True RMS (mech_balance.conventions).']
    else:
        lines.append('No RMS table: the scene asks for kinematics only.')
    lines += ['', f'{scene.description}', '',
              f'Scene file `{getattr(scene, "source", "?")}`; crank joint {rig.crank_joint} at '
              f'{_fmt(scene.crank_speed_rad_s)} rad/s '
              f'({_fmt(scene.crank_speed_rad_s * 60.0 / (2.0 * math.pi))} rpm); {samples} '
              'samples per crank turn.']
    if both:
        src = balanced_source or getattr(layout.rigs['balanced'].scene, 'source', '?')
        lines.append(f'Balanced design: {src}.')
    lines += ['', '## How to read the views', '']
    if both:
        lines.append('* Left: the original rig; right: the balanced rig. They move alike (same '
                     'geometry); only the mass distribution differs.')
    lines.append('* Grey: the frame, its pivots, fixed axes and guides; coloured: the links; '
                 'white dots: the joints. The bar under the rig is a length scale.')
    if layout.on('mass_centres'):
        lines.append("* Dots in a link's colour: its mass centre; the large white dot CoM: the "
                     'mass centre of all moving links (it stands still when the rig is force '
                     'balanced).')
    if layout.has_added:
        lines.append('* Grey-blue discs: the counterweights and balancing weights of the '
                     'design, at true size on their links.')
    if layout.on('point_masses'):
        lines.append('* Blue and red discs: the three equimomental point masses of each link '
                     '(seed 001 eqs. 13-15); disc area proportional to the mass, light '
                     'positive, pink negative.')
    if layout.on('shaking_force_arrow'):
        lines.append(f'* Red arrow in the gauge beside the rig: the shaking force on the frame; '
                     f'scale {_fmt(layout.force_scale_m_per_N)} m per N, i.e. 1 cm of arrow '
                     f'= {_fmt(0.01 / layout.force_scale_m_per_N)} N.')
    if layout.on('shaking_moment_arc'):
        if layout.dim == 2:
            lines.append(f"* Purple arc on the gauge's dial: the shaking moment about "
                         f"{layout.pivot_name}, counter-clockwise positive from 12 o'clock; "
                         f'90 deg of arc = {_fmt(90.0 / layout.moment_scale)} N*m.')
        else:
            lines.append(f'* Purple arrow in the gauge: the shaking moment vector about '
                         f'{layout.pivot_name}; {_fmt(layout.moment_scale)} m per N*m (1 cm = '
                         f'{_fmt(0.01 / layout.moment_scale)} N*m).')
    if layout.plots:
        lines.append('* Plots: ' + ', '.join(p.title for p in layout.plots)
                     + '; orange = original, blue = balanced.')
    lines.append('* Timelines: `crank_angle` = whole degrees turned from crank angle 0 (the '
                 'exact angle is written in each rig view), `time` = seconds at '
                 f'{_fmt(abs(scene.crank_speed_rad_s))} rad/s.')
    lines += ['', '## Design (bodies with what is fixed to them; SI)', '',
              '| body | design | mass kg | mass centre m | added bodies |',
              '|---|---|---:|---|---|']
    for i, name in enumerate(layout.link_names):
        for v in layout.variants:
            b = layout.drawings[v].bodies[i]
            added = '; '.join(f'{a.mass_kg:.4g} kg r {a.radius_m * 1e3:.3g} mm at ('
                              + ', '.join(_fmt(x) for x in a.centre_m[:layout.dim]) + ')'
                              for a in b.added) or '-'
            lines.append(f'| {name} | {v} | {_fmt(b.mass_kg or 0.0)} | '
                         + ', '.join(_fmt(x) for x in b.mass_centre_m[:layout.dim])
                         + f' | {added} |')
    return _markdown(lines)


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


def check_viewer_url(url, field='rerun_url'):
    """Return ``url`` if it is a rerun viewer's gRPC address (:func:`paths.check_viewer_url`)."""
    return paths.check_viewer_url(url, field)


# ------------------------------------------------------------------------------- logging


def _index(degrees, seconds):
    return [rr.TimeColumn('crank_angle', sequence=degrees),
            rr.TimeColumn('time', duration=seconds)]


def _xy(layout, a):
    """Return points ``(..., 3)`` as the view's coordinates (2-D: x, y)."""
    a = np.asarray(a, dtype=float)
    return a[..., :2] if layout.dim == 2 else a


def _archetypes(dim):
    if dim == 2:
        return rr.Points2D, rr.LineStrips2D, rr.Arrows2D
    return rr.Points3D, rr.LineStrips3D, rr.Arrows3D


def _radius(layout, share, ui):
    """Return a line or point radius: 2-D in ui points, 3-D in metres (tubes, spheres)."""
    return ui if layout.dim == 2 else share * layout.size_m


def _log_static(rec, layout):
    points, strips, arrows = _archetypes(layout.dim)
    if layout.dim == 3:
        rec.log('/', rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    else:
        # rerun's 2-D views draw y downwards (rerun-io/rerun#1387): mirror the drawing so
        # that the scene's y axis points up; the logged data stay in the scene's frame.
        for root in ('rig',) + layout.variants:
            rec.log(root, rr.Transform3D(scale=Y_UP_SCALE), static=True)
    if layout.on('info'):
        rec.log('info', rr.TextDocument(layout.text, media_type=rr.MediaType.MARKDOWN),
                static=True)
    if layout.on('frame'):
        if layout.frame_strips:
            rec.log('rig/frame', strips([_xy(layout, s) for s in layout.frame_strips],
                                        colors=[FRAME_COLOR],
                                        radii=[_radius(layout, FRAME_RADIUS_3D_SHARE,
                                                       FRAME_RADIUS_UI)]), static=True)
        rec.log('rig/pivots', points(_xy(layout, layout.frame_points), colors=[FRAME_COLOR],
                                     radii=[_radius(layout, JOINT_RADIUS_3D_SHARE,
                                                    JOINT_RADIUS_UI)]), static=True)
    if layout.on('links'):
        rec.log('rig/links', strips.from_fields(
            colors=layout.link_colors,
            radii=[_radius(layout, LINK_RADIUS_3D_SHARE, LINE_RADIUS_UI)]), static=True)
    if layout.on('joints'):
        rec.log('rig/joints', points.from_fields(
            colors=[JOINT_COLOR], radii=[_radius(layout, JOINT_RADIUS_3D_SHARE,
                                                 JOINT_RADIUS_UI)]), static=True)
    if layout.scale_bar is not None:
        rec.log('rig/scale', strips([_xy(layout, layout.scale_bar[0])], colors=[SCALE_COLOR],
                                    radii=[FRAME_RADIUS_UI]), static=True)
    if layout.dim == 2 and layout.dial_radius_m > 0.0:
        t = np.linspace(0.0, 2.0 * math.pi, DIAL_POINTS)
        circle = layout.gauge_m[:2] + layout.dial_radius_m * np.stack([np.cos(t), np.sin(t)],
                                                                      axis=-1)
        rec.log('rig/gauge', rr.LineStrips2D([circle], colors=[DIAL_COLOR],
                                             radii=[FRAME_RADIUS_UI]), static=True)
    size = layout.size_m
    for v in layout.variants:
        rec.log(f'{v}/labels', points.from_fields(radii=[0.0], show_labels=True),
                static=True)
        if layout.on('mass_centres'):
            n = len(layout.link_names)
            rec.log(f'{v}/mass_centres', points.from_fields(
                colors=list(layout.link_colors) + [SYSTEM_CENTRE_COLOR],
                radii=[CENTRE_RADIUS_SHARE * size] * n + [1.8 * CENTRE_RADIUS_SHARE * size]),
                static=True)
        added = [a for b in layout.drawings[v].bodies for a in b.added]
        if layout.has_added and added:
            behind = {'draw_order': ADDED_DRAW_ORDER} if layout.dim == 2 else {}
            rec.log(f'{v}/counterweights', points.from_fields(
                radii=[a.radius_m for a in added], colors=[ADDED_COLOR],
                labels=[f'{a.name}: {a.mass_kg:.3g} kg' for a in added], show_labels=False,
                **behind), static=True)
        if layout.has_point_masses:
            kg = np.array([m for b in layout.drawings[v].bodies for m, _ in b.point_masses])
            mmax = max(float(np.max(np.abs(np.array(
                [m for dr in layout.drawings.values() for b in dr.bodies
                 for m, _ in b.point_masses])))), 1e-300)
            rec.log(f'{v}/point_masses', points.from_fields(
                radii=POINT_MASS_RADIUS_SHARE * size * np.sqrt(np.abs(kg) / mmax),
                colors=[POSITIVE_MASS_COLOR if m >= 0.0 else NEGATIVE_MASS_COLOR for m in kg],
                labels=[f'{m * 1e3:+.4g} g' for m in kg], show_labels=False), static=True)
        if layout.on('shaking_force_arrow'):
            rec.log(f'{v}/shaking_force', arrows.from_fields(
                origins=[_xy(layout, layout.gauge_m)], colors=[FORCE_COLOR],
                radii=[_radius(layout, ARROW_3D_RADIUS_SHARE, LINE_RADIUS_UI)]),
                static=True)
        if layout.on('shaking_moment_arc'):
            if layout.dim == 2:
                rec.log(f'{v}/shaking_moment', rr.LineStrips2D.from_fields(
                    colors=[MOMENT_COLOR], radii=[LINE_RADIUS_UI]), static=True)
            else:
                rec.log(f'{v}/shaking_moment', rr.Arrows3D.from_fields(
                    origins=[layout.gauge_m], colors=[MOMENT_COLOR],
                    radii=[ARROW_3D_RADIUS_SHARE * size]), static=True)
    for p in layout.plots:
        for v in layout.variants:
            rec.log(f'plots/{p.entity}/{v}', rr.SeriesLines(colors=[SERIES_COLORS[v]],
                                                            names=[v], widths=[2.0]),
                    static=True)


def _moment_arc(centre, moment_Nm, scale_deg_per_Nm, radius):
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


def _log_motion(rec, layout, motion, degrees, seconds, labels=None):
    """Send the columns of a batch of samples (``labels``: precomputed per variant)."""
    index = _index(degrees, seconds)
    points, strips, arrows = _archetypes(layout.dim)
    p = motion.size
    if layout.on('links'):
        n = len(motion.links)
        flat = [_xy(layout, motion.links[i][k]) for k in range(p) for i in range(n)]
        rec.send_columns('rig/links', index,
                         strips.columns(strips=flat).partition(np.full(p, n)))
    if layout.on('joints') and motion.joints.shape[1]:
        n = motion.joints.shape[1]
        rec.send_columns('rig/joints', index, points.columns(
            positions=_xy(layout, motion.joints).reshape(-1, layout.dim)).partition(
                np.full(p, n)))
    for v in layout.variants:
        data = motion.data[v]
        if layout.on('mass_centres'):
            c = motion.centres[v]
            rec.send_columns(f'{v}/mass_centres', index, points.columns(
                positions=_xy(layout, c).reshape(-1, layout.dim)).partition(
                    np.full(p, c.shape[1])))
        if layout.has_added and motion.added[v].shape[1]:
            a = motion.added[v]
            rec.send_columns(f'{v}/counterweights', index, points.columns(
                positions=_xy(layout, a).reshape(-1, layout.dim)).partition(
                    np.full(p, a.shape[1])))
        if layout.has_point_masses:
            pm = motion.point_masses[v]
            rec.send_columns(f'{v}/point_masses', index, points.columns(
                positions=_xy(layout, pm).reshape(-1, layout.dim)).partition(
                    np.full(p, pm.shape[1])))
        if layout.on('shaking_force_arrow'):
            rec.send_columns(f'{v}/shaking_force', index, arrows.columns(
                vectors=_xy(layout, data.force_N * layout.force_scale_m_per_N)))
        if layout.on('shaking_moment_arc'):
            if layout.dim == 2:
                arc, head = _moment_arc(layout.gauge_m, data.moment_Nm[:, 2],
                                        layout.moment_scale, layout.dial_radius_m)
                flat = [s for k in range(p) for s in (arc[k], head[k])]
                rec.send_columns(f'{v}/shaking_moment', index,
                                 rr.LineStrips2D.columns(strips=flat).partition(
                                     np.full(p, 2)))
            else:
                rec.send_columns(f'{v}/shaking_moment', index, rr.Arrows3D.columns(
                    vectors=data.moment_Nm * layout.moment_scale))
        pos, texts, colors, counts = labels[v] if labels else _place_labels(layout, motion, v)
        rec.send_columns(f'{v}/labels', index, points.columns(
            positions=_xy(layout, pos).reshape(-1, layout.dim), labels=texts,
            colors=colors).partition(counts))
    for plot in layout.plots:
        for v, values in _plot_values(layout, motion, plot.entity):
            rec.send_columns(f'plots/{plot.entity}/{v}', index,
                             rr.Scalars.columns(scalars=np.asarray(values, dtype=np.float64)))


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
    """Return the default blueprint: rigs side by side over the RMS table, plots right."""
    spatial = []
    if set(_DRAWN_STREAMS) & set(layout.streams):
        for v in layout.variants:
            contents = ['/rig/**', f'/{v}/**']
            screen = layout.screens[v]
            name = _spatial_name(layout, v)
            if layout.dim == 2:
                (x0, x1), (y0, y1) = screen.bounds
                spatial.append(rrb.Spatial2DView(
                    origin='/', contents=contents, name=name,
                    visual_bounds=rrb.VisualBounds2D(x_range=[x0, x1], y_range=[-y1, -y0])))
            else:
                spatial.append(rrb.Spatial3DView(
                    origin='/', contents=contents, name=name,
                    eye_controls=rrb.EyeControls3D(
                        kind=rrb.Eye3DKind.Orbital, position=screen.eye_m,
                        look_target=screen.target_m, eye_up=screen.up),
                    line_grid=rrb.LineGrid3D(visible=True, spacing=_nice_floor(
                        SCALE_BAR_SHARE * layout.size_m), plane=rr.components.Plane3D.XY)))
    plots = [rrb.TimeSeriesView(origin=f'/plots/{p.entity}', name=p.title,
                                axis_y=rrb.ScalarAxis(range=p.y_range, zoom_lock=False),
                                plot_legend=rrb.PlotLegend(corner=rrb.Corner2D.RightTop,
                                                           visible=True))
             for p in layout.plots]
    left = []
    if spatial:
        left.append(rrb.Horizontal(*spatial) if len(spatial) > 1 else spatial[0])
    if layout.on('info'):
        left.append(rrb.TextDocumentView(origin='/info', name='RMS, design, how to read'))
    columns = []
    if left:
        columns.append(rrb.Vertical(*left, row_shares=[RIG_ROW_SHARE, 1.0 - RIG_ROW_SHARE])
                       if len(left) > 1 else left[0])
    if plots:
        columns.append(rrb.Vertical(*plots))
    root = rrb.Horizontal(*columns, column_shares=[LEFT_SHARE, 1.0 - LEFT_SHARE][:len(columns)])
    return rrb.Blueprint(
        root, rrb.BlueprintPanel(state='collapsed'), rrb.SelectionPanel(state='collapsed'),
        rrb.TimePanel(state='collapsed', timeline='time' if layout.live else 'crank_angle',
                      play_state='following' if layout.live else 'playing', loop_mode='all'))


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
    original alone); ``samples`` per crank turn (any count >= 4, default the scene's) over
    ``cycles`` turns from crank angle 0.  One turn is computed and repeated, since the rig's
    motion is periodic in the crank angle.  ``path`` is checked first by
    :func:`check_output_path` (its errors name ``field``).  Returns a
    :class:`RecordingSummary`.
    """
    t0 = time.perf_counter()
    path = check_output_path(path, field)
    samples = getattr(scene, 'samples', conventions.DEFAULT_SAMPLES) if samples is None \
        else samples
    _check_samples(samples, cycles, links=len(rig_for(scene).drawing.bodies))
    layout, motion = _plan(scene, balanced, int(samples), balanced_source)
    labels = {v: _place_labels(layout, motion, v) for v in layout.variants}
    if cycles > 1:
        labels = {v: (np.concatenate([pos] * cycles), texts * cycles, colors * cycles,
                      np.concatenate([counts] * cycles))
                  for v, (pos, texts, colors, counts) in labels.items()}
    motion = _tile(motion, int(cycles))
    degrees, seconds = turn_ticks(int(samples), scene.crank_speed_rad_s, int(cycles))
    # Encoded into one binary stream (its reads do not concatenate: read it once, at the end)
    # that this process writes atomically (atomic.py): a write error is raised here (rerun's
    # own file sink blocks on one) and an existing file survives any failure, SIGKILL too.
    rec = rr.RecordingStream(application_id(scene))
    stream = rec.binary_stream()
    try:
        _start(rec, scene, layout)
        _log_motion(rec, layout, motion, degrees, seconds, labels)
        data = stream.read(flush=True) or b''
    finally:
        rec.disconnect()
    atomic.write_bytes_atomic(path, data)
    return RecordingSummary(
        path=Path(path), size_bytes=os.path.getsize(path), samples_per_cycle=int(samples),
        cycles=int(cycles), rows=int(samples) * int(cycles),
        entity_paths=tuple(entity_paths(layout)), variants=layout.variants,
        seconds=time.perf_counter() - t0, layout=layout)


def entity_paths(layout):
    """Return the entity paths of the enabled streams (view furniture not included), sorted."""
    out = set()
    per_variant = {'mass_centres': 'mass_centres', 'point_masses': 'point_masses',
                   'shaking_force_arrow': 'shaking_force',
                   'shaking_moment_arc': 'shaking_moment'}
    for s in layout.streams:
        if s == 'info':
            out.add('/info')
        elif s == 'frame':
            out |= {'/rig/pivots'} | ({'/rig/frame'} if layout.frame_strips else set())
        elif s in ('links', 'joints'):
            out.add(f'/rig/{s}')
        elif s in per_variant:
            out |= {f'/{v}/{per_variant[s]}' for v in layout.variants}
    if layout.has_added:
        out |= {f'/{v}/counterweights' for v in layout.variants
                if any(b.added for b in layout.drawings[v].bodies)}
    for p in layout.plots:
        out |= {f'/plots/{p.entity}/{v}' for v in layout.variants}
    return sorted(out)


def furniture_paths(layout):
    """Return the entity paths of the view furniture (labels, scale bar, dial), sorted."""
    out = {f'/{v}/labels' for v in layout.variants}
    if layout.scale_bar is not None:
        out.add('/rig/scale')
    if layout.dim == 2 and layout.dial_radius_m > 0.0:
        out.add('/rig/gauge')
    return sorted(out)


# ------------------------------------------------------------------------------- live


class _LiveView:
    """
    The views of a running rig streamed to a viewer, throttled, on a thread of its own.

    :meth:`push` only queues a batch (the oldest is dropped when :data:`LIVE_QUEUE` are
    waiting) and returns; the thread keeps at most one sample per 1 / :data:`LIVE_MAX_RATE_HZ`
    seconds of the rig's clock, evaluates the other design and logs.  A viewer that is slow
    or gone never holds up the caller.
    """

    def __init__(self, url, scene, layout):
        self.url = url
        self.layout = layout
        self.samples_logged = 0
        self._queue = deque(maxlen=LIVE_QUEUE)
        self._cond = threading.Condition()
        self._stopped = False
        self._next_t = None
        self._t0 = None
        self._rec = rr.RecordingStream(application_id(scene))
        self._rec.connect_grpc(url)
        _start(self._rec, scene, layout)
        self._thread = threading.Thread(target=self._run, name='rig-live-view', daemon=True)
        self._thread.start()

    def push(self, t, psi, data):
        """Queue a batch (the rig's clock in s, cumulative crank angles, original RigData)."""
        with self._cond:
            if self._stopped:
                return
            self._queue.append((t, psi, data))
            self._cond.notify()

    def _run(self):
        pending = []        # (t, psi, data, keep) kept samples, not yet logged
        while True:
            with self._cond:
                if not self._queue and not self._stopped:
                    self._cond.wait(1.0 / LIVE_FLUSH_HZ)
                batches = list(self._queue)
                self._queue.clear()
                stopped = self._stopped
            for t, psi, data in batches:
                keep = self._keep(t)
                if keep.size:
                    pending.append((t[keep], psi[keep], data, keep))
            due = pending and (stopped or pending[-1][0][-1] - pending[0][0][0] >=
                               1.0 / LIVE_FLUSH_HZ)
            if due:
                try:
                    self._log(pending)
                except Exception:  # noqa: BLE001 - a viewer that went away stops nothing
                    pass
                pending = []
            if stopped:
                return

    def _keep(self, t):
        """Return the indices of the samples kept by the throttle (rig's clock)."""
        if self._next_t is None:
            self._next_t, self._t0 = float(t[0]), float(t[0])
        keep = []
        for k, tk in enumerate(t):
            if tk >= self._next_t:
                keep.append(k)
                self._next_t = tk + 1.0 / LIVE_MAX_RATE_HZ
        return np.array(keep, dtype=np.int64)

    def _log(self, pending):
        """Send the kept samples of several batches as one batch (one send per entity)."""
        motion = _concat([_live_motion(self.layout, psi, data, keep)
                          for _, psi, data, keep in pending])
        t = np.concatenate([p[0] for p in pending])
        psi = np.concatenate([p[1] for p in pending])
        _log_motion(self._rec, self.layout, motion, np.round(np.degrees(psi)).astype(np.int64),
                    t - self._t0)
        self.samples_logged += t.size

    def close(self):
        """Send what is queued and disconnect (idempotent)."""
        with self._cond:
            if self._stopped:
                return
            self._stopped = True
            self._cond.notify()
        self._thread.join(CLOSE_TIMEOUT_S)
        try:
            self._rec.flush(timeout_sec=CLOSE_TIMEOUT_S)
        finally:
            self._rec.disconnect()


def _concat(motions):
    """Return one :class:`_Motion` of several, sample after sample."""
    if len(motions) == 1:
        return motions[0]

    def cat(arrays):
        return np.concatenate(arrays, axis=0)

    def cat_data(ds):
        from mech_balance.core.rig import BodyPoses
        b = ds[0].bodies
        return _Data(BodyPoses(b.names, cat([d.bodies.origin_m for d in ds]),
                               cat([d.bodies.rotation for d in ds])),
                     cat([d.crank_angle_rad for d in ds]),
                     None if ds[0].force_N is None else cat([d.force_N for d in ds]),
                     None if ds[0].moment_Nm is None else cat([d.moment_Nm for d in ds]),
                     {k: cat([d.series[k] for d in ds]) for k in ds[0].series})
    m0 = motions[0]
    return _Motion([cat([m.links[i] for m in motions]) for i in range(len(m0.links))],
                   cat([m.joints for m in motions]),
                   {v: cat([m.centres[v] for m in motions]) for v in m0.centres},
                   {v: cat([m.added[v] for m in motions]) for v in m0.added},
                   {v: cat([m.point_masses[v] for m in motions]) for v in m0.point_masses},
                   {v: cat_data([m.data[v] for m in motions]) for v in m0.data},
                   cat([m.degrees for m in motions]))


class _Data:
    """What :func:`_motion` reads of a RigData: poses, angles, wrench and series."""

    def __init__(self, bodies, crank_angle_rad, force_N, moment_Nm, series):
        self.bodies, self.crank_angle_rad = bodies, crank_angle_rad
        self.force_N, self.moment_Nm, self.series = force_N, moment_Nm, series

    def __len__(self):
        """Return the number of samples."""
        return self.crank_angle_rad.shape[0]


def _live_motion(layout, psi, data, keep=None):
    """Return the motion of live samples: the original's data (given or computed), the rest."""
    from mech_balance.core.rig import BodyPoses
    sel = slice(None) if keep is None else keep
    speed = accel = None
    if data is not None:
        speed, accel = data.crank_speed_rad_s[sel], data.crank_accel_rad_s2[sel]
        data = _Data(BodyPoses(data.bodies.names, data.bodies.origin_m[sel],
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
    return _motion(layout, evaluated)


class LiveRecorder:
    """
    Record a running rig sample by sample (used by the rig node): to a file and/or a viewer.

    ``LiveRecorder(path, scene, balanced=None)`` opens ``path`` (``.rrd``, checked by
    :func:`check_output_path`, whose errors name ``field``; None for no file) and, with
    ``url`` (a running viewer's ``rerun+http://HOST:PORT/proxy``), streams the same views to
    it, throttled to :data:`LIVE_MAX_RATE_HZ` on a thread of its own.  Both are laid out
    from one reference turn (``scene.samples`` angles).  :meth:`log_sample` appends samples
    (the file gets every one); :meth:`close` (also run at interpreter exit) flushes and
    closes, is idempotent and safe to call from a signal handler or another thread.  Until
    then the file's samples go to ``.NAME.partial-XXXXXXXX`` next to ``path``
    (:mod:`mech_balance.atomic`); :meth:`close` renames it over ``path``, so an existing
    recording is replaced only by a complete one.
    """

    def __init__(self, path, scene, balanced=None, balanced_source=None, *, field='path',
                 url=None, url_field='rerun_url'):
        self.path = None if path is None else check_output_path(path, field)
        self.url = None if url is None else check_viewer_url(url, url_field)
        if self.path is None and self.url is None:
            raise ValueError(f'{field}, {url_field}: got neither, expected a file or a viewer')
        self.scene = scene
        samples = getattr(scene, 'samples', conventions.DEFAULT_SAMPLES)
        self.layout, _ = _plan(scene, balanced, samples, balanced_source, live=True)
        self._lock = threading.Lock()
        self._owner = None
        self._closed = False
        self._close_requested = False
        self.samples_logged = 0
        self._t0 = None
        self._rec = self._partial = self._view = None
        if self.path is not None:
            # visibly partial (.NAME.partial-XXXXXXXX) until close() renames it over the path
            self._partial = atomic.partial_path(self.path)
            try:
                self._rec = rr.RecordingStream(application_id(scene))
                self._rec.save(str(self._partial))
                _start(self._rec, scene, self.layout)
            except BaseException:
                atomic.discard(self._partial)
                raise
        if self.url is not None:
            self._view = _LiveView(self.url, scene, self.layout)
        atexit.register(self.close)

    @property
    def closed(self):
        """Return whether the recording has been closed."""
        return self._closed

    @property
    def view_samples_logged(self):
        """Return how many samples the live view has sent (after throttling)."""
        return 0 if self._view is None else self._view.samples_logged

    def log_sample(self, time_s, crank_angle_rad, state=None, wrenches=None,
                   balanced_wrenches=None, data=None):
        """
        Append one sample (scalars) or a batch ``(p,)`` of samples; return the count taken.

        ``crank_angle_rad`` is the cumulative crank angle (the ``crank_angle`` timeline shows
        it rounded to whole degrees), ``time_s`` the rig's clock in seconds (the ``time``
        timeline counts from the first sample logged).  ``data`` is the original design's
        :class:`~mech_balance.core.rig.RigData` at those angles if the caller has it (the
        node does), saving its evaluation; everything missing is evaluated here through the
        rig.  ``state``, ``wrenches`` and ``balanced_wrenches`` (a planar core's own
        results) are accepted for older callers and not read: the rig's data is.  After
        :meth:`close` nothing is logged and 0 is returned.
        """
        t = np.atleast_1d(np.asarray(time_s, dtype=float)).ravel()
        psi = np.atleast_1d(np.asarray(crank_angle_rad, dtype=float)).ravel()
        if t.shape != psi.shape or t.size == 0:
            raise ValueError(f'time_s: got shape {t.shape}, expected the shape of '
                             f'crank_angle_rad {psi.shape} (one time per angle, >= 1)')
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(psi))):
            raise ValueError('time_s, crank_angle_rad: got non-finite values, expected finite')
        if data is not None and len(data) != psi.size:
            raise ValueError(f'data: got {len(data)} angles, expected {psi.size}')
        if state is not None and getattr(state, 'size', psi.size) != psi.size:
            raise ValueError(f'state: got {state.size} angles, expected {psi.size}')
        if self._closed or self._close_requested:
            return 0
        if self._view is not None:
            self._view.push(t, psi, data)
        if self._rec is None:
            return psi.size
        motion = _live_motion(self.layout, psi, data)
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
        """Flush and close the file and the viewer stream (idempotent; signal-safe)."""
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
                    if self._view is not None:
                        self._view.close()
                finally:
                    atexit.unregister(self.close)
                    if self._rec is not None:
                        try:
                            self._rec.flush(timeout_sec=CLOSE_TIMEOUT_S)
                        finally:
                            self._rec.disconnect()
                        # complete: replace the target (a failed flush leaves the .partial)
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
                if np.issubdtype(values.dtype, np.timedelta64):
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


def read_blueprint(path):
    """
    Return the views of an ``.rrd`` file's blueprint: ``[{kind, name, origin, ...}]``.

    Each view's properties where set: ``bounds`` (2-D: ``{x_range, y_range}``), ``y_range``
    (plots), ``eye`` (3-D: ``{position, look_target, eye_up}``).
    """
    from rerun.chunk import RrdReader
    reader = RrdReader(str(path))
    views, props = {}, {}
    for store in reader.blueprints():
        for chunk in reader.stream(store=store):
            batch = chunk.to_record_batch()
            cols = {n: batch.column(n).to_pylist() for n in batch.schema.names
                    if n not in ('log_time', 'log_tick', 'blueprint')}
            entity = chunk.entity_path
            if 'ViewBlueprint:class_identifier' in cols:
                for kind, name, origin in zip(cols['ViewBlueprint:class_identifier'],
                                              cols['ViewBlueprint:display_name'],
                                              cols['ViewBlueprint:space_origin']):
                    views[entity] = {'kind': kind[0], 'name': name[0] if name else '',
                                     'origin': origin[0] if origin else ''}
            view = '/'.join(entity.split('/')[:3])
            if 'VisualBounds2D:range' in cols:
                props.setdefault(view, {})['bounds'] = cols['VisualBounds2D:range'][-1][0]
            if 'ScalarAxis:range' in cols:
                props.setdefault(view, {})['y_range'] = tuple(cols['ScalarAxis:range'][-1][0])
            if 'EyeControls3D:position' in cols:
                props.setdefault(view, {})['eye'] = {
                    k: tuple(cols[f'EyeControls3D:{k}'][-1][0])
                    for k in ('position', 'look_target', 'eye_up')
                    if f'EyeControls3D:{k}' in cols}
    for entity, view in views.items():
        view.update(props.get(entity, {}))
    return sorted(views.values(), key=lambda v: (v['kind'], v['name'], v['origin']))


def read_blueprint_views(path):
    """Return ``[(kind, name, origin)]`` of the views in an ``.rrd`` file's blueprint."""
    return sorted((v['kind'], v['name'], v['origin']) for v in read_blueprint(path))
