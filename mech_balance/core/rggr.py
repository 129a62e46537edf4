"""
RGGR spatial four-bar (seed 002, Hedaya): scene, kinematics, dynamics and balancing.

Geometry (seed 002, section 'Mechanism description and coordinate systems', eqs. 15-21)
    Oxyz is fixed to the frame.  The output axis DO passes through O, lies in the xz-plane
    and makes the angle beta with z; its unit vector is w3 = (sin beta, 0, cos beta).  The
    input (crank) axis AE is parallel to z through E = (0, l2, 0), so OE (along y) is the
    common normal of the two axes.  Q1 = (0, l2, l1) and Q3 = l3 * w3 are the feet of the
    perpendiculars from the crank pin B and the output pin C on their axes.  The crank angle
    phi1 is the angle of Q1B from x about z; the output angle phi3 that of Q3C from x' about
    w3, where Ox'y'z' is Oxyz turned by beta about y (eq. 19).  Then
    B = Q1 + a1 (cos phi1, sin phi1, 0) and C = Q3 + a3 (cos beta cos phi3, sin phi3,
    -sin beta cos phi3) (eqs. 16, 20).  The coupler BC is a thin rod of length a2 with
    spherical joints at both ends; c2 = |BG2|.

Link frames
    Q1uvw is fixed to the crank (w along z, u along Q1B) and Q3uvw to the output link (w along
    w3, u along Q3C).  A link's centre of mass (u, v, w) and its inertia parameters are given
    in its frame and about its pivot point Q1 or Q3: the moment of inertia I_ww about the axis
    of rotation and the paper's products I_wu = integral(w u dm), I_vw = integral(v w dm)
    (positive integrals; the inertia matrix carries -I_wu and -I_vw off the diagonal, eq. 53).
    For a rotation about a fixed axis these three are the only inertia parameters that enter
    the dynamics; I_uu, I_vv and I_uv do not.  The coupler's only inertia parameter is its
    transverse moment of inertia I = I_v = I_w about G2 (eq. 60).

Assembly branch (``assembly.branch``)
    Eq. 23 has two solutions phi3 = delta +/- acos(-D1 / sqrt(D2^2 + D3^2)) with
    delta = atan2(D3, D2).  ``branch = +1`` takes the + sign, ``-1`` the - sign.
    Geometrically, ``branch`` is the sign of the triple product w3 . (BC x Q3C): on branch +1
    the turn from the coupler direction B->C to the output-link direction Q3->C is
    counter-clockwise about the output axis w3.  The two branches meet only at dead-centre
    positions of the output link (the coupler BC lies in the plane containing the output axis
    and Q3C), where :func:`kinematics` raises instead of switching branch.

The shaking wrench follows ``mech_balance.conventions``: f = -dp/dt, n = -dH_O/dt about O in
the world axes, including the motor's reaction torque.  Gravity is not included (seed 002 and
the conventions consider inertia effects only).
"""

import dataclasses
import math
import time

from mech_balance.conventions import cycle_angles
from mech_balance.conventions import DEFAULT_SAMPLES
from mech_balance.conventions import normalize_force
from mech_balance.conventions import normalize_moment
from mech_balance.conventions import rms
import numpy as np

KIND = 'rggr'
"""Value of the top-level ``kind`` field of an RGGR scene."""

SCHEMA_VERSION = 1
"""Accepted value of the optional top-level ``schema_version`` (as for planar scenes)."""

BRANCH_SEPARATION_MIN = 1e-6
"""
Smallest sine of half the angle between the two solutions of eq. 23 that is accepted.

Below it the output link is at (or numerically indistinguishable from) a dead centre: the
branches meet, the output rates are unbounded and the branch is undefined.
"""

DEGENERATE_LOOP_TOL = 1e-12
"""sqrt(D2^2 + D3^2) relative to 2 a3 (|l1| + |l2| + a1) below which eq. 23 has no phi3 term."""

COUPLER_FRAME_MIN = 1e-9
"""h / a2 (eq. 43) below which the coupler frame of eqs. 42 and 44 is undefined."""

FULL_ROTATION_SAMPLES = 3600
"""Crank angles (one per 0.1 deg) at which the report functions check full-cycle mobility."""

PARALLEL_AXIS_RTOL = 1e-9
"""Relative slack of the check I_ww >= m (u^2 + v^2) (parallel-axis theorem)."""

_DEG = math.pi / 180.0


# ---------------------------------------------------------------------------------------------
# Scene
# ---------------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class RggrGeometry:
    """
    Link dimensions of the RGGR mechanism (seed 002, eqs. 15-21), in m and rad.

    ``l1_m`` = EQ1, ``l2_m`` = y-coordinate of E, ``l3_m`` = OQ3, ``beta_rad`` = angle from z
    to the output axis, ``a1_m`` = Q1B, ``a2_m`` = BC, ``a3_m`` = Q3C.
    """

    l1_m: float
    l2_m: float
    l3_m: float
    beta_rad: float
    a1_m: float
    a2_m: float
    a3_m: float


@dataclasses.dataclass(frozen=True)
class PivotBody:
    """
    A body turning about a fixed axis: a link, a balancing weight or both together.

    ``centre_uvw_m`` is the centre of mass in the link frame relative to the pivot point (Q1 or
    Q3); the inertia parameters are about the pivot point in the link frame (module docstring).
    """

    mass_kg: float
    centre_uvw_m: tuple
    inertia_ww_kg_m2: float
    product_wu_kg_m2: float
    product_vw_kg_m2: float

    def first_moment_kg_m(self):
        """Return m * (u, v, w) of the body, shape (3,)."""
        return self.mass_kg * np.asarray(self.centre_uvw_m, dtype=float)


@dataclasses.dataclass(frozen=True)
class Coupler:
    """Thin-rod coupler BC: mass, distance c2 = |BG2| and transverse inertia I about G2."""

    mass_kg: float
    centre_from_b_m: float
    transverse_inertia_kg_m2: float


@dataclasses.dataclass(frozen=True)
class BalancingDesign:
    """
    Inputs of the complete force balancing (seed 002, eqs. 6-14).

    ``crank_weight_mass_kg`` is m_b1 (chosen freely, eqs. 6-8); ``output_weight_density_length``
    is rho * L of the cylindrical output weight in kg/m^2 (eq. 13).
    """

    crank_weight_mass_kg: float
    output_weight_density_length_kg_m2: float


@dataclasses.dataclass(frozen=True)
class RggrScene:
    """
    A validated RGGR scene, all values SI (see :func:`load_rggr_scene` for the schema).

    ``crank`` and ``output`` are the links without balancing weights (mass m_o1, m_o3);
    ``crank_weight`` and ``output_weight`` are the fitted balancing weights or None.
    ``normalization`` holds m_o1, a1 and omega for the paper's dimensionless view.
    """

    name: str
    description: str
    source: str
    geometry: RggrGeometry
    crank: PivotBody
    coupler: Coupler
    output: PivotBody
    crank_weight: object
    output_weight: object
    design: object
    branch: int
    crank_speed_rad_s: float
    normalization: dict
    kind: str = KIND

    def crank_total(self):
        """Return the crank with its balancing weight (link 1 of eqs. 53-56)."""
        return combine_bodies(self.crank, self.crank_weight)

    def output_total(self):
        """Return the output link with its balancing weight (link 3 of eqs. 57-59)."""
        return combine_bodies(self.output, self.output_weight)

    def inertia_parameters_kg_m2(self):
        """Return J1..J4 = (I_1wu, I_1vw, I_3wu, I_3vw) of the links with weights, shape (4,)."""
        c, o = self.crank_total(), self.output_total()
        return np.array([c.product_wu_kg_m2, c.product_vw_kg_m2,
                         o.product_wu_kg_m2, o.product_vw_kg_m2])


