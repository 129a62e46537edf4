"""
``mech-balance balance``: optimal mass redistribution and analytic force balance of a scene.

A thin verb over :mod:`mech_balance.balancing` (its seed-002 weights report:
:func:`mech_balance.balancing.weights.balance_report`).  The seed-001
reference values printed next to the results are the papers' tables
(:mod:`mech_balance.seed_tables`).
"""

import argparse
import sys

from mech_balance import atomic, conventions
from mech_balance.balancing import defaults, options, paper_tables as seed_tables
from mech_balance.balancing.defaults import DEFAULT_CASE
from mech_balance.cli import jsonout, main as cli

TABLE3_MASS_FACTORS = (1.0, 2.0, 5.0)
"""Seed 001 Table 3 cases (1)-(3): crank and rocker masses 1x, 2x, 5x the original."""
BENCH_REPEAT_MAX = 20
"""Timed optimizations per bench figure at most (the median is printed)."""
OUTPUT_SUFFIXES = ('.yaml', '.yml')
"""``--output``: what the balanced scene's file name ends in (so that it loads as a scene)."""
OPTIMIZE_OPTIONS = ('--weights', '--case', '--paper-constraints', '--no-realizable',
                    '--margin', '--mass-factors', '--distance-factors', '--torque-weight',
                    '--reaction-weight', '--max-added-mass', '--fix')
"""Options of the seed-001 optimization: rejected with --analytic and for spatial rigs."""
ANALYTIC_OPTIONS = ('--mass-factor', '--keep-centroidal')
"""Options of --analytic alone: rejected without it."""
COUNTERWEIGHT_OPTIONS = ('--density', '--max-thickness', '--max-radius-factor',
                         '--max-mass-factor', '--max-gyration-factor')
"""Options of --counterweights alone: rejected without it."""
COUNTERWEIGHT_PLACEMENT = ('--planes', '--max-rim-radius-factor', '--clearance-margin',
                           '--no-clearance', '--disc-side', '--max-overhang', '--build-sheet')
"""Options of --counterweights alone that have no number default (checked by the solver)."""
COUNTERWEIGHT_KEYS = {'--density': 'density_kg_m3', '--max-thickness': 'max_thickness_m',
                      '--max-radius-factor': 'max_radius_factor',
                      '--max-mass-factor': 'max_mass_factor',
                      '--max-gyration-factor': 'max_gyration_factor'}
"""The counterweight options and their keys in :data:`.defaults.COUNTERWEIGHT_RANGES`."""
COUNTERWEIGHT_SHARED = ('--weights', '--torque-weight', '--reaction-weight')
"""Options of the optimization that --counterweights uses too (the rest it rejects)."""
PLANAR_OPTIONS = OPTIMIZE_OPTIONS + ANALYTIC_OPTIONS + COUNTERWEIGHT_OPTIONS + \
    COUNTERWEIGHT_PLACEMENT + ('--analytic', '--counterweights', '--model')
"""Options of the planar balancing (spatial rigs take only :data:`SPATIAL_SHARED` of them)."""
SPATIAL_SHARED = ('--weights', '--mass-factors', '--fix', '--counterweights', '--density',
                  '--max-mass-factor', '--max-radius-factor', '--clearance-margin',
                  '--no-clearance')
"""Options of the planar balancing that spatial rigs (body kinematics) take too."""
SPATIAL_OPTIONS = ('--method', '--extent-factor', '--force-balanced', '--free')
"""Options of spatial rigs alone (mech_balance.balancing.spatial)."""
SPATIAL_METHODS = ('auto', 'weights', 'force-balance', 'redistribution', 'counterweights')
"""``--method`` values (auto: the scene's balancing weights, else the redistribution)."""


TABLE_KEYS = tuple(opt.key for opt in options.OPTIONS if opt.flag is not None)
"""The options of :data:`mech_balance.balancing.options.OPTIONS` this verb offers, in order."""
PLANAR_KEYS = tuple(k for k in TABLE_KEYS if k not in ('extent_factor', 'force_balanced',
                                                       'free'))
"""Those the planar methods take (the rest are the spatial implementation's)."""
SPATIAL_KEYS = {'redistribution': ('weights', 'mass_factors', 'fixed_links', 'extent_factor',
                                   'force_balanced', 'samples'),
                'counterweights': ('links', 'weights', 'density_kg_m3', 'max_mass_factor',
                                   'max_radius_factor', 'samples', 'clearance_margin_m',
                                   'clearance'),
                'force_balance': ('free', 'samples')}
"""The options of each spatial method (:data:`mech_balance.balancing.SPATIAL_OPTIONS`)."""
TYPES = {'weights': cli.weight, 'torque_weight': cli.weight, 'reaction_weight': cli.weight,
         'samples': cli.int_at_least(4, conventions.MAX_SAMPLES, cli.FIXED_LIMIT)}
