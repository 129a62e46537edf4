"""
Balancing: one entry point, :func:`balance`, for the command line, the node and recordings.

``balance(rig, method=..., **options)`` returns a :class:`Design`; :data:`METHODS` by capability
(``auto``: the first the rig supports; docs/balancing.md, "Dispatch").
"""

from mech_balance.balancing.defaults import CENTROIDAL_MARGIN, DEFAULT_MAX_GYRATION_FACTOR, \
    DEFAULT_MAX_THICKNESS_M, DEFAULT_WEIGHTS, PAPER_DISTANCE_FACTORS, PAPER_MASS_FACTORS, \
    SPATIAL_MASS_FACTOR_RANGE
from mech_balance.balancing.result import Design

METHODS = {
    'redistribution': 'mass_redistribution',
    'weights': 'balancing_weights',
    'counterweights': 'counterweights',
    'analytic': 'analytic_balance',
    'force_balance': 'body_kinematics',
}
"""Balancing methods by name, and the rig capability each needs."""
ALTERNATIVES = {'redistribution': 'body_kinematics', 'counterweights': 'body_kinematics'}
"""Methods that a second capability (the spatial implementation) also supports."""
AUTO_LAST = ('force_balance',)
"""Methods ``auto`` picks only when nothing else applies."""
SPATIAL_OPTIONS = {
    'redistribution': ('weights', 'samples', 'mass_bounds', 'mass_factors', 'fixed_links',
                       'extent_bounds', 'extent_factor', 'force_balanced'),
    'counterweights': ('links', 'weights', 'samples', 'density_kg_m3', 'max_mass_factor',
                       'max_radius_factor'),
    'force_balance': ('samples', 'free')}
"""The options of each spatial method (other options: :data:`PLANAR_DEFAULTS`)."""
PLANAR_DEFAULTS = {'case': 'a', 'realizable': True, 'paper_constraints': False,
                   'distance_bounds': None, 'torque_weight': 0.0, 'reaction_weight': 0.0,
                   'max_added_mass_kg': None, 'max_thickness_m': DEFAULT_MAX_THICKNESS_M,
                   'max_gyration_factor': DEFAULT_MAX_GYRATION_FACTOR,
                   'distance_factors': PAPER_DISTANCE_FACTORS, 'tie_break': True,
                   'centroidal_margin': CENTROIDAL_MARGIN, 'mass_factors': PAPER_MASS_FACTORS,
                   'mass_bounds': None, 'fixed_links': (), 'disc_side': 'auto',
                   'max_overhang_m': None}
"""Planar options a spatial method ignores at these values (the node passes them all)."""


def _design(result, method, certificate, report=None):
    """Return the :class:`Design` of a result with a before/after table (``certificate``: text)."""
    rows = {r['quantity'].split()[1]: r for r in result.table
            if r['quantity'].startswith('shaking ')}
    return Design(result.balanced_scene, result.to_dict() if report is None else report, method,
                  result, {'force_N': (rows['force']['before_si'], rows['force']['after_si']),
                           'moment_Nm': (rows['moment']['before_si'],
                                         rows['moment']['after_si']),
                           'certificate': certificate})


LINK_OPTIONS = ('mass_bounds', 'distance_bounds')
"""Per-link options of the redistribution (``{link: (min, max)}``)."""


def link_options(rig):
    """Return the per-link options (:data:`LINK_OPTIONS`) the redistribution of ``rig`` takes."""
    caps = rig.capabilities
    if METHODS['redistribution'] in caps:
        return LINK_OPTIONS
    if ALTERNATIVES['redistribution'] in caps:
        return tuple(o for o in LINK_OPTIONS if o in SPATIAL_OPTIONS['redistribution'])
    return ()


def _supports(method, caps):
    return METHODS[method] in caps or ALTERNATIVES.get(method) in caps


SPATIAL_RANGES = {'redistribution': {'mass_factors': SPATIAL_MASS_FACTOR_RANGE}}
"""Options whose range is narrower in the spatial implementation of a method."""


def option_ranges(rig, method):
    """Return ``{option: (low, high)}``: the ranges of ``method`` narrower on ``rig``."""
    caps = rig.capabilities
    if METHODS.get(method) in caps or ALTERNATIVES.get(method) not in caps:
        return {}
    return dict(SPATIAL_RANGES.get(method, {}))


def _certificate_text(cert):
    """Return a certificate in a few words: status, certified or not, gap, failed stages."""
    text = (f'{cert.status}, {"certified" if cert.certified else "NOT certified"}, '
            f'lower bound {cert.lower_bound:.6g} <= z {cert.primal:.6g}, relative gap '
            f'{cert.gap_rel:.1e}')
    failed = [f['stage'] for f in cert.failed_stages or ()]
    if failed:
        text += f'; failed stage(s): {", ".join(failed)}'
    return text


def method_for(rig, method='auto'):
    """Return the method that balances ``rig`` (``auto``: the first the rig supports)."""
    caps = rig.capabilities
    if method == 'auto':
        for name, need in METHODS.items():
            if need in caps and name not in AUTO_LAST:
                return name
        for name, need in list(ALTERNATIVES.items()) + [(m, METHODS[m]) for m in AUTO_LAST]:
            if need in caps:
                return name
        raise ValueError(f'scene {rig.name!r}: no balancing method supports this rig')
    if method not in METHODS:
        raise ValueError(f'method: got {method!r}, expected auto or one of '
                         f'{", ".join(METHODS)}')
    if not _supports(method, caps):
        supported = [m for m in METHODS if _supports(m, caps)]
        raise ValueError(f'method: got {method!r}, which does not apply to scene '
                         f'{rig.name!r}; expected one of {", ".join(supported) or "none"}')
    return method


