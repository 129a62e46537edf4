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
  balancing weights) at true size, on their bodies, in their link's colour, labelled in kg;
  ``/{variant}/counterweight_planes``: a ring in each one's plane;
* ``/{variant}/mass_changes`` [links]: a redistribution design's moved mass centres, a line
  from the link to each, labelled with the mass added or removed;
* ``/{variant}/point_masses`` [point_masses, off unless a scene asks]: the equimomental
  point masses of the bodies, where the rig has them;
* ``/{variant}/shaking_force`` [shaking_force_arrow] and ``/{variant}/shaking_moment``
  [shaking_moment_arc]: a gauge beside the rig (2-D: an arrow inside a dial whose arc is
  the moment; 3-D: two arrows);
* ``/balanced/collisions``, ``/balanced/collision_bodies``: where and when a counterweight
  design's bodies collide (:mod:`.collisions`);
* ``/plots/{quantity}/{variant}`` [``{quantity}_plot``]: |shaking force| (N), shaking
  moment (N*m, 3-D: its norm) and every series of ``RigData.series`` (driving torque,
  kinetic energy, ...: :data:`mech_balance.schema.scene.SERIES`).

View furniture, not switchable: ``/{variant}/labels`` (every label of that view, placed so
that none overlaps another, none is crossed by a line and each is nearer its own point than
any other at the default window, :data:`WINDOW_PX`), ``/rig/scale`` (2-D scale bar),
``/rig/gauge`` (the moment dial), ``/rig/grid`` (3-D: the grid on z = 0, sized to the rig
and its gauge; the viewer's endless grid is off).

Timelines: ``crank_angle_deg`` (the default) and ``crank_angle`` (the same values), the
crank angle turned from 0 in whole degrees (offline: a turn starts at 0 deg, sample k of n
at round(360 k / n), any n; live: the rig's cumulative angle), and ``time``, seconds
(offline at the scene's crank speed; live on the rig's clock).  The exact angle is written
in every rig view.  Geometry and styles are static; whole time series go out through
``send_columns``.  :func:`record` writes a file;
:class:`LiveRecorder` the same views sample by sample, to a file and/or to a running viewer
(``url``), the viewer throttled to :data:`LIVE_MAX_RATE_HZ` on a thread of its own.

The package's face; the work is split by concern: :mod:`.style` (sizes, colours),
:mod:`.layout` (the screen, the views, the eye), :mod:`.labels` (label
placement), :mod:`.plots` (the plots' ranges and ticks), :mod:`.drawing` (the drawing adapter of
the Rig protocol), :mod:`.text` (the info panel), :mod:`.blueprint`, :mod:`.streams`
(logging to rerun), :mod:`.live` (the live stream) and :mod:`.readback` (reading back).
"""

from dataclasses import dataclass
import os
from pathlib import Path
import time

from mech_balance import atomic, conventions
from mech_balance.core.rig import rig_for
from mech_balance.viz import collisions
from mech_balance.viz.blueprint import blueprint
from mech_balance.viz.drawing import (
    align_design, check_samples, plan, tile, turn_angles, turn_ticks, VARIANTS
)
from mech_balance.viz.labels import label_box_px, label_size_px, LABEL_TEXT_PX
from mech_balance.viz.layout import Screen, WINDOW_PX, window_px
from mech_balance.viz.live import LIVE_MAX_RATE_HZ, LiveRecorder
from mech_balance.viz.plots import ANGLE_ROOT
from mech_balance.viz.readback import (
    EntityData, read_blueprint, read_blueprint_views, read_recording
)
from mech_balance.viz.streams import (
    application_id, check_output_path, check_viewer_url, log_motion, RRD_SUFFIX, start_stream
)
import numpy as np
import rerun as rr


__all__ = [
    'align_design', 'application_id', 'blueprint', 'check_output_path', 'check_viewer_url',
    'entity_paths', 'EntityData', 'furniture_paths', 'label_box_px', 'label_size_px',
    'LABEL_TEXT_PX', 'LIVE_MAX_RATE_HZ', 'LiveRecorder', 'read_blueprint',
    'read_blueprint_views', 'read_recording', 'record',
    'RecordingSummary', 'RRD_SUFFIX', 'Screen', 'turn_angles', 'VARIANTS', 'window_px',
    'WINDOW_PX',
]


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


def record(path, scene, balanced=None, cycles=1, samples=None, balanced_source=None, *,
           field='path', clearance_margin_m=0.0, spheres=None):
    """
    Write an offline recording of ``scene`` (and ``balanced``) to ``path`` (``.rrd``).

    ``balanced`` is a scene with the same geometry and other inertias (or None for the
    original alone); ``samples`` per crank turn (any count >= 4, default the scene's) over
    ``cycles`` turns from crank angle 0.  One turn is computed and repeated, since the rig's
    motion is periodic in the crank angle.  ``path`` is checked first by
    :func:`check_output_path` (its errors name ``field``).  A counterweight design's bodies
    closer than ``clearance_margin_m`` are marked where and when (:mod:`.collisions`; a
    spatial design's sphere counterweights ``{body: [sphere, ...]}`` given as ``spheres``).
    Returns a :class:`RecordingSummary`.
    """
    t0 = time.perf_counter()
    path = check_output_path(path, field)
    samples = getattr(scene, 'samples', conventions.DEFAULT_SAMPLES) if samples is None \
        else samples
    check_samples(samples, cycles, links=len(rig_for(scene).drawing.bodies))
    layout, motion = plan(scene, balanced, int(samples), balanced_source)
    labels = {k: t[:4] for k, t in layout.placed.items()}
    if cycles > 1:
        labels = {k: (np.concatenate([pos] * cycles), texts * cycles, colors * cycles,
                      np.concatenate([counts] * cycles))
                  for k, (pos, texts, colors, counts) in labels.items()}
    motion = tile(motion, int(cycles))
    degrees, seconds = turn_ticks(int(samples), scene.crank_speed_rad_s, int(cycles))
    # Encoded into one binary stream (its reads do not concatenate: read it once, at the end)
    # that this process writes atomically (atomic.py): a write error is raised here (rerun's
    # own file sink blocks on one) and an existing file survives any failure, SIGKILL too.
    rec = rr.RecordingStream(application_id(scene))
    stream = rec.binary_stream()
    try:
        start_stream(rec, scene, layout)
        log_motion(rec, layout, motion, degrees, seconds, labels)
        marked = collisions.log_collisions(rec, scene, balanced, samples, cycles, degrees,
                                           seconds, clearance_margin_m, spheres)
        data = stream.read(flush=True) or b''
    finally:
        rec.disconnect()
    atomic.write_bytes_atomic(path, data)
    return RecordingSummary(
        path=Path(path), size_bytes=os.path.getsize(path), samples_per_cycle=int(samples),
        cycles=int(cycles), rows=int(samples) * int(cycles),
        entity_paths=tuple(sorted(set(entity_paths(layout)) | marked)), variants=layout.variants,
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
        for v in layout.variants:
            if any(b.added for b in layout.drawings[v].bodies):
                out |= {f'/{v}/counterweights', f'/{v}/counterweight_planes'}
    if layout.on('links'):
        out |= {f'/{v}/mass_changes' for v, moved in (layout.changes or {}).items() if moved}
    for p in layout.plots:
        out |= {f'/plots/{p.entity}/{v}' for v in layout.variants}
        if not layout.live:
            out |= {f'/{ANGLE_ROOT}/{p.entity}/{k}'
                    for k in layout.variants + ('cursor', 'values')}
    return sorted(out)


def furniture_paths(layout):
    """Return the entity paths of the view furniture (labels, scale bar, dial), sorted."""
    out = {f'/{v}/labels' for v in layout.variants}
    if layout.scale_bar is not None:
        out.add('/rig/scale')
    if layout.dim == 2 and layout.dial_radius_m > 0.0:
        out.add('/rig/gauge')
    if layout.grid_box is not None:
        out.add('/rig/grid')
    if not layout.live:
        out |= {f'/{ANGLE_ROOT}/{p.entity}/{k}' for p in layout.plots
                for k in ('grid', 'axes', 'labels')}
    return sorted(out)