"""The command line's number parsers of some options (the rest: float, int, str)."""


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Append ``(default: ...)`` unless the default is None or False (said in words, or off)."""

    def _get_help_string(self, action):
        if action.default is None or action.default is False or action.default == []:
            return action.help
        if isinstance(action.default, tuple):   # the values as they are typed
            return f'{action.help} (default: {" ".join(f"{v:g}" for v in action.default)})'
        return super()._get_help_string(action)


def _range(key):
    lowest, highest = defaults.COUNTERWEIGHT_RANGES[key]
    return f'; range {lowest:g} to {highest:g}'


def _dest(option):
    return option.lstrip('-').replace('-', '_')


def add_weight_and_case(p, when='', case_when=None):
    """
    Add ``--weights W1 W2`` and ``--case a|b`` (default None: the caller applies the defaults).

    ``when`` prefixes the help texts (e.g. ``'with --balance (planar): '``), ``case_when``
    the help of ``--case`` when it applies in fewer cases (default: ``when``).  The weights
    are checked where they are used, by :func:`mech_balance.balancing.redistribution.optimize`.
    """
    case_when = when if case_when is None else case_when
    w1, w2 = defaults.DEFAULT_WEIGHTS
    p.add_argument('--weights', nargs=2, type=cli.weight, default=None, metavar=('W1', 'W2'),
                   help=f'{when}weights on the RMS normalized shaking force and shaking '
                        f'moment, Chaudhary & Saha eq. 43 (default: {w1:g} {w2:g}, their '
                        'case (2))')
    p.add_argument('--case', choices=defaults.CASES, default=None,
                   help=f'{case_when}Chaudhary & Saha sec. 4.1.2: a = point masses of any '
                        'sign, b = non-negative point masses (counterweights) (default: '
                        f'{DEFAULT_CASE})')


def register(subparsers):
    """Add the ``balance`` verb."""
    p = subparsers.add_parser(
        'balance', help='optimal mass redistribution (SOCP, certified) or analytic force '
                        'balance of a scene',
        description='Redistribute the link masses of a planar scene to minimize '
                    'w1 * RMS shaking force + w2 * RMS shaking moment (Chaudhary & Saha '
                    'eqs. 42-53) to a certified global optimum, or (--analytic) balance the '
                    'shaking force completely (Sinatra & Angeles eqs. 44-75, Chaudhary & Saha '
                    'eq. 48). Prints the design per link, the before/after RMS table, the '
                    'duality-gap certificate and the solve time. Scenes that list '
                    'balancing_weights (the RGGR) print the balancing-weight report of Hedaya. '
                    'Papers: see README.md, "The papers".',
        formatter_class=_HelpFormatter)
    p.add_argument('--scene', default='hoeken',
                   help='built-in scene name (see `mech-balance scenes`) or path to a YAML file')
    options.add_arguments(p, TABLE_KEYS[:TABLE_KEYS.index('links')], TYPES)
    p.add_argument('--analytic', action='store_true',
                   help='analytic complete force balance instead: slider-crank (Sinatra & '
                        'Angeles eqs. 44-75) or four-bar (Berkof-Lowen, Chaudhary & Saha '
                        'eq. 48)')
    p.add_argument('--mass-factor', type=float, action='append', default=None, metavar='K',
                   help='--analytic four-bar: crank and rocker masses K x original '
                        '(repeatable; default 1, 2 and 5 as in Chaudhary & Saha Table 3)')
    p.add_argument('--keep-centroidal', action='store_true',
                   help='--analytic four-bar: keep the centroidal inertias (always realizable) '
                        'instead of the point-mass distance l (the paper)')
    options.add_arguments(p, TABLE_KEYS[TABLE_KEYS.index('links'):
                                        TABLE_KEYS.index('extent_factor')], TYPES)
    p.add_argument('--build-sheet', default=None, metavar='FILE.svg',
                   help='--counterweights: write the build sheet (.svg; .png or .pdf by '
                        'rsvg-convert; each link as built with its '
                        'disc to scale, dimensions, material and mass; SVG)')
    p.add_argument('--model', choices=('three-point', 'two-point'), default='three-point',
                   help='two-point: also solve Chaudhary & Saha Appendix B (eqs. B.1-B.3, '
                        'Table 12) with two point masses per link at 0 and 90 deg, and print the '
                        "certified bounds next to the paper's rows")
    p.add_argument('--method', choices=SPATIAL_METHODS, default='auto',
                   help="spatial rigs (kind spatial): weights (Hedaya, the scene's "
                        'balancing_weights; the default where listed, e.g. rggr), '
                        'force-balance (the null space of the shaking force: conditions and '
                        'the least-change design), '
                        'redistribution (certified, every body a PSD pseudo-inertia; the '
                        'default of kind spatial), counterweights (add-only spheres, with '
                        '--counterweights LINKS)')
    options.add_arguments(p, TABLE_KEYS[TABLE_KEYS.index('extent_factor'):], TYPES)
    cli.add_units(p)
    p.add_argument('--json', action='store_true', help='print the result as JSON')
    p.add_argument('--output', default=None, metavar='FILE.yaml',
                   help='write the balanced scene (loadable by every other command) to a '
                        'file in an existing directory; checked before the solve')
    p.set_defaults(func=cmd_balance, option_defaults={
        option: p.get_default(_dest(option)) for option in PLANAR_OPTIONS + SPATIAL_OPTIONS})


def _given(args, options):
    """Return those of ``options`` that the command line set to other than their defaults."""
    def plain(value):
        return tuple(value) if isinstance(value, (list, tuple)) else value
    return [o for o in options
            if plain(getattr(args, _dest(o))) != plain(args.option_defaults[o])]


def _check_options(args):
    """Raise ValueError for an option the chosen method would ignore (no scene needed)."""
    import numpy as np
    if args.counterweights is not None:
        from mech_balance import identifiers
        identifiers.check_name_list(args.counterweights, '--counterweights')  # the node's
        if args.analytic:
            raise ValueError('--counterweights: a method of its own, expected no --analytic '
                             'with --counterweights')
        ignored = _given(args, tuple(o for o in OPTIMIZE_OPTIONS + ANALYTIC_OPTIONS
                                     if o not in COUNTERWEIGHT_SHARED))
        if args.model != 'three-point':
            ignored.insert(0, '--model')
        if ignored:
            raise ValueError(f'{ignored[0]} does not apply to --counterweights; expected no '
                             f'{ignored[0]} with --counterweights')
        for option in COUNTERWEIGHT_OPTIONS:
            value = getattr(args, _dest(option))
            if not (np.isfinite(value) and value > 0.0):
                raise ValueError(f'{option}: got {value:g}, expected a finite number > 0')
            defaults.check_counterweight_option(COUNTERWEIGHT_KEYS[option], value, option)
        if args.no_clearance and _given(args, ('--clearance-margin',)):
            raise ValueError('--clearance-margin: no clearance is asked for with '
                             '--no-clearance; expected one of them')
        options.check_args(args, ('clearance_margin_m', 'max_overhang_m'))
        if args.max_rim_radius_factor is not None:
            defaults.check_counterweight_option('max_rim_radius_factor',
                                                args.max_rim_radius_factor,
                                                '--max-rim-radius-factor')
        return
    given_cw = _given(args, COUNTERWEIGHT_OPTIONS + COUNTERWEIGHT_PLACEMENT)
    if given_cw:
        raise ValueError(f'{given_cw[0]} applies with --counterweights only, expected '
                         f'--counterweights LINK[,LINK...] or no {given_cw[0]}')
    if args.model != 'three-point' and (args.analytic or args.paper_constraints or
                                        args.torque_weight or args.reaction_weight):
        raise ValueError('--model two-point: Chaudhary & Saha eqs. B.1-B.3 have their own '
                         'bounds and weights w1, w2 only; expected no --analytic, '
                         '--paper-constraints, --torque-weight or --reaction-weight with it')
    ignored = _given(args, OPTIMIZE_OPTIONS if args.analytic else ANALYTIC_OPTIONS)
    if ignored and args.analytic:
        raise ValueError(f'{ignored[0]} applies to the optimization, not to --analytic; '
                         f'expected no {ignored[0]} with --analytic')
    if ignored:
        raise ValueError(f'{ignored[0]} applies with --analytic only, expected --analytic or '
                         f'no {ignored[0]}')


def cmd_balance(args):
    """Balance a scene and print the design, the before/after table and the certificate."""
    from mech_balance import balancing as front, schema as scene_mod
    from mech_balance.balancing import two_point
    from mech_balance.core.rig import rig_for
    if args.samples is not None and args.samples < 4:
        raise ValueError(f'--samples: got {args.samples}, expected an integer >= 4')
    _check_options(args)
    sc = scene_mod.load(args.scene)
    caps = scene_mod.kind_of(sc).rig_factory().capabilities
    spatial_given = _given(args, SPATIAL_OPTIONS)
    if 'mass_redistribution' not in caps and 'body_kinematics' in caps:
        cli.requires(sc, 'mass_redistribution', **dict.fromkeys(
            [o for o in _given(args, PLANAR_OPTIONS) if o not in SPATIAL_SHARED], True))
        return _spatial(sc, args)
    cli.requires(sc, 'body_kinematics', **dict.fromkeys(spatial_given, True))
    cli.requires(sc, 'mass_redistribution',
                 **dict.fromkeys(_given(args, PLANAR_OPTIONS), True))
    if spatial_given:
        raise ValueError(f'{spatial_given[0]}: applies to spatial rigs (body kinematics), got '
                         f'the planar scene {sc.name!r}; expected no {spatial_given[0]}')
    if args.output:
        cli.writable_path('--output', args.output, OUTPUT_SUFFIXES)
    if args.analytic:
        return _analytic(sc, args)
    if args.counterweights is not None:
        return _counterweights(sc, args)
    design = front.balance(rig_for(sc), 'redistribution',
                           **options.from_args(args, 'redistribution', PLANAR_KEYS))
    result = design.result
    if args.output:
        _write(result.balanced_scene, args.output, result.summary())
    table12 = None
    if args.model == 'two-point':
        table12 = two_point.table12(sc, result.weights, args.samples)
    if args.json:
        out = design.to_dict(args.normalized)
        if table12 is not None:
            out['report']['two_point_model'] = table12.to_dict()
        print(jsonout.dumps(out))
        return exit_status(result.certificate)
    print(format_result(result, normalized=args.normalized, cost=design.report['cost']))
    confidence = design.report.get('identification_confidence')
    if confidence is not None:
        from mech_balance.analysis import identify
        print(identify.format_balance_confidence(confidence))
    if table12 is not None:
        print('\n' + format_table12(table12))
    if args.output:
        print(f'balanced scene written to {args.output}')
    _warn(result.certificate)
    return exit_status(result.certificate)


def exit_status(cert):
    """Return 0 when the primary objective is certified, else 2 (a failed stage is warned)."""
    return 0 if cert.certified else 2


def certificate_lines(cert):
    """Return the certificate as text: primal, safe lower bound, gap, stages, violations."""
    lines = [f'certificate ({cert.solver}): status {cert.status}'
             + (f' (attempts: {", ".join(cert.attempts)})' if cert.attempts and
                len(cert.attempts) > 1 else '')
             + f', primal {cert.primal:.9g}, lower bound {cert.lower_bound:.9g}, gap '
             f'{cert.gap_abs:.2e} (relative {cert.gap_rel:.2e}), '
             + ('certified' if cert.certified else 'NOT certified')
             + f'; {cert.iterations} iterations, residuals {cert.residual_primal:.1e} / '
             f'{cert.residual_dual:.1e}',
             f"max constraint violation of the solver's design {cert.max_violation:.1e}"
             + (f' (moved {cert.feasibility_pull:.0e} of the way to a feasible anchor; the '
                'design reported satisfies every constraint)' if cert.feasibility_pull else
                ' (the design reported satisfies every constraint)'
                if cert.max_violation else '')]
    return lines


def _warn(cert):
    """Print one warning line per failed stage, and one if the objective is not certified."""
    for f in cert.failed_stages or ():
        print(f"warning: stage '{f['stage']}' failed: {f['reason']}; the design is "
              f"{f['design']}", file=sys.stderr)
    if not cert.certified:
        print(f'warning: the primary objective is not certified (relative gap '
              f'{cert.gap_rel:.1e} > {_certified_gap():.0e}); exit status 2', file=sys.stderr)


EXIT_NO_CLEAR_DESIGN = 3
"""Exit status of --counterweights when no collision-free design exists within the bounds."""


def _certified_gap():
    from mech_balance.balancing.certificate import CERTIFIED_GAP_REL
    return CERTIFIED_GAP_REL


def _counterweights(sc, args):
    from mech_balance import balancing as front
    from mech_balance.balancing.clearance_design import NoClearDesign
    from mech_balance.core.rig import rig_for
    from mech_balance.viz import build_sheet
    if args.build_sheet:   # checked before the solve
        build_sheet.check_path(args.build_sheet)
    try:
        design = front.balance(rig_for(sc), 'counterweights',
                               **options.from_args(args, 'counterweights', PLANAR_KEYS))
    except NoClearDesign as exc:   # no collision-free design: say why, give none
        result = exc.result
        if args.json:   # the Design's keys that exist without a design; why: in the report
            print(jsonout.dumps(no_design_dict(sc, result)))
        else:
            print('\n'.join(result.clearance_design.lines()))
        print(f'error: {NO_CLEAR_MESSAGE} (see above); none given (--no-clearance gives the '
              'convex optimum as is)', file=sys.stderr)
        return EXIT_NO_CLEAR_DESIGN
    result = design.result
    if args.output:
        _write(result.balanced_scene, args.output, result.summary())
    if args.build_sheet:
        build_sheet.write(result, args.build_sheet)
    for text in result.clearance.warnings():   # once, here only
        print(f'warning: {text}', file=sys.stderr)
    if args.json:
        print(jsonout.dumps(design.to_dict(args.normalized)))
        return exit_status(result.certificate)
    print(format_counterweights(result, normalized=args.normalized))
    if args.build_sheet:
        print(f'build sheet written to {args.build_sheet}')
    if args.output:
        print(f'scene with counterweights written to {args.output}')
    _warn(result.certificate)
    return exit_status(result.certificate)


def no_design_dict(sc, result):
    """
    Return ``balance --json`` of a counterweight problem with no collision-free design.

    The keys of :meth:`mech_balance.balancing.result.Design.to_dict` that exist without a
    design (``success`` false); ``report`` is the solver's, its ``clearance_design`` says why.
    """
    from mech_balance.schema import registry
    return {'scene': sc.name, 'kind': registry.kind_of(sc).name, 'method': 'counterweights',
            'success': False, 'message': NO_CLEAR_MESSAGE, 'report': result.to_dict()}


NO_CLEAR_MESSAGE = 'no collision-free counterweight design within the bounds'
"""What ``balance --counterweights`` says when :class:`.clearance_design.NoClearDesign`."""


def format_counterweights(result, normalized=False):
    """Return a :class:`~mech_balance.counterweights.CounterweightResult` as readable text."""
    from mech_balance.balancing import counterweights as cw_mod
    sc, opt = result.scene, result.options
    view = normalized and sc.normalization is not None
    w1, w2 = opt.weights
    lines = [f'scene: {sc.name} ({sc.source}); {opt.samples} crank angles per revolution',
             f'problem: add one solid disc to each of {", ".join(opt.links)}; minimize z = '
             f'{w1:g} f~ + {w2:g} n~'
             + (f' + {opt.torque_weight:g} tau~' if opt.torque_weight else '')
             + (f' + {opt.reaction_weight:g} sum f~_bearing' if opt.reaction_weight else ''),
             f'discs: density {opt.density_kg_m3:g} kg/m^3, thickness <= '
             f'{opt.max_thickness_m:g} m, centre <= {opt.max_radius_factor:g} x joint reach, '
             f'mass <= {opt.max_mass_factor:g} x link mass, radius of gyration <= '
             f'{opt.max_gyration_factor:g} x joint reach'
             + ('' if opt.max_rim_radius_factor is None else
                f', rim <= {opt.max_rim_radius_factor:g} x joint reach'), '']
    head = (f"{'link':<10}{'mass kg':>10}{'r m':>10}{'angle':>9}{'x m':>11}{'y m':>11}"
            f"{'disc R m':>10}{'t mm':>8}{'total kg':>10}{'total I_C':>11}")
    lines += ['counterweights (centre in the link frame; disc radius R and thickness t as '
              'built)', head, '-' * len(head)]
    for d in result.designs:
        tot = result.link_totals[d.link]
        lines.append(f'{d.link:<10}{d.mass_kg:>10.5g}{d.centre_radius_m:>10.5g}'
                     f'{d.centre_angle_deg:>9.2f} {d.centre_m[0]:>10.4g} {d.centre_m[1]:>10.4g}'
                     f'{d.radius_m:>10.5g}{d.thickness_m * 1e3:>8.3g}{tot["mass_kg"]:>10.5g}'
                     f'{tot["inertia_com_kg_m2"]:>11.4g}')
    for name in result.omitted:
        lines.append(f'{name:<10}  no counterweight (the optimal disc mass is zero)')
    lines.append(f'total added mass {result.added_mass_kg:.6g} kg')
    if result.clearance is not None:
        lines += result.clearance.lines()
    if result.clearance_design is not None:
        lines += result.clearance_design.lines()
    lines += ['', _before_after_text(result.table, si=not view), '']
    obj, cert = result.objective, result.certificate
    lines += [f"objective z = {obj['z']:.6g} (original {obj['z_original']:.6g}): "
              f"f~ = {obj['shaking_force_rms']:.6g}, n~ = {obj['shaking_moment_rms']:.6g}",
              *certificate_lines(cert)]
    if cert.stage2 is not None:
        s2 = cert.stage2
        lines.append(f"tie-break: minimized {s2['minimized']} among optimal designs"
                     + (' with the shaking force exactly zero' if s2['exact_force_balance']
                        else '') + f": {s2['objective']:.6g} (lower bound "
                     f"{s2['lower_bound']:.6g}; {s2['status']})")
    if result.least_mass is not None:
        lm = result.least_mass
        lines.append(f"tie-break: least total added mass {lm['objective_kg']:.6g} kg "
                     f"(lower bound {lm['lower_bound_kg']:.6g} kg; {lm['status']})")
    for f in cert.failed_stages or ():
        lines.append(f"FAILED stage '{f['stage']}': {f['reason']}; the design is "
                     f"{f['design']}")
    lines.append(cw_mod.format_cost(result.cost))
    lines.append(f'solve time {result.solve_time_s * 1e3:.1f} ms (linear maps '
                 f'{result.maps_time_s * 1e3:.1f} ms, cone programs '
                 f'{result.conic_time_s * 1e3:.1f} ms)')
    return '\n'.join(lines)


def format_table12(r):
    """Return seed 001 Table 12's comparison (:func:`mech_balance.two_point.table12`)."""
    paper = seed_tables.TABLE12.get(r.scene)
    head = f"{'seed 001 eqs. B.1-B.5':<44}{'torque':>10}{'force':>10}{'moment':>10}{'z':>10}"
    lines = [f'two-point-mass model (seed 001 Appendix B), weights ({r.weights[0]:g}, '
             f'{r.weights[1]:g}), normalized RMS', head, '-' * len(head)]

    def row(label, tau, f, n):
        z = r.weights[0] * f + r.weights[1] * n
        return f'{label:<44}{tau:>10.4g}{f:>10.4g}{n:>10.4g}{z:>10.5g}'

    if paper is not None and tuple(r.weights) == (0.5, 0.5):
        for key, label in (('two', 'paper, two point masses'),
                           ('three', 'paper, three point masses')):
            lines.append(row(label, *paper[key]))
    lo, up = r.lower_terms, r.upper_terms
    lines.append(row('three point masses = relaxation (certified)', lo['driving_torque'],
                     lo['shaking_force'], lo['shaking_moment']))
    lines.append(row('two point masses, best design found', up['driving_torque'],
                     up['shaking_force'], up['shaking_moment']))
    lines.append(f'certified: {r.lower_bound_z:.6g} <= two-point optimum <= '
                 f'{r.upper_bound_z:.6g} (bounds {r.gap_rel * 100:.2f}% apart; relaxation '
                 f'gap {r.lower_bound_gap_rel:.1e}); links the relaxation leaves outside the '
                 f'two-point set: {", ".join(r.band_links) or "none"}')
    return '\n'.join(lines)


