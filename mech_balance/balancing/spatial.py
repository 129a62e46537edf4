"""
Balancing of spatial rigs: complete force balance, certified redistribution, counterweights.

Generic over every rig with the ``'body_kinematics'`` capability (the general ``kind:
spatial``, the RGGR of seed 002 among its scenes): the shaking wrench is linear in the ten
inertial parameters of each moving body (:mod:`mech_balance.core.regressor`), so

* **complete force balance** (:func:`force_balance`): the shaking force over the cycle is
  ``F theta``; its zero set is the null space of F (in the masses and first moments: the
  inertia columns of F are zero).  The conditions are reported as equations expressing r
  pivot parameters through the others (r the rank of F), and the least change of the free
  bodies that meets them is returned;
* **optimal redistribution** (:func:`redistribute`): minimize ``w1 f~ + w2 n~`` (RMS of the
  normalized shaking force and moment) over the free bodies' parameters, each body physically
  realizable: its pseudo-inertia ``J = [[Sigma, h], [h^T, m]]`` (``Sigma = tr(I)/2 1 - I``)
  positive semi-definite (Wensing, Kim & Slotine 2017: J is PSD exactly when some
  non-negative mass distribution has these parameters), with mass bounds and an extent bound
  ``tr(Sigma) <= m r^2`` (the RMS distance of the body's mass from its origin at most r);
  an SOC epigraph per RMS term and a 4x4 PSD cone per body, solved by Clarabel;
* **counterweights** (:func:`counterweights`): add-only; each listed body keeps its
  parameters and gains a counterweight of steel spheres (below), certified the same way.

Every program carries the safe lower bound of
:func:`mech_balance.balancing.certificate.safe_lower_bound`; the PSD and power cones, which
that function does not know, are folded into the objective first (:func:`_fold_cones`).  The
primal value is the core's evaluation (``rig.at``) of the written design, and the design
satisfies every constraint (its largest violation is reported; a realizability violation
at round-off is repaired before the design is written).

A kind takes part through a parameter model (:data:`PARAMETER_MODELS`, by kind name): which
parameters of each body its scene can hold (a basis), how to write a design back as a scene,
how to fit counterweights.  The derivations: docs/_drafts/spatialbal.md.
"""

from dataclasses import dataclass, field
import math
import time

import clarabel
from mech_balance import schema
from mech_balance.balancing import certificate, socp
from mech_balance.balancing.defaults import check_range, DEFAULT_DENSITY_KG_M3, \
    DEFAULT_MAX_MASS_FACTOR, DEFAULT_MAX_RADIUS_FACTOR, DEFAULT_WEIGHTS, EXTENT_FACTOR_RANGE, \
    PAPER_MASS_FACTORS, SPATIAL_MASS_FACTOR_RANGE
from mech_balance.conventions import cycle_angles, DEFAULT_SAMPLES, MAX_WEIGHT, rms
from mech_balance.core import regressor
from mech_balance.core.rig import rig_for
from mech_balance.schema import registry
from mech_balance.schema.scene import SERIES
import numpy as np
import scipy.sparse as sp

CAPABILITY = 'body_kinematics'
"""The rig capability every method of this module needs."""
EXTENT_FACTOR = 1.5
"""Default extent bound: RMS distance of a body's mass from its origin at most this factor
times its reach (the farthest point of its drawing from its origin)."""
RANK_REL_TOL = 1e-9
"""Singular values of the force map below this fraction of the largest span its null space."""
FORCE_BALANCED_REL = 1e-9
"""A design whose RMS shaking force is at most this fraction of the original's counts as
completely force balanced (issue 21's acceptance)."""
CONDITION_COEFF_REL = 1e-12
"""Coefficients of a printed force-balance condition below this fraction of its largest are
round-off (left out of the text, kept in the matrix)."""
PSD_ROUNDOFF = 64.0 * np.finfo(float).eps
"""A body's normalized pseudo-inertia counts as PSD down to this fraction of its largest
eigenvalue below zero (the eigenvalue solver's round-off; a thin rod has exact zeros)."""
VIOLATION_TOL = 16.0 * np.finfo(float).eps
"""A design meets a constraint when it violates it by at most this (units of its body's mass
and reach): the rounding of evaluating the constraint (equal mass bounds are met exactly
otherwise only by luck)."""
INERTIA_CLIP_RTOL = 1e-12
"""A designed body's principal moment of inertia below zero by at most this fraction of its
m reach^2 is round-off (the design at the edge of the PSD set) and is written as 0."""
TIGHT_TOL_SCALE = 1e-3
"""A program whose first solve is not certified is solved again with Clarabel's tolerances
this factor tighter (its dual residual, paid with the box, shrinks with them)."""
REPAIR_GROWTH = 2.0
"""The realizability repair multiplies its step by this factor until the body is PSD."""
REPAIR_STEPS = 60
"""Most steps of the realizability repair."""
CLUSTER_SPREAD_REL = 1e-6
"""Eigenvalues of a counterweight's spread about its centre below this fraction of dm reach^2
are round-off: no sphere pair is placed along them (the error is evaluated: the primal is the
core's value of the built spheres)."""


class SpatialBalanceError(socp.BalanceError):
    """A spatial balancing problem is ill-posed, infeasible or cannot be solved."""


# ============================================================================ parameter models


@dataclass(frozen=True)
class BodyModel:
    """
    What a kind's scene can hold of one body: ``theta = basis @ y`` (``basis`` (10, d)).

    ``orders[j]`` is 0, 1 or 2 for a column in kg, kg m or kg m^2 (its scale);
    ``reach_m`` the farthest drawn point from the body origin; ``counterweights`` whether
    the scene can carry one on this body (else the reason, text).
    """

    name: str
    basis: np.ndarray
    orders: tuple
    reach_m: float
    counterweights: object = True
    labels: tuple = regressor.PARAMETERS
    line_offset_m: float = 0.0   # a body on a line: distance of the line's origin point


@dataclass
class ParameterModel:
    """The bodies of a rig, their parameters theta (10 nb,), and the scene writers."""

    bodies: tuple
    theta: np.ndarray
    build: object          # theta (10 nb,) -> scene
    add: object            # ({body: added theta (10,)}, {body: [sphere dict]}) -> scene

    def index(self, name, option):
        """Return the index of a body by name, or a ValueError naming ``option``."""
        names = [b.name for b in self.bodies]
        if name not in names:
            raise SpatialBalanceError(f'{option}: got {name!r}, expected one of '
                                      f'{", ".join(names)}')
        return names.index(name)


def _full_body(name, reach):
    return BodyModel(name, np.eye(10), (0, 1, 1, 1, 2, 2, 2, 2, 2, 2), reach)


def line_basis(point_a, point_b):
    """
    Return the (10, 3) basis of mass distributions on the line through two points (body axes).

    With p(s) = a + s d (d the unit direction), Sigma = int p p^T dm = mu0 a a^T + mu1 (a d^T
    + d a^T) + mu2 d d^T and h = mu0 a + mu1 d, linear in the moments (mu0, mu1, mu2) of the
    mass along the line (mu0 = m); J is PSD exactly when [[mu0, mu1], [mu1, mu2]] is.  A
    slender rod on an S-S line (its idle spin needs zero inertia about the line).
    """
    a = np.asarray(point_a, dtype=float)
    d = np.asarray(point_b, dtype=float) - a
    d = d / np.linalg.norm(d)
    out = np.zeros((10, 3))
    for j, (h, sigma) in enumerate(((a, np.outer(a, a)), (d, np.outer(a, d) + np.outer(d, a)),
                                    (np.zeros(3), np.outer(d, d)))):
        i_o = np.trace(sigma) * np.eye(3) - sigma
        out[:, j] = [1.0 if j == 0 else 0.0, *h, i_o[0, 0], i_o[0, 1], i_o[1, 1], i_o[0, 2],
                     i_o[1, 2], i_o[2, 2]]
    return out


def spatial_model(rig):
    """
    Return the :class:`ParameterModel` of a ``kind: spatial`` rig.

    Every link has its ten parameters, except a link held only by two spherical joints (an
    idle spin, :class:`mech_balance.core.spatial.kinematics` fixes it by convention): its mass
    stays on the line through the two joints (:func:`line_basis`), as the rig requires.  A
    design is written as the links' mass, mass centre and inertia about it; counterweights are
    folded into their link's (the scene has no counterweight field; the spheres are in the
    report and the provenance).
    """
    from mech_balance.schema.spatial import SpatialLink
    sc = rig.scene
    idle = {name: (ja, jb) for name, ja, jb in getattr(rig.linkage, 'idle_spins', ())}
    joints = {j.name: j for j in sc.joints}
    names = [b.name for b in rig.drawing.bodies]
    reaches = {name: max([float(np.linalg.norm(p)) for p in sc.link(name).points.values()]
                         + [0.0]) for name in names}
    # a link whose points all sit at its origin (a slider carriage) has no span of its own:
    # it is given the smallest span of the rig's other links (the size of its parts), not a
    # metre, so its extent bound and its counterweight's distance stay within the rig
    spans = [r for r in reaches.values() if r > 0.0]
    least_span = min(spans) if spans else 1.0
    bodies, thetas = [], []
    for name in names:
        lk = sc.link(name)
        reach = reaches[name]
        if reach <= 0.0:
            reach = max(float(np.linalg.norm(lk.com_m)), least_span)
        thetas.append(regressor.parameters(lk.mass_kg, lk.com_m, lk.inertia_matrix()))
        if name in idle:
            ends = [lk.points[j.point_a if j.link_a == name else j.point_b]
                    for j in (joints[idle[name][0]], joints[idle[name][1]])]
            bodies.append(BodyModel(name, line_basis(*ends), (0, 1, 2), reach,
                                    f'{name} is held only by the spherical joints '
                                    f'{idle[name][0]} and {idle[name][1]}: a sphere would give '
                                    'it inertia about their line (its idle spin); expected a '
                                    'link with a revolute, prismatic or universal joint',
                                    ('m', 'm s', 'm s^2'),
                                    float(np.linalg.norm(ends[0]))))
        else:
            bodies.append(_full_body(name, reach))

    def build(t, name=None):
        t = np.asarray(t, dtype=float).reshape(-1, 10)
        links = []
        for lk in sc.links:
            if lk.name not in names:
                links.append(lk)
                continue
            k = names.index(lk.name)
            tk = t[k]
            if not np.any(tk):   # a massless link left massless (fixed): as the scene says
                links.append(lk)
                continue
            m = float(tk[0])
            c = tk[1:4] / m
            i_c = regressor.inertia_matrix(tk[4:10]) - m * (np.dot(c, c) * np.eye(3)
                                                            - np.outer(c, c))
            i_c = _clip_roundoff(i_c, abs(m) * bodies[k].reach_m ** 2)
            links.append(SpatialLink(lk.name, lk.points, m, tuple(float(x) for x in c),
                                     tuple(float(x) for x in (i_c[0, 0], i_c[1, 1], i_c[2, 2],
                                                              i_c[0, 1], i_c[0, 2],
                                                              i_c[1, 2]))))
        return sc.with_links(links, name=name or f'{sc.name}_balanced')

    theta = np.concatenate(thetas)

    def add(added, spheres, name=None):
        t = theta.copy()
        for key, extra in added.items():
            k = names.index(key)
            t[10 * k:10 * k + 10] += extra
        return build(t, name or f'{sc.name}_counterweights')

    return ParameterModel(tuple(bodies), theta, build, add)