def combine_bodies(body, weight):
    """
    Return ``body`` and ``weight`` (or None) as one body about the same pivot.

    Masses, first moments and the inertia parameters about the common pivot add.
    """
    if weight is None:
        return body
    mass = body.mass_kg + weight.mass_kg
    first = body.first_moment_kg_m() + weight.first_moment_kg_m()
    centre = first / mass if mass > 0.0 else np.zeros(3)
    return PivotBody(
        mass_kg=mass,
        centre_uvw_m=tuple(float(x) for x in centre),
        inertia_ww_kg_m2=body.inertia_ww_kg_m2 + weight.inertia_ww_kg_m2,
        product_wu_kg_m2=body.product_wu_kg_m2 + weight.product_wu_kg_m2,
        product_vw_kg_m2=body.product_vw_kg_m2 + weight.product_vw_kg_m2)


def _fail(path, value, expected):
    raise ValueError(f'{path}: got {value!r}, expected {expected}')


def _mapping(data, path, required, optional=()):
    if not isinstance(data, dict):
        _fail(path, data, 'a mapping')
    unknown = sorted(str(key) for key in set(data) - set(required) - set(optional))
    if unknown:
        allowed = ', '.join(list(required) + list(optional))
        where = f'{path}.{unknown[0]}' if path else unknown[0]
        raise ValueError(f'{where}: unknown field, expected one of: {allowed}')
    for key in required:
        if key not in data:
            raise ValueError(f'{path}.{key}: missing, expected it in {path or "the scene"}'
                             if path else f'{key}: missing, expected it at the top level')
    return data


def _number(value, path, minimum=None, strict=False, nonzero=False):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        _fail(path, value, 'a number')
    x = float(value)
    if not math.isfinite(x):
        _fail(path, value, 'a finite number')
    if minimum is not None:
        if strict and not x > minimum:
            _fail(path, value, f'a number > {minimum:g}')
        if not strict and not x >= minimum:
            _fail(path, value, f'a number >= {minimum:g}')
    if nonzero and x == 0.0:
        _fail(path, value, 'a nonzero number')
    return x


def _vector3(value, path):
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        _fail(path, value, 'a list of 3 numbers [u, v, w] in m')
    return tuple(_number(x, f'{path}[{i}]') for i, x in enumerate(value))


def _pivot_body(data, path, mass_strict):
    _mapping(data, path, ('mass_kg', 'centre_uvw_m', 'inertia_about_pivot_kg_m2'))
    mass = _number(data['mass_kg'], f'{path}.mass_kg', 0.0, strict=mass_strict)
    centre = _vector3(data['centre_uvw_m'], f'{path}.centre_uvw_m')
    ipath = f'{path}.inertia_about_pivot_kg_m2'
    inertia = _mapping(data['inertia_about_pivot_kg_m2'], ipath, ('ww', 'wu', 'vw'))
    ww = _number(inertia['ww'], f'{ipath}.ww', 0.0)
    floor = mass * (centre[0] ** 2 + centre[1] ** 2)
    if ww < floor * (1.0 - PARALLEL_AXIS_RTOL):
        _fail(f'{ipath}.ww', inertia['ww'],
              f'>= mass * (u^2 + v^2) = {floor:.6g} kg m^2 (parallel-axis theorem)')
    return PivotBody(mass_kg=mass, centre_uvw_m=centre, inertia_ww_kg_m2=ww,
                     product_wu_kg_m2=_number(inertia['wu'], f'{ipath}.wu'),
                     product_vw_kg_m2=_number(inertia['vw'], f'{ipath}.vw'))


def load_rggr_scene(data, source='<dict>'):
    """
    Validate a parsed YAML mapping and return an :class:`RggrScene` (values in SI).

    Schema (``config/rggr.yaml`` is a commented example)::

        kind: rggr
        schema_version: 1                             # optional
        name: <str>                                   # optional
        description: <str>                            # optional, one line
        geometry: {l1_m, l2_m, l3_m, beta_deg, a1_m, a2_m, a3_m}
        links:
          crank:   {mass_kg, centre_uvw_m: [u, v, w],
                    inertia_about_pivot_kg_m2: {ww, wu, vw}}
          coupler: {mass_kg, centre_from_b_m, transverse_inertia_kg_m2}
          output:  {mass_kg, centre_uvw_m, inertia_about_pivot_kg_m2: {ww, wu, vw}}
        balancing_weights: {crank: <body>, output: <body>}   # optional, each optional
        balancing_design:                                      # optional (needed by balance)
          {crank_weight_mass_kg, output_weight_density_length_kg_m2}
        assembly: {branch: +1 | -1}
        crank: {speed_rad_s}

    Every error is a ValueError naming the field path, the bad value and what was expected.
    """
    _mapping(data, '', ('kind', 'geometry', 'links', 'assembly', 'crank'),
             ('schema_version', 'name', 'description', 'balancing_weights', 'balancing_design'))
    if data['kind'] != KIND:
        _fail('kind', data['kind'], f'{KIND!r}')
    version = data.get('schema_version', SCHEMA_VERSION)
    if isinstance(version, bool) or version != SCHEMA_VERSION:
        _fail('schema_version', version, f'{SCHEMA_VERSION}')
    name = data.get('name', 'rggr')
    if not isinstance(name, str):
        _fail('name', name, 'a string')
    description = data.get('description', '')
    if not isinstance(description, str):
        _fail('description', description, 'a string')

    geo = _mapping(data['geometry'], 'geometry',
                   ('l1_m', 'l2_m', 'l3_m', 'beta_deg', 'a1_m', 'a2_m', 'a3_m'))
    geometry = RggrGeometry(
        l1_m=_number(geo['l1_m'], 'geometry.l1_m'),
        l2_m=_number(geo['l2_m'], 'geometry.l2_m'),
        l3_m=_number(geo['l3_m'], 'geometry.l3_m'),
        beta_rad=_number(geo['beta_deg'], 'geometry.beta_deg') * _DEG,
        a1_m=_number(geo['a1_m'], 'geometry.a1_m', 0.0, strict=True),
        a2_m=_number(geo['a2_m'], 'geometry.a2_m', 0.0, strict=True),
        a3_m=_number(geo['a3_m'], 'geometry.a3_m', 0.0, strict=True))

    links = _mapping(data['links'], 'links', ('crank', 'coupler', 'output'))
    crank = _pivot_body(links['crank'], 'links.crank', mass_strict=True)
    output = _pivot_body(links['output'], 'links.output', mass_strict=False)
    cpl = _mapping(links['coupler'], 'links.coupler',
                   ('mass_kg', 'centre_from_b_m', 'transverse_inertia_kg_m2'))
    coupler = Coupler(
        mass_kg=_number(cpl['mass_kg'], 'links.coupler.mass_kg', 0.0),
        centre_from_b_m=_number(cpl['centre_from_b_m'], 'links.coupler.centre_from_b_m'),
        transverse_inertia_kg_m2=_number(cpl['transverse_inertia_kg_m2'],
                                         'links.coupler.transverse_inertia_kg_m2', 0.0))

    crank_weight = output_weight = None
    if data.get('balancing_weights') is not None:
        bw = _mapping(data['balancing_weights'], 'balancing_weights', (), ('crank', 'output'))
        if bw.get('crank') is not None:
            crank_weight = _pivot_body(bw['crank'], 'balancing_weights.crank', False)
        if bw.get('output') is not None:
            output_weight = _pivot_body(bw['output'], 'balancing_weights.output', False)

    design = None
    if data.get('balancing_design') is not None:
        bd = _mapping(data['balancing_design'], 'balancing_design',
                      ('crank_weight_mass_kg', 'output_weight_density_length_kg_m2'))
        design = BalancingDesign(
            crank_weight_mass_kg=_number(bd['crank_weight_mass_kg'],
                                         'balancing_design.crank_weight_mass_kg',
                                         0.0, strict=True),
            output_weight_density_length_kg_m2=_number(
                bd['output_weight_density_length_kg_m2'],
                'balancing_design.output_weight_density_length_kg_m2', 0.0, strict=True))

    assembly = _mapping(data['assembly'], 'assembly', ('branch',))
    branch = assembly['branch']
    if isinstance(branch, bool) or branch not in (1, -1):
        _fail('assembly.branch', branch, '+1 or -1')

    crank_cfg = _mapping(data['crank'], 'crank', ('speed_rad_s',))
    omega = _number(crank_cfg['speed_rad_s'], 'crank.speed_rad_s', nonzero=True)

    return RggrScene(
        name=name, description=description, source=str(source), geometry=geometry,
        crank=crank, coupler=coupler, output=output, crank_weight=crank_weight,
        output_weight=output_weight, design=design,
        branch=int(branch), crank_speed_rad_s=omega,
        normalization={'mass_kg': crank.mass_kg, 'length_m': geometry.a1_m,
                       'omega_rad_s': abs(omega)})