# ============================================================================ text output


def format_result(result, normalized=False, cost=None):
    """
    Return a :class:`~mech_balance.balancing.redistribution.BalanceResult` as readable text.

    ``cost`` is the design's cost of balancing (the report's; computed when None).
    """
    from mech_balance.balancing import counterweights as cw_mod
    sc = result.scene
    view = normalized and sc.normalization is not None
    w1, w2 = result.weights
    lines = [f'scene: {sc.name} ({sc.source}); {result.samples} crank angles per revolution',
             f'problem: minimize z = {w1:g} f~ + {w2:g} n~'
             + (f' + {result.torque_weight:g} tau~' if result.torque_weight else '')
             + (f' + {result.reaction_weight:g} sum f~_bearing' if result.reaction_weight
                else '')
             + ' (seed 001 eqs. 42-53, RMS of normalized quantities)',
             f'constraints: case {result.case} ('
             + ('point masses >= 0' if result.case == 'b' else 'point masses of any sign')
             + '), ' + ('paper constraints (eqs. 50/53), realizability not imposed'
                        if result.paper_constraints else
                        'realizable links (centroidal inertia >= margin x I_O)'
                        if result.realizable_constraint else 'realizability not imposed')]
    if result.max_added_mass_kg is not None:
        lines.append(f'total added mass <= {result.max_added_mass_kg:g} kg')
    lines += ['', _links_table(result.links, view, sc), '']
    lines.append(_before_after_text(result.table, si=not view))
    obj, cert = result.objective, result.certificate
    lines += ['', f"objective z = {obj['z']:.6g} (original {obj['z_original']:.6g}): "
              f"f~ = {obj['shaking_force_rms']:.6g}, n~ = {obj['shaking_moment_rms']:.6g}",
              *certificate_lines(cert)]
    for f in cert.failed_stages or ():
        lines.append(f"FAILED stage '{f['stage']}': {f['reason']}; the design is "
                     f"{f['design']}")
    if cert.stage2 is not None:
        s2 = cert.stage2
        lines.append(f"tie-break (optimum not unique): minimized {s2['minimized']} among "
                     'optimal designs' + (' with the shaking force exactly zero'
                                          if s2['exact_force_balance'] else '')
                     + f": {s2['objective']:.6g} (lower bound {s2['lower_bound']:.6g}; "
                     f"{s2['status']}, {s2['iterations']} iterations)")
    lines.append('design realizable: ' + ('yes' if result.realizable else 'NO ('
                 + ', '.join(d.name for d in result.links if not d.realizable) + ')'))
    if cost is None:
        cost = cw_mod.cost_of_balancing(sc, result.balanced_scene, result.table)
    lines.append(cw_mod.format_cost(cost))
    lines.append(f'solve time {result.solve_time_s * 1e3:.1f} ms (linear maps '
                 f'{result.maps_time_s * 1e3:.1f} ms, cone programs '
                 f'{result.conic_time_s * 1e3:.1f} ms)')
    lines += _paper_comparison(result)
    return '\n'.join(lines)


