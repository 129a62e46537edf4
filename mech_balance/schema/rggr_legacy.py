"""
Files of the former ``kind: rggr`` (seed 002's RGGR), read as the ``kind: spatial`` scene.

:func:`translate` maps an old file to the spatial R-S-S-R (``config/rggr.yaml``), logging
once per file; the old schema: docs/scenes.md#a-former-rggr-file-kind-rggr.
"""

import logging
import math

from mech_balance.schema import fields
from mech_balance.schema.fields import SceneError

KIND = 'rggr'
"""The former kind's ``kind:`` value."""
LOG = logging.getLogger('mech_balance')
_TOLD = set()
PARALLEL_AXIS_RTOL = 1e-9
"""Relative slack of the check I_ww >= m (u^2 + v^2) (parallel-axis theorem)."""


def _num(node, key, where, positive=False):
    if not isinstance(node, dict) or key not in node:
        raise SceneError(f'{where}.{key}: missing, expected a number')
    get = fields.positive if positive else fields.number
    return get(node[key], f'{where}.{key}')


def _pivot(spec, where):
    """Return (m, (u, v, w), ww, wu, vw) of a pivot body, checked."""
    spec = fields.mapping(spec, where)
    fields.known_keys(spec, {'mass_kg', 'centre_uvw_m', 'inertia_about_pivot_kg_m2'}, where)
    m = _num(spec, 'mass_kg', where, positive=True)
    c = fields.vector(fields.require(spec, 'centre_uvw_m', where), f'{where}.centre_uvw_m', 3)
    ip = f'{where}.inertia_about_pivot_kg_m2'
    inertia = fields.mapping(fields.require(spec, 'inertia_about_pivot_kg_m2', where), ip)
    fields.known_keys(inertia, {'ww', 'wu', 'vw'}, ip)
    ww, wu, vw = (_num(inertia, k, ip) for k in ('ww', 'wu', 'vw'))
    floor = m * (c[0] ** 2 + c[1] ** 2)
    if ww < floor * (1.0 - PARALLEL_AXIS_RTOL):
        raise SceneError(f'{ip}.ww: got {ww!r}, expected >= mass * (u^2 + v^2) = {floor:.6g} '
                         'kg m^2 (parallel-axis theorem)')
    return m, tuple(c), ww, wu, vw


def _combine(body, weight):
    """Return the pivot body of a link with its weight (masses, moments, I and products add)."""
    m = body[0] + weight[0]
    c = tuple((body[0] * a + weight[0] * b) / m for a, b in zip(body[1], weight[1]))
    return (m, c) + tuple(a + b for a, b in zip(body[2:], weight[2:]))


def _link(name, body, pin_name, pin_m):
    """Return a spatial link mapping of a pivot body (pivot at its origin, u along x)."""
    m, (u, v, w), ww, wu, vw = body
    spread = max(ww - m * (u * u + v * v), 0.0)    # I_ww about the centre
    bu, bv = wu - m * w * u, vw - m * v * w          # products about the centre
    if bv == 0.0:           # a rod along u: all the spread there, the product from w
        suu, svv = spread, 0.0
        sww = bu * bu / spread if spread > 0.0 else 0.0
    else:
        suu = svv = 0.5 * spread
        sww = (bu * bu + bv * bv) / (0.5 * spread) if spread > 0.0 else 0.0
    if spread == 0.0 and (bu or bv):
        raise SceneError(f'links.{name}.inertia_about_pivot_kg_m2: products ({wu!r}, {vw!r}) '
                         'with no spread about the axis; expected a larger ww')
    # I_com = tr(S) 1 - S with S the second moments about the centre: (ixx, iyy, izz, ixy, ...)
    inertia = [svv + sww, suu + sww, suu + svv, 0.0, -bu, -bv]
    return {'points': {pin_name[0]: [0.0, 0.0, 0.0], pin_name[1]: [pin_m, 0.0, 0.0]},
            'mass_kg': m, 'com_m': [u, v, w], 'inertia_com_kg_m2': inertia}


def _cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _unit(a):
    n = math.sqrt(sum(x * x for x in a))
    return [x / n for x in a]