# ---------------------------------------------------------------------------------------------
# Kinematics
# ---------------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class RggrKinematics:
    """
    Closed-form kinematics over ``n`` crank angles; vectors are ``(n, 3)`` in Oxyz, SI.

    ``crank_axes`` and ``output_axes`` are ``(n, 3, 3)`` with the link frame's unit vectors
    u, v, w as columns.  ``coupler_m`` is A2 = C - B; ``loop_residual_m`` is |BC| - a2.
    """

    crank_angle_rad: np.ndarray
    crank_speed_rad_s: float
    output_angle_rad: np.ndarray
    output_rate_rad_s: np.ndarray
    output_accel_rad_s2: np.ndarray
    crank_axes: np.ndarray
    output_axes: np.ndarray
    pin_b_m: np.ndarray
    pin_b_vel_m_s: np.ndarray
    pin_b_acc_m_s2: np.ndarray
    pin_c_m: np.ndarray
    pin_c_vel_m_s: np.ndarray
    pin_c_acc_m_s2: np.ndarray
    coupler_m: np.ndarray
    coupler_vel_m_s: np.ndarray
    coupler_acc_m_s2: np.ndarray
    crank_centre_m: np.ndarray
    crank_centre_acc_m_s2: np.ndarray
    coupler_centre_m: np.ndarray
    coupler_centre_vel_m_s: np.ndarray
    coupler_centre_acc_m_s2: np.ndarray
    output_centre_m: np.ndarray
    output_centre_acc_m_s2: np.ndarray
    loop_residual_m: np.ndarray


def _crank_angles(crank_angle_rad):
    phi1 = np.asarray(crank_angle_rad, dtype=float)
    if phi1.ndim == 0:
        phi1 = phi1.reshape(1)
    if phi1.ndim != 1 or phi1.size == 0:
        raise ValueError(f'crank_angle_rad: got shape {phi1.shape}, expected (n,) with n >= 1')
    if not np.all(np.isfinite(phi1)):
        raise ValueError('crank_angle_rad: got non-finite values, expected finite angles in rad')
    return phi1


def _check_assembly(phi1, cos_half, sin_half, amp, amp_scale):
    """Raise ValueError naming the first crank angle where eq. 23 has no regular solution."""
    degenerate = amp <= DEGENERATE_LOOP_TOL * amp_scale
    if np.any(degenerate):
        k = int(np.argmax(degenerate))
        raise ValueError(
            f'crank angle {phi1[k] / _DEG:.6g} deg: D2 = D3 = 0 in seed 002 eq. 23, so phi3 '
            'is undetermined (output pin on the output axis or geometry degenerate); '
            'expected a geometry with sqrt(D2^2 + D3^2) > 0')
    apart = np.abs(cos_half) > 1.0
    if np.any(apart):
        k = int(np.argmax(apart))
        raise ValueError(
            f'crank angle {phi1[k] / _DEG:.6g} deg: the RGGR linkage cannot be assembled '
            f'(|D1| / sqrt(D2^2 + D3^2) = {abs(cos_half[k]):.6g}, expected <= 1 by seed 002 '
            'eq. 23); the coupler length geometry.a2_m does not fit this crank position')
    merged = sin_half < BRANCH_SEPARATION_MIN
    if np.any(merged):
        k = int(np.argmax(merged))
        raise ValueError(
            f'crank angle {phi1[k] / _DEG:.6g} deg: the two assembly branches meet '
            f'(sine of half their separation {sin_half[k]:.3g}, expected >= '
            f'{BRANCH_SEPARATION_MIN:g}); the output link is at a dead centre where the '
            'branch is undefined and the output rates are unbounded')


def _pivot_centre(q_m, axes, centre_uvw, rate, accel):
    """
    Position, velocity and acceleration of a point fixed in a link turning about w.

    seed 002, eqs. 27/50 (crank, rate = omega, accel = 0) and eqs. 28/52 (output link).
    """
    u, v, w = centre_uvw
    rho = u * axes[:, :, 0] + v * axes[:, :, 1] + w * axes[:, :, 2]
    turned = u * axes[:, :, 1] - v * axes[:, :, 0]      # w x rho
    radial = u * axes[:, :, 0] + v * axes[:, :, 1]      # -w x (w x rho)
    pos = q_m + rho
    vel = rate[:, None] * turned
    acc = accel[:, None] * turned - (rate ** 2)[:, None] * radial
    return pos, vel, acc


