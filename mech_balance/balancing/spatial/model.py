"""The spatial parameter models (:data:`PARAMETER_MODELS`), objective units and RMS maps."""

from dataclasses import dataclass
import math

from mech_balance.balancing.checks import BalanceError
from mech_balance.balancing.defaults import check_range
from mech_balance.conventions import cycle_angles, DEFAULT_SAMPLES, MAX_WEIGHT
from mech_balance.core import regressor
from mech_balance.schema import registry
import numpy as np

CAPABILITY = 'body_kinematics'
"""The rig capability every method of this module needs."""
INERTIA_CLIP_RTOL = 1e-12
"""A designed principal moment of inertia in [-this x m reach^2, 0) is written as 0."""
PSD_ROUNDOFF = 64.0 * np.finfo(float).eps
"""A body's normalized pseudo-inertia counts as PSD down to this fraction of its largest
eigenvalue below zero (the eigenvalue solver's round-off; a thin rod has exact zeros)."""
RANK_REL_TOL = 1e-9
"""Singular values of the force map below this fraction of the largest span its null space."""


class SpatialBalanceError(BalanceError):
    """A spatial balancing problem is ill-posed, infeasible or cannot be solved."""


@dataclass(frozen=True)
class BodyModel:
    """What a kind's scene can hold of one body: ``theta = basis @ y`` (``basis`` (10, d))."""

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


def line_basis(point_a, point_b):
    """Return the (10, 3) basis of mass on the line from ``point_a`` (moments mu0, mu1, mu2)."""
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
    """Return the :class:`ParameterModel` of a ``kind: spatial`` rig (S-S links: line_basis)."""
    from mech_balance.schema.spatial import SpatialLink
    sc = rig.scene
    idle = {name: (ja, jb) for name, ja, jb in getattr(rig.linkage, 'idle_spins', ())}
    joints = {j.name: j for j in sc.joints}
    names = [b.name for b in rig.drawing.bodies]
    reaches = {name: max([float(np.linalg.norm(p)) for p in sc.link(name).points.values()]
                         + [0.0]) for name in names}
    # a link whose points all sit at its origin (a slider carriage): the least span of others
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
            bodies.append(BodyModel(name, np.eye(10), (0, 1, 1, 1, 2, 2, 2, 2, 2, 2), reach))

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
            i_c = clip_roundoff(i_c, abs(m) * bodies[k].reach_m ** 2)
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


def clip_roundoff(inertia, scale):
    """Return an inertia (3, 3) with principal moments in [-INERTIA_CLIP_RTOL scale, 0) set 0."""
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
    """The RMS shaking force and moment as compressed maps: ``RMS(force) = ||force @ theta||``."""

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


def design_columns(model, free):
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


def coordinates(body, theta_k):
    """Return y with basis @ y = theta_k (least squares; exact for a theta of the basis)."""
    return np.linalg.lstsq(body.basis, theta_k, rcond=None)[0]


def program_units(model, k, m_lo, m_hi, radius):
    """Return (M, R): body k's units (:func:`reference_units`) moved into its bounds."""
    m0, r0 = reference_units(model, k)
    return (float(min(max(m0, m_lo), m_hi)),
            float(min(r0, radius + model.bodies[k].line_offset_m)))


def reference_units(model, k):
    """Return (m0, r0): body k's original mass and its reach (the units of its variables)."""
    m0 = float(model.theta[10 * k])
    return (m0 if m0 > 0.0 else 1.0), model.bodies[k].reach_m


def body_scales(model, free_idx, units):
    """Return the scale of each design column of the free bodies (their m0 r0^order)."""
    out = []
    for k in sorted(free_idx):
        m0, r0 = reference_units(model, k)
        out += [m0 * r0 ** o for o in model.bodies[k].orders]
    return np.array(out)


def free_bodies(model, free, option):
    """Return the set of body indices named by ``free`` (None: every body)."""
    if free is None:
        return set(range(len(model.bodies)))
    if isinstance(free, str):
        free = [part for part in free.split(',') if part]
    out = {model.index(n, option) for n in free}
    if not out:
        raise SpatialBalanceError(f'{option}: got none, expected at least one body')
    return out


def check_samples(samples, rig=None):
    """Return the number of crank angles (the scene's without ``samples``), at least 4."""
    if samples is None:
        return int(getattr(getattr(rig, 'scene', None), 'samples', None) or DEFAULT_SAMPLES)
    if isinstance(samples, bool) or int(samples) != samples or samples < 4:
        raise SpatialBalanceError(f'samples: got {samples!r}, expected an integer >= 4')
    return int(samples)


def check_weights(weights):
    """Return (w1, w2): two numbers in [0, MAX_WEIGHT], not both zero."""
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


def checked_range(name, value, lowest, highest, unit=''):
    """Return :func:`defaults.check_range` of a value, its ValueError a SpatialBalanceError."""
    try:
        return check_range(name, value, lowest, highest, unit)
    except ValueError as err:
        raise SpatialBalanceError(str(err)) from None


__all__ = ['BodyModel', 'CAPABILITY', 'line_basis', 'Maps', 'maps_of', 'parameter_model',
           'PARAMETER_MODELS', 'ParameterModel', 'spatial_model', 'SpatialBalanceError', 'Units',
           'units_of']
