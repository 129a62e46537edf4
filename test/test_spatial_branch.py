"""
The stated assembly branch, always (issue 28): a spatial linkage assembles where its scene says.

A property test over random single-loop spatial rigs whose tree joints are universal,
cylindrical, prismatic, revolute and spherical (either end first): every assembly each rig
has at its start angle, found by an independent solver (world poses, joint rows written
here from the scene mapping), is stated in turn as the scene's ``assembly.poses``; the
linkage must assemble exactly there, from the exact poses and from poses a degree off, and
must refuse a statement that mixes two assemblies.  Then ``spatial_two_loop``: its stated
pose honoured (it was not: coupler2 170 deg and rocker2 158 deg off), its other assemblies
(the coupler flipped about its line through the universal joint, the second rocker on its
other side) honoured when stated, refused when stated half-way; and ``axis_b`` checked
against the stated poses at load.
"""

import copy
import math

from mech_balance import rotations, schema
from mech_balance.core.rig import rig_for
from mech_balance.core.spatial import kinematics
from mech_balance.core.spatial.kinematics import SpatialError
from mech_balance.schema.fields import SceneError
from mech_balance.schema.spatial import POSE_TOL_DEG, POSE_TOL_REL, spatial_from_dict
import numpy as np
from numpy.testing import assert_allclose
import pytest
from scipy.optimize import brentq, least_squares
from scipy.spatial.transform import Rotation

SEED = 20261206
"""Seed of the random rigs."""
COMBOS = (('universal', 'spherical', 'revolute'), ('universal', 'spherical', 'prismatic'),
          ('cylindrical', 'spherical', 'revolute'), ('cylindrical', 'spherical', 'prismatic'),
          ('revolute', 'spherical', 'cylindrical'), ('spherical', 'universal', 'revolute'),
          ('spherical', 'cylindrical', 'revolute'), ('prismatic', 'spherical', 'universal'))
"""Joint types (crank-coupler, coupler-output, output-frame) of the random loops: one
freedom with the revolute input (sum of freedoms 7); the first and the last are tree
joints (the spanning tree from the frame), the middle one is cut."""
GEOMETRIES_PER_COMBO = 3
"""Random geometries per combination, each with at least two assemblies at its start."""
STARTS = 12
"""Random starts of the independent solver per geometry."""
SOLVED_TOL = 1e-12
"""Largest row of the independent solver's residual (m, or a cosine) for an assembly."""
SAME_TOL = 1e-6
"""Two assemblies whose poses differ by less than this (rotation entries, origin / size)
are one."""
PERTURB_DEG = 1.0
"""Rotation of each stated pose (about a random axis) in the perturbed statements."""
PERTURB_REL = 0.005
"""Shift of each stated origin, relative to the linkage's size, in the perturbed statements."""
LINKS = ('crank', 'coupler', 'output')


def _unit(v):
    v = np.asarray(v, dtype=float)
    return v / math.sqrt(v @ v)   # np.linalg.norm's sqrt(v.dot(v)), without its overhead


def _cross(a, b):
    """
    Return ``np.cross(a, b)`` of two 3-vectors, bit for bit, without its overhead.

    The same products and differences as numpy's (``a1 b2 - a2 b1``, ...); ``np.cross`` of
    two 3-vectors costs about ten times more, and the closure rows of the random rigs'
    solver (:func:`_rows`) are evaluated some 10^5 times.
    """
    a0, a1, a2 = (float(x) for x in a)
    b0, b1, b2 = (float(x) for x in b)
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


def _rpy(r):
    return [math.degrees(math.atan2(r[2, 1], r[2, 2])),
            math.degrees(math.atan2(-r[2, 0], math.hypot(r[0, 0], r[1, 0]))),
            math.degrees(math.atan2(r[1, 0], r[0, 0]))]


def _rot(axis, angle):
    return Rotation.from_rotvec(_unit(axis) * angle).as_matrix()


