"""
Clearance between the bodies of a planar rig over its cycle: where counterweights collide.

Bodies as built (:mod:`mech_balance.analysis.layers`); the model and the rim cuts:
docs/balancing.md#clearance-over-the-cycle.
"""

from dataclasses import dataclass
import math

from mech_balance.analysis import layers as layer_model
from mech_balance.conventions import cycle_angles
from mech_balance.core.planar import drawn
from mech_balance.core.planar.rig import PlanarRig
from mech_balance.schema.scene import FRAME
import numpy as np

REFINE_POINTS = 17
REFINE_PASSES = 2
"""The least pair is refined on REFINE_POINTS angles across its neighbouring samples,
REFINE_PASSES times, each pass 8 times finer (to 1/64 of the sample step)."""
RIM_CUT_POINTS = (0.0, 1.0 / 6.0, 1.0 / 3.0)
"""Tangent points x0 / rho of the rim cuts (:func:`rim_cuts`); 1/3 is the last convex one."""
TOUCH_TOL_M = 1e-12
"""Two slabs along z overlap when they share more than this thickness (m)."""
ADDED_SHAPES = ('disc', 'shaft', 'web')
"""The shapes of body a counterweight adds; only pairs with one of them are checked."""


@dataclass(frozen=True)
class Body:
    """
    One body as built: a capsule fixed to ``link`` (``frame`` for the frame), in its link frame.

    ``a``, ``b``: ends (complex, m); ``radius_m``; ``z_m`` and ``thickness_m``: its slab;
    ``shape``; ``exempt``: bodies it passes through by design.
    """

    name: str
    link: str
    a: complex
    b: complex
    radius_m: float
    z_m: float
    thickness_m: float
    shape: str = 'bar'
    exempt: frozenset = frozenset()

    @property
    def added(self):
        """Return whether the body is part of a counterweight (disc, its shaft or web)."""
        return self.shape in ADDED_SHAPES

    def z_gap(self, other):
        """Return the gap between the two slabs along z (m; negative: they overlap)."""
        return abs(self.z_m - other.z_m) - 0.5 * (self.thickness_m + other.thickness_m)


@dataclass
class Contact:
    """
    The least clearance of one pair over the cycle: where and how much (SI, deg).

    ``point_a_m``, ``point_b_m``: witness points (m) at ``crank_angle_deg``, or None.
    """

    body_a: str
    body_b: str
    clearance_m: float
    crank_angle_deg: float
    point_a_m: tuple = None
    point_b_m: tuple = None

    def to_dict(self):
        """Return the contact as a plain dict."""
        out = {'body_a': self.body_a, 'body_b': self.body_b,
               'clearance_m': float(self.clearance_m),
               'crank_angle_deg': float(self.crank_angle_deg)}
        if self.point_a_m is not None:
            out['point_a_m'] = [float(v) for v in self.point_a_m]
            out['point_b_m'] = [float(v) for v in self.point_b_m]
        return out

    def warning(self):
        """Return the collision line: the two bodies, the crank angle and the overlap."""
        return (f'collision: {self.body_a} and {self.body_b} overlap by '
                f'{-self.clearance_m * 1e3:.3g} mm at crank angle {self.crank_angle_deg:.2f} '
                'deg')