def _clip_roundoff(inertia, scale):
    """
    Return an inertia tensor (3, 3) with its round-off negative principal moments set to 0.

    A design at the edge of the feasible set (a rod's transverse inertia driven to zero)
    comes out of ``I_O - m (|c|^2 1 - c c^T)`` a few 1e-15 below zero, which the scene's
    loader would refuse although the design is a body; principal moments below zero by at
    most :data:`INERTIA_CLIP_RTOL` of the body's ``m reach^2`` (``scale``) are that
    round-off and are clipped, the tensor rebuilt from its eigenvectors.  A larger negative
    one (a design that is no body) is kept, so the loader names it.
    """
    eig, vec = np.linalg.eigh(0.5 * (inertia + inertia.T))
    if eig[0] >= 0.0 or eig[0] < -INERTIA_CLIP_RTOL * scale:
        return inertia
    return (vec * np.maximum(eig, 0.0)) @ vec.T


PARAMETER_MODELS = {'spatial': spatial_model}
"""The parameter model of each kind of rig that this module balances (kind name -> factory)."""


def parameter_model(rig):
    """Return the :class:`ParameterModel` of a rig (the rig's own model first, if it has one)."""
    if CAPABILITY not in rig.capabilities:
        raise SpatialBalanceError(f'scene {rig.name!r}: its rig has no {CAPABILITY!r} '
                                  'capability, expected a spatial rig')
    own = getattr(rig, 'parameter_model', None)
    if callable(own):
        return own()
    kind = registry.kind_of(rig).name
    if kind not in PARAMETER_MODELS:
        raise SpatialBalanceError(f'scene {rig.name!r}: kind {kind!r} has no parameter model; '
                                  f'expected one of {", ".join(PARAMETER_MODELS)}')
    return PARAMETER_MODELS[kind](rig)


# ============================================================================ units and maps


@dataclass(frozen=True)
class Units:
    """The objective's units: force by m l omega^2, moment by m l^2 omega^2."""

    mass_kg: float
    length_m: float
    omega_rad_s: float
    source: str

    @property
    def force_N(self):
        """Return the unit of force, N."""
        return self.mass_kg * self.length_m * self.omega_rad_s ** 2

    @property
    def moment_Nm(self):
        """Return the unit of moment, N m."""
        return self.force_N * self.length_m


def units_of(rig, model):
    """Return the scene's normalization, or (first body's mass, largest reach, crank speed)."""
    norm = getattr(rig.scene, 'normalization', None)
    if norm is not None:
        get = norm.get if isinstance(norm, dict) else (lambda k: getattr(norm, k))
        return Units(float(get('mass_kg')), float(get('length_m')),
                     abs(float(get('omega_rad_s'))), 'scene')
    speed = abs(float(rig.at([0.0], outputs=('kinematics',)).crank_speed_rad_s[0]))
    if not speed > 0.0:
        raise SpatialBalanceError(f'scene {rig.name!r}: crank speed 0, expected a nonzero '
                                  'speed for the RMS objective')
    return Units(float(model.theta[0]), max(b.reach_m for b in model.bodies), speed,
                 'first body')


@dataclass
class Maps:
    """
    The RMS shaking force and moment as compressed maps of theta (10 nb,) in SI.

    ``RMS(force) = ||force @ theta||`` (N) and likewise the moment (N m), over ``samples``
    crank angles (:func:`mech_balance.conventions.rms`).
    """

    force: np.ndarray
    moment: np.ndarray
    samples: int
    angles: np.ndarray


def cycle_of(rig, samples):
    """Return the crank angles of one revolution, from the scene's assembly angle (analyze's)."""
    return cycle_angles(samples, float(getattr(rig.scene, 'assembly_crank_angle_rad', 0.0)))


def maps_of(rig, samples):
    """Return the :class:`Maps` of a rig from its body kinematics over one revolution."""
    psi = cycle_of(rig, samples)
    kin = rig.body_kinematics(psi)
    y = regressor.wrench_regressor(kin, rig.moment_point_m)
    root = math.sqrt(psi.size)

    def compress(rows):
        mat = rows.reshape(-1, rows.shape[-1]) / root
        return np.linalg.qr(mat, mode='r') if mat.shape[0] > mat.shape[1] else mat
    return Maps(compress(y[:, :3]), compress(y[:, 3:]), psi.size, psi)


def _design_columns(model, free):
    """Return the (10 nb, D) basis of the free bodies, their column scales' orders, slices."""
    cols, orders, where = [], [], {}
    start = 0
    nb = len(model.bodies)
    for k, body in enumerate(model.bodies):
        if k not in free:
            continue
        block = np.zeros((10 * nb, body.basis.shape[1]))
        block[10 * k:10 * k + 10] = body.basis
        cols.append(block)
        orders += list(body.orders)
        where[k] = slice(start, start + body.basis.shape[1])
        start += body.basis.shape[1]
    return (np.hstack(cols) if cols else np.zeros((10 * nb, 0))), orders, where


def _coordinates(body, theta_k):
    """Return y with basis @ y = theta_k (least squares; exact for a theta of the basis)."""
    return np.linalg.lstsq(body.basis, theta_k, rcond=None)[0]


# ============================================================================ (a) force balance


@dataclass
class ForceBalance:
    """
    The complete force balance of a spatial rig.

    ``conditions`` ``[{'parameter': name, 'equals': {name: coefficient}}]`` (SI: kg and
    kg m) hold exactly for the force-balanced designs: r = ``rank`` pivot parameters in terms
    of the others.  ``theta`` is the least change of the free bodies that meets them (or, when
    none does, the least-squares one); ``attainable`` says whether its RMS shaking force is at
    most :data:`FORCE_BALANCED_REL` of the original's.  ``added_first_moment_kg_m`` gives per
    free body the change of h (body axes), ``added_mass_kg`` of m.
    """

    scene: object
    balanced_scene: object
    rank: int
    nullity: int
    conditions: list
    theta: np.ndarray
    attainable: bool
    force_rms_N: tuple
    moment_rms_Nm: tuple
    added_first_moment_kg_m: dict
    added_mass_kg: dict
    free: tuple
    samples: int
    unrealizable: dict = field(default_factory=dict)
    table: list = field(default_factory=list)

    @property
    def realizable(self):
        """Return whether every body of the design is a body (:func:`unrealizable_bodies`)."""
        return not self.unrealizable

    def to_dict(self):
        """Return the result as a plain dict."""
        return schema.plain({
            'scene': self.scene.name, 'method': 'complete force balance (null space)',
            'samples': self.samples, 'free': list(self.free), 'rank': self.rank,
            'nullity': self.nullity, 'conditions': self.conditions,
            'attainable': self.attainable, 'realizable': self.realizable,
            'unrealizable': self.unrealizable,
            'added_first_moment_kg_m': self.added_first_moment_kg_m,
            'added_mass_kg': self.added_mass_kg, 'table': self.table})

    def summary(self):
        """Return the provenance stored with the balanced scene."""
        return schema.plain({'source_scene': self.scene.name,
                             'method': 'complete force balance (null space)',
                             'attainable': self.attainable, 'rank': self.rank})


def force_balance(rig, free=None, samples=None):
    """
    Return the :class:`ForceBalance` of a rig: its conditions and the least-change design.

    ``free`` names the bodies that may change (default all); the others keep their
    parameters.  The conditions are those of every body (the rig's own); the design changes
    the free bodies' parameters by the least amount (in the units of each body: its mass and
    reach) that zeroes the shaking force at every crank angle.
    """
    model = parameter_model(rig)
    samples = _samples(samples, rig)
    maps = maps_of(rig, samples)
    nb = len(model.bodies)
    free_idx = _free(model, free, 'free')
    units = units_of(rig, model)
    # conditions over the parameters the scene can hold (every body's basis), each in units
    # of its body's mass and reach
    every = set(range(nb))
    full_basis, _, _ = _design_columns(model, every)
    full_scale = _body_scales(model, every, units)
    fmat = maps.force @ full_basis * full_scale
    _, sv, vt = np.linalg.svd(fmat)
    rank = int(np.sum(sv > RANK_REL_TOL * sv[0])) if sv.size and sv[0] > 0 else 0
    labels = [f'{b.name}.{lab}' for b in model.bodies for lab in b.labels]
    conditions = _conditions(vt[:rank], full_scale, labels)
    # least change of the free bodies (normalized by their own mass and reach)
    basis, orders, _ = _design_columns(model, free_idx)
    body_scale = _body_scales(model, free_idx, units)
    g = maps.force @ basis * body_scale                          # N per unit design step
    f0 = maps.force @ model.theta
    step, *_ = np.linalg.lstsq(g, -f0, rcond=None)
    theta = model.theta + basis @ (step * body_scale)
    balanced = model.build(theta)
    force = (float(np.linalg.norm(f0)), float(np.linalg.norm(maps.force @ theta)))
    moment = (float(np.linalg.norm(maps.moment @ model.theta)),
              float(np.linalg.norm(maps.moment @ theta)))
    added_h, added_m = {}, {}
    for k in free_idx:
        d = theta[10 * k:10 * k + 10] - model.theta[10 * k:10 * k + 10]
        added_h[model.bodies[k].name] = [float(x) for x in d[1:4]]
        added_m[model.bodies[k].name] = float(d[0])
    result = ForceBalance(
        scene=rig.scene, balanced_scene=balanced, rank=rank, nullity=full_basis.shape[1] - rank,
        conditions=conditions, theta=theta,
        attainable=force[1] <= FORCE_BALANCED_REL * max(force[0], 1e-300),
        force_rms_N=force, moment_rms_Nm=moment, added_first_moment_kg_m=added_h,
        added_mass_kg=added_m, free=tuple(model.bodies[k].name for k in free_idx),
        samples=samples, unrealizable=unrealizable_bodies(model, theta, free_idx))
    result.table = before_after(rig, balanced, samples, units)
    return result