def _angle(ra, rb):
    """Return the angle (rad) of the rotation from ``ra`` to ``rb``."""
    return Rotation.from_matrix(ra.T @ rb).magnitude()


def _poses_mapping(poses):
    return {k: {'origin_m': [float(v) for v in o], 'rpy_deg': _rpy(r)}
            for k, (r, o) in poses.items()}


# ----------------------------------------------------------------------------- random loops

def _joint(kind, ends, poses, x, rng):
    """
    Return a joint's mapping and its points on its two links (local), closed at ``poses``.

    ``x`` is the joint's world point; a prismatic or cylindrical joint's b point lies a
    random slide along the axis from it; a prismatic joint's ``angle_deg`` is the turn
    about the axis of ``R_a^T R_b Z^T`` (``Z`` the smallest rotation taking ``axis_b`` onto
    ``axis``, the scene's convention).
    """
    (la, ra, oa), (lb, rb, ob) = ((k, *poses[k]) for k in ends)
    w = _unit(rng.normal(size=3))
    xb = x + (rng.uniform(-0.02, 0.02) * w if kind in ('cylindrical', 'prismatic') else 0.0)
    spec = {'type': kind}
    if kind == 'universal':
        w2 = _unit(np.cross(w, rng.normal(size=3)))
        spec.update(axis=[float(v) for v in ra.T @ w], axis_b=[float(v) for v in rb.T @ w2])
    elif kind != 'spherical':
        spec.update(axis=[float(v) for v in ra.T @ w], axis_b=[float(v) for v in rb.T @ w])
    if kind == 'prismatic':
        a, b = np.array(spec['axis']), np.array(spec['axis_b'])
        z = rotations.min_rotation(b, a)
        m = ra.T @ rb @ z.T   # a turn about a
        r = _unit(np.cross(a, [0.3, -0.5, 0.8]))
        spec['angle_deg'] = math.degrees(math.atan2(a @ np.cross(r, m @ r), r @ m @ r))
    return spec, ra.T @ (x - oa), rb.T @ (xb - ob)


def random_loop(rng, kinds):
    """
    Return ``(mapping, poses)``: a random loop frame-crank-coupler-output-frame, assembled.

    The input is a revolute joint on the frame (its own axis numbers in the crank, so the
    crank angle is the crank's turn); ``kinds`` are the types of the other three joints,
    each with its ends in a random order (a tree joint hung from its end b too).
    """
    a1 = _unit(rng.normal(size=3))
    psi = rng.uniform(-math.pi, math.pi)
    poses = {'frame': (np.eye(3), np.zeros(3)), 'crank': (_rot(a1, psi), np.zeros(3)),
             'coupler': (Rotation.random(random_state=rng).as_matrix(), rng.normal(size=3) * 0.05),
             'output': (Rotation.random(random_state=rng).as_matrix(), rng.normal(size=3) * 0.05)}
    x = {'J2': poses['crank'][0] @ np.array([rng.uniform(0.02, 0.04), 0.0, 0.0]),
         'J3': rng.normal(size=3) * 0.06, 'J4': rng.normal(size=3) * 0.08}
    points = {'frame': {'A': [0.0, 0.0, 0.0]}, 'crank': {'A': [0.0, 0.0, 0.0]},
              'coupler': {}, 'output': {}}
    joints = {'A': {'type': 'revolute', 'a': 'frame.A', 'b': 'crank.A',
                    'axis': [float(v) for v in a1], 'axis_b': [float(v) for v in a1]}}
    for name, kind, ends in zip(('J2', 'J3', 'J4'), kinds,
                                (('crank', 'coupler'), ('coupler', 'output'),
                                 ('output', 'frame'))):
        if rng.uniform() < 0.5:
            ends = ends[::-1]
        spec, pa, pb = _joint(kind, ends, poses, x[name], rng)
        points[ends[0]][name] = [float(v) for v in pa]
        points[ends[1]][name] = [float(v) for v in pb]
        spec.update(a=f'{ends[0]}.{name}', b=f'{ends[1]}.{name}')
        joints[name] = spec
    links = {}
    for k in LINKS:
        m = rng.uniform(0.1, 1.0)
        dims = rng.uniform(0.01, 0.1, size=3)
        box = m / 12.0 * np.array([dims[1] ** 2 + dims[2] ** 2, dims[0] ** 2 + dims[2] ** 2,
                                   dims[0] ** 2 + dims[1] ** 2])
        links[k] = {'points': points[k], 'mass_kg': float(m),
                    'com_m': [float(v) for v in rng.normal(size=3) * 0.02],
                    'inertia_com_kg_m2': [float(v) for v in box] + [0.0, 0.0, 0.0]}
    data = {'kind': 'spatial', 'name': 'random_loop',
            'frame': {'points': points['frame']}, 'links': links, 'joints': joints,
            'crank': {'joint': 'A', 'speed_rad_s': 10.0}, 'moment_point_m': [0.0, 0.0, 0.0],
            'assembly': {'crank_angle_deg': math.degrees(psi),
                         'poses': _poses_mapping({k: poses[k] for k in LINKS})},
            'samples': 36}
    return data, {k: poses[k] for k in LINKS}