@dataclass
class Clearance:
    """
    The least clearance of a design over its cycle.

    ``least`` (None: no pair shares a plane); ``collisions``: worst first; ``planes_m``,
    ``rims_m``: each disc's mid-plane z and ``|r| + R``.
    """

    least: Contact
    collisions: list
    pairs: int
    samples: int
    planes_m: dict
    rims_m: dict
    margin_m: float = 0.0

    @property
    def least_clearance_m(self):
        """Return the least clearance (m; +inf when no two bodies share a plane)."""
        return math.inf if self.least is None else self.least.clearance_m

    def warnings(self):
        """Return one line per collision."""
        return [c.warning() for c in self.collisions]

    def to_dict(self):
        """Return the clearance as a plain dict (``least_clearance_m`` None: no pair)."""
        return {'least_clearance_m': None if self.least is None else
                float(self.least.clearance_m),
                'least': None if self.least is None else self.least.to_dict(),
                'collisions': [c.to_dict() for c in self.collisions],
                'pairs_sharing_a_plane': int(self.pairs), 'samples': int(self.samples),
                'disc_planes_m': {k: float(v) for k, v in self.planes_m.items()},
                'disc_rims_m': {k: float(v) for k, v in self.rims_m.items()},
                'margin_m': float(self.margin_m)}

    def lines(self):
        """Return the clearance as text: the least pair, the disc planes, each collision."""
        if self.least is None:
            lines = ['clearance: no counterweight can come near another body (no pair within '
                     f'{self.margin_m * 1e3:.3g} mm along z)']
        else:
            c = self.least
            lines = [f'least clearance {c.clearance_m * 1e3:.4g} mm over the cycle: {c.body_a} '
                     f'and {c.body_b} at crank angle {c.crank_angle_deg:.2f} deg ({self.pairs} '
                     f'pair{"" if self.pairs == 1 else "s"} of bodies checked; margin '
                     f'{self.margin_m * 1e3:.3g} mm)']
        if self.planes_m:
            lines.append('disc planes (z of the mid-plane, mm): ' + ', '.join(
                f'{k} {v * 1e3:.4g}' for k, v in self.planes_m.items()))
        if self.collisions:
            lines.append(f'COLLISIONS: {len(self.collisions)} pairs overlap (listed as '
                         'warnings)')
        return lines


def bodies(rig, layers=None):
    """Return every :class:`Body` of a planar rig as built (frame, links, bosses, pins, discs)."""
    sc, lk = rig.scene, rig.linkage
    lay = layers or layer_model.Layers.of(sc, lk)
    pin_r, boss = lay.pin_radius_m, lay.boss_length_m
    points = {FRAME: sc.frame_points, **{link.name: link.points for link in sc.links}}
    out = []
    for name in lk.body_names:
        own = lay.layers[name]
        z, bar_t, half_bar = own.z_m, own.thickness_m, 0.5 * own.bar_width_m
        local = {k: complex(*v) for k, v in points[name].items()}
        for a, b in drawn.bar_edges(local):
            if local[a] != local[b]:
                out.append(Body(f'{name} bar {a}-{b}', name, local[a], local[b], half_bar, z,
                                bar_t))
        if name != FRAME and len(local) == 1:
            (p,) = local.values()
            length, width = (v * lk.length_scale for v in drawn.BLOCK_SIZE)
            # the capsule that holds the block's box: its corners on the end caps
            half = 0.5 * max(length - width, 0.0)
            out.append(Body(f'{name} block', name, p - half, p + half,
                            width / math.sqrt(2.0), z, bar_t, 'block'))
        for k, p in local.items():
            out.append(Body(f'{name} boss {k}', name, p, p, pin_r, z, boss, 'boss'))
    for jt in sc.joints:
        if jt.prismatic:
            continue
        lo, hi = lay.pin_span(jt.link_a, jt.link_b)
        p = complex(*points[jt.link_a][jt.point_a])
        out.append(Body(f'pin {jt.name}', jt.link_a, p, p, pin_r, 0.5 * (lo + hi), hi - lo,
                        'pin'))
    for link in sc.links:
        z = lay.z_m(link.name)
        width = lay.layers[link.name].bar_width_m
        for i, cw in enumerate(link.counterweights):
            c = complex(*cw.centre_m)
            label = f'{link.name} counterweight {i + 1}'
            zc, t = z + float(cw.plane_m), float(cw.thickness_m)
            out.append(Body(label, link.name, c, c, float(cw.radius_m), zc, t, 'disc'))
            if cw.plane_m == 0.0:
                continue
            key, m = layer_model.mount_point(link, cw.centre_m, cw.mount)
            # the shaft: from the link's face towards the disc to the disc's near face
            side = math.copysign(1.0, cw.plane_m)
            near, face = zc - side * 0.5 * t, z + side * 0.5 * lay.layers[link.name].thickness_m
            out.append(Body(f'{label} shaft', link.name, m, m, pin_r, 0.5 * (face + near),
                            max(side * (near - face), 0.0), 'shaft',
                            _through(sc, lk, link.name, key, points)))
            if abs(c - m) > 0.0:
                out.append(Body(f'{label} web', link.name, m, c, 0.5 * width, zc, t, 'web'))
    return out


