"""
The collisions of a counterweight design, drawn where and when they happen.

``/balanced/collisions``: a red point per contact closer than the margin
(:func:`mech_balance.analysis.clearance.contacts_at`, or
:func:`mech_balance.analysis.spatial_clearance.contacts_at`); ``/balanced/collision_bodies``:
the two outlines and the witness segment.  Absent for a collision-free design.
"""

from mech_balance.analysis import clearance, spatial_clearance
from mech_balance.core.planar.rig import PlanarRig
from mech_balance.core.rig import rig_for
from mech_balance.viz.drawing import turn_angles
from mech_balance.viz.streams import time_index
import numpy as np
import rerun as rr

COLLISION_COLOR = (255, 40, 40)
"""The colour of a collision's point, its bodies' outlines and its witness segment."""
COLLISION_POINT_UI = rr.components.Radius.ui_points(7.0)
"""The radius of a collision's point on screen."""
COLLISION_LINE_UI = rr.components.Radius.ui_points(2.5)
"""The width of the outlines and of the witness segment on screen."""
OUTLINE_POINTS = 32
"""Points on the outline of a highlighted body."""
VARIANT = 'balanced'
"""The view a design's collisions are drawn in."""
POINTS_PATH = f'/{VARIANT}/collisions'
BODIES_PATH = f'/{VARIANT}/collision_bodies'


def marks(scene, balanced, samples, margin_m=0.0, spheres=None):
    """
    Return the collision marks of one recorded turn, or None (nothing to check).

    ``(points (n, d), labels, counts (samples,), strips [(m, d)], strip_counts (samples,))``,
    d = 2 (planar) or 3 (spatial).
    """
    psi = turn_angles(samples, scene.crank_speed_rad_s)
    if spheres:             # (body a, body b, gap, witness a, witness b, outlines)
        per_sample = [[c + ((),) for c in found] for found in spatial_clearance.contacts_at(
            rig_for(scene), spheres, psi, margin_m)]
        dim = 3
    else:
        rig = rig_for(scene)
        if balanced is None or not isinstance(rig, PlanarRig) or not any(
                getattr(lk, 'counterweights', ()) for lk in getattr(balanced, 'links', ())):
            return None
        found, sweep = clearance.contacts_at(rig.with_scene(balanced), psi, margin_m)
        per_sample = [[(c.body_a, c.body_b, c.clearance_m, c.point_a_m, c.point_b_m,
                        [sweep.outline(b, k, OUTLINE_POINTS) for b in (body_a, body_b)])
                       for c, body_a, body_b in contacts] for k, contacts in enumerate(found)]
        dim = 2
    points, labels, counts, strips, strip_counts = [], [], [], [], []
    for contacts in per_sample:
        counts.append(len(contacts))
        before = len(strips)
        for name_a, name_b, gap, pa, pb, outlines in contacts:
            pa, pb = np.asarray(pa)[:dim], np.asarray(pb)[:dim]
            points.append(0.5 * (pa + pb))
            what = 'overlap' if gap < 0.0 else 'clearance'
            labels.append(f'{name_a} / {name_b}: {what} {abs(gap) * 1e3:.3g} mm')
            strips += [np.vstack([r, r[:1]]) for r in outlines] + [np.array([pa, pb])]
        strip_counts.append(len(strips) - before)
    if not points:
        return None
    return (np.array(points), labels, np.array(counts), strips, np.array(strip_counts))


def log_collisions(rec, scene, balanced, samples, cycles, degrees, seconds, margin_m=0.0,
                   spheres=None):
    """Log the collision marks at the recording's ticks; return the entity paths logged."""
    found = marks(scene, balanced, int(samples), margin_m, spheres)
    if found is None:
        return set()
    points, labels, counts, strips, strip_counts = found
    point_type, strip_type = (rr.Points3D, rr.LineStrips3D) if points.shape[1] == 3 else \
        (rr.Points2D, rr.LineStrips2D)
    rec.log(POINTS_PATH, point_type.from_fields(
        colors=[COLLISION_COLOR], radii=[COLLISION_POINT_UI], show_labels=False), static=True)
    rec.log(BODIES_PATH, strip_type.from_fields(
        colors=[COLLISION_COLOR], radii=[COLLISION_LINE_UI]), static=True)
    index = time_index(degrees, seconds)
    rec.send_columns(POINTS_PATH, index, point_type.columns(
        positions=np.concatenate([points] * int(cycles)),
        labels=labels * int(cycles)).partition(np.tile(counts, int(cycles))))
    rec.send_columns(BODIES_PATH, index, strip_type.columns(
        strips=strips * int(cycles)).partition(np.tile(strip_counts, int(cycles))))
    return {POINTS_PATH, BODIES_PATH}