def _size(data):
    pts = [np.array(p) for p in data['frame']['points'].values()]
    pts += [np.array(p) for lk in data['links'].values() for p in lk['points'].values()]
    return max(np.linalg.norm(a - b) for a in pts for b in pts)


# ----------------------------------------------------------------------------- independent solver

def _rows(data, turn):
    """
    Return ``rows(poses)``: the closure rows of joints J2, J3, J4 at world poses (12 numbers).

    Written from the mapping alone: a coincident point (3 rows: R, U, S), the b axis normal
    to two vectors normal to the a axis (R, C, P), the universal's axes normal (1), the b
    point on the a line (C, P: 2), and a prismatic joint's turn (1, against ``turn``: b's
    vector ``f`` normal to the axis and a's vector ``g`` it must stay on, from the
    construction).
    """
    joints = []
    for name in ('J2', 'J3', 'J4'):
        jt = data['joints'][name]
        ends = []
        for k in 'ab':
            link, point = jt[k].split('.')
            pts = data['frame']['points'] if link == 'frame' else data['links'][link]['points']
            ends.append((link, np.array(pts[point])))
        axes = (None, None) if jt['type'] == 'spherical' else \
            (_unit(jt['axis']), _unit(jt['axis_b']))
        joints.append((jt['type'], ends, axes, turn.get(name)))

    def rows(poses):
        out = []
        for t, ((la, pa), (lb, pb)), (a, b), fg in joints:
            (ra, oa), (rb, ob) = poses[la], poses[lb]
            d = ob + rb @ pb - oa - ra @ pa
            if t in ('revolute', 'universal', 'spherical'):
                out += list(d)
            if t == 'spherical':
                continue
            wa, wb = ra @ a, rb @ b
            if t == 'universal':
                out.append(wa @ wb)
                continue
            e1 = _unit(_cross(wa, [0.31, 0.77, -0.55]))
            e2 = _cross(wa, e1)
            out += [wb @ e1, wb @ e2]
            if t in ('cylindrical', 'prismatic'):
                out += [d @ e1, d @ e2]
            if t == 'prismatic':
                out.append((rb @ fg[0]) @ _cross(wa, ra @ fg[1]))
        return np.array(out)
    return rows


def _rodrigues(v):
    th = math.sqrt(v @ v)
    if th < 1e-300:
        return np.eye(3)
    k = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]]) / th
    return np.eye(3) + math.sin(th) * k + (1.0 - math.cos(th)) * (k @ k)


def _turns(data, poses):
    """Return, per prismatic joint, b's vector f normal to its axis and a's image g of it."""
    out = {}
    for name in ('J2', 'J3', 'J4'):
        jt = data['joints'][name]
        if jt['type'] == 'prismatic':
            la, lb = jt['a'].split('.')[0], jt['b'].split('.')[0]
            f = _unit(np.cross(jt['axis_b'], [0.3, -0.5, 0.8]))
            out[name] = (f, poses[la][0].T @ poses[lb][0] @ f)
    return out