def _poses(g, branch):
    """Return the assembly poses at crank angle 0 on ``branch`` (seed 002, eq. 23)."""
    l1, l2, l3, beta, a1, a2, a3 = g
    sb, cb = math.sin(beta), math.cos(beta)
    q1, q3 = [0.0, l2, l1], [l3 * sb, 0.0, l3 * cb]
    b = [a1, l2, l1]
    ex, ey, w3 = [cb, 0.0, -sb], [0.0, 1.0, 0.0], [sb, 0.0, cb]    # Ry(beta) x, y, z
    d = [q - p for q, p in zip(q3, b)]
    big_a = 2.0 * a3 * sum(x * y for x, y in zip(d, ex))
    big_b = 2.0 * a3 * sum(x * y for x, y in zip(d, ey))
    rhs = a2 * a2 - sum(x * x for x in d) - a3 * a3
    r = math.hypot(big_a, big_b)
    if r == 0.0 or abs(rhs) > r:
        raise SceneError(f'geometry: the RGGR cannot be assembled at crank angle 0 (|BC| = '
                         f'a2_m = {a2!r} is out of reach); expected a2_m within the reach of '
                         'the output link')
    delta = math.atan2(big_b, big_a)
    for phi3 in (delta + math.acos(rhs / r), delta - math.acos(rhs / r)):
        radial = [math.cos(phi3) * x + math.sin(phi3) * y for x, y in zip(ex, ey)]
        c = [q + a3 * x for q, x in zip(q3, radial)]
        bc = [y - x for x, y in zip(b, c)]
        triple = sum(x * y for x, y in zip(w3, _cross(bc, [a3 * x for x in radial])))
        if (triple > 0.0) == (branch > 0):
            break
    out_rot = [[radial[i], _cross(w3, radial)[i], w3[i]] for i in range(3)]
    x = _unit(bc)
    y = _unit(_cross([0.0, 0.0, 1.0], x)) if abs(x[2]) < 0.99 else _unit(_cross(ey, x))
    z = _cross(x, y)
    cpl_rot = [[x[i], y[i], z[i]] for i in range(3)]
    from mech_balance.rotations import matrix_rpy   # on first use: the parsers need no numpy
    return {'crank': {'origin_m': q1, 'rpy_deg': [0.0, 0.0, 0.0]},
            'coupler': {'origin_m': b, 'rpy_deg': [float(v) for v in matrix_rpy(cpl_rot, True)]},
            'output': {'origin_m': q3, 'rpy_deg': [float(v) for v in matrix_rpy(out_rot, True)]}}