def _through(sc, lk, link, key, points):
    """Return the bodies a shaft at joint point ``link.key`` runs through by design."""
    out = set()
    for jt in sc.joints:
        ends = ((jt.link_a, jt.point_a), (jt.link_b, jt.point_b))
        if (link, key) not in ends or jt.prismatic:
            continue
        other, q = ends[1] if ends[0] == (link, key) else ends[0]
        out.add(f'pin {jt.name}')
        # the partner's bearing: its bosses and bar ends at the joint (by position: two
        # points of one body may coincide, a slider's guide point on a pivot)
        local = {k: complex(*v) for k, v in points[other].items()}
        at = {k for k, v in local.items() if v == local[q]}
        out.update(f'{other} boss {k}' for k in at)
        out.update(f'{other} bar {a}-{b}' for a, b in drawn.bar_edges(local)
                   if a in at or b in at)
    return frozenset(out)


def pairs(body_list, gap_m=0.0):
    """
    Return the pairs ``(i, j)`` that can meet: a counterweight's body and one of another link.

    Their slabs along z overlap (or lie less than ``gap_m`` apart) and neither is exempt.
    """
    out = []
    for i, bi in enumerate(body_list):
        for j in range(i + 1, len(body_list)):
            bj = body_list[j]
            if bi.link == bj.link or not (bi.added or bj.added) or bj.name in bi.exempt \
                    or bi.name in bj.exempt:
                continue
            gap = bi.z_gap(bj)
            if (gap < -TOUCH_TOL_M) if gap_m <= 0.0 else (gap < gap_m):
                out.append((i, j))
    return out


def _project(p, a, b):
    """Return the points of segments ``a``-``b`` nearest the points ``p`` (complex arrays)."""
    d = b - a
    den = (d * np.conj(d)).real
    t = np.where(den > 0.0, ((p - a) * np.conj(d)).real / np.where(den > 0.0, den, 1.0), 0.0)
    return a + np.clip(t, 0.0, 1.0) * d


def _point_segment(p, a, b):
    """Return the distance from points ``p`` to segments ``a``-``b`` (complex arrays)."""
    return np.abs(p - _project(p, a, b))


def _cross(u, v):
    return (np.conj(u) * v).imag


def _crossing(a1, b1, a2, b2):
    """Return where segments ``a1``-``b1`` and ``a2``-``b2`` cross (complex arrays)."""
    d1, d2 = b1 - a1, b2 - a2
    return (_cross(d1, a2 - a1) * _cross(d1, b2 - a1) < 0.0) & \
        (_cross(d2, a1 - a2) * _cross(d2, b1 - a2) < 0.0)