def _aligned(data, poses, turn):
    """Return whether every aligned axis is aligned, not opposed (rows allow both)."""
    for name in ('J2', 'J3', 'J4'):
        jt = data['joints'][name]
        if jt['type'] in ('universal', 'spherical'):
            continue
        (la, _), (lb, _) = (jt[k].split('.') for k in 'ab')
        (ra, _), (rb, _) = poses[la], poses[lb]
        if (ra @ _unit(jt['axis'])) @ (rb @ _unit(jt['axis_b'])) < 0.0:
            return False
        if name in turn and (rb @ turn[name][0]) @ (ra @ turn[name][1]) < 0.0:
            return False
    return True


def _differ(p, q, size):
    return max(max(np.max(np.abs(p[k][0] - q[k][0])), np.max(np.abs(p[k][1] - q[k][1])) / size)
               for k in LINKS)


def assemblies(data, poses, rng):
    """
    Return every assembly of the loop found at its start angle (the constructed one first).

    Levenberg-Marquardt on the coupler's and output's world poses (12 unknowns, 12 rows of
    :func:`_rows`) from :data:`STARTS` random starts; kept when every row is within
    :data:`SOLVED_TOL`, the axes aligned and the rows' Jacobian of full rank.
    """
    turn = _turns(data, {'frame': (np.eye(3), np.zeros(3)), **poses})
    rows = _rows(data, turn)
    crank = poses['crank']
    found = [poses]

    turned = {}   # (link, rotation vector) -> its rotation: a finite-difference column of
    #               least_squares moves one unknown, so the other link's rotation is reused

    def rotation(k, v, base):
        key = (k, v.tobytes())
        if key not in turned:
            turned[key] = _rodrigues(v) @ base
        return turned[key]

    def unpack(z, base):
        return {'frame': (np.eye(3), np.zeros(3)), 'crank': crank,
                'coupler': (rotation(0, z[:3], base[0]), z[3:6]),
                'output': (rotation(1, z[6:9], base[1]), z[9:])}

    for _ in range(STARTS):
        base = [Rotation.random(random_state=rng).as_matrix() for _ in range(2)]
        turned.clear()
        z0 = np.concatenate([np.zeros(3), rng.normal(size=3) * 0.05,
                             np.zeros(3), rng.normal(size=3) * 0.05])
        sol = least_squares(lambda z: rows(unpack(z, base)), z0, method='lm',
                            xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=300)
        p = unpack(sol.x, base)
        if np.max(np.abs(rows(p))) > SOLVED_TOL or not _aligned(data, p, turn):
            continue
        if np.linalg.matrix_rank(sol.jac, tol=1e-8 * np.linalg.norm(sol.jac, 2)) < 12:
            continue
        p = {k: p[k] for k in LINKS}
        if all(_differ(p, q, _size(data)) > SAME_TOL for q in found):
            found.append(p)
    return found


def _assembled(data):
    """Return the linkage of ``data`` and its assembled poses ``{link: (R, origin)}``."""
    lk = kinematics.Linkage(spatial_from_dict(data))
    fr = lk.frames(lk.q0, lk.sph0)
    return lk, fr, {k: (fr.rot[0, lk.body_names.index(k)], fr.origin[0, lk.body_names.index(k)])
                    for k in LINKS}


def _accuracy(lk, fr):
    """
    Return the pose accuracy the assembly reports: ``n NEWTON_TOL / sigma_min`` (rad, or m / size).

    Newton stops at a scaled residual of NEWTON_TOL; the scaled Jacobian's least singular
    value turns it into the coordinates' error, and a body's pose sums those of its path.
    """
    js = lk.scaled(lk.jacobian(fr))[0]
    smin = np.linalg.svd(js, compute_uv=False)[-1]
    return 10.0 * lk.ndof * kinematics.NEWTON_TOL / smin