def translate(data, source='<dict>'):
    """Return the ``kind: spatial`` mapping of a ``kind: rggr`` mapping (module docstring)."""
    data = fields.mapping(data, 'scene')
    fields.known_keys(data, {'kind', 'schema_version', 'name', 'description', 'geometry',
                             'links', 'balancing_weights', 'balancing_design', 'assembly',
                             'crank'}, '')
    version = data.get('schema_version', 1)
    if isinstance(version, bool) or version != 1:
        raise SceneError(f'schema_version: got {version!r}, expected 1')
    geo = fields.mapping(fields.require(data, 'geometry', ''), 'geometry')
    keys = ('l1_m', 'l2_m', 'l3_m', 'beta_deg', 'a1_m', 'a2_m', 'a3_m')
    fields.known_keys(geo, set(keys), 'geometry')
    g = [_num(geo, k, 'geometry', positive=k in ('a1_m', 'a2_m', 'a3_m')) for k in keys]
    g[3] = math.radians(g[3])
    l1, l2, l3, beta, a1, a2, a3 = g
    links = fields.mapping(fields.require(data, 'links', ''), 'links')
    fields.known_keys(links, {'crank', 'coupler', 'output'}, 'links')
    crank = _pivot(fields.require(links, 'crank', 'links'), 'links.crank')
    output = _pivot(fields.require(links, 'output', 'links'), 'links.output')
    cpl = fields.mapping(fields.require(links, 'coupler', 'links'), 'links.coupler')
    fields.known_keys(cpl, {'mass_kg', 'centre_from_b_m', 'transverse_inertia_kg_m2'},
                      'links.coupler')
    m2 = _num(cpl, 'mass_kg', 'links.coupler', positive=True)
    c2 = _num(cpl, 'centre_from_b_m', 'links.coupler')
    i2 = fields.nonneg(fields.require(cpl, 'transverse_inertia_kg_m2', 'links.coupler'),
                       'links.coupler.transverse_inertia_kg_m2')
    m_o1 = crank[0]
    fitted = fields.mapping(data.get('balancing_weights') or {}, 'balancing_weights')
    fields.known_keys(fitted, {'crank', 'output'}, 'balancing_weights')
    if fitted.get('crank') is not None:
        crank = _combine(crank, _pivot(fitted['crank'], 'balancing_weights.crank'))
    if fitted.get('output') is not None:
        output = _combine(output, _pivot(fitted['output'], 'balancing_weights.output'))
    branch = fields.require(fields.mapping(fields.require(data, 'assembly', ''), 'assembly'),
                            'branch', 'assembly')
    if isinstance(branch, bool) or branch not in (1, -1):
        raise SceneError(f'assembly.branch: got {branch!r}, expected +1 or -1')
    crank_cfg = fields.mapping(fields.require(data, 'crank', ''), 'crank')
    fields.known_keys(crank_cfg, {'speed_rad_s'}, 'crank')
    omega = fields.nonzero(fields.require(crank_cfg, 'speed_rad_s', 'crank'),
                           'crank.speed_rad_s')
    sb, cb = math.sin(beta), math.cos(beta)
    out = {
        'kind': 'spatial', 'schema_version': 1, 'name': data.get('name', 'rggr'),
        'description': data.get('description', ''),
        'normalization': {'mass_kg': m_o1, 'length_m': a1, 'omega_rad_s': abs(omega)},
        'frame': {'points': {'O': [0.0, 0.0, 0.0], 'E': [0.0, l2, 0.0],
                             'Q1': [0.0, l2, l1], 'Q3': [l3 * sb, 0.0, l3 * cb]}},
        'links': {'crank': _link('crank', crank, ('Q1', 'B'), a1),
                  'coupler': {'points': {'B': [0.0, 0.0, 0.0], 'C': [a2, 0.0, 0.0]},
                              'mass_kg': m2, 'com_m': [c2, 0.0, 0.0],
                              'inertia_com_kg_m2': [0.0, i2, i2, 0.0, 0.0, 0.0]},
                  'output': _link('output', output, ('Q3', 'C'), a3)},
        'joints': {'crank': {'type': 'revolute', 'a': 'frame.Q1', 'b': 'crank.Q1',
                             'axis': [0.0, 0.0, 1.0]},
                   'output': {'type': 'revolute', 'a': 'frame.Q3', 'b': 'output.Q3',
                              'axis': [sb, 0.0, cb], 'axis_b': [0.0, 0.0, 1.0]},
                   'B': {'type': 'spherical', 'a': 'crank.B', 'b': 'coupler.B'},
                   'C': {'type': 'spherical', 'a': 'coupler.C', 'b': 'output.C'}},
        'crank': {'joint': 'crank', 'speed_rad_s': omega, 'acceleration_rad_s2': 0.0},
        'moment_point_m': [0.0, 0.0, 0.0],
        'assembly': {'crank_angle_deg': 0.0, 'poses': _poses(g, branch)},
        'outputs': ['kinematics', 'shaking_wrench', 'driving_torque', 'bearing_reactions'],
    }
    design = data.get('balancing_design')
    if design is not None:
        design = fields.mapping(design, 'balancing_design')
        fields.known_keys(design, {'crank_weight_mass_kg',
                                   'output_weight_density_length_kg_m2'}, 'balancing_design')
        out['balancing_weights'] = {
            'crank': {'mass_kg': _num(design, 'crank_weight_mass_kg', 'balancing_design',
                                      positive=True)},
            'output': {'density_length_kg_m2': _num(
                design, 'output_weight_density_length_kg_m2', 'balancing_design',
                positive=True)}}
    if source not in _TOLD:
        _TOLD.add(source)
        LOG.warning('%s: kind rggr is read as the equivalent kind: spatial scene (the '
                    'closed-form RGGR model was removed); convert the file once with '
                    '`mech-balance scenes --convert %s --out NEW.yaml`', source, source)
    return out