def segment_witness(a1, b1, a2, b2):
    """Return ``(q1, q2)``: the nearest points of segments ``a1``-``b1`` and ``a2``-``b2``."""
    a1, b1, a2, b2 = np.broadcast_arrays(*(np.asarray(v, dtype=complex) for v in
                                           (a1, b1, a2, b2)))
    cands = [(a1, _project(a1, a2, b2)), (b1, _project(b1, a2, b2)),
             (_project(a2, a1, b1), a2), (_project(b2, a1, b1), b2)]
    dist = np.stack([np.abs(p - q) for p, q in cands])
    k = np.argmin(dist, axis=0)
    q1 = np.choose(k, [p for p, _ in cands])
    q2 = np.choose(k, [q for _, q in cands])
    crossing = _crossing(a1, b1, a2, b2)
    if np.any(crossing):
        d1, d2 = b1 - a1, b2 - a2
        den = _cross(d1, d2)
        t = _cross(a2 - a1, d2) / np.where(crossing, den, 1.0)
        x = a1 + t * d1
        q1, q2 = np.where(crossing, x, q1), np.where(crossing, x, q2)
    return q1, q2


def segment_distance(a1, b1, a2, b2):
    """
    Return the distance between segments ``a1``-``b1`` and ``a2``-``b2`` (complex, broadcast).

    Zero where they cross; otherwise the least of the four end-to-segment distances.
    """
    a1, b1, a2, b2 = np.broadcast_arrays(*(np.asarray(v, dtype=complex) for v in
                                           (a1, b1, a2, b2)))
    dist = np.minimum.reduce([_point_segment(a1, a2, b2), _point_segment(b1, a2, b2),
                              _point_segment(a2, a1, b1), _point_segment(b2, a1, b1)])
    return np.where(_crossing(a1, b1, a2, b2), 0.0, dist)