@pytest.fixture(scope='module')
def random_cases():
    """Return ``[(kinds, mapping, assemblies)]``: GEOMETRIES_PER_COMBO per combination."""
    rng = np.random.default_rng(SEED)
    cases = []
    for kinds in COMBOS:
        count = 0
        while count < GEOMETRIES_PER_COMBO:
            data, poses = random_loop(rng, kinds)
            if min(np.linalg.norm(np.subtract(a, b)) for lk in data['links'].values()
                   for i, a in enumerate(lk['points'].values())
                   for b in list(lk['points'].values())[i + 1:]) < 0.01:
                continue   # a link shorter than 1 cm: draw again
            found = assemblies(data, poses, rng)
            if len(found) < 2:
                continue
            cases.append((kinds, data, found))
            count += 1
    return cases


def test_random_rigs_assemble_where_stated(random_cases):
    """
    Every assembly of every random loop, stated exactly or a degree off: assembled there.

    The exact statement must give the stated poses to the assembly's own accuracy
    (:func:`_accuracy`); a statement each pose of which is turned PERTURB_DEG about a
    random axis and shifted PERTURB_REL of the size must give the same assembly, wherever
    the assembly is apart from the others by more than ten times that.
    """
    rng = np.random.default_rng(SEED + 1)
    stated = perturbed = 0
    for kinds, data, found in random_cases:
        size = _size(data)
        for i, poses in enumerate(found):
            trial = copy.deepcopy(data)
            trial['assembly']['poses'] = _poses_mapping(poses)
            lk, fr, got = _assembled(trial)
            tol = _accuracy(lk, fr)
            for k in LINKS:
                assert _angle(poses[k][0], got[k][0]) <= tol, (kinds, i, k)
                assert np.linalg.norm(got[k][1] - poses[k][1]) <= tol * size, (kinds, i, k)
            stated += 1
            apart = min(max(math.degrees(_angle(poses[k][0], q[k][0])) for k in LINKS)
                        for j, q in enumerate(found) if j != i)
            if apart < 10.0 * PERTURB_DEG:
                continue
            rough = {}
            for k in LINKS[1:]:
                turn = _rot(rng.normal(size=3), math.radians(PERTURB_DEG))
                rough[k] = (turn @ poses[k][0],
                            poses[k][1] + PERTURB_REL * size * _unit(rng.normal(size=3)))
            trial['assembly']['poses'] = _poses_mapping({'crank': poses['crank'], **rough})
            _, _, got = _assembled(trial)
            for k in LINKS:
                assert _angle(poses[k][0], got[k][0]) <= tol, (kinds, i, k, 'perturbed')
                assert np.linalg.norm(got[k][1] - poses[k][1]) <= tol * size
            perturbed += 1
    # both branches of every geometry, and most of them a degree off too
    assert stated >= 2 * len(random_cases) == 2 * GEOMETRIES_PER_COMBO * len(COMBOS)
    assert perturbed >= stated // 2


def test_random_rigs_refuse_a_statement_of_two_assemblies(random_cases):
    """
    One link stated on another assembly than the rest: refused, never solved in silence.

    Skipped where the mixed statement is itself (within the tolerances) an assembly found.
    """
    refused = 0
    for kinds, data, found in random_cases:
        size = _size(data)
        a, b = found[0], found[1]
        for k in LINKS[1:]:
            mixed = dict(a)
            mixed[k] = b[k]
            if any(all(math.degrees(_angle(mixed[n][0], q[n][0])) <= POSE_TOL_DEG
                       and np.linalg.norm(mixed[n][1] - q[n][1]) <= POSE_TOL_REL * size
                       for n in LINKS) for q in found):
                continue
            trial = copy.deepcopy(data)
            trial['assembly']['poses'] = _poses_mapping(mixed)
            with pytest.raises((SpatialError, SceneError),
                               match=r'assembly\.poses|axis_b'):
                _assembled(trial)
            refused += 1
    assert refused >= len(random_cases)


# ----------------------------------------------------------------------------- spatial_two_loop

