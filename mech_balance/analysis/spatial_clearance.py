"""
Clearance of a spatial rig's sphere counterweights over the cycle (bodies as 3-D solids).

The answer is a :class:`mech_balance.analysis.clearance.Clearance`; the model:
docs/build.md#spatial-rigs-sphere-counterweights.
"""

import math

from mech_balance.analysis.clearance import Clearance, Contact
from mech_balance.conventions import cycle_angles
from mech_balance.core.planar import drawn
import numpy as np


def _span(points):
    pts = [np.asarray(p, dtype=float) for p in points.values()]
    return max((float(np.linalg.norm(a - b)) for a in pts for b in pts), default=0.0)


def length_scale(rig):
    """Return the rig's length scale L (m): the span of the crank body, else the largest."""
    bodies = rig.drawing.bodies
    crank = next((j for j in getattr(rig.scene, 'joints', ()) if j.name == rig.crank_joint),
                 None)
    names = {getattr(crank, 'link_a', None), getattr(crank, 'link_b', None)}
    spans = [_span(b.points) for b in bodies if b.name in names] or \
        [_span(b.points) for b in bodies]
    scale = max(spans) if spans else 0.0
    return scale if scale > 0.0 else max(_span(b.points) for b in bodies)


def solids(rig):
    """
    Return the rig's solids as built: ``[(name, body, a (3,), b (3,), radius_m), ...]``.

    ``body`` is the carrying body's name (``frame`` for a bearing housing); a ball has a == b.
    """
    scale = length_scale(rig)
    tube, ball = 0.5 * drawn.BAR_WIDTH * scale, drawn.PIN_RADIUS * scale
    out = []
    for name, p in rig.drawing.frame.items():
        q = np.asarray(p, dtype=float)
        out.append((f'frame bearing {name}', 'frame', q, q, ball))
    for body in rig.drawing.bodies:
        pts = {k: np.asarray(v, dtype=float) for k, v in body.points.items()}
        chain = list(body.outline)
        for a, b in zip(chain, chain[1:]):
            out.append((f'{body.name} tube {a}-{b}', body.name, pts[a], pts[b], tube))
        for k, p in pts.items():
            out.append((f'{body.name} joint {k}', body.name, p, p, ball))
    return out


def _nearest(p, a, b):
    """Return the points of segments a-b ``(..., 3)`` nearest the points ``p (..., 3)``."""
    d = b - a
    den = np.sum(d * d, axis=-1)
    t = np.where(den > 0.0, np.sum((p - a) * d, axis=-1) / np.where(den > 0.0, den, 1.0), 0.0)
    return a + np.clip(t, 0.0, 1.0)[..., None] * d


def _witness(p, q, r_p, r_q):
    """Return the surface points of balls (or capsules) about ``p`` and ``q`` facing each other."""
    d = q - p
    size = float(np.linalg.norm(d))
    u = d / size if size > 0.0 else np.zeros(3)
    return tuple(float(v) for v in p + r_p * u), tuple(float(v) for v in q - r_q * u)


def _pairs(rig, spheres, psi):
    """Yield ``(name_a, name_b, gap (n,), centre_a (n, 3), centre_b, r_a, r_b)`` per pair."""
    poses = rig.at(psi).bodies
    index = {n: k for k, n in enumerate(poses.names)}

    def world(body, local):
        k = index[body]
        return poses.origin_m[:, k] + poses.rotation[:, k] @ np.asarray(local, dtype=float)

    balls = []
    for body, cluster in spheres.items():
        for i, s in enumerate(cluster):
            balls.append((f'{body} counterweight sphere {i + 1}', body,
                          world(body, s['centre_m']), float(s['outer_radius_m'])))
    others = [(n, body, world(body, a), world(body, b), r) for n, body, a, b, r in solids(rig)]
    for i, (name, body, c, r) in enumerate(balls):
        for n2, b2, a, b, r2 in others:
            if b2 != body:
                q = _nearest(c, a, b)
                yield n2, name, np.linalg.norm(c - q, axis=-1) - r - r2, q, c, r2, r
        for name2, body2, c2, r2 in balls[i + 1:]:
            if body2 != body:
                yield name, name2, np.linalg.norm(c - c2, axis=-1) - r - r2, c, c2, r, r2


def contacts_at(rig, spheres, psi, margin_m=0.0):
    """Return per angle of ``psi`` ``[(name_a, name_b, clearance_m, point_a, point_b)]``."""
    psi = np.asarray(psi, dtype=float)
    per_angle = [[] for _ in psi]
    for name_a, name_b, gap, ca, cb, ra, rb in _pairs(rig, spheres, psi):
        for k in np.flatnonzero(gap < margin_m):
            per_angle[k].append((name_a, name_b, float(gap[k]),
                                 *_witness(ca[k], cb[k], ra, rb)))
    return per_angle


def check(rig, spheres, samples=None, margin_m=0.0):
    """
    Return the :class:`Clearance` of sphere counterweights over the cycle.

    ``spheres``: ``{body: [sphere, ...]}`` with ``centre_m`` (body axes) and ``outer_radius_m``.
    """
    p = int(getattr(rig.scene, 'samples', 360) if samples is None else samples)
    psi = cycle_angles(p)
    contacts = []
    for name_a, name_b, gap, ca, cb, ra, rb in _pairs(rig, spheres, psi):
        k = int(np.argmin(gap))
        contacts.append(Contact(name_a, name_b, float(gap[k]), math.degrees(psi[k]) % 360.0,
                                *_witness(ca[k], cb[k], ra, rb)))
    rims = {f'{body} counterweight sphere {i + 1}': float(sph['outer_radius_m'])
            for body, cluster in spheres.items() for i, sph in enumerate(cluster)}
    if not contacts:
        return Clearance(None, [], 0, p, {}, rims, margin_m)
    least = min(contacts, key=lambda c: c.clearance_m)
    collisions = sorted((c for c in contacts if c.clearance_m < 0.0),
                        key=lambda c: c.clearance_m)
    return Clearance(least, collisions, len(contacts), p, {}, rims, margin_m)