def kinematics(scene, crank_angle_rad):
    """
    Return the closed-form :class:`RggrKinematics` at the crank angles ``(n,)`` in rad.

    Raises ValueError naming the crank angle where the linkage cannot be assembled or is at
    a dead centre (the branch is never switched silently).
    """
    phi1 = _crank_angles(crank_angle_rad)
    g = scene.geometry
    om = scene.crank_speed_rad_s
    l1, l2, l3, a1, a2, a3 = g.l1_m, g.l2_m, g.l3_m, g.a1_m, g.a2_m, g.a3_m
    sb, cb = math.sin(g.beta_rad), math.cos(g.beta_rad)
    c1, s1 = np.cos(phi1), np.sin(phi1)
    n = phi1.size

    # seed 002, eqs. 24-26
    d1 = (l1 ** 2 + l2 ** 2 + l3 ** 2 - 2.0 * l1 * l3 * cb + a1 ** 2 - a2 ** 2 + a3 ** 2
          - 2.0 * l3 * a1 * sb * c1 + 2.0 * l2 * a1 * s1)
    d2 = 2.0 * a3 * (l1 * sb - a1 * cb * c1)
    d3 = -2.0 * a3 * (l2 + a1 * s1)

    # seed 002, eq. 23, D1 + D2 cos(phi3) + D3 sin(phi3) = 0, solved in closed form:
    # D2 cos + D3 sin = R cos(phi3 - delta), R = hypot(D2, D3), delta = atan2(D3, D2), so
    # phi3 = delta + branch * acos(-D1 / R).  The paper only says 'the suitable value is
    # chosen according to the initial mechanism position'; the branch is the scene's.
    amp = np.hypot(d2, d3)
    amp_scale = 2.0 * a3 * (abs(l1) + abs(l2) + a1)
    with np.errstate(divide='ignore', invalid='ignore'):
        cos_half = -d1 / amp
    sin_half = np.sqrt(np.clip(1.0 - cos_half ** 2, 0.0, None))
    _check_assembly(phi1, cos_half, sin_half, amp, amp_scale)
    phi3 = np.arctan2(d3, d2) + scene.branch * np.arccos(cos_half)
    phi3 = np.mod(phi3 + math.pi, 2.0 * math.pi) - math.pi
    c3, s3 = np.cos(phi3), np.sin(phi3)
    den = d2 * s3 - d3 * c3          # = branch * R * sin_half, never near zero here

    # seed 002, eqs. 30-33
    d4 = 2.0 * a1 * om * (l2 * c1 + l3 * sb * s1)
    d5 = 2.0 * a1 * a3 * om * cb * s1
    d6 = -2.0 * a1 * a3 * om * c1
    rate = (d4 + d5 * c3 + d6 * s3) / den

    # seed 002, eqs. 47-49 (the text prints l_3 / Gamma for phi3; D7 is d(D4)/dt, and the
    # printed D8, D9 agree with differentiating eq. 30 once more, which we re-derived)
    d7 = 2.0 * a1 * om ** 2 * (l3 * sb * c1 - l2 * s1)
    d8 = 2.0 * a1 * a3 * om ** 2 * cb * c1 - rate * (d2 * rate + 4.0 * a1 * a3 * om * c1)
    d9 = 2.0 * a1 * a3 * om ** 2 * s1 - rate * (d3 * rate + 4.0 * a1 * a3 * om * cb * s1)
    accel = (d7 + d8 * c3 + d9 * s3) / den

    zeros, ones = np.zeros(n), np.ones(n)
    # link frames: crank Q1uvw (eq. 27), output Q3uvw = Ry(beta) Rz(phi3) (eqs. 19, 28)
    crank_axes = np.stack([np.stack([c1, s1, zeros], -1),
                           np.stack([-s1, c1, zeros], -1),
                           np.stack([zeros, zeros, ones], -1)], -1)
    output_axes = np.stack([np.stack([cb * c3, s3, -sb * c3], -1),
                            np.stack([-cb * s3, c3, sb * s3], -1),
                            np.tile([sb, 0.0, cb], (n, 1))], -1)
    q1 = np.array([0.0, l2, l1])                  # seed 002, eq. 15
    q3 = l3 * np.array([sb, 0.0, cb])             # seed 002, eqs. 17, 19

    u1, v1 = crank_axes[:, :, 0], crank_axes[:, :, 1]
    u3, v3 = output_axes[:, :, 0], output_axes[:, :, 1]
    pin_b = q1 + a1 * u1                          # seed 002, eq. 16
    pin_b_vel = a1 * om * v1
    pin_b_acc = -a1 * om ** 2 * u1
    pin_c = q3 + a3 * u3                          # seed 002, eq. 20
    pin_c_vel = a3 * rate[:, None] * v3
    pin_c_acc = a3 * (accel[:, None] * v3 - (rate ** 2)[:, None] * u3)
    coupler = pin_c - pin_b                       # seed 002, eq. 21
    coupler_vel = pin_c_vel - pin_b_vel           # seed 002, eq. 34
    coupler_acc = pin_c_acc - pin_b_acc           # seed 002, eq. 72 (garbled print; this is
    #                                               the derivative of eq. 34)

    crank_total, output_total = scene.crank_total(), scene.output_total()
    g1, _, g1_acc = _pivot_centre(q1, crank_axes, crank_total.centre_uvw_m,
                                  np.full(n, om), zeros)
    g3, _, g3_acc = _pivot_centre(q3, output_axes, output_total.centre_uvw_m, rate, accel)
    mu = scene.coupler.centre_from_b_m / a2         # seed 002, eq. 12
    g2 = pin_b + mu * coupler                       # seed 002, eq. 29
    g2_vel = pin_b_vel + mu * coupler_vel
    g2_acc = pin_b_acc + mu * coupler_acc           # seed 002, eq. 51

    return RggrKinematics(
        crank_angle_rad=phi1, crank_speed_rad_s=om, output_angle_rad=phi3,
        output_rate_rad_s=rate, output_accel_rad_s2=accel,
        crank_axes=crank_axes, output_axes=output_axes,
        pin_b_m=pin_b, pin_b_vel_m_s=pin_b_vel, pin_b_acc_m_s2=pin_b_acc,
        pin_c_m=pin_c, pin_c_vel_m_s=pin_c_vel, pin_c_acc_m_s2=pin_c_acc,
        coupler_m=coupler, coupler_vel_m_s=coupler_vel, coupler_acc_m_s2=coupler_acc,
        crank_centre_m=g1, crank_centre_acc_m_s2=g1_acc,
        coupler_centre_m=g2, coupler_centre_vel_m_s=g2_vel, coupler_centre_acc_m_s2=g2_acc,
        output_centre_m=g3, output_centre_acc_m_s2=g3_acc,
        loop_residual_m=np.linalg.norm(coupler, axis=1) - a2)


def coupler_frame(kin):
    """
    Return the coupler frame G2uvw, ``(n, 3, 3)`` with U, V, W as columns.

    seed 002, eqs. 38, 42-44: U along BC, V parallel to the xy-plane (the paper's choice for
    the coupler's idle spin), W = U x V.  Undefined where BC is parallel to z (h = 0).
    """
    a = kin.coupler_m
    a2 = np.linalg.norm(a, axis=1)
    h = np.hypot(a[:, 0], a[:, 1])                                    # eq. 43
    bad = h < COUPLER_FRAME_MIN * a2
    if np.any(bad):
        k = int(np.argmax(bad))
        raise ValueError(
            f'crank angle {kin.crank_angle_rad[k] / _DEG:.6g} deg: coupler parallel to z '
            f'(h / a2 = {h[k] / a2[k]:.3g}, expected >= {COUPLER_FRAME_MIN:g}), so the frame '
            'of seed 002 eq. 42 is undefined')
    u = a / a2[:, None]                                               # eq. 38
    v = np.stack([a[:, 1], -a[:, 0], np.zeros_like(h)], -1) / h[:, None]  # eq. 42
    w = np.stack([a[:, 0] * a[:, 2], a[:, 1] * a[:, 2], -h ** 2], -1) / (a2 * h)[:, None]
    return np.stack([u, v, w], -1)                                    # eq. 44 for W