def _spatial_options(method, options):
    """Return the options of a spatial method (planar defaults dropped, others refused)."""
    accepted = SPATIAL_OPTIONS[method]
    out = {}
    for key, value in options.items():
        if key in accepted:
            if value is not None:
                out['fixed' if key == 'fixed_links' else key] = value
            continue
        plain = tuple(value) if isinstance(value, list) else value
        if key in PLANAR_DEFAULTS and (plain == PLANAR_DEFAULTS[key] or value is None):
            continue
        raise ValueError(f'{key}: not an option of the spatial {method} method (it takes '
                         f'{", ".join(accepted)}); got {value!r}')
    return out


def _spatial(rig, method, options):
    """Balance a rig with body kinematics (:mod:`mech_balance.balancing.spatial`)."""
    from mech_balance.balancing import clearance_design, spatial
    options = dict(options)   # the counterweights' clearance margin (None: the check off)
    margin = options.pop('clearance_margin_m', clearance_design.DEFAULT_CLEARANCE_MARGIN_M)
    options = _spatial_options(method, options)
    if method == 'force_balance':
        result = spatial.force_balance(rig, **options)
        ratio = result.force_rms_N[1] / max(result.force_rms_N[0], 1e-300)
        unbuilt = '' if result.realizable else \
            f', NOT realizable ({", ".join(result.unrealizable)})'
        return _design(result, method, f'null space (rank {result.rank}), RMS shaking force '
                                       f'after/before {ratio:.1e}{unbuilt}')
    if method == 'redistribution':
        result = spatial.redistribute(rig, **options)
    else:
        result = spatial.counterweights(rig, options.pop('links', ()), **options)
    cert = result.certificate
    # shorter than _certificate_text: a spatial optimum is often ~0 (e-notation on both sides)
    text = (f'{cert.status}, {"certified" if cert.certified else "NOT certified"}, '
            f'L {cert.lower_bound:.4g} <= z {cert.primal:.4g}, gap {cert.gap_rel:.1e}')
    entries = {}
    if method == 'counterweights':   # the spheres clear of every body (sphere_clearance)
        from mech_balance.balancing import sphere_clearance
        result, entries = sphere_clearance.design(rig, result, options.get('samples'), margin)
    return _design(result, method, text, dict(result.to_dict(), **entries))


def balance(rig, method='auto', **options):
    """Balance a rig (or scene) by ``method`` with its ``options``; return its :class:`Design`."""
    from mech_balance.core.rig import as_rig
    rig = as_rig(rig)
    method = method_for(rig, method)
    sc = rig.scene
    if method == 'force_balance' or METHODS[method] not in rig.capabilities:
        return _spatial(rig, method, options)
    if method == 'redistribution':
        from mech_balance.balancing import counterweights, redistribution
        result = redistribution.optimize(sc, **options)
        report = result.to_dict()
        report['identification_confidence'] = None
        if getattr(sc, 'identification', None) is not None:   # a calibrated scene: +-1 SE
            from mech_balance.analysis import identify   # (and scipy.linalg: only then)
            report['identification_confidence'] = identify.balance_confidence(
                sc, result.balanced_scene)
        report['cost'] = counterweights.cost_of_balancing(sc, result.balanced_scene,
                                                          result.table)
        return _design(result, method, _certificate_text(result.certificate), report)
    if method == 'counterweights':
        from mech_balance.balancing import clearance_design, counterweights
        result = counterweights.balance_with_counterweights(sc, options.pop('links', ()),
                                                            **options)
        if not result.answered:   # never a colliding design as the answer
            raise clearance_design.NoClearDesign(
                '; '.join(result.clearance_design.lines()), result)
        # the price of clearance and the least clearance: in the report (clearance_design)
        return _design(result, method, _certificate_text(result.certificate))
    if method == 'analytic':
        from mech_balance.balancing import analytic, counterweights
        if any(j.prismatic for j in sc.joints):
            result = analytic.slider_crank_balance(sc, **options)
        else:
            result = analytic.four_bar_balance(sc, **options)
        report = result.to_dict()
        report['cost'] = counterweights.cost_of_balancing(sc, result.balanced_scene,
                                                          result.table)
        return _design(result, method, 'closed form, RMS shaking force after/before '
                                       f'{result.force_rms_ratio:.1e}', report)
    from mech_balance.balancing import weights
    unknown = sorted(set(options) - {'samples'})
    if unknown:
        raise ValueError(f'{unknown[0]}: not an option of the {method} method (it takes '
                         'samples)')
    result = weights.balance_weights(rig, options.get('samples'))
    report = weights.balance_report(rig, result)
    rows = {r['rig']: r for r in report['rigs']}
    before, after = rows['unbalanced'], rows['optimized']
    figures = {'force_N': (before['shaking_force_rms'], after['shaking_force_rms']),
               'moment_Nm': (before['shaking_moment_rms'], after['shaking_moment_rms']),
               'certificate': 'least squares, normal-equation residual '
                              f'{result.normal_equation_residual:.1e}, RMS moment lower bound '
                              f'{result.moment_rms_lower_bound_Nm:.6g} N m'}
    return Design(result.balanced_scene, report, method, result, figures)


__all__ = ['ALTERNATIVES', 'balance', 'DEFAULT_WEIGHTS', 'Design', 'link_options', 'method_for',
           'METHODS']
