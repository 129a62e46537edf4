"""
``mech-balance balance``: optimal mass redistribution and analytic force balance of a scene.

A thin verb over :mod:`mech_balance.balancing` (planar scenes) and
:func:`mech_balance.rggr.balance_report` (RGGR scenes).  The seed-001 reference values
printed next to the results are the papers' tables (:mod:`mech_balance.seed_tables`).
"""

import argparse
import json
import sys

from mech_balance import atomic, balancing, bench, cli, conventions, scene as scene_mod, \
    seed_tables
import numpy as np

TABLE3_MASS_FACTORS = (1.0, 2.0, 5.0)
"""Seed 001 Table 3 cases (1)-(3): crank and rocker masses 1x, 2x, 5x the original."""
BENCH_REPEAT_MAX = 20
"""Timed optimizations per bench figure at most (the median is printed)."""
DEFAULT_CASE = 'a'
"""``--case`` of ``balance`` and ``record --balance``: seed 001 case a, masses of any sign."""
OUTPUT_SUFFIXES = ('.yaml', '.yml')
"""``--output``: what the balanced scene's file name ends in (so that it loads as a scene)."""
OPTIMIZE_OPTIONS = ('--weights', '--case', '--paper-constraints', '--no-realizable',
                    '--margin', '--mass-factors', '--distance-factors', '--torque-weight',
                    '--reaction-weight', '--max-added-mass', '--fix')