def coupler_angular_velocity(kin):
    """
    Return the coupler's angular velocity without its idle spin, ``(n, 3)`` in rad/s.

    seed 002, eqs. 45-46, returned as Omega_v V + Omega_w W.  Reconstruction: eq. 36 prints
    (dA2/dt)_w = a2 Omega_v, but dA2/dt = Omega x A2 gives -a2 Omega_v; eq. 45 as printed
    (Omega_v = dA2z/dt / h) follows from the corrected sign, so eqs. 45-46 are used as
    printed.  The result equals U x dU/dt, the form :func:`shaking_moment_coefficients` uses.
    """
    axes = coupler_frame(kin)
    a, da = kin.coupler_m, kin.coupler_vel_m_s
    a2 = np.linalg.norm(a, axis=1)
    h = np.hypot(a[:, 0], a[:, 1])
    omega_v = da[:, 2] / h                                                   # eq. 45
    omega_w = (a[:, 1] * da[:, 0] - a[:, 0] * da[:, 1]) / (a2 * h)           # eq. 46
    return omega_v[:, None] * axes[:, :, 1] + omega_w[:, None] * axes[:, :, 2]


# ---------------------------------------------------------------------------------------------
# Dynamics
# ---------------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class RggrDynamics:
    """
    Shaking wrench about O and driving torque over ``n`` crank angles (SI).

    ``shaking_force_N`` and ``shaking_moment_Nm`` are ``(n, 3)`` in Oxyz (sign convention:
    ``mech_balance.conventions``); ``driving_torque_Nm`` ``(n,)`` is the motor torque on the
    crank about +z (the crank axis w1).
    """

    kinematics: RggrKinematics
    shaking_force_N: np.ndarray
    shaking_moment_Nm: np.ndarray
    driving_torque_Nm: np.ndarray


def _pivots(geometry):
    sb, cb = math.sin(geometry.beta_rad), math.cos(geometry.beta_rad)
    q1 = np.array([0.0, geometry.l2_m, geometry.l1_m])      # seed 002, eq. 15
    q3 = geometry.l3_m * np.array([sb, 0.0, cb])            # seed 002, eqs. 17, 19
    return q1, q3


def shaking_moment_coefficients(scene, kin):
    """
    Return ``(f0, f)`` with the shaking moment about O equal to ``f0 + f @ J``.

    seed 002, eqs. 73-88: ``f0`` ``(n, 3)`` holds every term not multiplied by a product of
    inertia (eqs. 77-79, J0 = 1) and ``f`` ``(n, 3, 4)`` the coefficients of
    J = (I_1wu, I_1vw, I_3wu, I_3vw) (eqs. 80-88), the products of the crank and output link
    with their weights about Q1 and Q3.  Valid for any mass distribution (balanced or not).
    """
    # Reconstruction: the list defining J1..J4 ('these parameters are denoted as follows:')
    # is missing from the text.  Matching eqs. 80-88 with the J terms of eqs. 56 and 59 gives
    # J1 = I_1wu, J2 = I_1vw, J3 = I_3wu, J4 = I_3vw; eqs. 83-84 print l_3/i_3 for phi3 and
    # eq. 78 prints x'_g1 for x_g1.
    om = kin.crank_speed_rad_s
    crank, output, cpl = scene.crank_total(), scene.output_total(), scene.coupler
    q1, q3 = _pivots(scene.geometry)
    u1, v1 = kin.crank_axes[:, :, 0], kin.crank_axes[:, :, 1]
    u3, v3, w3 = (kin.output_axes[:, :, i] for i in range(3))
    rate = kin.output_rate_rad_s[:, None]
    accel = kin.output_accel_rad_s2[:, None]

    # seed 002, eqs. 53-56: moment of link 1's inertia forces about O without the J terms;
    # the I_1w term vanishes because the crank turns at constant speed.
    moment_crank = -np.cross(q1, crank.mass_kg * kin.crank_centre_acc_m_s2)
    # seed 002, eqs. 57-59 without the J terms (eq. 59 prints '+ m3 l3 x''_g3' in its y row;
    # eq. 57 and eq. 78 have the minus sign used here: -Q3 x m3 a_g3).
    moment_output = (-output.inertia_ww_kg_m2 * accel * w3
                     - np.cross(q3, output.mass_kg * kin.output_centre_acc_m_s2))
    # seed 002, eqs. 60-63, reconstructed.  Eq. 63 prints -I [dV/dt alpha_v + dV/dt Omega_v
    # + ...]; the derivative of eq. 62's first term is I (alpha_v V + Omega_v dV/dt + alpha_w W
    # + Omega_w dW/dt), and eq. 61 prints dx_g1/dt where dx_g2/dt is meant.  Omega_v V +
    # Omega_w W is the angular velocity normal to the rod, U x dU/dt with U = A2 / a2, so the
    # coupler's angular momentum about G2 is I U x dU/dt and its rate I U x d2U/dt2 - the
    # same quantity, free of the V-parallel-to-xy spin convention and of its singularity.
    a2 = scene.geometry.a2_m
    moment_coupler = (-cpl.transverse_inertia_kg_m2 / a2 ** 2
                      * np.cross(kin.coupler_m, kin.coupler_acc_m_s2)
                      - np.cross(kin.coupler_centre_m, cpl.mass_kg * kin.coupler_centre_acc_m_s2))
    f0 = moment_crank + moment_coupler + moment_output                       # eqs. 77-79

    f = np.stack([om ** 2 * v1,                       # eqs. 80-82: f_1 = om^2 (-s1, c1, 0)
                  -om ** 2 * u1,                      # eqs. 80-82: f_2 = om^2 (-c1, -s1, 0)
                  accel * u3 + rate ** 2 * v3,        # eqs. 83, 85, 86
                  accel * v3 - rate ** 2 * u3], -1)   # eqs. 84, 87, 88
    return f0, f


def dynamics(scene, crank_angle_rad):
    """
    Return the :class:`RggrDynamics` of ``scene`` at the crank angles ``(n,)`` in rad.

    Shaking force -(sum m_i a_Gi) (time derivative of seed 002 eq. 1), shaking moment
    f0 + f J about O (eqs. 73-75), driving torque from the power balance.
    """
    kin = kinematics(scene, crank_angle_rad)
    crank, output, cpl = scene.crank_total(), scene.output_total(), scene.coupler
    force = -(crank.mass_kg * kin.crank_centre_acc_m_s2
              + cpl.mass_kg * kin.coupler_centre_acc_m_s2
              + output.mass_kg * kin.output_centre_acc_m_s2)
    f0, f = shaking_moment_coefficients(scene, kin)
    moment = f0 + f @ scene.inertia_parameters_kg_m2()                       # eqs. 73-75

    # Driving torque (not derived in seed 002): with the crank at constant speed, torque *
    # omega = dT/dt, where T = 1/2 I_3w phi3'^2 (I_3w about the output axis) + 1/2 m2 |v_G2|^2
    # + 1/2 I |dU/dt|^2 (the crank's kinetic energy is constant).
    a2 = scene.geometry.a2_m
    power = (output.inertia_ww_kg_m2 * kin.output_rate_rad_s * kin.output_accel_rad_s2
             + cpl.mass_kg * np.einsum('ij,ij->i', kin.coupler_centre_vel_m_s,
                                       kin.coupler_centre_acc_m_s2)
             + cpl.transverse_inertia_kg_m2 / a2 ** 2
             * np.einsum('ij,ij->i', kin.coupler_vel_m_s, kin.coupler_acc_m_s2))
    return RggrDynamics(kinematics=kin, shaking_force_N=force, shaking_moment_Nm=moment,
                        driving_torque_Nm=power / kin.crank_speed_rad_s)