def _two_loop():
    data, _ = schema.load_data('spatial_two_loop')
    return copy.deepcopy(data)


def test_spatial_two_loop_assembles_where_stated():
    """
    Regression: rig.at(0) puts every body where the scene states (coupler2 was 170 deg off).

    The stated poses are given to 1e-3 deg and 1e-6 m: within those digits.
    """
    sc = schema.load('spatial_two_loop')
    rig = rig_for(sc)
    bodies = rig.at([0.0], outputs=('kinematics',)).bodies
    for name, pose in sc.assembly_poses.items():
        k = bodies.names.index(name)
        assert math.degrees(_angle(pose.rotation(), bodies.rotation[0, k])) <= 1e-3, name
        assert np.linalg.norm(bodies.origin_m[0, k] - pose.origin_m) <= 1e-6, name


def _flipped(poses, name, axis_world, through):
    """Return ``poses`` with link ``name`` turned half a turn about a world line."""
    out = dict(poses)
    r, o = out[name]
    flip = _rot(axis_world, math.pi)
    out[name] = (flip @ r, through + flip @ (o - through))
    return out


def _two_loop_poses():
    sc = spatial_from_dict(_two_loop())
    lk = kinematics.Linkage(sc)
    fr = lk.frames(lk.q0, lk.sph0)
    return {n: (fr.rot[0, i], fr.origin[0, i]) for i, n in enumerate(lk.body_names) if i}


def _two_loop_with(poses):
    data = _two_loop()
    data['assembly']['poses'] = _poses_mapping(poses)
    return data


def _other_rocker2(poses):
    """Return the second rocker's other assembly: F on its circle at the coupler's length."""
    data = _two_loop()
    r2, d2 = poses['rocker2']
    w = r2 @ np.array(data['joints']['D2']['axis_b'])
    f0 = d2 + r2 @ np.array(data['links']['rocker2']['points']['F'])
    e = poses['coupler2'][1]   # coupler2's origin is its point E
    length = np.linalg.norm(data['links']['coupler2']['points']['F'])

    def gap(phi):
        return np.linalg.norm(d2 + _rot(w, phi) @ (f0 - d2) - e) - length

    grid = np.linspace(1e-3, 2 * math.pi - 1e-3, 3600)
    values = [gap(p) for p in grid]
    i = next(j for j in range(len(grid) - 1) if values[j] * values[j + 1] < 0.0)
    phi = brentq(gap, grid[i], grid[i + 1], xtol=1e-15)
    f = d2 + _rot(w, phi) @ (f0 - d2)
    out = dict(poses)
    out['rocker2'] = (_rot(w, phi) @ r2, d2)
    # coupler2: x from E to F, its z (the U's axis_b) normal to the rocker's U axis
    a_w = poses['rocker'][0] @ _unit(data['joints']['U']['axis'])
    x = _unit(f - e)
    z = _unit(np.cross(x, a_w))
    z = z if z @ poses['coupler2'][0][:, 2] > 0.0 else -z
    out['coupler2'] = (np.stack([x, np.cross(z, x), z], -1), e)
    return out


def test_spatial_two_loop_other_assemblies_are_honoured():
    """
    Other assemblies of spatial_two_loop, when stated: honoured.

    The coupler flipped about its line EF (the U's other solution) and the second rocker on
    its other side: each assembled where stated; the flip moves coupler2's mass centre (off
    its line), so the shaking moment differs from the default's.
    """
    poses = _two_loop_poses()
    data = _two_loop()
    e = poses['coupler2'][1]
    f = poses['rocker2'][1] + poses['rocker2'][0] @ np.array(
        data['links']['rocker2']['points']['F'])
    flipped = _flipped(poses, 'coupler2', f - e, e)
    other = _other_rocker2(poses)
    assert math.degrees(_angle(poses['rocker2'][0], other['rocker2'][0])) > 30.0
    base = rig_for(spatial_from_dict(data)).at([0.0])
    for stated in (flipped, other):
        lk, fr, _ = _assembled_two_loop(stated)
        tol = _accuracy(lk, fr)
        for name, (r, o) in stated.items():
            k = lk.body_names.index(name)
            assert _angle(r, fr.rot[0, k]) <= tol, name
            assert np.linalg.norm(fr.origin[0, k] - o) <= tol * lk.length_scale, name
    # the flipped coupler's mass centre (off its line) changes the shaking moment
    rig = rig_for(spatial_from_dict(_two_loop_with(flipped)), cache=False)
    got = rig.at([0.0])
    assert np.max(np.abs(got.moment_Nm - base.moment_Nm)) > \
        1e-3 * np.max(np.abs(base.moment_Nm))