def unrealizable_bodies(model, theta, indices):
    """
    Return ``{body: reason}`` of the bodies among ``indices`` that no physical body realizes.

    A body is realizable when its mass is positive and its pseudo-inertia is PSD (down to
    :data:`PSD_ROUNDOFF` of its largest eigenvalue): the least-change force balance is a
    least-squares step that knows neither, and may ask for a negative mass.
    """
    out = {}
    for k in indices:
        t = theta[10 * k:10 * k + 10]
        name = model.bodies[k].name
        if not t[0] > 0.0:
            out[name] = f'mass {t[0]:.6g} kg (not positive)'
            continue
        eig = np.linalg.eigvalsh(regressor.pseudo_inertia(t))
        if eig[0] < -PSD_ROUNDOFF * float(np.abs(eig).max()):
            out[name] = (f'pseudo-inertia eigenvalue {eig[0]:.3g} < 0 (a mass distribution '
                         'no body has)')
    return out


def _conditions(rows, scale, names):
    """
    Return the conditions ``rows @ (y / scale) = 0`` as pivot = sum(coefficient * other).

    The pivots are chosen by a column-pivoted QR of the row basis (the best-conditioned
    parameters to solve for); the coefficients are SI (kg, kg m per kg, ...).
    """
    import scipy.linalg
    if rows.shape[0] == 0:
        return []
    _, _, piv = scipy.linalg.qr(rows, pivoting=True)
    r = rows.shape[0]
    pivots, others = piv[:r], piv[r:]
    coeff = -np.linalg.solve(rows[:, pivots], rows[:, others])
    out = []
    for i, p in enumerate(pivots):
        terms = {}
        big = float(np.max(np.abs(coeff[i]))) if coeff.shape[1] else 0.0
        for j, o in enumerate(others):
            c = coeff[i, j]
            if abs(c) > CONDITION_COEFF_REL * max(big, 1.0):
                terms[names[o]] = float(c * scale[p] / scale[o])
        out.append({'parameter': names[p], 'equals': terms})
    return out


def format_conditions(conditions):
    """Return the force-balance conditions as lines of text (SI)."""
    lines = []
    for cond in conditions:
        rhs = ' '.join(f'{"-" if c < 0 else "+"} {abs(c):.6g} {n}'
                       for n, c in cond['equals'].items()) or '0'
        lines.append(f'  {cond["parameter"]} = {rhs.lstrip("+ ")}')
    return lines


# ============================================================================ (b) redistribution


def redistribute(rig, weights=DEFAULT_WEIGHTS, samples=None, *, mass_factors=PAPER_MASS_FACTORS,
                 mass_bounds=None, extent_factor=EXTENT_FACTOR, extent_bounds=None,
                 fixed=(), force_balanced=False):
    """
    Return the certified optimal redistribution (:class:`SpatialResult`) of a spatial rig.

    Minimizes ``w1 f~ + w2 n~`` over the parameters of every body not in ``fixed``, each
    with a PSD pseudo-inertia, ``mass_bounds`` ``{body: (lo_kg, hi_kg)}`` (default
    ``mass_factors`` x its mass) and ``extent_bounds`` ``{body: r_m}`` (default
    ``extent_factor`` x its reach).  ``force_balanced`` adds the shaking force's null space
    as equalities (complete force balance); when it is infeasible the result says so and
    minimizes the RMS shaking force instead (``weights`` (1, 0)).
    """
    t_start = time.perf_counter()
    w = _weights(weights)
    model = parameter_model(rig)
    samples = _samples(samples, rig)
    nb = len(model.bodies)
    fixed_idx = {model.index(n, 'fixed') for n in (fixed or ())}
    free_idx = [k for k in range(nb) if k not in fixed_idx]
    if not free_idx:
        raise SpatialBalanceError('fixed: got every body, expected at least one free body')
    units = units_of(rig, model)
    maps = maps_of(rig, samples)
    mlo, mhi = _mass_bounds(model, free_idx, mass_bounds, mass_factors)
    extent = _extent_bounds(model, free_idx, extent_bounds, extent_factor)
    prog = _redistribution_program(model, maps, units, free_idx, w, mlo, mhi, extent,
                                   force_balanced)
    note = None
    run = prog.solve() if prog.balanceable is not False else None
    if force_balanced and (run is None or run.status in socp.INFEASIBLE):
        note = ('complete force balance is not attainable with realizable bodies within the '
                'bounds; minimized the RMS shaking force instead')
        w = (1.0, 0.0)
        prog = _redistribution_program(model, maps, units, free_idx, w, mlo, mhi, extent,
                                       False)
        run = prog.solve()
    _check_run(run, rig, units)
    checks = _RealizableChecks(model, free_idx, mlo, mhi, extent)
    options = {'mass_bounds_kg': {model.bodies[k].name: [mlo[k], mhi[k]] for k in free_idx},
               'extent_bounds_m': {model.bodies[k].name: extent[k] for k in free_idx},
               'fixed': sorted(model.bodies[k].name for k in fixed_idx),
               'force_balanced': bool(force_balanced), 'note': note}

    def design(run):
        theta = prog.theta(run.sol.x)
        if prog.balanceable:
            theta = prog.project_null(theta)
        violation = checks.violation(theta)
        theta, pull = checks.repair(
            theta, keep_force=bool(prog.balanceable),
            objective=lambda t: w[0] * np.linalg.norm(maps.force @ t) / units.force_N
            + w[1] * np.linalg.norm(maps.moment @ t) / units.moment_Nm)
        options['violation_after_pull'] = checks.violation(theta)
        return _finish(rig, model, units, maps, prog, run, theta, model.build(theta), w,
                       samples, violation, pull, t_start,
                       'redistribution (PSD pseudo-inertia, SOCP+SDP)', dict(options))
    return _best(prog, run, design)


def _best(prog, run, design):
    """Return design(run), or that of a tighter solve when the first is not certified."""
    result = design(run)
    if result.certificate.certified:
        return result
    tight = prog.solve(TIGHT_TOL_SCALE)
    if not tight.ok:
        return result
    other = design(tight)
    if other.certificate.certified or other.certificate.gap_abs < result.certificate.gap_abs:
        return other
    return result


def _redistribution_program(model, maps, units, free_idx, w, mlo, mhi, extent, force_balanced):
    """Return the :class:`_Program` of a redistribution (variables per body: its basis)."""
    basis, orders, where = _design_columns(model, free_idx)
    units_k = {k: _program_units(model, k, mlo[k], mhi[k], extent[k]) for k in free_idx}
    body_scale = np.concatenate([[units_k[k][0] * units_k[k][1] ** o
                                  for o in model.bodies[k].orders] for k in sorted(free_idx)])
    offset = model.theta.copy()
    for k in free_idx:
        offset[10 * k:10 * k + 10] = 0.0
    prog = _Program(basis * body_scale, offset, units)
    prog.epigraphs(maps, w)
    for k in sorted(free_idx):
        body = model.bodies[k]
        cols = where[k]
        b_k = body.basis * body_scale[cols]
        m_k, r_k = units_k[k]
        prog.mass_rows(cols, b_k, mlo[k], mhi[k], m_k)
        prog.psd(cols, b_k, m_k, r_k)
        prog.extent(cols, b_k, extent[k], m_k, r_k)
        # the box of every feasible point: lo <= m <= hi, |h_i| <= m r, |I_ij| <= m r^2 (on a
        # line from the point a: s <= |p| + |a|, so int s^2 dm <= m (r + |a|)^2 and
        # |int s dm| <= m (r + |a|), Cauchy-Schwarz with int |p|^2 dm <= m r^2)
        reach = extent[k] + body.line_offset_m
        for j, order in zip(range(cols.start, cols.stop), body.orders):
            size = mhi[k] * reach ** order / body_scale[j] * (1.0 + 1e-12)
            prog.box_lo[j] = mlo[k] / body_scale[j] * (1.0 - 1e-12) if order == 0 else -size
            prog.box_hi[j] = size
    prog.balanceable = prog.force_null(maps) if force_balanced else None
    return prog


def _program_units(model, k, m_lo, m_hi, radius):
    """
    Return (M, R): the units of body k's variables in the redistribution and its checks.

    The rig's own units (the original mass m0 and reach r0, :func:`_ref`) moved into the
    bounds: M = m0 clipped into [m_lo, m_hi], R = min(r0, radius) (on a line, radius plus the
    line's offset from the origin).  A body whose mass is fixed at 1e3 m0 or must lie within
    0.1 r0 of its origin then still has variables of order one at the optimum and a PSD
    block ``D J D`` (D = diag(1/(sqrt(M) R) 1, 1/sqrt(M))) with entries of order one, and
    its constraints are checked to round-off of its own size.  (In units of a wide bound,
    1e6 m0, the solver stalls on the designs near m0 that the objective prefers.)
    """
    m0, r0 = _ref(model, k)
    return (float(min(max(m0, m_lo), m_hi)),
            float(min(r0, radius + model.bodies[k].line_offset_m)))


# ============================================================================ (c) counterweights


SVEC = ((0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2), (0, 3), (1, 3), (2, 3), (3, 3))
"""Clarabel's PSDTriangleConeT order of a 4x4 matrix: the upper triangle by columns (its
off-diagonal entries times sqrt(2))."""
SIGMA_ENTRIES = ((0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2))
"""The order of Sigma's six entries (as the inertia entries of theta)."""
SIGMA_TO_INERTIA = np.array([[0, 0, 1, 0, 0, 1], [0, -1, 0, 0, 0, 0], [1, 0, 0, 0, 0, 1],
                             [0, 0, 0, -1, 0, 0], [0, 0, 0, 0, -1, 0], [1, 0, 1, 0, 0, 0]],
                            dtype=float)