def check_full_rotation(scene, samples=FULL_ROTATION_SAMPLES):
    """Raise ValueError if the crank cannot turn a full revolution on the scene's branch."""
    return kinematics(scene, cycle_angles(samples))


# ---------------------------------------------------------------------------------------------
# Complete force balancing (seed 002, eqs. 1-14)
# ---------------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class ForceBalance:
    """
    The force-balanced rig: ``scene`` with both weights fitted (products of inertia zero).

    ``output_weight_radius_m`` is r of eq. 14; ``coupler_mass_fraction`` is mu = c2 / a2.
    """

    scene: RggrScene
    crank_weight: PivotBody
    output_weight: PivotBody
    output_weight_radius_m: float
    coupler_mass_fraction: float


def force_balance(scene):
    """
    Return the :class:`ForceBalance` of ``scene`` from its ``balancing_design``.

    Any weights already in the scene are replaced.  The crank weight's I_ww (which has no
    influence at constant crank speed) is that of a point mass; both weights get zero
    products of inertia, which the shaking-moment optimization then sets.
    """
    if scene.design is None:
        raise ValueError('balancing_design: missing, expected {crank_weight_mass_kg, '
                         'output_weight_density_length_kg_m2} for the force balancing')
    g, cpl = scene.geometry, scene.coupler
    mu = cpl.centre_from_b_m / g.a2_m                                       # eq. 12
    m2 = cpl.mass_kg

    # seed 002, eqs. 4 and 6-8: m_b1 (u, v, w)_b1 = -m_o1 (u, v, w)_o1 - m2 a1 (1 - mu) e_u
    first_b1 = 0.0 - scene.crank.first_moment_kg_m()      # 0.0 - avoids -0.0 in reports
    first_b1[0] -= m2 * g.a1_m * (1.0 - mu)
    mb1 = scene.design.crank_weight_mass_kg
    centre_b1 = first_b1 / mb1
    crank_weight = PivotBody(
        mass_kg=mb1, centre_uvw_m=tuple(float(x) for x in centre_b1),
        inertia_ww_kg_m2=float(mb1 * (centre_b1[0] ** 2 + centre_b1[1] ** 2)),
        product_wu_kg_m2=0.0, product_vw_kg_m2=0.0)

    # seed 002, eqs. 5 and 9-11: m_b3 (u, v, w)_b3 = -m_o3 (u, v, w)_o3 - m2 a3 mu e_u
    first_b3 = 0.0 - scene.output.first_moment_kg_m()
    first_b3[0] -= m2 * g.a3_m * mu
    radial_first = math.hypot(first_b3[0], first_b3[1])
    if radial_first == 0.0:
        raise ValueError(
            'links.output: the output link needs no radial first moment m_b3 (u_b3, v_b3) = 0, '
            'expected a nonzero one for the cylindrical weight of seed 002 eqs. 13-14')
    # seed 002, eq. 13, reconstructed.  Printed: m_b3 = {pi r^2 L [(m3 u_b3)^2 +
    # (m3 v_b3)^2]}^(1/3) with 'where f is the density'.  The cylinder has m_b3 = rho pi r^2
    # L and, with the rotation axis on a generator, r^2 = u_b3^2 + v_b3^2 (eq. 14), hence
    # m_b3^3 = rho L pi [(m_b3 u_b3)^2 + (m_b3 v_b3)^2].  With rho L = m_o1 / a1^2 (printed
    # as 'beta L') this gives m_b3 / m_o1 = 8.5075, the paper's 8.5.
    rho_l = scene.design.output_weight_density_length_kg_m2
    mb3 = (rho_l * math.pi * radial_first ** 2) ** (1.0 / 3.0)
    centre_b3 = first_b3 / mb3
    radius = math.hypot(centre_b3[0], centre_b3[1])                          # eq. 14
    # I_b3w is printed (34.56) without a formula: a solid cylinder of radius r about one of
    # its generators has m r^2 / 2 + m r^2, whatever the inclination alpha of its end faces
    # (the faces shear the cylinder along its axis, conclusion 5).
    output_weight = PivotBody(
        mass_kg=mb3, centre_uvw_m=tuple(float(x) for x in centre_b3),
        inertia_ww_kg_m2=1.5 * mb3 * radius ** 2,
        product_wu_kg_m2=0.0, product_vw_kg_m2=0.0)

    balanced = dataclasses.replace(scene, crank_weight=crank_weight, output_weight=output_weight)
    return ForceBalance(scene=balanced, crank_weight=crank_weight, output_weight=output_weight,
                        output_weight_radius_m=radius, coupler_mass_fraction=mu)


# ---------------------------------------------------------------------------------------------
# Minimum RMS shaking moment (seed 002, eqs. 73-95) and weight design (eqs. 96-103)
# ---------------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class ShakingMomentOptimum:
    """
    Products of inertia J1..J4 minimizing the RMS shaking moment over ``samples`` angles.

    ``inertia_parameters_kg_m2`` = (I_1wu, I_1vw, I_3wu, I_3vw) of the links with weights;
    ``gram_matrix`` (5, 5) is F_ij of eq. 93 (index 0 for J0 = 1); the normal-equation
    residual is max_i |sum_j F_ij J_j + F_i0| / max |F_ij| (eq. 94, i = 1..4).
    """

    inertia_parameters_kg_m2: np.ndarray
    moment_rms_at_scene_Nm: float
    moment_rms_optimal_Nm: float
    gram_matrix: np.ndarray
    normal_equation_residual: float
    rank: int
    samples: int


def optimize_shaking_moment(scene, samples=DEFAULT_SAMPLES):
    """
    Return the :class:`ShakingMomentOptimum` of ``scene`` (meant for a force-balanced one).

    seed 002, eqs. 89-95: M_r^2 = sum F_ij J_i J_j is quadratic in J, so its minimum is the
    linear least-squares solution of f J = -f0 stacked over the samples (eq. 91's integral
    is the RMS of ``mech_balance.conventions`` over equally spaced angles).  Solved by an
    orthogonal factorization (numpy.linalg.lstsq), equivalent to eq. 94 without squaring
    its condition number.
    """
    angles = cycle_angles(samples)
    kin = kinematics(scene, angles)
    f0, f = shaking_moment_coefficients(scene, kin)
    n = angles.size
    design = f.reshape(3 * n, 4)
    target = -f0.reshape(3 * n)
    j_opt, _, rank, _ = np.linalg.lstsq(design, target, rcond=None)
    residual = design @ j_opt - target
    columns = np.concatenate([f0.reshape(3 * n, 1), design], axis=1)
    gram = columns.T @ columns / n                                           # eq. 93
    normal = gram[1:, 1:] @ j_opt + gram[1:, 0]                              # eq. 94
    scale = float(np.max(np.abs(gram[1:, 1:]))) or 1.0
    current = f0 + f @ scene.inertia_parameters_kg_m2()
    return ShakingMomentOptimum(
        inertia_parameters_kg_m2=j_opt,
        moment_rms_at_scene_Nm=float(rms(current)),
        moment_rms_optimal_Nm=float(math.sqrt(residual @ residual / n)),
        gram_matrix=gram,
        normal_equation_residual=float(np.max(np.abs(normal)) / scale),
        rank=int(rank), samples=n)


