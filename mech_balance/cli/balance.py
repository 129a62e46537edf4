"""``mech-balance balance``: optimal mass redistribution and analytic force balance of a scene."""

import sys

from mech_balance import atomic, conventions
from mech_balance.balancing import options
from mech_balance.cli import balance_flags as flags, balance_text as text, jsonout, main as cli
from mech_balance.cli.balance_flags import add_weight_and_case, DEFAULT_CASE  # noqa: F401

OUTPUT_SUFFIXES = ('.yaml', '.yml')
"""``--output``: what the balanced scene's file name ends in (so that it loads as a scene)."""
SPATIAL_METHODS = ('auto', 'weights', 'force-balance', 'redistribution', 'counterweights')
"""``--method`` values (auto: the scene's balancing weights, else the redistribution)."""
EXIT_NOT_CERTIFIED = 2
"""Exit status when the primary objective is not certified (a failed stage is warned)."""
EXIT_NO_CLEAR_DESIGN = 3
"""Exit status of --counterweights when no collision-free design exists within the bounds."""
TABLE_KEYS = tuple(opt.key for opt in options.OPTIONS if opt.flag is not None)
"""The options of :data:`mech_balance.balancing.options.OPTIONS` this verb offers, in order."""
PLANAR_KEYS = tuple(opt.key for opt in options.OPTIONS
                    if opt.flag is not None and opt.flag not in flags.SPATIAL_OPTIONS)
"""Those the planar methods take (the rest are the spatial implementation's)."""
TYPES = {'weights': cli.weight, 'torque_weight': cli.weight, 'reaction_weight': cli.weight,
         'samples': cli.int_at_least(4, conventions.MAX_SAMPLES, cli.FIXED_LIMIT)}
"""The command line's number parsers of some options (the rest: float, int, str)."""


def register(subparsers):
    """Add the ``balance`` verb."""
    p = subparsers.add_parser(
        'balance', help='optimal mass redistribution (SOCP, certified) or analytic force '
                        'balance of a scene',
        description='Redistribute the link masses to minimize w1 * RMS shaking force + w2 * '
                    'RMS shaking moment to a certified global optimum (Chaudhary & Saha eqs. '
                    '42-53), or balance the shaking force completely (--analytic); prints '
                    'the design, the before/after table and the certificate (docs/balancing.md).',
        formatter_class=flags.HelpFormatter)
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
                   help="spatial rigs: weights (Hedaya, the scene's balancing_weights; auto "
                        'where listed), force-balance (conditions, least-change design), '
                        'redistribution (certified; auto otherwise), counterweights (add-only '
                        'spheres, with --counterweights LINKS)')
    options.add_arguments(p, TABLE_KEYS[TABLE_KEYS.index('extent_factor'):], TYPES)
    cli.add_units(p)
    p.add_argument('--json', action='store_true', help='print the result as JSON')
    p.add_argument('--output', default=None, metavar='FILE.yaml',
                   help='write the balanced scene (loadable by every other command) to a '
                        'file in an existing directory; checked before the solve')
    p.set_defaults(func=cmd_balance, option_defaults={
        flag: p.get_default(flags.dest(flag))
        for flag in flags.PLANAR_OPTIONS + flags.SPATIAL_OPTIONS})