"""Options of the seed-001 optimization: rejected with --analytic and for RGGR scenes."""
ANALYTIC_OPTIONS = ('--mass-factor', '--keep-centroidal')
"""Options of --analytic alone: rejected without it."""
PLANAR_OPTIONS = OPTIMIZE_OPTIONS + ANALYTIC_OPTIONS + ('--analytic',)
"""Options RGGR scenes reject: their balancing (seed 002) has no such choices."""


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Append ``(default: ...)`` unless the default is None or False (said in words, or off)."""

    def _get_help_string(self, action):
        if action.default is None or action.default is False:
            return action.help
        return super()._get_help_string(action)


def _dest(option):
    return option.lstrip('-').replace('-', '_')


def add_weight_and_case(p, when=''):
    """
    Add ``--weights W1 W2`` and ``--case a|b`` (default None: the caller applies the defaults).

    ``when`` prefixes the help texts (e.g. ``'with --balance (planar): '``).  The weights
    are checked where they are used, by :func:`mech_balance.balancing.optimize`.
    """
    w1, w2 = balancing.DEFAULT_WEIGHTS
    p.add_argument('--weights', nargs=2, type=cli.weight, default=None, metavar=('W1', 'W2'),
                   help=f'{when}weights on the RMS normalized shaking force and shaking '
                        f'moment, seed 001 eq. 43 (default: {w1:g} {w2:g}, seed 001 case (2))')
    p.add_argument('--case', choices=balancing.CASES, default=None,
                   help=f'{when}seed 001 sec. 4.1.2: a = point masses of any sign, b = '
                        f'non-negative point masses (counterweights) (default: {DEFAULT_CASE})')


def register(subparsers):
    """Add the ``balance`` verb."""
    p = subparsers.add_parser(
        'balance', help='optimal mass redistribution (SOCP, certified) or analytic force '
                        'balance of a scene',
        description='Redistribute the link masses of a planar scene to minimize '
                    'w1 * RMS shaking force + w2 * RMS shaking moment (seed 001 eqs. 42-53) '
                    'to a certified global optimum, or (--analytic) balance the shaking force '
                    'completely (seed 000 eqs. 44-75, seed 001 eq. 48). Prints the design per '
                    'link, the before/after RMS table, the duality-gap certificate and the '
                    'solve time. RGGR scenes print the seed-002 balancing report.',
        formatter_class=_HelpFormatter)
    p.add_argument('--scene', default='hoeken',
                   help='built-in scene name (see `mech-balance scenes`) or path to a YAML file')
    add_weight_and_case(p)
    p.add_argument('--paper-constraints', action='store_true',
                   help="reproduce seed 001's problem exactly (eqs. 50/53: masses in [1, 5] x "
                        'original, l in [0.5, 1.5] x original, no realizability constraint)')
    p.add_argument('--no-realizable', action='store_true',
                   help='drop the realizability constraint (centroidal inertia >= margin x I_O)')
    p.add_argument('--margin', type=float, default=balancing.CENTROIDAL_MARGIN,
                   help='realizability margin: centroidal inertia >= MARGIN x inertia about '
                        'the link origin')
    p.add_argument('--mass-factors', nargs=2, type=float, metavar=('LO', 'HI'),
                   default=balancing.PAPER_MASS_FACTORS,
                   help='link mass bounds as factors of the original masses')
    p.add_argument('--distance-factors', nargs=2, type=float, metavar=('LO', 'HI'),
                   default=balancing.PAPER_DISTANCE_FACTORS,
                   help='point-mass distance bounds as factors of the original l = sqrt(I_O/m)')
    p.add_argument('--torque-weight', type=cli.weight, default=0.0,
                   help='extra weight on the RMS normalized driving torque')
    p.add_argument('--reaction-weight', type=cli.weight, default=0.0,
                   help='extra weight on the sum of the RMS normalized bearing forces')
    p.add_argument('--max-added-mass', type=float, default=None, metavar='KG',
                   help='cap on the total added mass (kg, over the original total)')
    p.add_argument('--fix', action='append', default=[], metavar='LINK',
                   help='keep this link as it is (repeatable)')
    p.add_argument('--samples', type=cli.int_at_least(4, conventions.MAX_SAMPLES,
                                                      'conventions.MAX_SAMPLES'), default=None,
                   help="crank angles per revolution (default: the scene's, usually 360)")
    p.add_argument('--analytic', action='store_true',
                   help='analytic complete force balance instead: slider-crank (seed 000 eqs. '
                        '44-75) or four-bar (Berkof-Lowen, seed 001 eq. 48)')
    p.add_argument('--mass-factor', type=float, action='append', default=None, metavar='K',
                   help='--analytic four-bar: crank and rocker masses K x original '
                        '(repeatable; default 1, 2 and 5 as in seed 001 Table 3)')
    p.add_argument('--keep-centroidal', action='store_true',
                   help='--analytic four-bar: keep the centroidal inertias (always realizable) '
                        'instead of the point-mass distance l (the paper)')
    p.add_argument('--si', action='store_true',
                   help="print SI values (default: the papers' normalized units when the scene "
                        'records a normalization)')
    p.add_argument('--json', action='store_true', help='print the result as JSON')
    p.add_argument('--output', default=None, metavar='FILE.yaml',
                   help='write the balanced scene (loadable by every other command) to a '
                        'file in an existing directory; checked before the solve')
    p.set_defaults(func=cmd_balance, option_defaults={
        option: p.get_default(_dest(option)) for option in PLANAR_OPTIONS})


def _given(args, options):
    """Return those of ``options`` that the command line set to other than their defaults."""
    def plain(value):
        return tuple(value) if isinstance(value, (list, tuple)) else value
    return [o for o in options
            if plain(getattr(args, _dest(o))) != plain(args.option_defaults[o])]


def _check_options(args):
    """Raise ValueError for an option the chosen method would ignore (no scene needed)."""
    ignored = _given(args, OPTIMIZE_OPTIONS if args.analytic else ANALYTIC_OPTIONS)
    if ignored and args.analytic:
        raise ValueError(f'{ignored[0]} applies to the optimization, not to --analytic; '
                         f'expected no {ignored[0]} with --analytic')
    if ignored:
        raise ValueError(f'{ignored[0]} applies with --analytic only, expected --analytic or '
                         f'no {ignored[0]}')


def cmd_balance(args):
    """Balance a scene and print the design, the before/after table and the certificate."""
    if args.samples is not None and args.samples < 4:
        raise ValueError(f'--samples: got {args.samples}, expected an integer >= 4')
    _check_options(args)
    sc = scene_mod.load(args.scene)
    if getattr(sc, 'kind', 'planar') == 'rggr':
        cli.planar_only(sc, **dict.fromkeys(_given(args, PLANAR_OPTIONS), True))
        return _rggr(sc, args)
    if args.output:
        cli.writable_path('--output', args.output, OUTPUT_SUFFIXES)
    if args.analytic:
        return _analytic(sc, args)
    paper = args.paper_constraints
    result = balancing.optimize(
        sc, weights=balancing.DEFAULT_WEIGHTS if args.weights is None else tuple(args.weights),
        case=DEFAULT_CASE if args.case is None else args.case,
        realizable=not args.no_realizable, paper_constraints=paper,
        samples=args.samples, torque_weight=args.torque_weight,
        reaction_weight=args.reaction_weight, max_added_mass_kg=args.max_added_mass,
        fixed_links=tuple(args.fix), mass_factors=tuple(args.mass_factors),
        distance_factors=tuple(args.distance_factors), centroidal_margin=args.margin)
    if args.output:
        _write(result.balanced_scene, args.output, result.summary())
    if args.json:
        print(json.dumps(result.to_dict(), indent=2))
        return 0
    print(format_result(result, normalized=not args.si))
    if args.output:
        print(f'balanced scene written to {args.output}')
    return 0


# ============================================================================ text output


def format_result(result, normalized=True):
    """Return a :class:`~mech_balance.balancing.BalanceResult` as readable text."""
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
              f'certificate ({cert.solver}): status {cert.status}, primal {cert.primal:.9g}, '
              f'dual {cert.dual:.9g}, gap {cert.gap_abs:.2e} (relative {cert.gap_rel:.2e}), '
              f'residuals {cert.residual_primal:.1e} / {cert.residual_dual:.1e}, '
              f'{cert.iterations} iterations',
              f'max constraint violation {cert.max_violation:.1e}']
    if cert.stage2 is not None:
        s2 = cert.stage2
        lines.append(f"tie-break (optimum not unique): minimized {s2['minimized']} among "
                     'optimal designs' + (' with the shaking force exactly zero'
                                          if s2['exact_force_balance'] else '')
                     + f": {s2['objective']:.6g} ({s2['status']}, {s2['iterations']} "
                     'iterations)')
    lines.append('design realizable: ' + ('yes' if result.realizable else 'NO ('
                 + ', '.join(d.name for d in result.links if not d.realizable) + ')'))
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
    from mech_balance import equimomental
    design = equimomental.apply_design(sc, x, normalized=True)
    return [balancing.link_design(lk, counterweights, sc.normalization)
            for lk in design.links]


# ============================================================================ analytic, RGGR


def _analytic(sc, args):
    kinds = {j.kind for j in sc.joints}
    if 'prismatic' in kinds:
        results = [balancing.slider_crank_balance(sc, samples=args.samples),
                   balancing.slider_crank_balance(sc, printed_eq75=True, samples=args.samples)]
    else:
        factors = args.mass_factor or list(TABLE3_MASS_FACTORS)
        inertia = 'centroidal' if args.keep_centroidal else 'distance'
        results = [balancing.four_bar_balance(sc, k, inertia, samples=args.samples)
                   for k in factors]
    if args.output:
        _write(results[0].balanced_scene, args.output,
               {'source_scene': sc.name, 'method': results[0].method,
                'parameters': results[0].parameters})
    if args.json:
        print(json.dumps([r.to_dict() for r in results], indent=2))
        return 0
    view = not args.si and sc.normalization is not None
    blocks = []
    for r in results:
        params = ', '.join(f'{k} = {v:.6g}' if isinstance(v, float) else f'{k} = {v}'
                           for k, v in r.parameters.items())
        blocks.append('\n'.join([
            f'{r.method}', f'parameters: {params}', '',
            _links_table(r.links, view, sc), '', _before_after_text(r.table, not view), '',
            f'RMS shaking force after / before: {r.force_rms_ratio:.3e}']))
    text = ('\n\n' + '=' * 99 + '\n\n').join(blocks)
    print(f'scene: {sc.name} ({sc.source})\n\n{text}')
    if args.output:
        print(f'balanced scene ({results[0].method}) written to {args.output}')
    return 0


def _rggr(sc, args):
    from mech_balance import rggr
    if args.output:
        raise ValueError('--output: RGGR scenes are balanced by mech_balance.rggr, which does '
                         'not export scenes; expected no --output for kind rggr')
    report = rggr.balance_report(sc, args.samples or rggr.DEFAULT_SAMPLES,
                                 normalized=not args.si)
    print(json.dumps(report, indent=2) if args.json else rggr.format_report(report))
    return 0


def _write(balanced, path, summary):
    text = balancing.scene_to_yaml(balanced, balance=summary)
    atomic.write_text_atomic(  # a failed write leaves an existing file as it was
        path, f'# written by mech-balance balance from scene {summary["source_scene"]}\n'
        + text)


# ============================================================================ bench


def bench_section(args, progress):
    """Return the bench table of :func:`balancing.optimize`: median wall time per case."""
    names = args.scene or ['hoeken', 'carpet_scraper']
    repeat = min(int(args.repeat), BENCH_REPEAT_MAX)
    head = (f"{'balance: scene':<18}{'case':<6}{'weights':<12}{'constraints':<13}"
            f"{'z':>12}{'rel. gap':>10}{'median ms':>11}{'cone ms':>9}")
    lines = [f'balance (seed 001 SOCP): median of {repeat} optimizations after '
             f'{bench.WARMUP} warm-up runs, {args.samples} crank angles'
             + (f' (--repeat {args.repeat} capped at {BENCH_REPEAT_MAX})'
                if args.repeat > repeat else ''),
             head, '-' * len(head)]
    header_lines = len(lines)
    for name in names:
        if name not in ('hoeken', 'carpet_scraper'):
            continue
        sc = scene_mod.load(name)
        cases = ('a', 'b') if name == 'hoeken' else ('a',)
        for case in cases:
            for w in seed_tables.WEIGHT_CASES:
                for paper in (True, False):
                    progress(f'  timing balance {name} {case} {w} '
                             f'{"paper" if paper else "realizable"} ...')
                    last = {}

                    def run(w=w, case=case, paper=paper, last=last):
                        last['r'] = balancing.optimize(sc, w, case, paper_constraints=paper,
                                                       samples=args.samples)
                    sec = bench.median_seconds(run, repeat=repeat)
                    r = last['r']
                    lines.append(f"{name:<18}{case:<6}{f'({w[0]:g}, {w[1]:g})':<12}"
                                 f"{'paper' if paper else 'realizable':<13}"
                                 f"{r.objective['z']:>12.6g}{r.certificate.gap_rel:>10.1e}"
                                 f'{sec * 1e3:>11.1f}{r.conic_time_s * 1e3:>9.1f}')
    if len(lines) == header_lines:
        lines.append('(no balancing benchmark for the selected scenes)')
    return '\n'.join(lines)


if __name__ == '__main__':  # pragma: no cover - use `mech-balance balance`
    sys.exit(cli.main(['balance', *sys.argv[1:]]))
