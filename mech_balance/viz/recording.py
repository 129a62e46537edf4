"""
Rerun recordings of a rig in motion: the original mechanism against its balanced design.

The only part of mech_balance that imports rerun; one drawing adapter of the Rig protocol
(:mod:`mech_balance.core.rig`).  :func:`record` writes a file; :class:`LiveRecorder`
the same views sample by sample.  What is drawn: `docs/recordings.md`.
"""

from dataclasses import dataclass
import os
from pathlib import Path
import time

from mech_balance import atomic, conventions
from mech_balance.core.rig import rig_for
from mech_balance.viz import collisions
from mech_balance.viz.drawing import align_design, check_samples, concat_motions, plan, \
    turn_angles, turn_ticks
from mech_balance.viz.labels import label_box_px, LABEL_TEXT_PX
from mech_balance.viz.layout import Screen, WINDOW_PX
from mech_balance.viz.live import LiveRecorder
from mech_balance.viz.plots import ANGLE_ROOT
from mech_balance.viz.readback import read_blueprint, read_blueprint_views, read_recording
from mech_balance.viz.streams import application_id, check_output_path, log_motion, \
    start_stream
import numpy as np
import rerun as rr


__all__ = [
    'align_design', 'check_output_path', 'entity_paths', 'furniture_paths', 'label_box_px',
    'LABEL_TEXT_PX', 'LiveRecorder', 'read_blueprint', 'read_blueprint_views',
    'read_recording', 'record', 'RecordingSummary', 'Screen', 'turn_angles', 'WINDOW_PX',
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

    ``balanced``: same geometry, other inertias, or None; ``samples`` per turn (>= 4) over
    ``cycles`` turns; bodies closer than ``clearance_margin_m`` are marked (``spheres``: a
    spatial design's).  Errors name ``field``.  Returns a :class:`RecordingSummary`.
    """
    t0 = time.perf_counter()
    path = check_output_path(path, field)
    samples = getattr(scene, 'samples', conventions.DEFAULT_SAMPLES) if samples is None \
        else samples
    check_samples(samples, cycles, links=len(rig_for(scene).drawing.bodies))
    layout, motion = plan(scene, balanced, int(samples), balanced_source)
    labels = {k: (np.concatenate([t[0]] * cycles), t[1] * cycles, t[2] * cycles,
                  np.tile(t[3], cycles)) for k, t in layout.placed.items()}
    motion = concat_motions([motion] * int(cycles))   # periodic in the crank angle
    degrees, seconds = turn_ticks(int(samples), scene.crank_speed_rad_s, int(cycles))
    # one binary stream (read once, at the end), written atomically: a write error is raised
    # here and an existing file survives any failure
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
