"""
The RGGR scene (``kind: rggr``, seed 002): its dataclasses, its loader and its writer.

The geometry, link frames and inertia parameters are described in
:mod:`mech_balance.core.rggr`; the schema in :func:`load_rggr_scene`.  The field checks are
the planar loader's (:mod:`mech_balance.schema.fields`): finite numbers of bounded
magnitude, positive masses, inertias that a body can have.
"""

import dataclasses
import math

from mech_balance.schema import fields
from mech_balance.schema.fields import SceneError
from mech_balance.schema.scene import Normalization
import numpy as np

BETA_MAX_DEG = 360.0
"""Largest |beta_deg| accepted (an angle between two axes; larger values are typos)."""


KIND = 'rggr'
"""Value of the top-level ``kind`` field of an RGGR scene."""


SCHEMA_VERSION = 1
"""Accepted value of the optional top-level ``schema_version`` (as for planar scenes)."""


PARALLEL_AXIS_RTOL = 1e-9
"""Relative slack of the check I_ww >= m (u^2 + v^2) (parallel-axis theorem)."""


_DEG = math.pi / 180.0


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
    normalization: Normalization
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
    raise SceneError(f'{path}: got {value!r}, expected {expected}')


def _mapping(data, path, required, optional=()):
    if not isinstance(data, dict):
        _fail(path, data, 'a mapping')
    unknown = sorted(str(key) for key in set(data) - set(required) - set(optional))
    if unknown:
        allowed = ', '.join(list(required) + list(optional))
        where = f'{path}.{unknown[0]}' if path else unknown[0]
        raise SceneError(f'{where}: unknown field, expected one of: {allowed}')
    for key in required:
        if key not in data:
            raise SceneError(f'{path}.{key}: missing, expected it in {path or "the scene"}'
                             if path else f'{key}: missing, expected it at the top level')
    return data


def _number(value, path, minimum=None, strict=False, nonzero=False):
    x = fields.number(value, path)   # finite, bounded magnitude (the planar loader's check)
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
    if not isinstance(data, dict):
        _fail('scene', data, 'a mapping')
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
        beta_rad=_beta(geo['beta_deg']) * _DEG,
        a1_m=_number(geo['a1_m'], 'geometry.a1_m', 0.0, strict=True),
        a2_m=_number(geo['a2_m'], 'geometry.a2_m', 0.0, strict=True),
        a3_m=_number(geo['a3_m'], 'geometry.a3_m', 0.0, strict=True))

    links = _mapping(data['links'], 'links', ('crank', 'coupler', 'output'))
    crank = _pivot_body(links['crank'], 'links.crank', mass_strict=True)
    output = _pivot_body(links['output'], 'links.output', mass_strict=True)
    cpl = _mapping(links['coupler'], 'links.coupler',
                   ('mass_kg', 'centre_from_b_m', 'transverse_inertia_kg_m2'))
    coupler = Coupler(
        mass_kg=_number(cpl['mass_kg'], 'links.coupler.mass_kg', 0.0, strict=True),
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
        normalization=Normalization(crank.mass_kg, geometry.a1_m, abs(omega)))


def _beta(value):
    beta = _number(value, 'geometry.beta_deg')
    if abs(beta) > BETA_MAX_DEG:
        _fail('geometry.beta_deg', value, f'an angle with |beta_deg| <= {BETA_MAX_DEG:g}')
    return beta


def _body_dict(body):
    return {'mass_kg': body.mass_kg, 'centre_uvw_m': list(body.centre_uvw_m),
            'inertia_about_pivot_kg_m2': {'ww': body.inertia_ww_kg_m2,
                                          'wu': body.product_wu_kg_m2,
                                          'vw': body.product_vw_kg_m2}}


def rggr_to_dict(scene):
    """Return an :class:`RggrScene` as the mapping :func:`load_rggr_scene` reads back."""
    g = scene.geometry
    data = {'kind': KIND, 'schema_version': SCHEMA_VERSION, 'name': scene.name,
            'description': scene.description,
            'geometry': {'l1_m': g.l1_m, 'l2_m': g.l2_m, 'l3_m': g.l3_m,
                         'beta_deg': math.degrees(g.beta_rad), 'a1_m': g.a1_m,
                         'a2_m': g.a2_m, 'a3_m': g.a3_m},
            'links': {'crank': _body_dict(scene.crank),
                      'coupler': {'mass_kg': scene.coupler.mass_kg,
                                  'centre_from_b_m': scene.coupler.centre_from_b_m,
                                  'transverse_inertia_kg_m2':
                                      scene.coupler.transverse_inertia_kg_m2},
                      'output': _body_dict(scene.output)}}
    weights = {k: _body_dict(w) for k, w in (('crank', scene.crank_weight),
                                             ('output', scene.output_weight)) if w is not None}
    if weights:
        data['balancing_weights'] = weights
    if scene.design is not None:
        data['balancing_design'] = dataclasses.asdict(scene.design)
    data['assembly'] = {'branch': scene.branch}
    data['crank'] = {'speed_rad_s': scene.crank_speed_rad_s}
    return data


def geometry(scene):
    """Return what a design of an RGGR scene may not change, and its name in words."""
    return (scene.geometry, scene.branch), 'geometry and assembly.branch'