def _links_table(links, view, sc):
    u = sc.normalization
    if view:
        head = (f"{'link':<10}{'m_1':>9}{'m_2':>9}{'m_3':>9}{'l':>9}{'mass':>9}{'d':>9}"
                f"{'theta':>8}{'I_O':>10}{'I_C':>10}  realizable")
        unit = '(normalized: masses by m1, lengths by a1, inertias by m1 a1^2; theta in deg)'
    else:
        head = (f"{'link':<10}{'m_1 kg':>10}{'m_2 kg':>10}{'m_3 kg':>10}{'l m':>10}"
                f"{'mass kg':>10}{'d m':>10}{'theta':>8}{'I_O kgm2':>11}{'I_C kgm2':>11}"
                '  realizable')
        unit = '(SI; theta in deg)'
    out = [unit, head, '-' * len(head)]
    for d in links:
        ok = 'yes' if d.realizable else f'NO: {d.reason}'
        if view:
            ms, ls = u.mass_kg, u.length_m
            i_s = ms * ls * ls
            pm = [m / ms for m in d.point_masses_kg]
            out.append(f'{d.name:<10}' + ''.join(f'{v:>9.4f}' for v in pm)
                       + f'{d.distance_m / ls:>9.4f}{d.mass_kg / ms:>9.4f}'
                       f'{d.com_distance_m / ls:>9.4f}{d.com_angle_deg:>8.2f}'
                       f'{d.inertia_origin_kg_m2 / i_s:>10.4f}'
                       f'{d.inertia_com_kg_m2 / i_s:>10.4f}  {ok}')
        else:
            out.append(f'{d.name:<10}' + ''.join(f'{v:>10.4g}' for v in d.point_masses_kg)
                       + f'{d.distance_m:>10.4g}{d.mass_kg:>10.4g}{d.com_distance_m:>10.4g}'
                       f'{d.com_angle_deg:>8.2f}{d.inertia_origin_kg_m2:>11.4g}'
                       f'{d.inertia_com_kg_m2:>11.4g}  {ok}')
    return '\n'.join(out)