def cmd_balance(args):
    """Balance a scene and print the design, the before/after table and the certificate."""
    from mech_balance import balancing, schema
    from mech_balance.balancing import two_point
    flags.check_planar(args)
    sc = schema.load(args.scene)
    caps = schema.kind_of(sc).rig_factory().capabilities
    spatial_given = flags.given(args, flags.SPATIAL_OPTIONS)
    if 'mass_redistribution' not in caps and 'body_kinematics' in caps:
        cli.requires(sc, 'mass_redistribution', **dict.fromkeys(
            [f for f in flags.given(args, flags.PLANAR_OPTIONS)
             if f not in flags.SPATIAL_SHARED], True))
        return _spatial(sc, args)
    cli.requires(sc, 'body_kinematics', **dict.fromkeys(spatial_given, True))
    cli.requires(sc, 'mass_redistribution',
                 **dict.fromkeys(flags.given(args, flags.PLANAR_OPTIONS), True))
    if spatial_given:
        raise ValueError(f'{spatial_given[0]}: applies to spatial rigs (body kinematics), got '
                         f'the planar scene {sc.name!r}; expected no {spatial_given[0]}')
    if args.output:
        cli.writable_path('--output', args.output, OUTPUT_SUFFIXES)
    if args.analytic:
        return _analytic(sc, args)
    if args.counterweights is not None:
        return _counterweights(sc, args)
    design = balancing.balance(sc, 'redistribution',
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
    print(text.format_result(design, normalized=args.normalized))
    if table12 is not None:
        print('\n' + text.format_table12(table12))
    if args.output:
        print(f'balanced scene written to {args.output}')
    _warn(result.certificate)
    return exit_status(result.certificate)


def exit_status(cert):
    """Return 0 when the primary objective is certified, else :data:`EXIT_NOT_CERTIFIED`."""
    return 0 if cert.certified else EXIT_NOT_CERTIFIED


def _warn(cert):
    for line in text.warning_lines(cert):
        print(line, file=sys.stderr)


def _counterweights(sc, args):
    from mech_balance import balancing
    from mech_balance.balancing.clearance_design import NoClearDesign
    from mech_balance.viz import build_sheet
    if args.build_sheet:   # checked before the solve
        build_sheet.check_path(args.build_sheet)
    try:
        design = balancing.balance(sc, 'counterweights',
                                   **options.from_args(args, 'counterweights', PLANAR_KEYS))
    except NoClearDesign as exc:   # no collision-free design: say why, give none
        result = exc.result
        if args.json:   # the Design's keys that exist without a design; why: in the report
            print(jsonout.dumps(text.no_design_dict(sc, result)))
        else:
            print('\n'.join(result.clearance_design.lines()))
        print(f'error: {text.NO_CLEAR_MESSAGE} (see above); none given (--no-clearance gives the '
              'convex optimum as is)', file=sys.stderr)
        return EXIT_NO_CLEAR_DESIGN
    result = design.result
    if args.output:
        _write(result.balanced_scene, args.output, result.summary())
    if args.build_sheet:
        build_sheet.write(result, args.build_sheet)
    for warning in result.clearance.warnings():   # once, here only
        print(f'warning: {warning}', file=sys.stderr)
    if args.json:
        print(jsonout.dumps(design.to_dict(args.normalized)))
        return exit_status(result.certificate)
    print(text.format_counterweights(design, normalized=args.normalized))
    if args.build_sheet:
        print(f'build sheet written to {args.build_sheet}')
    if args.output:
        print(f'scene with counterweights written to {args.output}')
    _warn(result.certificate)
    return exit_status(result.certificate)


def _analytic(sc, args):
    from mech_balance.balancing import paper_tables
    designs = paper_tables.analytic_variants(sc, args.mass_factor, args.keep_centroidal,
                                             args.samples)
    first = designs[0].result
    if args.output:
        _write(first.balanced_scene, args.output,
               {'source_scene': sc.name, 'method': first.method, 'parameters': first.parameters})
    if args.json:
        out = designs[0].to_dict(args.normalized)
        out['report']['variants'] = [d.to_dict(args.normalized) for d in designs[1:]]
        print(jsonout.dumps(out))
        return 0
    print(text.format_analytic(sc, designs, args.normalized))
    if args.output:
        print(f'balanced scene ({first.method}) written to {args.output}')
    return 0


def _weights(sc, rig, args):
    """Balance by balancing weights (seed 002, the scene's ``balancing_weights``); report."""
    from mech_balance import balancing
    from mech_balance.balancing import spatial, weights
    if args.output:
        cli.writable_path('--output', args.output, OUTPUT_SUFFIXES)
    design = balancing.balance(rig, 'weights', samples=args.samples)
    if args.output:
        spatial.write_scene(design.result, args.output)
    # seed 002's report in the units asked for (the design's is in SI)
    report = weights.balance_report(rig, design.result, normalized=args.normalized)
    if args.json:
        out = design.to_dict(args.normalized)
        out['report'] = report
        print(jsonout.dumps(out))
        return 0
    print(text.format_weights(design, report))
    if args.output:
        print(f'balanced scene written to {args.output}')
    return 0


def _spatial(sc, args):
    """Balance a rig with body kinematics (kind spatial) and print its result."""
    from mech_balance import balancing
    from mech_balance.balancing import spatial
    from mech_balance.balancing.clearance_design import NoClearDesign
    from mech_balance.core.rig import rig_for
    rig = rig_for(sc)
    method = balancing.method_for(rig, 'counterweights' if args.counterweights is not None
                                  else args.method.replace('-', '_'))
    if method == 'weights':
        flags.check_spatial(args, rig, method)
        return _weights(sc, rig, args)
    if args.output:
        cli.writable_path('--output', args.output, OUTPUT_SUFFIXES)
    flags.check_spatial(args, rig, method)
    keys = balancing.SPATIAL_OPTIONS.get(method, ('samples',)) + flags.CLEARANCE_KEYS
    try:
        design = balancing.balance(rig, method, **options.from_args(args, method, keys))
    except NoClearDesign as exc:   # the spheres collide: say why, give no design
        if args.json:   # every outcome JSON (balancing.sphere_clearance.NoSphereDesign)
            print(jsonout.dumps(text.no_design_dict(rig.scene, exc.result)))
        else:
            print(str(exc).replace('; ', '\n'))
        print('error: no collision-free counterweight design (see above); none given '
              '(--no-clearance gives the certified optimum as is)', file=sys.stderr)
        return EXIT_NO_CLEAR_DESIGN
    for warning in design.report.get('warnings', []) if method == 'counterweights' else ():
        print(f'warning: {warning}', file=sys.stderr)
    if args.output:
        spatial.write_scene(design.result, args.output)
    if args.json:
        print(jsonout.dumps(design.to_dict(args.normalized)))
    else:
        print(text.format_spatial(design, args.normalized))
        if args.output:
            print(f'balanced scene written to {args.output}')
    cert = getattr(design.result, 'certificate', None)
    return 0 if cert is None or cert.certified else EXIT_NOT_CERTIFIED


def _write(balanced, path, summary):
    """Write a balanced scene to ``path`` atomically, after checking that it loads."""
    from mech_balance import schema
    from mech_balance.balancing import redistribution
    from mech_balance.schema.registry import from_dict
    from mech_balance.schema.scene import parse_yaml
    scene_text = redistribution.scene_to_yaml(balanced, balance=summary)
    try:   # a written scene always loads: check it as the loader will, before writing
        from_dict(parse_yaml(scene_text, f'--output {path}'), source=str(path))
    except (ValueError, schema.SceneError) as exc:
        raise ValueError(f'--output: the design is not a scene the loader accepts ({exc}); '
                         'nothing written') from None
    atomic.write_text_atomic(  # a failed write leaves an existing file as it was
        path, f'# written by mech-balance balance from scene {summary["source_scene"]}\n'
        + scene_text)