class Sweep:
    """The poses of a rig's bodies at crank angles ``psi`` (one batched core evaluation)."""

    def __init__(self, rig, psi):
        self.psi = np.atleast_1d(np.asarray(psi, dtype=float))
        state, _ = rig.evaluate(np.ravel(self.psi), ('kinematics',))
        self.origin, self.rot = state.pose.origin, state.pose.rot
        self.index = {n: k for k, n in enumerate(rig.linkage.body_names)}

    def _ends(self, body_list, todo, cols):
        """Return the pairs' segment ends in the world ``(4, pairs, k)`` (complex, m)."""
        if cols is None:
            cols = np.arange(self.origin.shape[1])
        cols = np.asarray(cols)
        if cols.ndim == 1:
            cols = np.broadcast_to(cols, (len(todo), cols.size))
        ka = np.array([self.index[body_list[i].link] for i, _ in todo])[:, None]
        kb = np.array([self.index[body_list[j].link] for _, j in todo])[:, None]
        local = np.array([[body_list[i].a, body_list[i].b, body_list[j].a, body_list[j].b]
                          for i, j in todo])
        oa, ra, ob, rb = self.origin[ka, cols], self.rot[ka, cols], self.origin[kb, cols], \
            self.rot[kb, cols]
        return (oa + ra * local[:, 0, None], oa + ra * local[:, 1, None],
                ob + rb * local[:, 2, None], ob + rb * local[:, 3, None])

    def witness(self, body_list, todo, cols=None):
        """Return the witness points ``(pa, pb)`` of the pairs ``todo``, ``(pairs, k, 3)`` (m)."""
        a1, b1, a2, b2 = self._ends(body_list, todo, cols)
        q1, q2 = segment_witness(a1, b1, a2, b2)
        d = q2 - q1
        size = np.abs(d)
        u = np.where(size > 0.0, d / np.where(size > 0.0, size, 1.0), 0.0)
        ra = np.array([body_list[i].radius_m for i, _ in todo])[:, None]
        rb = np.array([body_list[j].radius_m for _, j in todo])[:, None]
        pa, pb = q1 + ra * u, q2 - rb * u
        # along z: (pairs, 2) slabs of body a and body b
        z = np.array([[body_list[i].z_m, body_list[j].z_m] for i, j in todo])
        half = 0.5 * np.array([[body_list[i].thickness_m, body_list[j].thickness_m]
                               for i, j in todo])
        lo, hi = z - half, z + half
        start, end = lo.max(axis=1), hi.min(axis=1)      # the overlap, if start <= end
        mid, overlap, below = 0.5 * (start + end), start <= end, z[:, 0] < z[:, 1]
        za = np.where(overlap, mid, np.where(below, hi[:, 0], lo[:, 0]))
        zb = np.where(overlap, mid, np.where(below, lo[:, 1], hi[:, 1]))
        za = np.broadcast_to(za[:, None], pa.shape)
        zb = np.broadcast_to(zb[:, None], pb.shape)
        return (np.stack([pa.real, pa.imag, za], axis=-1),
                np.stack([pb.real, pb.imag, zb], axis=-1))

    def outline(self, body, k, points=32):
        """Return the outline ``(n, 2)`` of a body's capsule at sample ``k`` in the world (m)."""
        t = np.linspace(0.0, 2.0 * math.pi, points, endpoint=False)
        o, r = self.origin[self.index[body.link], k], self.rot[self.index[body.link], k]
        a, b = o + r * body.a, o + r * body.b
        u = (b - a) / abs(b - a) if b != a else 1.0 + 0.0j
        ring = body.radius_m * np.exp(1j * t) * u
        half = points // 2
        # the cap around b on the far side of a, then the cap around a (closed by the caller)
        z = np.concatenate([b + ring[(np.arange(half) - points // 4) % points],
                            a + ring[(np.arange(half) + points // 4) % points]])
        return np.column_stack([z.real, z.imag])

    def gaps(self, body_list, todo, cols=None):
        """
        Return the clearance ``(pairs, k)`` of each pair of ``todo`` (m; negative: overlap).

        ``cols``: the sample columns, ``(k,)`` or ``(pairs, k)`` (default all).
        """
        local = np.array([[body_list[i].a, body_list[i].b, body_list[j].a, body_list[j].b]
                          for i, j in todo])
        radii = np.array([body_list[i].radius_m + body_list[j].radius_m for i, j in todo])
        dz = np.array([body_list[i].z_gap(body_list[j]) for i, j in todo])
        a1, b1, a2, b2 = self._ends(body_list, todo, cols)
        # a disc or a boss is a point: spare the segment arithmetic where a body has none
        seg1, seg2 = local[:, 0] != local[:, 1], local[:, 2] != local[:, 3]
        out = np.abs(a1 - a2)
        for rows, dist in ((seg1 & seg2,
                            lambda r: segment_distance(a1[r], b1[r], a2[r], b2[r])),
                           (seg1 & ~seg2, lambda r: _point_segment(a2[r], a1[r], b1[r])),
                           (~seg1 & seg2, lambda r: _point_segment(a1[r], a2[r], b2[r]))):
            if np.any(rows):
                out[rows] = dist(rows)
        plane = out - radii[:, None]
        apart = dz > TOUCH_TOL_M
        if np.any(apart):
            plane[apart] = np.hypot(np.maximum(plane[apart], 0.0), dz[apart, None])
        return plane


def contacts_at(scene_or_rig, psi, margin_m=0.0):
    """Return ``([[(Contact, body_a, body_b), ...] per angle of psi], Sweep)`` within margin."""
    rig = scene_or_rig if isinstance(scene_or_rig, PlanarRig) else PlanarRig(scene_or_rig)
    psi = np.atleast_1d(np.asarray(psi, dtype=float))
    body_list = bodies(rig)
    todo = pairs(body_list, margin_m)
    sweep = Sweep(rig, psi)
    out = [[] for _ in range(psi.size)]
    if not todo:
        return out, sweep
    gap = sweep.gaps(body_list, todo)
    rows, cols = np.nonzero(gap < margin_m)
    if rows.size:
        pa, pb = sweep.witness(body_list, [todo[n] for n in rows], cols[:, None])
        for m, (n, k) in enumerate(zip(rows, cols)):
            i, j = todo[n]
            out[k].append((Contact(body_list[i].name, body_list[j].name, float(gap[n, k]),
                                   math.degrees(float(psi[k])) % 360.0, tuple(pa[m, 0]),
                                   tuple(pb[m, 0])), body_list[i], body_list[j]))
    return out, sweep


def pair_clearance(rig, body_a, body_b, psi):
    """Return the clearance (m) of two bodies at crank angles ``psi`` (rad), ``(n,)``."""
    return Sweep(rig, psi).gaps([body_a, body_b], [(0, 1)])[0]


def clearance(scene_or_rig, samples=None, margin_m=0.0, sweep=None):
    """
    Return the :class:`Clearance` of a planar scene (or rig) over its cycle.

    ``samples``: a count or a :class:`Sweep`; slabs ``margin_m`` apart along z are clear.
    """
    rig = scene_or_rig if isinstance(scene_or_rig, PlanarRig) else PlanarRig(scene_or_rig)
    sc = rig.scene
    p = int(sc.samples if samples is None else samples)
    psi = cycle_angles(p)
    body_list = bodies(rig)
    planes = {b.name: b.z_m for b in body_list if b.shape == 'disc'}
    rims = {f'{link.name} counterweight {i + 1}': math.hypot(*cw.centre_m) + float(cw.radius_m)
            for link in sc.links for i, cw in enumerate(link.counterweights)}
    todo = pairs(body_list, margin_m)
    if not todo:
        return Clearance(None, [], 0, p, planes, rims, margin_m)
    sweep = sweep if sweep is not None and sweep.psi.size == p else Sweep(rig, psi)
    gap = sweep.gaps(body_list, todo)   # (pairs, p)
    worst_k = np.argmin(gap, axis=1)
    worst = gap[np.arange(len(todo)), worst_k]
    step = 2.0 * math.pi / p
    # refine the least pair between its neighbouring samples
    refine = [int(np.argmin(worst))]
    angles = psi[worst_k].copy()
    for _ in range(REFINE_PASSES):
        grid = angles[refine, None] + step * np.linspace(-1.0, 1.0, REFINE_POINTS)[None, :]
        local = Sweep(rig, grid.ravel()).gaps(
            body_list, [todo[n] for n in refine], np.arange(grid.size).reshape(grid.shape))
        best = np.argmin(local, axis=1)
        for row, n in enumerate(refine):
            if local[row, best[row]] < worst[n]:
                worst[n], angles[n] = local[row, best[row]], grid[row, best[row]]
        step *= 2.0 / (REFINE_POINTS - 1)
    # the witness points of every pair at its least angle (one batched evaluation)
    pa, pb = Sweep(rig, angles).witness(body_list, todo, np.arange(len(todo))[:, None])
    contacts = [Contact(body_list[i].name, body_list[j].name, float(worst[n]),
                        math.degrees(float(angles[n])) % 360.0, tuple(pa[n, 0]),
                        tuple(pb[n, 0]))
                for n, (i, j) in enumerate(todo)]
    least = min(contacts, key=lambda c: c.clearance_m)
    collisions = sorted((c for c in contacts if c.clearance_m < 0.0),
                        key=lambda c: c.clearance_m)
    return Clearance(least, collisions, len(todo), p, planes, rims, margin_m)


def rim_cuts(rho_m):
    """
    Return the convex rim cuts of a disc inside radius ``rho_m`` of its link's origin.

    ``[(c_h, c_m), ...]``: cones ``dI + c_h |dh| <= c_m dm`` (m, m^2).
    """
    rho = float(rho_m)
    out = []
    for share in RIM_CUT_POINTS:
        x0 = share * rho
        slope = rho - 3.0 * x0                     # -f'(x0) >= 0
        out.append((slope, x0 * x0 + 0.5 * (rho - x0) ** 2 + slope * x0))
    return out


def of_design(original, design, samples=None, margin_m=0.0, sweep=None):
    """Return the :class:`Clearance` of ``design``, a design of ``original``'s geometry."""
    return clearance(PlanarRig(original).with_scene(design), samples, margin_m, sweep)