def _before_after_text(table, si=False):
    head = f"{'RMS over the cycle':<26}{'unit':>13}{'before':>13}{'after':>13}{'change':>10}"
    out = [head, '-' * len(head)]
    sfx = '_si' if si else ''
    for r in table:
        ch = 'n/a' if r['change_percent'] is None else f"{r['change_percent']:+.1f}%"
        out.append(f"{r['quantity']:<26}{r['unit' + sfx]:>13}{r['before' + sfx]:>13.6g}"
                   f"{r['after' + sfx]:>13.6g}{ch:>10}")
    return '\n'.join(out)


def _case_index(weights):
    import numpy as np
    for k, w in enumerate(seed_tables.WEIGHT_CASES, 1):
        if np.allclose(weights, w):
            return k
    return None


def _paper_comparison(result):
    """Return lines comparing with seed 001 Tables 5/7 (Hoeken) or 9/10 (carpet scraper)."""
    k = _case_index(result.weights)
    name = result.scene.name
    if k is None or result.torque_weight or result.reaction_weight or \
            name not in ('hoeken', 'carpet_scraper'):
        return []
    w1, w2 = result.weights
    z = result.objective['z']
    lines = ['']
    if name == 'hoeken':
        f, n = seed_tables.TABLE7[(result.case, k)]
        x = seed_tables.TABLE5[(result.case, k)]
        label = f'Table 7 case {result.case}({k})'
    else:
        if result.case != 'a':
            return []
        _, f, n = seed_tables.TABLE10[k]
        x = seed_tables.TABLE9[k]
        label = f'Table 10 case ({k})'
    z_paper = w1 * f + w2 * n
    rel = (z - z_paper) / z_paper * 100.0
    lines.append(f'seed 001 {label}: f~ = {f:g}, n~ = {n:g}, z = {z_paper:.6g}; this optimum '
                 f'z = {z:.6g} ({rel:+.3f}%)'
                 + ('' if result.paper_constraints else
                    ' [other constraints than the paper: see --paper-constraints]'))
    designs = _paper_design_links(result.scene, x, result.case == 'b')
    bad = [f'{d.name} ({d.reason})' for d in designs if not d.realizable]
    lines.append("the paper's design vector: " + ('realizable' if not bad else
                                                  'NOT realizable: ' + '; '.join(bad)))
    return lines