@dataclasses.dataclass(frozen=True)
class BalancingWeightDesign:
    """
    Both balancing weights with the optimal products of inertia, and alpha and gamma.

    ``alpha_rad`` is the inclination of the output weight's end faces to its axis and
    ``gamma_rad`` the angle from the link's uw-plane to the plane of the faces' major axes
    (seed 002, Fig. 2).  ``scene`` is the force-balanced rig with these weights (its J
    equals the optimum).
    """

    scene: RggrScene
    crank_weight: PivotBody
    output_weight: PivotBody
    output_weight_radius_m: float
    alpha_rad: float
    gamma_rad: float


def design_balancing_weights(balance, optimum):
    """
    Return the :class:`BalancingWeightDesign` giving the links the optimal J1..J4.

    seed 002, eqs. 96-103.  The crank weight may be 'designed in a similar way, or in any form
    which gives I_1wu and I_1vw the values obtained' (text after eq. 103): only its products
    are returned.
    """
    j = optimum.inertia_parameters_kg_m2
    scene = balance.scene
    crank_weight = dataclasses.replace(
        balance.crank_weight,
        product_wu_kg_m2=float(j[0] - scene.crank.product_wu_kg_m2),
        product_vw_kg_m2=float(j[1] - scene.crank.product_vw_kg_m2))
    weight = balance.output_weight
    ib3wu = float(j[2] - scene.output.product_wu_kg_m2)
    ib3vw = float(j[3] - scene.output.product_vw_kg_m2)
    ub, vb, wb = weight.centre_uvw_m
    m, r = weight.mass_kg, balance.output_weight_radius_m
    # seed 002, eqs. 96-97: products about the weight's centre B3 in axes u', v', w' parallel
    # to the link's u, v, w.
    iwu_c = ib3wu - m * wb * ub
    ivw_c = ib3vw - m * vb * wb
    # seed 002, eqs. 98-101, reconstructed.  Eq. 98 prints I_w'u' = I_w''u'' cos^2(alpha)
    # - I_w''v'' sin^2(alpha) and eq. 99 is missing.  u'' makes the angle gamma with u' about
    # the common axis w' = w'', so the products transform as I_w'u' = I_w''u'' cos(gamma) -
    # I_v''w'' sin(gamma) and I_v'w' = I_w''u'' sin(gamma) + I_v''w'' cos(gamma).  The end
    # faces w'' = -u'' cot(alpha) +/- L/2 give I_w''u'' = -m r^2 / (4 tan(alpha)) (eq. 100)
    # and I_v''w'' = 0 (eq. 101).  Hence:
    magnitude = math.hypot(iwu_c, ivw_c)
    alpha = math.atan2(m * r ** 2, 4.0 * magnitude)                          # eq. 102
    # eq. 103 prints gamma = atan(I_v'w' / I_w'u'); the quadrant follows from I_w''u'' < 0:
    # cos(gamma) = -I_w'u' / |I_w''u''|, sin(gamma) = -I_v'w' / |I_w''u''|.
    gamma = math.atan2(-ivw_c, -iwu_c) % (2.0 * math.pi) if magnitude > 0.0 else 0.0
    output_weight = dataclasses.replace(weight, product_wu_kg_m2=ib3wu, product_vw_kg_m2=ib3vw)
    designed = dataclasses.replace(scene, crank_weight=crank_weight, output_weight=output_weight)
    return BalancingWeightDesign(
        scene=designed, crank_weight=crank_weight, output_weight=output_weight,
        output_weight_radius_m=r, alpha_rad=alpha, gamma_rad=gamma)


@dataclasses.dataclass(frozen=True)
class BalanceResult:
    """Force balance, shaking-moment optimum and weight design of one scene."""

    force_balance: ForceBalance
    optimum: ShakingMomentOptimum
    design: BalancingWeightDesign
    solve_time_s: float


def balance_scene(scene, samples=DEFAULT_SAMPLES):
    """Return the :class:`BalanceResult` of ``scene`` (force balance, optimum, weight design)."""
    start = time.perf_counter()
    balance = force_balance(scene)
    check_full_rotation(balance.scene)
    optimum = optimize_shaking_moment(balance.scene, samples)
    design = design_balancing_weights(balance, optimum)
    return BalanceResult(force_balance=balance, optimum=optimum, design=design,
                         solve_time_s=time.perf_counter() - start)


# ---------------------------------------------------------------------------------------------
# Reports for the command line
# ---------------------------------------------------------------------------------------------

class _View:
    """SI values or the paper's dimensionless view (by m_o1, a1, omega)."""

    def __init__(self, scene, normalized):
        self.normalized = bool(normalized)
        norm = scene.normalization
        self.mass_kg, self.length_m = norm['mass_kg'], norm['length_m']
        self.omega_rad_s = norm['omega_rad_s']

    def units(self):
        if self.normalized:
            return {'mass': 'm_o1', 'length': 'a1', 'inertia': 'm_o1 a1^2',
                    'force': 'm_o1 a1 omega^2', 'moment': 'm_o1 a1^2 omega^2',
                    'torque': 'm_o1 a1^2 omega^2', 'angle': 'deg'}
        return {'mass': 'kg', 'length': 'm', 'inertia': 'kg m^2', 'force': 'N',
                'moment': 'N m', 'torque': 'N m', 'angle': 'deg'}

    def mass(self, x):
        return float(x) / self.mass_kg if self.normalized else float(x)

    def length(self, x):
        x = np.asarray(x, dtype=float)
        out = x / self.length_m if self.normalized else x
        return out.tolist() if out.ndim else float(out)

    def inertia(self, x):
        return float(x) / (self.mass_kg * self.length_m ** 2) if self.normalized else float(x)

    def force(self, x):
        if not self.normalized:
            return np.asarray(x, dtype=float)
        return normalize_force(x, self.mass_kg, self.length_m, self.omega_rad_s)

    def moment(self, x):
        if not self.normalized:
            return np.asarray(x, dtype=float)
        return normalize_moment(x, self.mass_kg, self.length_m, self.omega_rad_s)


METRIC_KEYS = ('shaking_force_rms', 'shaking_force_max', 'shaking_moment_rms',
               'shaking_moment_max', 'driving_torque_rms', 'driving_torque_max')
"""Keys of one row of metrics in the report dicts (units in the report's ``units``)."""


def _metrics(dyn, view):
    force = view.force(dyn.shaking_force_N)
    moment = view.moment(dyn.shaking_moment_Nm)
    torque = view.moment(dyn.driving_torque_Nm)
    return {'shaking_force_rms': float(rms(force)),
            'shaking_force_max': float(np.max(np.linalg.norm(force, axis=1))),
            'shaking_moment_rms': float(rms(moment)),
            'shaking_moment_max': float(np.max(np.linalg.norm(moment, axis=1))),
            'driving_torque_rms': float(rms(torque)),
            'driving_torque_max': float(np.max(np.abs(torque)))}


def _header(scene, command, samples, view):
    return {'kind': KIND, 'command': command, 'scene': scene.name, 'source': scene.source,
            'samples': int(samples), 'normalized': view.normalized, 'units': view.units(),
            'normalization': dict(scene.normalization), 'assembly_branch': scene.branch,
            'crank_speed_rad_s': scene.crank_speed_rad_s}