"""I = tr(Sigma) 1 - Sigma: (I_xx, I_xy, I_yy, I_xz, I_yz, I_zz) from (S_xx, S_xy, ...)."""
INERTIA_TO_SIGMA = np.linalg.inv(SIGMA_TO_INERTIA)
"""Sigma = tr(I)/2 1 - I, the inverse map."""


def _j_map():
    """Return G (10, 10): svec(J(theta)) = G theta (Clarabel's scaled triangle)."""
    g = np.zeros((10, 10))
    for row, (i, j) in enumerate(SVEC):
        f = 1.0 if i == j else math.sqrt(2.0)
        if j < 3:
            g[row, 4:10] = f * INERTIA_TO_SIGMA[SIGMA_ENTRIES.index((min(i, j), max(i, j)))]
        elif i < 3:
            g[row, 1 + i] = f
        else:
            g[row, 0] = 1.0
    return g


J_MAP = _j_map()


def counterweights(rig, links, weights=DEFAULT_WEIGHTS, samples=None, *,
                   density_kg_m3=DEFAULT_DENSITY_KG_M3, max_mass_factor=DEFAULT_MAX_MASS_FACTOR,
                   max_radius_factor=DEFAULT_MAX_RADIUS_FACTOR):
    """
    Return the certified optimal add-only spheres on the listed bodies (a SpatialResult).

    Each listed body keeps its parameters and gains a counterweight of mass at most
    ``max_mass_factor`` x its mass, made of spheres of ``density_kg_m3``, whose mass lies
    within RMS distance ``max_radius_factor`` x its reach of the body origin.  The convex set
    (docs/_drafts/spatialbal.md): ``[[Sigma - s 1, dh], [dh^T, dm]]`` PSD and
    ``s >= k dm^(5/3)`` (a power cone; ``k dm^(5/3)`` the spread of one solid sphere of mass
    dm) is exactly what clusters of hollow spheres realize, so the optimum is built
    (:func:`sphere_cluster`): up to six spheres, in pairs about the counterweight's centre
    along the principal axes of its spread.
    """
    t_start = time.perf_counter()
    w = _weights(weights)
    model = parameter_model(rig)
    samples = _samples(samples, rig)
    if isinstance(links, str):
        links = [part for part in links.split(',') if part]
    if not links:
        raise SpatialBalanceError('links: got none, expected at least one body for a '
                                  'counterweight')
    idx = []
    for name in links:
        k = model.index(name, 'links')
        if model.bodies[k].counterweights is not True:
            raise SpatialBalanceError(f'links: got {name!r}: {model.bodies[k].counterweights}')
        if k not in idx:
            idx.append(k)
    for value, option in ((density_kg_m3, 'density_kg_m3'),
                          (max_mass_factor, 'max_mass_factor'),
                          (max_radius_factor, 'max_radius_factor')):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or \
                not (math.isfinite(value) and value > 0.0):
            raise SpatialBalanceError(f'{option}: got {value!r}, expected a finite number > 0')
    units = units_of(rig, model)
    maps = maps_of(rig, samples)
    k_sphere = (3.0 / (4.0 * math.pi * density_kg_m3)) ** (2.0 / 3.0) / 5.0
    prog = _counterweight_program(model, maps, units, idx, w, max_mass_factor,
                                  max_radius_factor, k_sphere)
    run = prog.solve()
    _check_run(run, rig, units)

    def design(run):
        x = np.asarray(run.sol.x)
        added, spheres, violation = {}, {}, 0.0
        theta = model.theta.copy()
        for j, k in enumerate(idx):
            body = model.bodies[k]
            dm, dh, sigma, s = prog.counterweight(x, j)
            hi = max_mass_factor * model.theta[10 * k]
            viol, (dm, dh, sigma, s) = _cw_check(dm, dh, sigma, s, k_sphere, hi,
                                                 (max_radius_factor * body.reach_m) ** 2)
            violation = max(violation, viol / max(model.theta[10 * k], 1e-300))
            if dm <= MIN_COUNTERWEIGHT_REL * model.theta[10 * k]:
                continue
            cluster = sphere_cluster(dm, dh, sigma, s, density_kg_m3, body.reach_m)
            spheres[body.name] = cluster
            added[body.name] = cluster_theta(cluster)
            theta[10 * k:10 * k + 10] += added[body.name]
        extra = {'links': [model.bodies[k].name for k in idx], 'density_kg_m3': density_kg_m3,
                 'max_mass_factor': max_mass_factor, 'max_radius_factor': max_radius_factor,
                 'counterweights': spheres,
                 'added_mass_kg': {n: float(sum(c['mass_kg'] for c in cl))
                                   for n, cl in spheres.items()},
                 'sphere_overlap_m': {n: cluster_overlap_m(cl) for n, cl in spheres.items()}}
        return _finish(rig, model, units, maps, prog, run, theta, model.add(added, spheres), w,
                       samples, violation, 0.0, t_start,
                       'counterweights (add-only spheres, SOCP+SDP)', extra)
    return _best(prog, run, design)


MIN_COUNTERWEIGHT_REL = 1e-9
"""A counterweight lighter than this fraction of its body's mass is none (round-off)."""


def _counterweight_program(model, maps, units, idx, w, max_mass_factor, max_radius_factor,
                           k_sphere):
    # variables per counterweight j (11): dm, dh (3), Sigma (6, SIGMA_ENTRIES), s; in units
    # of the body's mass m0 and reach r0
    nvar = 11 * len(idx)
    nb = len(model.bodies)
    basis = np.zeros((10 * nb, nvar))
    for j, k in enumerate(idx):
        m0, r0 = float(model.theta[10 * k]), model.bodies[k].reach_m
        block = np.zeros((10, 11))
        block[0, 0] = m0
        block[1:4, 1:4] = m0 * r0 * np.eye(3)
        block[4:10, 4:10] = m0 * r0 * r0 * SIGMA_TO_INERTIA
        basis[10 * k:10 * k + 10, 11 * j:11 * j + 11] = block
    prog = _Program(basis, model.theta.copy(), units)
    prog.epigraphs(maps, w)
    fr2 = max_radius_factor ** 2
    hi = max_mass_factor
    for j, k in enumerate(idx):
        m0, r0 = float(model.theta[10 * k]), model.bodies[k].reach_m
        c = 11 * j
        prog.rows('nonneg', [_unit(prog.nx, c, -1.0), _unit(prog.nx, c, 1.0)], [0.0, hi])
        lin = np.zeros((10, prog.nx))
        for row, (a, b) in enumerate(SVEC):
            f = 1.0 if a == b else math.sqrt(2.0)
            if b < 3:
                lin[row, c + 4 + SIGMA_ENTRIES.index((a, b))] = f
                if a == b:
                    lin[row, c + 10] = -1.0
            elif a < 3:
                lin[row, c + 1 + a] = f
            else:
                lin[row, c] = 1.0
        prog.rows('psd', -lin, np.zeros(10))
        ext = np.zeros(prog.nx)
        ext[[c + 4, c + 6, c + 9]] = 1.0            # tr(Sigma) <= dm (f r0)^2
        ext[c] = -fr2
        prog.rows('nonneg', [ext], [0.0])
        # s >= k dm^(5/3)  <=>  (s / kk, 1, dm) in K_pow(3/5): (s/kk)^(3/5) >= |dm|
        kk = k_sphere * m0 ** (5.0 / 3.0) / (m0 * r0 * r0)
        pw = np.zeros((3, prog.nx))
        pw[0, c + 10] = -1.0 / kk
        pw[2, c] = -1.0
        prog.rows('pow', pw, [0.0, 1.0, 0.0])
        # the box every feasible point lies in (module docstring of certificate):
        # |dh_i| <= dm f r0, |Sigma_ij| <= tr Sigma <= dm (f r0)^2, s <= tr Sigma / 3
        prog.box_lo[c:c + 11] = [0.0] + [-hi * max_radius_factor] * 3 + [-hi * fr2] * 6 + [0.0]
        prog.box_hi[c:c + 11] = [hi] + [hi * max_radius_factor] * 3 + [hi * fr2] * 6 \
            + [hi * fr2 / 3.0]
        prog.cw.append((c, m0, r0))
    return prog


def _cw_check(dm, dh, sigma, s, k_sphere, mass_hi, radius2):
    """Return (worst violation in kg-units, repaired (dm, dh, Sigma, s)) of a counterweight."""
    viol = max(-dm, dm - mass_hi, 0.0)
    dm = min(max(dm, 0.0), mass_hi)
    if dm <= 0.0:
        return viol, (0.0, np.zeros(3), np.zeros((3, 3)), 0.0)
    s_min = k_sphere * dm ** (5.0 / 3.0)
    viol = max(viol, (s_min - s) / radius2)
    viol = max(viol, (np.trace(sigma) - dm * radius2) / radius2)
    s_new = max(s, s_min * (1.0 + 1e-12))
    sigma = sigma + (s_new - s) * np.eye(3) if s_new > s else sigma
    spread = sigma - s_new * np.eye(3) - np.outer(dh, dh) / dm
    low = float(np.linalg.eigvalsh(spread)[0])
    viol = max(viol, -low / radius2)
    if low < 0.0:
        sigma = sigma + (-low) * (1.0 + 1e-9) * np.eye(3)
    return viol, (dm, dh, sigma, s_new)


def hollow_sphere(mass_kg, spread_kg_m2, density_kg_m3):
    """
    Return (outer, inner) radii, m, of a hollow sphere of the mass and spread int(x^2 dm).

    m = rho 4/3 pi (R^3 - r^3) and int(x^2 dm) = rho 4/15 pi (R^5 - r^5); r = 0 is the solid
    sphere (the least spread of a sphere of that mass); R^5 - r^5 grows with r at fixed mass.
    """
    from scipy.optimize import brentq
    a = 3.0 * mass_kg / (4.0 * math.pi * density_kg_m3)
    b = 15.0 * spread_kg_m2 / (4.0 * math.pi * density_kg_m3)
    if b <= a ** (5.0 / 3.0):
        return a ** (1.0 / 3.0), 0.0

    def excess(r):
        return (a + r ** 3) ** (5.0 / 3.0) - r ** 5 - b
    hi = max(b ** 0.2, a ** (1.0 / 3.0))
    while excess(hi) < 0.0:
        hi *= 2.0
    r = brentq(excess, 0.0, hi, xtol=1e-15 * hi, rtol=1e-15, maxiter=200)
    return (a + r ** 3) ** (1.0 / 3.0), r