def _paper_design_links(sc, x, counterweights):
    from mech_balance.balancing import tables
    from mech_balance.core import equimomental
    design = equimomental.apply_design(sc, x, normalized=True)
    return [tables.link_design(lk, counterweights, sc.normalization)
            for lk in design.links]


# ============================================================================ analytic, weights


def _analytic(sc, args):
    from mech_balance import balancing as front
    from mech_balance.balancing import counterweights as cw_mod
    from mech_balance.core.rig import rig_for
    rig = rig_for(sc)
    kinds = {j.joint_type for j in sc.joints}
    if 'prismatic' in kinds:
        designs = [front.balance(rig, 'analytic', samples=args.samples),
                   front.balance(rig, 'analytic', printed_eq75=True, samples=args.samples)]
    else:
        factors = args.mass_factor or list(TABLE3_MASS_FACTORS)
        inertia = 'centroidal' if args.keep_centroidal else 'distance'
        designs = [front.balance(rig, 'analytic', mass_factor=k, inertia=inertia,
                                 samples=args.samples) for k in factors]
    results = [d.result for d in designs]
    if args.output:
        _write(results[0].balanced_scene, args.output,
               {'source_scene': sc.name, 'method': results[0].method,
                'parameters': results[0].parameters})
    if args.json:
        out = designs[0].to_dict(args.normalized)
        out['report']['variants'] = [d.to_dict(args.normalized) for d in designs[1:]]
        print(jsonout.dumps(out))
        return 0
    view = args.normalized and sc.normalization is not None
    blocks = []
    for d, r in zip(designs, results):
        params = ', '.join(f'{k} = {v:.6g}' if isinstance(v, float) else f'{k} = {v}'
                           for k, v in r.parameters.items())
        blocks.append('\n'.join([
            f'{r.method}', f'parameters: {params}', '',
            _links_table(r.links, view, sc), '', _before_after_text(r.table, not view), '',
            f'RMS shaking force after / before: {r.force_rms_ratio:.3e}',
            cw_mod.format_cost(d.report['cost'])]))
    text = ('\n\n' + '=' * 99 + '\n\n').join(blocks)
    print(f'scene: {sc.name} ({sc.source})\n\n{text}')
    if args.output:
        print(f'balanced scene ({results[0].method}) written to {args.output}')
    return 0