def _assembled_two_loop(poses):
    lk = kinematics.Linkage(spatial_from_dict(_two_loop_with(poses)))
    return lk, lk.frames(lk.q0, lk.sph0), None


def test_spatial_two_loop_half_stated_assembly_is_refused():
    """The second rocker stated on its other side, the coupler on this one: refused, named."""
    poses = _two_loop_poses()
    other = _other_rocker2(poses)
    mixed = dict(poses)
    mixed['rocker2'] = other['rocker2']
    with pytest.raises(SpatialError, match=r'assembly: at crank angle 0\.0000 deg the linkage '
                                           r'does not close at the stated poses: '
                                           r'(rocker2|coupler2) closed [0-9.]+ deg'):
        kinematics.Linkage(spatial_from_dict(_two_loop_with(mixed)))


# ----------------------------------------------------------------------------- axis_b at load

def test_universal_axis_b_not_normal_at_the_poses_is_refused():
    data = _two_loop()
    data['joints']['U']['axis_b'] = [0.0, 0.6, 0.8]
    with pytest.raises(SceneError, match=r'joints\.U\.axis_b: got \[0\.0, 0\.6, 0\.8\], which '
                                         r'is [0-9.]+ deg \(not 90\) from the joint\'s axis'):
        spatial_from_dict(data)


def test_missing_axis_b_is_refused_naming_the_one_the_poses_imply():
    data = _two_loop()
    del data['joints']['D']['axis_b']
    with pytest.raises(SceneError) as err:
        spatial_from_dict(data)
    text = str(err.value)
    assert text.startswith('joints.D.axis_b: missing, and its default (the numbers of axis, '
                           '[1.0, 0.35, 0.4]) is ')
    # the implied axis_b is the one the scene had: rocker's z
    implied = [float(v) for v in text.split("link rocker's axes, [")[1].split(']')[0].split(',')]
    assert_allclose(implied, [0.0, 0.0, 1.0], atol=1e-4)


def test_inconsistent_axis_b_is_refused():
    data = _two_loop()
    data['joints']['D2']['axis_b'] = [1.0, 0.0, 0.0]
    with pytest.raises(SceneError, match=r'joints\.D2\.axis_b: got \[1\.0, 0\.0, 0\.0\], which '
                                         r'is [0-9.]+ deg from the joint\'s axis at the stated '
                                         r'poses \(assembly\.poses of frame and rocker2\)'):
        spatial_from_dict(data)


def test_axis_b_with_a_link_not_stated_is_not_checked_at_load():
    """Without a pose for its link the check cannot apply; the assembly still names it."""
    data = _two_loop()
    data['joints']['D2']['axis_b'] = [1.0, 0.0, 0.0]
    del data['assembly']['poses']['rocker2']
    spatial_from_dict(data)


def test_pose_off_its_joint_is_refused_after_assembly_naming_the_link():
    """A pose the joints cannot take (the slider turned about its guide): the link named."""
    data, _ = schema.load_data('rssp_slider')
    data = copy.deepcopy(data)
    data['assembly']['poses']['slider']['rpy_deg'] = [0.0, -25.59, 73.3]
    with pytest.raises(SpatialError, match=r'slider closed 19\.2 deg and [0-9.e-]+ m from '
                                           r'assembly\.poses\.slider \(there: origin_m'):
        kinematics.Linkage(spatial_from_dict(data))