def sphere_cluster(dm, dh, sigma, s, density_kg_m3, reach_m):
    """
    Return the spheres realizing a counterweight (dm, dh, Sigma about the origin, spread s).

    c = dh / dm, S = Sigma - s 1 - dm c c^T (PSD) = sum_j sigma_j u_j u_j^T over its r
    eigenvalues above round-off (:data:`CLUSTER_SPREAD_REL` dm reach^2): masses dm / (2 r) at
    c +/- sqrt(r sigma_j / dm) u_j carry S exactly (one sphere at c when r = 0); each gets
    the spread s mu / dm, a hollow sphere (:func:`hollow_sphere`; s mu / dm >= k mu^(5/3)
    since mu <= dm).  Each entry: mass_kg, centre_m (body axes), spread_kg_m2,
    outer_radius_m, inner_radius_m.
    """
    c = np.asarray(dh, dtype=float) / dm
    spread = np.asarray(sigma, dtype=float) - s * np.eye(3) - dm * np.outer(c, c)
    vals, vecs = np.linalg.eigh(0.5 * (spread + spread.T))
    keep = vals > CLUSTER_SPREAD_REL * dm * reach_m ** 2
    r = int(np.sum(keep))
    points = [(c, dm)] if r == 0 else []
    for val, vec in zip(vals[keep], vecs.T[keep]):
        off = math.sqrt(r * val / dm) * vec
        points += [(c + off, dm / (2 * r)), (c - off, dm / (2 * r))]
    out = []
    for p, mu in points:
        spread_i = s * mu / dm
        outer, inner = hollow_sphere(mu, spread_i, density_kg_m3)
        out.append({'mass_kg': float(mu), 'centre_m': [float(x) for x in p],
                    'spread_kg_m2': float(spread_i), 'outer_radius_m': float(outer),
                    'inner_radius_m': float(inner)})
    return out


def cluster_overlap_m(cluster):
    """Return the largest overlap of two spheres, m: sum of outer radii - distance (<= 0: none)."""
    worst = -math.inf
    for i, a in enumerate(cluster):
        for b in cluster[i + 1:]:
            gap = np.linalg.norm(np.subtract(a['centre_m'], b['centre_m']))
            worst = max(worst, a['outer_radius_m'] + b['outer_radius_m'] - float(gap))
    return float(worst) if math.isfinite(worst) else 0.0


def cluster_theta(cluster):
    """Return theta (10,) of a list of spheres (their inertia 2 x spread about the centre)."""
    return sum(regressor.parameters(c['mass_kg'], c['centre_m'],
                                    2.0 * c['spread_kg_m2'] * np.eye(3)) for c in cluster)


# ============================================================================ the cone program


class _Program:
    """
    ``min q'x s.t. A x + s = b, s in K`` with x = (y, t_f, t_n): theta = offset + basis y.

    Blocks of rows by cone ('zero', 'nonneg', 'soc', 'psd' (4x4), 'pow' (alpha 3/5)); the
    box (box_lo, box_hi) contains every feasible y (for the certificate).
    """

    def __init__(self, basis, offset, units):
        self.basis = np.asarray(basis, dtype=float)
        self.offset = np.asarray(offset, dtype=float)
        self.units = units
        self.nd = self.basis.shape[1]
        self.nx = self.nd + 2
        self.blocks = []
        self.q = np.zeros(self.nx)
        self.box_lo = np.full(self.nx, -math.inf)
        self.box_hi = np.full(self.nx, math.inf)
        self.cw = []
        self.norm_maps = []
        self.balanceable = None

    def theta(self, x):
        """Return the parameters (10 nb,) of a solution x."""
        return self.offset + self.basis @ np.asarray(x, dtype=float)[:self.nd]

    def rows(self, kind, a, b):
        """Add a block of rows ``b - a x in K``."""
        self.blocks.append((kind, np.atleast_2d(np.asarray(a, dtype=float)),
                            np.asarray(b, dtype=float).ravel()))

    def epigraphs(self, maps, w):
        """Add t_f >= RMS force, t_n >= RMS moment (normalized) and the objective."""
        for i, (mat, unit) in enumerate(((maps.force, self.units.force_N),
                                         (maps.moment, self.units.moment_Nm))):
            g = mat / unit
            a = np.zeros((1 + g.shape[0], self.nx))
            a[0, self.nd + i] = -1.0
            a[1:, :self.nd] = -g @ self.basis
            self.rows('soc', a, np.concatenate([[0.0], g @ self.offset]))
            self.q[self.nd + i] = w[i]
            self.norm_maps.append((g @ self.basis, g @ self.offset))
        self.box_lo[self.nd:] = 0.0

    def mass_rows(self, cols, b_k, lo, hi, m0):
        """Add lo <= m <= hi of the body with design columns ``cols`` (rows in units m0)."""
        a = np.zeros((2, self.nx))
        a[0, cols], a[1, cols] = -b_k[0] / m0, b_k[0] / m0
        self.rows('nonneg', a, [-lo / m0, hi / m0])

    def psd(self, cols, b_k, m0, r0):
        """Add J(theta_k) PSD, as D J D with D = diag(1/(sqrt(m0) r0) 1, 1/sqrt(m0))."""
        d = np.array([1.0 / (math.sqrt(m0) * r0)] * 3 + [1.0 / math.sqrt(m0)])
        scale = np.array([d[i] * d[j] for i, j in SVEC])
        a = np.zeros((10, self.nx))
        a[:, cols] = -(scale[:, None] * J_MAP) @ b_k
        self.rows('psd', a, np.zeros(10))

    def extent(self, cols, b_k, radius, m0, r0):
        """Add tr(Sigma) = tr(I)/2 <= m radius^2 (units m0 r0^2)."""
        row = 0.5 * (b_k[4] + b_k[6] + b_k[9]) - radius ** 2 * b_k[0]
        a = np.zeros((1, self.nx))
        a[0, cols] = row / (m0 * r0 * r0)
        self.rows('nonneg', a, [0.0])

    def force_null(self, maps):
        """Add RMS shaking force = 0 (rows of the force map's range); False if impossible."""
        g = maps.force / self.units.force_N
        mat, c = g @ self.basis, g @ self.offset
        u, sv, vt = np.linalg.svd(mat, full_matrices=False)
        rank = int(np.sum(sv > RANK_REL_TOL * sv[0])) if sv.size and sv[0] > 0 else 0
        a = np.zeros((rank, self.nx))
        a[:, :self.nd] = vt[:rank]
        self.rows('zero', a, -(u[:, :rank].T @ c) / sv[:rank])
        outside = c - u[:, :rank] @ (u[:, :rank].T @ c)
        self.null = (vt[:rank], u[:, :rank], sv[:rank])
        self.force_norm = g
        return float(np.linalg.norm(outside)) <= RANK_REL_TOL * max(np.linalg.norm(c), 1e-300)

    def project_null(self, theta):
        """Return theta moved (least change of y) onto the force map's null space exactly."""
        rows, u, sv = self.null
        y = np.linalg.lstsq(self.basis, theta - self.offset, rcond=None)[0]
        g_y = rows @ y + (u.T @ (self.force_norm @ self.offset)) / sv
        return self.offset + self.basis @ (y - rows.T @ g_y)

    def counterweight(self, x, j):
        """Return (dm, dh, Sigma (3, 3), s) of counterweight j in SI."""
        c, m0, r0 = self.cw[j]
        v = np.asarray(x, dtype=float)[c:c + 11]
        sigma = np.zeros((3, 3))
        for i, (a, b) in enumerate(SIGMA_ENTRIES):
            sigma[a, b] = sigma[b, a] = v[4 + i] * m0 * r0 * r0
        return float(v[0] * m0), v[1:4] * m0 * r0, sigma, float(v[10] * m0 * r0 * r0)

    def assemble(self):
        """Return (A csc, b, clarabel cones, [(kind, rows)])."""
        a = sp.csc_matrix(np.vstack([blk[1] for blk in self.blocks]))
        b = np.concatenate([blk[2] for blk in self.blocks])
        cones, layout = [], []
        for kind, blk, _ in self.blocks:
            n = blk.shape[0]
            cones.append({'zero': lambda: clarabel.ZeroConeT(n),
                          'nonneg': lambda: clarabel.NonnegativeConeT(n),
                          'soc': lambda: clarabel.SecondOrderConeT(n),
                          'psd': lambda: clarabel.PSDTriangleConeT(4),
                          'pow': lambda: clarabel.PowerConeT(POWER_ALPHA)}[kind]())
            layout.append((kind, n))
        return a, b, cones, layout

    def solve(self, tol_scale=None):
        """
        Solve with the retries of :func:`mech_balance.balancing.socp.run_solver`.

        With ``tol_scale`` one solve with Clarabel's tolerances scaled by it instead.
        """
        a, b, cones, layout = self.assemble()
        if tol_scale is None:
            run = socp.run_solver(self.q, a, b, cones)
        else:
            t0 = time.perf_counter()
            settings = socp.solver_settings(tol_scale=tol_scale, max_iter=400)
            sol = clarabel.DefaultSolver(sp.csc_matrix((self.nx, self.nx)), self.q, a, b,
                                         cones, settings).solve()
            run = socp.Solve(sol, str(sol.status), (f'{sol.status} (tolerances x '
                                                    f'{tol_scale:g})',), self.q, a, b, cones,
                             time.perf_counter() - t0)
        run.layout = layout
        return run

    def box(self, primal):
        """Return the certificate's box: explicit bounds, the epigraphs' from norm bounds."""
        lo, hi = self.box_lo.copy(), self.box_hi.copy()
        for i, (g, c) in enumerate(self.norm_maps):
            bound = certificate.norm_bound(g, c, lo[:self.nd], hi[:self.nd])
            if self.q[self.nd + i] > 0.0:
                bound = min(bound, primal / self.q[self.nd + i] * (1.0 + 1e-12))
            hi[self.nd + i] = bound
        return lo, hi


POWER_ALPHA = 0.6
"""The power cone x^alpha y^(1 - alpha) >= |z| of the spheres' least spread (5/3 = 1/alpha)."""


def _unit(nx, i, value):
    row = np.zeros(nx)
    row[i] = value
    return row