def _weights(sc, args):
    """Balance by balancing weights (seed 002, the scene's ``balancing_weights``); report."""
    from mech_balance import balancing as front
    from mech_balance.balancing import spatial, weights
    from mech_balance.core.rig import rig_for
    if args.output:
        cli.writable_path('--output', args.output, OUTPUT_SUFFIXES)
    rig = rig_for(sc)
    design = front.balance(rig, 'weights', samples=args.samples)
    result = design.result
    if args.output:
        spatial.write_scene(result, args.output)
    report = weights.balance_report(rig, result, normalized=args.normalized)
    if args.json:
        out = design.to_dict(args.normalized)
        out['report'] = report   # the seed 002 report in the units asked for
        print(jsonout.dumps(out))
        return 0
    print(weights.format_report(report))
    print(f'certificate: RMS shaking moment {result.moment_rms_optimal_Nm:.9g} N m, safe '
          f'lower bound {result.moment_rms_lower_bound_Nm:.9g} N m (least squares, Hedaya '
          'eqs. 89-95)')
    if args.output:
        print(f'balanced scene written to {args.output}')
    return 0


def _spatial(sc, args):
    """Balance a rig with body kinematics (kind spatial) and print its result."""
    from mech_balance import balancing as front
    from mech_balance.balancing import spatial
    from mech_balance.core.rig import rig_for
    rig = rig_for(sc)
    method = 'counterweights' if args.counterweights is not None else \
        args.method.replace('-', '_')
    method = front.method_for(rig, method)
    if method == 'weights':
        ignored = [o for o in _given(args, SPATIAL_SHARED + SPATIAL_OPTIONS) if o != '--method']
        if ignored:
            raise ValueError(f'{ignored[0]}: not an option of the method weights (Hedaya, '
                             f'which takes --samples only); expected no {ignored[0]}, or '
                             '--method redistribution, force-balance or counterweights')
        return _weights(sc, args)
    if args.output:
        cli.writable_path('--output', args.output, OUTPUT_SUFFIXES)
    keys = SPATIAL_KEYS.get(method, ('samples',))
    if method == 'redistribution':
        # checked where read, before the solve (spatial.redistribute checks them again)
        defaults.check_range('--extent-factor', args.extent_factor,
                             *defaults.EXTENT_FACTOR_RANGE)
        for option, (low, high) in front.option_ranges(rig, method).items():
            for value in getattr(args, option):
                defaults.check_range(f'--{option.replace("_", "-")}', value, low, high)
    elif method == 'counterweights' and not args.counterweights:
        raise ValueError('--method counterweights: expected --counterweights LINK[,LINK...]')
    extent = options.BY_KEY['extent_factor'].default
    for option, value in (('--free', args.free), ('--force-balanced', args.force_balanced),
                          ('--extent-factor', args.extent_factor != extent)):
        wanted = {'--free': 'force_balance', '--force-balanced': 'redistribution',
                  '--extent-factor': 'redistribution'}[option]
        if value and method != wanted:
            raise ValueError(f'{option}: applies to --method {wanted.replace("_", "-")}, got '
                             f'method {method}; expected no {option}')
    from mech_balance.balancing.clearance_design import NoClearDesign
    try:
        design = front.balance(rig, method, **options.from_args(args, method, keys))
    except NoClearDesign as exc:   # the spheres collide: say why, give no design
        print(str(exc).replace('; ', '\n'))
        print('error: no collision-free counterweight design (see above); none given '
              '(--no-clearance gives the certified optimum as is)', file=sys.stderr)
        return EXIT_NO_CLEAR_DESIGN
    for text in design.report.get('warnings', []) if method == 'counterweights' else ():
        print(f'warning: {text}', file=sys.stderr)
    if args.output:
        spatial.write_scene(design.result, args.output)
    if args.json:
        print(jsonout.dumps(design.to_dict(args.normalized)))
    else:
        print(format_spatial(design, args.normalized))
        if args.output:
            print(f'balanced scene written to {args.output}')
    cert = getattr(design.result, 'certificate', None)
    return 0 if cert is None or cert.certified else 2