def analyze_report(scene, samples=DEFAULT_SAMPLES, normalized=False):
    """
    Return the analysis of ``scene`` as a plain dict of floats and lists.

    RMS and max of |shaking force|, |shaking moment| about O and |driving torque| over
    ``samples`` crank angles, per-axis RMS of the force and moment (x, y, z), the output
    angle range and the worst loop residual |BC| - a2.
    """
    view = _View(scene, normalized)
    check_full_rotation(scene)
    dyn = dynamics(scene, cycle_angles(samples))
    force = view.force(dyn.shaking_force_N)
    moment = view.moment(dyn.shaking_moment_Nm)
    phi3_deg = np.degrees(np.unwrap(dyn.kinematics.output_angle_rad))
    report = _header(scene, 'analyze', samples, view)
    report.update({
        'balancing_weights': {'crank': scene.crank_weight is not None,
                              'output': scene.output_weight is not None},
        'metrics': _metrics(dyn, view),
        'shaking_force_rms_xyz': [float(rms(force[:, i])) for i in range(3)],
        'shaking_moment_rms_xyz': [float(rms(moment[:, i])) for i in range(3)],
        'output_angle_range_deg': [float(phi3_deg.min()), float(phi3_deg.max())],
        'loop_residual_max_m': float(np.max(np.abs(dyn.kinematics.loop_residual_m))),
    })
    return report


def balance_report(scene, samples=DEFAULT_SAMPLES, normalized=False):
    """
    Return the force balancing and shaking-moment optimization of ``scene`` as a plain dict.

    The balancing weights (masses, centres, products, output weight radius, I_b3w, alpha,
    gamma), the optimal J1..J4, a before/after table (unbalanced = links without weights,
    force-balanced = weights with zero products, optimized), the least-squares optimum, the
    worst loop residual and the solve time.
    """
    view = _View(scene, normalized)
    result = balance_scene(scene, samples)
    angles = cycle_angles(samples)
    bare = dataclasses.replace(scene, crank_weight=None, output_weight=None)
    rows = []
    residual = 0.0
    for label, rig in (('unbalanced', bare), ('force-balanced', result.force_balance.scene),
                       ('optimized', result.design.scene)):
        dyn = dynamics(rig, angles)
        residual = max(residual, float(np.max(np.abs(dyn.kinematics.loop_residual_m))))
        rows.append({'rig': label, **_metrics(dyn, view)})
    cw, ow, des = result.design.crank_weight, result.design.output_weight, result.design
    opt = result.optimum
    report = _header(scene, 'balance', samples, view)
    report.update({
        'coupler_mass_fraction': result.force_balance.coupler_mass_fraction,
        'crank_weight': {'mass': view.mass(cw.mass_kg),
                         'centre_uvw': view.length(cw.centre_uvw_m),
                         'product_wu': view.inertia(cw.product_wu_kg_m2),
                         'product_vw': view.inertia(cw.product_vw_kg_m2)},
        'output_weight': {'mass': view.mass(ow.mass_kg),
                          'centre_uvw': view.length(ow.centre_uvw_m),
                          'radius': view.length(des.output_weight_radius_m),
                          'inertia_ww': view.inertia(ow.inertia_ww_kg_m2),
                          'product_wu': view.inertia(ow.product_wu_kg_m2),
                          'product_vw': view.inertia(ow.product_vw_kg_m2),
                          'alpha_deg': math.degrees(des.alpha_rad),
                          'gamma_deg': math.degrees(des.gamma_rad)},
        'inertia_parameters': dict(zip(('I_1wu', 'I_1vw', 'I_3wu', 'I_3vw'),
                                       (view.inertia(x) for x in opt.inertia_parameters_kg_m2))),
        'table': rows,
        'optimum': {'shaking_moment_rms': float(view.moment(opt.moment_rms_optimal_Nm)),
                    'normal_equation_residual': opt.normal_equation_residual,
                    'rank': opt.rank},
        'loop_residual_max_m': residual,
        'solve_time_s': result.solve_time_s,
    })
    return report


def format_report(report):
    """Return an analyze or balance report as a readable fixed-width text table."""
    u = report['units']
    lines = [f"RGGR spatial four-bar '{report['scene']}' ({report['source']}): "
             f"{report['command']}, branch {report['assembly_branch']:+d}, "
             f"crank {report['crank_speed_rad_s']:g} rad/s, {report['samples']} angles"]
    if report['normalized']:
        n = report['normalization']
        lines.append(f"normalized by m_o1 = {n['mass_kg']:g} kg, a1 = {n['length_m']:g} m, "
                     f"omega = {n['omega_rad_s']:g} rad/s")
    lines.append(f"units: force {u['force']}; moment, torque {u['moment']}; "
                 f"mass {u['mass']}; length {u['length']}; inertia {u['inertia']}")
    head = (f"{'rig':<16}{'|f| rms':>12}{'|f| max':>12}{'|n| rms':>12}{'|n| max':>12}"
            f"{'tau rms':>12}{'|tau| max':>12}")
    rows = report['table'] if report['command'] == 'balance' else [
        {'rig': 'as given', **report['metrics']}]
    lines += ['', head, '-' * len(head)]
    for row in rows:
        lines.append(f"{row['rig']:<16}" + ''.join(f'{row[k]:>12.5g}' for k in METRIC_KEYS))
    lines.append('')
    if report['command'] == 'analyze':
        fx, fy, fz = report['shaking_force_rms_xyz']
        nx, ny, nz = report['shaking_moment_rms_xyz']
        lo, hi = report['output_angle_range_deg']
        lines += [f'shaking force RMS (x, y, z):  {fx:12.5g}{fy:12.5g}{fz:12.5g}',
                  f'shaking moment RMS (x, y, z): {nx:12.5g}{ny:12.5g}{nz:12.5g}',
                  f'output angle phi3: {lo:.3f} .. {hi:.3f} deg']
    else:
        cw, ow, j = report['crank_weight'], report['output_weight'], report['inertia_parameters']
        lines += [
            f"coupler mass fraction mu = c2/a2: {report['coupler_mass_fraction']:.6g}",
            f"crank weight:  m_b1 {cw['mass']:10.5g}   (u, v, w)_b1 "
            + ' '.join(f'{x:10.5g}' for x in cw['centre_uvw'])
            + f"   I_b1wu {cw['product_wu']:10.5g}   I_b1vw {cw['product_vw']:10.5g}",
            f"output weight: m_b3 {ow['mass']:10.5g}   (u, v, w)_b3 "
            + ' '.join(f'{x:10.5g}' for x in ow['centre_uvw'])
            + f"   r {ow['radius']:10.5g}   I_b3w {ow['inertia_ww']:10.5g}",
            f"               I_b3wu {ow['product_wu']:10.5g}   I_b3vw {ow['product_vw']:10.5g}"
            f"   alpha {ow['alpha_deg']:8.3f} deg   gamma {ow['gamma_deg']:8.3f} deg",
            'optimal products (links with weights): '
            + '   '.join(f'{k} {v:10.5g}' for k, v in j.items()),
            f"least-squares optimum: |n| rms {report['optimum']['shaking_moment_rms']:.6g}, "
            f"normal-equation residual {report['optimum']['normal_equation_residual']:.2e}, "
            f"rank {report['optimum']['rank']}",
            f"solve time: {report['solve_time_s'] * 1e3:.1f} ms"]
    lines.append(f"worst loop residual |BC| - a2: {report['loop_residual_max_m']:.3e} m")
    return '\n'.join(lines)