def _fold_cones(run, lo, hi):
    """
    Return the safe lower bound of a program with PSD and power cones.

    Their duals are moved into K* (PSD: eigenvalues clipped and raised by their rounding
    bound; power: the dual cone {(u, v, w): (u/a)^a (v/(1-a))^(1-a) >= |w|} reached by
    scaling u, v up) and folded into the objective: for z_P in K*, q'x >= (q + A_P'z_P)'x -
    b_P'z_P on every feasible x, so a safe bound of the rest (zero, nonneg, soc) with q' =
    q + A_P'z_P, minus b_P'z_P and its rounding bound, bounds the program.  Every dual point
    gives a bound: the solver's and those of :func:`_refine_dual` are tried, the best kept.
    """
    z = np.asarray(run.sol.z, dtype=float)
    best = _fold_at(run, z, lo, hi)
    if not (math.isfinite(best[0]) and
            abs(best[1].residual_term) <= certificate.REFINE_BELOW * max(1.0, abs(best[0]))):
        for cand in _refine_dual(run, z):
            out = _fold_at(run, cand, lo, hi)
            if out[0] > best[0]:
                best = out
    return best


REFINE_ROUNDS = 3
"""Rounds of :func:`_refine_dual` (each re-projects onto K* and corrects what that undid)."""
REFINE_WEIGHT_FLOOR = 1e-10
"""The least weight of a dual entry in :func:`_refine_dual`, relative to the largest slack
(the entries of active constraints, slack 0, move almost freely)."""


def _refine_dual(run, z):
    """
    Return dual points whose residual ``r = q + A'z`` is removed where it costs least.

    The bound (1) of :mod:`.certificate` pays each residual r_i with the box of x_i, which a
    mass bound of 1e6 x the original makes wide.  A correction Delta with A'Delta = -r removes
    it instead; at the solver's primal point (x, s = b - A x) the dual objective changes by
    ``-b'Delta = r'x - s'Delta``: the residual at the point the solver found (not at the box's
    corner) less ``s'Delta``, small when Delta lives on the active constraints.  So Delta is
    the least ``sum w_i Delta_i^2`` with w_i the slack of row i (a PSD block in the eigenbasis
    of its slack matrix S: entry (i, j) weighted (lambda_i + lambda_j)/2, the diagonal ones
    being exactly <S, Delta Z>), plus a floor.  Projecting z + Delta back onto K* may undo a
    little of it; a few rounds.  Only a heuristic for choosing z: each point is certified by
    :func:`_fold_at` as any other (any z in K* gives a bound).
    """
    a = sp.csr_matrix(run.a).toarray()
    m = a.shape[0]
    s = np.asarray(run.sol.s, dtype=float)
    if s.size != m or not np.all(np.isfinite(s)) or not np.all(np.isfinite(z)):
        return []
    floor = REFINE_WEIGHT_FLOOR * max(float(np.abs(s).max(initial=0.0)), 1e-300)
    rot = np.eye(m)
    weight = np.full(m, floor)
    start = 0
    for cone, n in run.layout:
        rows = slice(start, start + n)
        blk = s[rows]
        if cone == 'nonneg':
            weight[rows] += np.maximum(blk, 0.0)
        elif cone == 'psd':
            vals, vecs = np.linalg.eigh(_smat(blk))
            vals = np.maximum(vals, 0.0)
            basis = np.zeros((n, n))
            for col, (i, j) in enumerate(SVEC):
                e = np.outer(vecs[:, i], vecs[:, j])
                e = e if i == j else (e + e.T) / math.sqrt(2.0)
                basis[:, col] = _svec(e)
                weight[start + col] += 0.5 * (vals[i] + vals[j])
            rot[rows, rows] = basis
        elif cone != 'zero':
            weight[rows] += float(np.linalg.norm(blk))
        start += n
    root = np.sqrt(weight)
    scaled = (rot.T @ a) / root[:, None]          # rows of A' in the rotated, weighted entries
    out = []
    for _ in range(REFINE_ROUNDS):
        zp = _project_all(z, run)
        r = run.q + a.T @ zp
        u, *_ = np.linalg.lstsq(scaled.T, -r, rcond=None)
        z = zp + rot @ (u / root)
        if not np.all(np.isfinite(z)):
            break
        out.append(z)
    return out


def _project_all(z, run):
    """Return z with every block moved into its dual cone (as the certificate does)."""
    out = _compress(np.array(z, dtype=float), run)
    start = 0
    for cone, n in run.layout:
        rows = slice(start, start + n)
        out[rows] = DUAL_CONES[cone](out[rows]) if cone in DUAL_CONES else \
            certificate.project_dual(out[rows], [(cone, n)])
        start += n
    return out


STRUCTURAL_RANK_REL = 1e-12
"""Singular values of a PSD block's matrices below this fraction of the largest span no
direction of its structural range (:func:`_psd_ranges`)."""


def _psd_ranges(run):
    """
    Return ``{first row: P}``: the projector onto the range every J(y) of a PSD block spans.

    A body on a line (:func:`line_basis`) has J(y) of rank 2 for every y: the dual entries in
    the other directions enter no residual, and the solver leaves them large (1e4 where the
    dual objective is 1e-10).  Compressed onto the range (P Z P, PSD when Z is), they no
    longer scale the rounding shift of :func:`_dual_psd`.  None for a full-rank block.
    """
    cached = getattr(run, 'psd_ranges', None)
    if cached is not None:
        return cached
    a = sp.csc_matrix(run.a)
    out, start = {}, 0
    for cone, n in run.layout:
        if cone == 'psd':
            blk = a[start:start + n].toarray()
            mats = [_smat(col) for col in blk.T if np.any(col)]
            if mats:
                u, sv, _ = np.linalg.svd(np.hstack(mats))
                rank = int(np.sum(sv > STRUCTURAL_RANK_REL * sv[0])) if sv[0] > 0 else 0
                if rank < 4:
                    out[start] = u[:, :rank] @ u[:, :rank].T
        start += n
    run.psd_ranges = out
    return out


def _compress(z, run):
    """Return z with each rank-deficient PSD block's dual compressed onto its range."""
    ranges = _psd_ranges(run)
    if not ranges:
        return z
    z = np.array(z, dtype=float)
    for start, proj in ranges.items():
        z[start:start + 10] = _svec(proj @ _smat(z[start:start + 10]) @ proj)
    return z


def _smat(v):
    """Return the symmetric 4x4 matrix of a Clarabel svec (off-diagonals over sqrt(2))."""
    m = np.zeros((4, 4))
    for x, (i, j) in zip(v, SVEC):
        m[i, j] = m[j, i] = x if i == j else x / math.sqrt(2.0)
    return m


def _svec(m):
    """Return Clarabel's svec of a symmetric 4x4 matrix (off-diagonals times sqrt(2))."""
    return np.array([m[i, j] if i == j else m[i, j] * math.sqrt(2.0) for i, j in SVEC])


def _fold_at(run, z, lo, hi):
    """Return (value, LowerBound, fold rounding) of :func:`_fold_cones` at one dual point."""
    q, a, b = run.q, sp.csr_matrix(run.a), run.b
    z = _compress(z, run)
    keep, rest_cones, fold_rows, fold_z = [], [], [], []
    start = 0
    for kind, n in run.layout:
        rows = np.arange(start, start + n)
        start += n
        if kind in DUAL_CONES:
            zb = DUAL_CONES[kind](z[rows])
            fold_rows.append(rows)
            fold_z.append(zb)
        else:
            keep.append(rows)
            rest_cones.append((kind, n))
    shift, fold_err = 0.0, 0.0
    qf = q.copy()
    if fold_rows:
        rows = np.concatenate(fold_rows)
        zf = np.concatenate(fold_z)
        ap = a[rows]
        qf = q + ap.T @ zf
        shift = -float(b[rows] @ zf)
        box = np.maximum(np.abs(lo), np.abs(hi))
        k = rows.size + q.size + 4
        term = abs(ap).T @ np.abs(zf)
        fold_err = 2.0 * certificate.gamma(k) * (
            float(np.abs(b[rows]) @ np.abs(zf))
            + float(np.where(term > 0.0, box, 0.0) @ term))
    rows = np.concatenate(keep)
    bound = certificate.safe_lower_bound(qf, a[rows], b[rows], rest_cones, z[rows], lo, hi)
    value = bound.value + shift - fold_err
    return value, bound, fold_err


def _dual_psd(zb):
    """Return the svec of a PSD matrix nearest the svec ``zb`` (raised by its rounding)."""
    m = np.zeros((4, 4))
    for v, (i, j) in zip(zb, SVEC):
        m[i, j] = m[j, i] = v if i == j else v / math.sqrt(2.0)
    vals, vecs = np.linalg.eigh(m)
    vals = np.clip(vals, 0.0, None)
    m = (vecs * vals) @ vecs.T
    m += (64.0 * np.finfo(float).eps * max(float(vals.max(initial=0.0)), 1e-300)) * np.eye(4)
    while np.linalg.eigvalsh(m)[0] < 0.0:     # pragma: no cover - the shift above suffices
        m += np.finfo(float).eps * np.abs(m).max() * 16.0 * np.eye(4)
    return np.array([m[i, j] if i == j else m[i, j] * math.sqrt(2.0) for i, j in SVEC])


def _dual_pow(zb, alpha):
    """Return a point of the dual power cone near ``zb`` (u, v raised until it is inside)."""
    u, v, w = (float(x) for x in zb)
    tiny = 1e-300
    u, v = max(u, tiny), max(v, tiny)
    value = (u / alpha) ** alpha * (v / (1.0 - alpha)) ** (1.0 - alpha)
    if value < abs(w):
        grow = abs(w) / value * (1.0 + 1e-12)
        u, v = u * grow, v * grow
    return np.array([u, v, w])


DUAL_CONES = {'psd': lambda z: _dual_psd(z), 'pow': lambda z: _dual_pow(z, POWER_ALPHA)}
"""The cones the certificate module does not know, and how a dual point is moved into K*."""


# ============================================================================ results