def format_spatial(design, normalized=False):
    """Return a spatial design (:mod:`mech_balance.balancing.spatial`) as readable text."""
    from mech_balance.balancing import spatial
    rep = design.report
    lines = [design.summary(), '']
    if design.method == 'force_balance':
        lines.append(f"complete force balance: rank {rep['rank']}, {rep['nullity']} free "
                     f"combinations; {'attained' if rep['attainable'] else 'NOT attainable'} "
                     f"by changing {', '.join(rep['free'])}")
        lines.append('conditions (SI: kg, kg m):')
        lines += spatial.format_conditions(rep['conditions'])
        for name, h in rep['added_first_moment_kg_m'].items():
            lines.append(f'  {name}: first moment change (body axes) '
                         + ' '.join(f'{x:.6g}' for x in h) + ' kg m, mass change '
                         f"{rep['added_mass_kg'][name]:.6g} kg")
        for name, reason in rep['unrealizable'].items():
            lines.append(f'  NOT realizable: {name}: {reason}')
        if rep['unrealizable']:
            lines.append('  the least change is no buildable design; a realizable one with zero '
                         'shaking force, if any: balance --method redistribution '
                         '--force-balanced')
    else:
        cert = rep['certificate']
        lines.append(f"{rep['method']}, weights {rep['weights'][0]:g} {rep['weights'][1]:g}")
        lines.append(f"{'body':<12}{'mass kg':>12}{'centre x':>12}{'y':>12}{'z':>12}"
                     f"{'min eig J':>12}")
        for b in rep['bodies']:
            lines.append(f"{b['name']:<12}{b['mass_kg']:>12.6g}"
                         + ''.join(f'{x:>12.5g}' for x in b['mass_centre_m'])
                         + f"{b['pseudo_inertia_min_eigenvalue']:>12.3g}")
        for name, cluster in rep['options'].get('counterweights', {}).items():
            for c in cluster:
                lines.append(f"  counterweight on {name}: sphere {c['mass_kg']:.5g} kg at "
                             + ' '.join(f'{x:.5g}' for x in c['centre_m'])
                             + f" m, outer radius {c['outer_radius_m']:.4g} m, inner "
                             f"{c['inner_radius_m']:.4g} m")
        if rep['options'].get('note'):
            lines.append(f"note: {rep['options']['note']}")
        lines.append(f"certificate: {cert['status']}, primal {cert['primal']:.9g}, lower bound "
                     f"{cert['lower_bound']:.9g}, gap {cert['gap_abs']:.2e} (relative "
                     f"{cert['gap_rel']:.2e}), max violation {cert['max_violation']:.1e}, "
                     f"{'certified' if cert['certified'] else 'NOT certified'}")
    lines += ['', f"{'quantity':<18}{'unit':<16}{'before':>12}{'after':>12}{'change %':>10}"]
    for r in design.table_in(normalized):
        change = 'n/a' if r['change_percent'] is None else f"{r['change_percent']:.1f}"
        lines.append(f"{r['quantity']:<18}{r['unit']:<16}{r['before']:>12.5g}"
                     f"{r['after']:>12.5g}{change:>10}")
    return '\n'.join(lines)


def _write(balanced, path, summary):
    from mech_balance import schema
    from mech_balance.balancing import redistribution
    from mech_balance.schema.registry import from_dict
    from mech_balance.schema.scene import parse_yaml
    text = redistribution.scene_to_yaml(balanced, balance=summary)
    try:   # a written scene always loads: check it as the loader will, before writing
        from_dict(parse_yaml(text, f'--output {path}'), source=str(path))
    except (ValueError, schema.SceneError) as exc:
        raise ValueError(f'--output: the design is not a scene the loader accepts ({exc}); '
                         'nothing written') from None
    atomic.write_text_atomic(  # a failed write leaves an existing file as it was
        path, f'# written by mech-balance balance from scene {summary["source_scene"]}\n'
        + text)


# ============================================================================ bench


if __name__ == '__main__':  # pragma: no cover - use `mech-balance balance`
    sys.exit(cli.main(['balance', *sys.argv[1:]]))