@dataclass
class SpatialResult:
    """A spatial design, its certificate and its before/after table (the planar shape)."""

    scene: object
    balanced_scene: object
    method: str
    weights: tuple
    samples: int
    units: Units
    objective: dict
    certificate: object     # socp.Certificate
    table: list
    bodies: list
    options: dict
    solve_time_s: float
    theta: np.ndarray = None

    def summary(self):
        """Return the provenance stored with the balanced scene (``balance`` key)."""
        return schema.plain({
            'source_scene': self.scene.name, 'method': self.method,
            'weights': list(self.weights), 'objective': self.objective,
            'lower_bound': self.certificate.lower_bound,
            'relative_gap': self.certificate.gap_rel,
            'certified': self.certificate.certified})

    def to_dict(self):
        """Return everything as a plain, JSON-able dict (SI and normalized)."""
        u = self.units
        return schema.plain({
            'scene': self.scene.name, 'method': self.method, 'samples': self.samples,
            'weights': list(self.weights),
            'units': {'mass_kg': u.mass_kg, 'length_m': u.length_m,
                      'omega_rad_s': u.omega_rad_s, 'normalized_from': u.source},
            'bodies': self.bodies, 'objective': self.objective, 'options': self.options,
            'certificate': self.certificate.to_dict(), 'table': self.table,
            'solve_time_s': self.solve_time_s})


def _finish(rig, model, units, maps, prog, run, theta, balanced, w, samples, violation, pull,
            t_start, method, options):
    """Evaluate the written design with the core, certify it, and return the result."""
    rig2 = rig.with_scene(balanced) if hasattr(rig, 'with_scene') else rig_for(balanced)
    data = rig2.at(maps.angles)
    f = float(rms(data.force_N)) / units.force_N
    n = float(rms(data.moment_Nm)) / units.moment_Nm
    primal = w[0] * f + w[1] * n
    model_value = w[0] * np.linalg.norm(maps.force @ theta) / units.force_N + \
        w[1] * np.linalg.norm(maps.moment @ theta) / units.moment_Nm
    lo, hi = prog.box(primal)
    lower, bound, fold_err = _fold_cones(run, lo, hi)
    lower = min(lower, primal)
    gap, gap_rel = certificate.relative_gap(primal, lower, socp.GAP_FLOOR)
    cert = socp.Certificate(
        solver=f'clarabel {clarabel.__version__}', status=run.status, primal=primal,
        dual=lower, gap_abs=gap, gap_rel=gap_rel, residual_primal=float(run.sol.r_prim),
        residual_dual=float(run.sol.r_dual), iterations=int(run.sol.iterations),
        max_violation=float(violation), lower_bound=lower, attempts=list(run.attempts),
        bound_detail={'dual_objective': bound.dual_objective,
                      'residual_term': bound.residual_term,
                      'rounding': bound.rounding + fold_err,
                      'dual_residual': bound.dual_residual,
                      'projection_shift': bound.projection_shift,
                      'solver_objective': float(run.sol.obj_val),
                      'model_primal': float(model_value)},
        feasibility_pull=float(pull), failed_stages=[],
        certified=bool(math.isfinite(lower) and gap_rel <= socp.CERTIFIED_GAP_REL))
    base = rig.at(maps.angles)
    f0 = float(rms(base.force_N)) / units.force_N
    n0 = float(rms(base.moment_Nm)) / units.moment_Nm
    objective = {'z': primal, 'shaking_force_rms': f, 'shaking_moment_rms': n,
                 'z_original': w[0] * f0 + w[1] * n0}
    return SpatialResult(
        scene=rig.scene, balanced_scene=balanced, method=method, weights=tuple(w),
        samples=samples, units=units, objective=objective, certificate=cert,
        table=before_after(rig, balanced, samples, units, (base, data)),
        bodies=_bodies(model, theta), options=options,
        solve_time_s=time.perf_counter() - t_start, theta=theta)


def _bodies(model, theta):
    out = []
    for k, body in enumerate(model.bodies):
        t = theta[10 * k:10 * k + 10]
        m = float(t[0])
        c = t[1:4] / m if m > 0.0 else np.zeros(3)
        i_o = regressor.inertia_matrix(t[4:10])
        i_c = i_o - m * (np.dot(c, c) * np.eye(3) - np.outer(c, c))
        out.append({'name': body.name, 'mass_kg': m, 'mass_centre_m': c.tolist(),
                    'inertia_centre_kg_m2': i_c.tolist(),
                    'pseudo_inertia_min_eigenvalue':
                        float(np.linalg.eigvalsh(regressor.pseudo_inertia(t))[0])})
    return out


def before_after(rig, balanced, samples, units, data=None):
    """
    Return the before/after rows of RMS shaking force, moment and driving effort.

    The driving effort is the rig's :attr:`~mech_balance.core.rig.Rig.driving_series` under
    its label of :data:`~mech_balance.schema.scene.SERIES` (a driving torque, N m, or a
    prismatic input's driving force, N).

    The planar rows' shape (:func:`mech_balance.balancing.socp.before_after`): quantity,
    unit/before/after normalized (SI when the scene records no normalization), change_percent,
    unit_si, before_si, after_si.
    """
    if data is None:
        psi = cycle_of(rig, samples)
        rig2 = rig.with_scene(balanced)
        data = (rig.at(psi), rig2.at(psi))
    normalized = units.source == 'scene'
    rows = []
    # the driving effort under the rig's own series: a torque, or a prismatic input's force
    effort = rig.driving_series
    label, dim = SERIES[effort]
    for name, get, force in (
            ('shaking force', lambda d: d.force_N, True),
            ('shaking moment', lambda d: d.moment_Nm, False),
            (label, lambda d: d.series.get(effort), dim == 'force')):
        values = [get(d) for d in data]
        if any(v is None for v in values):
            continue
        before_si, after_si = (float(rms(v)) for v in values)
        unit_si = 'N' if force else 'N m'
        scale = (units.force_N if force else units.moment_Nm) if normalized else 1.0
        rows.append({'quantity': name,
                     'unit': ('m l omega^2' if force else 'm l^2 omega^2')
                     if normalized else unit_si,
                     'before': before_si / scale, 'after': after_si / scale,
                     'change_percent': (after_si - before_si) / before_si * 100.0
                     if before_si > 0.0 else None,
                     'unit_si': unit_si, 'before_si': before_si, 'after_si': after_si})
    return rows


class _RealizableChecks:
    """The constraints of a redistribution at a design, and the repair of round-off."""

    def __init__(self, model, free_idx, mlo, mhi, extent):
        self.model, self.free, self.mlo, self.mhi, self.extent = \
            model, free_idx, mlo, mhi, extent

    def _body(self, theta, k):
        t = theta[10 * k:10 * k + 10]
        m0, r0 = _program_units(self.model, k, self.mlo[k], self.mhi[k], self.extent[k])
        d = np.array([1.0 / (math.sqrt(m0) * r0)] * 3 + [1.0 / math.sqrt(m0)])
        j = regressor.pseudo_inertia(t) * np.outer(d, d)
        eig = np.linalg.eigvalsh(j)
        return [(self.mlo[k] - t[0]) / m0, (t[0] - self.mhi[k]) / m0,
                -float(eig[0]) - PSD_ROUNDOFF * float(np.abs(eig).max()),
                (0.5 * (t[4] + t[6] + t[9]) - t[0] * self.extent[k] ** 2) / (m0 * r0 * r0)]

    def violation(self, theta):
        """Return the worst constraint violation, >= 0 (units of each body's mass and reach)."""
        return float(max([0.0] + [max(self._body(theta, k)) for k in self.free]))

    def anchor(self, near=None):
        """
        Return a design strictly inside every bound.

        Without ``near``: each body's mass mid-range, first moment 0, spread m r^2 / 6.
        With it (the design being repaired), each body keeps its mass clipped into its bounds
        and (a full body) its first moment h, shrunk to |h| <= m r / 2, with the spread
        ``Sigma = h h^T / m + c 1``, ``c = (m r^2 - |h|^2 / m) / 6``: J is then positive
        definite and tr Sigma < m r^2.  The shaking force depends on m and h only, so a pull
        towards this anchor leaves it as the solver made it (a complete force balance of 1e3
        x heavier bodies stays one), and moves the rest by the fraction pulled of its size.
        """
        theta = self.model.theta.copy()
        for k in self.free:
            body = self.model.bodies[k]
            m = 0.5 * (self.mlo[k] + self.mhi[k]) if near is None else \
                min(max(float(near[10 * k]), self.mlo[k]), self.mhi[k])
            r2 = self.extent[k] ** 2
            if body.basis.shape[1] == 10:
                h = np.zeros(3) if near is None else np.array(near[10 * k + 1:10 * k + 4])
                size = float(np.linalg.norm(h))
                if size > 0.5 * m * math.sqrt(r2):
                    h = h * (0.5 * m * math.sqrt(r2) / size)
                sigma = np.outer(h, h) / m + (m * r2 - float(h @ h) / m) / 6.0 * np.eye(3)
                i_o = np.trace(sigma) * np.eye(3) - sigma
                target = np.array([m, *h, i_o[0, 0], i_o[0, 1], i_o[1, 1], i_o[0, 2],
                                   i_o[1, 2], i_o[2, 2]])
                theta[10 * k:10 * k + 10] = target
            else:   # a body on a line (m, its first and second moment along it)
                theta[10 * k:10 * k + 10] = body.basis @ self._line_anchor(body, m, r2, near, k)
        return theta

    @staticmethod
    def _line_anchor(body, m, r2, near, k):
        """
        Return y = (m, mu1, mu2) of a body on a line strictly inside its bounds.

        J is PSD exactly when [[m, mu1], [mu1, mu2]] is: mu2 = mu1^2 / m + c with c > 0 half
        the room the extent bound leaves (tr Sigma is linear in y); mu1 is the design's
        (``near``), halved until there is room (0: the anchor without a design).
        """
        def spread(y):
            t = body.basis @ y
            return 0.5 * (t[4] + t[6] + t[9])
        mu1 = 0.0 if near is None else float(_coordinates(body, near[10 * k:10 * k + 10])[1])
        for _ in range(60):
            y = np.array([m, mu1, mu1 * mu1 / m])
            unit = spread(np.array([0.0, 0.0, 1.0]))
            room = m * r2 - spread(y)
            if room > 0.0 and unit > 0.0:
                y[2] += 0.5 * room / unit
                return y
            mu1 = 0.0 if abs(mu1) < 1e-300 else 0.5 * mu1
        return np.array([m, 0.0, 0.0])

    def feasible(self, theta):
        """Return True if theta meets every constraint to :data:`VIOLATION_TOL`."""
        return self.violation(theta) <= VIOLATION_TOL

    def clip_masses(self, theta):
        """
        Return theta with each free body's mass clipped into its bounds.

        A full body: the mass alone (its first moment, which the shaking force sees with it,
        stays; J and the extent are the pull's to restore).  A body on a line: scaled (its
        mass column carries first and second moments too; keeps J PSD and the extent).
        """
        theta = theta.copy()
        for k in self.free:
            m = theta[10 * k]
            target = min(max(m, self.mlo[k]), self.mhi[k])
            if m > 0.0 and target != m:
                if self.model.bodies[k].basis.shape[1] == 10:
                    theta[10 * k] = target
                else:
                    theta[10 * k:10 * k + 10] *= target / m
        return theta

    def repair(self, theta, keep_force=False, objective=None):
        """
        Return (theta, pull): theta moved onto the feasible set where round-off left it.

        First each body's mass clipped into its bounds, then the least spread along the
        inertia (which the force map does not see) that makes each J PSD; ``pull`` is then
        that spread (units of the body's M R^2, :func:`_program_units`).  Where that breaks
        the extent bound (without equality constraints): the least fraction ``pull`` of the
        way to the :meth:`anchor` (a convex set holds the segment; bisection).  A solver
        point 1e-9 outside a PSD cone of a body 1e3 x heavier than the original is thus moved
        by 1e-9 of its own inertia, not towards an anchor whose inertia is m r^2.
        """
        if self.feasible(theta):
            return theta, 0.0
        if not keep_force:
            theta = self.clip_masses(theta)
            if self.feasible(theta):
                return theta, 0.0
        spread, worst = self._spread(theta)
        if keep_force:
            return spread, worst
        found = [(spread, worst)] if self.feasible(spread) else []
        anchor = self.anchor(theta)
        if not self.feasible(anchor):
            anchor = self.anchor()
        if self.feasible(anchor):
            lo, hi = 0.0, 1.0
            for _ in range(REPAIR_STEPS):
                mid = 0.5 * (lo + hi)
                if self.feasible((1 - mid) * theta + mid * anchor):
                    hi = mid
                else:
                    lo = mid
            found.append(((1 - hi) * theta + hi * anchor, hi))
        if not found:
            return spread, worst
        if objective is None:
            return found[0]
        return min(found, key=lambda pair: objective(pair[0]))   # both feasible: the better

    def _spread(self, theta):
        """Return (theta, step): each body's least isotropic spread that makes J PSD."""
        theta = theta.copy()
        worst = 0.0
        for k in self.free:
            if self._body(theta, k)[2] <= VIOLATION_TOL:
                continue
            body = self.model.bodies[k]
            m0, r0 = _program_units(self.model, k, self.mlo[k], self.mhi[k], self.extent[k])
            spread = body.basis @ _coordinates(body, np.array([0, 0, 0, 0, 2, 0, 2, 0, 0, 2.0]))
            step = max(self._body(theta, k)[2], np.finfo(float).eps) * m0 * r0 * r0
            for _ in range(REPAIR_STEPS):
                trial = theta.copy()
                trial[10 * k:10 * k + 10] += step * spread
                if self._body(trial, k)[2] <= VIOLATION_TOL:
                    theta = trial
                    worst = max(worst, step / (m0 * r0 * r0))
                    break
                step *= REPAIR_GROWTH
        return theta, worst


# ============================================================================ helpers


def _ref(model, k):
    """Return (m0, r0): body k's original mass and its reach (the units of its variables)."""
    m0 = float(model.theta[10 * k])
    return (m0 if m0 > 0.0 else 1.0), model.bodies[k].reach_m


def _scales(units, n):
    one = np.array([units.mass_kg] + [units.mass_kg * units.length_m] * 3
                   + [units.mass_kg * units.length_m ** 2] * 6)
    return np.tile(one, n // 10)


def _body_scales(model, free_idx, units):
    out = []
    for k in sorted(free_idx):
        m0, r0 = _ref(model, k)
        out += [m0 * r0 ** o for o in model.bodies[k].orders]
    return np.array(out)


def _free(model, free, option):
    if free is None:
        return set(range(len(model.bodies)))
    if isinstance(free, str):
        free = [part for part in free.split(',') if part]
    out = {model.index(n, option) for n in free}
    if not out:
        raise SpatialBalanceError(f'{option}: got none, expected at least one body')
    return out


def _samples(samples, rig=None):
    if samples is None:
        return int(getattr(getattr(rig, 'scene', None), 'samples', None) or DEFAULT_SAMPLES)
    if isinstance(samples, bool) or int(samples) != samples or samples < 4:
        raise SpatialBalanceError(f'samples: got {samples!r}, expected an integer >= 4')
    return int(samples)


def _weights(weights):
    try:
        w1, w2 = (float(x) for x in weights)
    except (TypeError, ValueError):
        raise SpatialBalanceError(f'weights: got {weights!r}, expected two numbers (w1, w2)')
    for x in (w1, w2):
        if not (math.isfinite(x) and 0.0 <= x <= MAX_WEIGHT):
            raise SpatialBalanceError(f'weights: got {weights!r}, expected numbers in [0, '
                                      f'{MAX_WEIGHT:g}]')
    if w1 + w2 == 0.0:
        raise SpatialBalanceError('weights: got all zero, expected at least one positive')
    return w1, w2


def _checked(name, value, lowest, highest, unit=''):
    """Return :func:`defaults.check_range` of a value, its ValueError a SpatialBalanceError."""
    try:
        return check_range(name, value, lowest, highest, unit)
    except ValueError as err:
        raise SpatialBalanceError(str(err)) from None


def _mass_bounds(model, free_idx, given, factors):
    lo_f, hi_f = (float(x) for x in factors)
    if not (0.0 < lo_f <= hi_f and math.isfinite(hi_f)):
        raise SpatialBalanceError(f'mass_factors: got {factors!r}, expected 0 < lo <= hi, '
                                  'finite')
    for value in (lo_f, hi_f):
        _checked('mass_factors', value, *SPATIAL_MASS_FACTOR_RANGE)
    given = dict(given or {})
    mlo, mhi = {}, {}
    for k in free_idx:
        name = model.bodies[k].name
        m0 = float(model.theta[10 * k])
        if m0 <= 0.0:
            raise SpatialBalanceError(
                f'links.{name}.mass_kg: got {m0:g}, a massless link, which the redistribution '
                'cannot scale (its mass bounds are mass_factors x the original mass), expected '
                f'a mass > 0 kg for it or the link fixed (--fix {name}, or '
                f'balance.fixed_links: [{name}])')
        lo, hi = given.pop(name, (lo_f * m0, hi_f * m0))
        lo, hi = float(lo), float(hi)
        if not (0.0 < lo <= hi and math.isfinite(hi)):
            raise SpatialBalanceError(f'mass_bounds.{name}: got ({lo:g}, {hi:g}), expected '
                                      '0 < lo <= hi, finite (kg)')
        low, high = SPATIAL_MASS_FACTOR_RANGE
        for value in (lo, hi):
            if not low * m0 * (1 - 1e-12) <= value <= high * m0 * (1 + 1e-12):
                raise SpatialBalanceError(
                    f'mass_bounds.{name}: got {value:g} kg, expected a mass in [{low:g}, '
                    f'{high:g}] x its original {m0:g} kg (defaults.SPATIAL_MASS_FACTOR_RANGE:'
                    ' the range in which the program certifies)')
        mlo[k], mhi[k] = lo, hi
    if given:
        raise SpatialBalanceError(f'mass_bounds: got {sorted(given)[0]!r}, expected a free '
                                  'body')
    return mlo, mhi


def _extent_bounds(model, free_idx, given, factor):
    factor = _checked('extent_factor', factor, *EXTENT_FACTOR_RANGE)
    given = dict(given or {})
    out = {}
    low, high = EXTENT_FACTOR_RANGE
    for k in free_idx:
        name = model.bodies[k].name
        reach = model.bodies[k].reach_m
        r = float(given.pop(name, factor * reach))
        if not (math.isfinite(r) and r > 0.0):
            raise SpatialBalanceError(f'extent_bounds.{name}: got {r!r}, expected a finite '
                                      'radius > 0 (m)')
        if not low * reach * (1 - 1e-12) <= r <= high * reach * (1 + 1e-12):
            raise SpatialBalanceError(
                f'extent_bounds.{name}: got {r:g} m, expected a radius in [{low:g}, {high:g}] '
                f'x its reach {reach:g} m (defaults.EXTENT_FACTOR_RANGE: the range in which '
                'the program certifies)')
        out[k] = r
    if given:
        raise SpatialBalanceError(f'extent_bounds: got {sorted(given)[0]!r}, expected a free '
                                  'body')
    return out


def _check_run(run, rig, units):
    if run.status in socp.INFEASIBLE:
        raise SpatialBalanceError(
            f'constraints: the balancing problem is infeasible (solver status {run.status}); '
            'widen mass_bounds / extent_bounds')
    if not run.ok:
        raise SpatialBalanceError(f'solver: {run.why()}{_scale_blame(rig, units)}')


def _scale_blame(rig, units):
    """Return the scene values that make a failed program ill-scaled ('' when none is)."""
    if units.source != 'scene':
        return ''   # the units are the crank speed's own
    speed = abs(float(rig.at([0.0], outputs=('kinematics',)).crank_speed_rad_s[0]))
    return socp.speed_blame(speed, units.omega_rad_s)


def write_scene(result, path):
    """
    Write the balanced scene to ``path`` (through :mod:`mech_balance.atomic`) and reload it.

    The provenance goes under the scene's ``balance`` key when its kind's loader accepts one,
    else into a comment header.  Returns the reloaded scene.
    """
    from mech_balance import atomic
    import yaml
    provenance = result.summary()
    text = schema.to_yaml(result.balanced_scene, provenance)
    try:
        schema.from_dict(yaml.safe_load(text), source=str(path))
    except ValueError:
        comment = yaml.safe_dump(provenance, sort_keys=False, width=95)
        text = ''.join(f'# {line}\n' for line in comment.splitlines()) + \
            schema.to_yaml(result.balanced_scene)
        # the design itself must load (a force balance may ask for a negative mass): checked
        # before anything is written, so a refused design leaves no file behind
        schema.from_dict(yaml.safe_load(text), source=str(path))
    atomic.write_text_atomic(path, f'# written by mech-balance balance from scene '
                                   f'{result.scene.name}\n' + text)
    return schema.load(str(path))


__all__ = ['counterweights', 'force_balance', 'ForceBalance', 'format_conditions',
           'parameter_model', 'PARAMETER_MODELS', 'redistribute', 'SpatialBalanceError',
           'SpatialResult', 'write_scene']
