"""
The ``mech-balance record`` verb: a rerun recording of a rig, original against balanced.

The verb is thin: it loads the scenes, finds the balanced design (a scene file, or the
balancing of :mod:`mech_balance.balancing`) and hands both to
:func:`mech_balance.viz.recording.record`.  Its bench section times that call.
"""

import argparse
from pathlib import Path
import shutil
import sys

from mech_balance import conventions
from mech_balance.balancing import defaults, options
from mech_balance.balancing.defaults import DEFAULT_CASE
from mech_balance.cli import balance as cli_balance

OUT_SUFFIXES = ('.rrd',)
"""``--out``: what the recording's file name ends in."""


def _samples(text):
    try:
        value = int(text)
    except ValueError:
        value = None
    if value is None or value < 4:
        raise argparse.ArgumentTypeError(
            f'got {text!r}, expected an integer >= 4 (samples per crank turn)')
    return value


def register(subparsers):
    """Add the ``record`` verb to the ``mech-balance`` sub-parsers."""
    from mech_balance.cli import main as cli
    p = subparsers.add_parser(
        'record', help='write a rerun recording (.rrd) of the rig, original vs balanced',
        description='Write an offline rerun recording of a scene: the rig moving (links, '
                    'joints, mass centres, counterweights at true size), a gauge of the '
                    'shaking force and moment, and time series of |shaking force|, shaking '
                    'moment and every scalar output (driving torque, ...) for the original '
                    'and the balanced design, on the timelines crank_angle_deg (degrees from '
                    '0, the one the viewer opens) and time (s). The point masses are off '
                    'unless the scene switches them on (recording: {streams: {point_masses: '
                    'true}}). '
                    'Open the file with `rerun FILE.rrd`.')
    p.add_argument('--scene', default='hoeken',
                   help='built-in scene name (see `mech-balance scenes`) or path to a YAML '
                        'file (default: %(default)s)')
    which = p.add_mutually_exclusive_group()
    which.add_argument('--design', metavar='BALANCED.yaml', default=None,
                       help='balanced scene file: the same geometry with other inertias '
                            '(e.g. written by `mech-balance balance --output`)')
    which.add_argument('--balance', action='store_true',
                       help='balance the scene first: Chaudhary & Saha optimization for '
                            'planar scenes (mech_balance.balancing.redistribution), Hedaya '
                            'force balance and minimum RMS shaking moment for a scene with '
                            'balancing_weights, the certified spatial redistribution for the '
                            'other spatial scenes (mech_balance.balancing.spatial)')
    which.add_argument('--counterweights', default=None, metavar='LINK[,LINK...]',
                       help='balance the scene first with add-only counterweight discs on '
                            'these links (mech_balance.balancing.counterweights, its defaults; '
                            'as `mech-balance balance --counterweights`): the recording draws '
                            "each disc in its link's colour with its mass and its plane")
    cli_balance.add_weight_and_case(p, when='with --balance (planar) or --counterweights: ',
                                    case_when='with --balance (planar) only: ')
    p.add_argument('--cycles', type=cli.cycles, default=1,
                   help=f'crank turns to record, at most {conventions.MAX_CYCLES} '
                        '(default: %(default)s)')
    p.add_argument('--samples', type=_samples, default=None,
                   help="samples per crank turn, any count >= 4 (default: the scene's, "
                        'usually 360)')
    # the clearance of a counterweight design (--counterweights, --design): its collisions
    # are marked where the clearance is below the margin (mech_balance.viz.collisions)
    options.add_arguments(p, ('clearance_margin_m', 'clearance'))
    p.add_argument('--out', required=True, metavar='FILE.rrd',
                   help='the recording to write (its directory is created if needed)')
    p.set_defaults(func=cmd_record)


def balanced_design(sc, weights=defaults.DEFAULT_WEIGHTS, case=DEFAULT_CASE):
    """
    Return ``(balanced_scene, description)`` for ``--balance``.

    Planar scenes use :func:`mech_balance.balancing.redistribution.optimize` with ``weights``
    and ``case``;
    a scene that lists ``balancing_weights`` (the RGGR) the method ``weights`` of seed 002
    (:mod:`mech_balance.balancing.weights`: force balance, then minimum RMS moment), which
    takes neither.
    """
    from mech_balance import balancing as front
    from mech_balance.core.rig import rig_for
    rig = rig_for(sc)
    method = front.method_for(rig)
    if method == 'weights':
        return (front.balance(rig, method).scene,
                'Hedaya complete force balance with the minimum RMS shaking moment '
                '(mech_balance.balancing.weights)')
    design = front.balance(rig, method, weights=tuple(weights), case=case)
    if front.METHODS[method] not in rig.capabilities:   # the spatial implementation
        return (design.scene, f'{design.report["method"]}, (w1, w2) = ({weights[0]:g}, '
                f'{weights[1]:g}) (mech_balance.balancing.spatial)')
    return (design.scene,
            f'Chaudhary & Saha optimum, (w1, w2) = ({weights[0]:g}, {weights[1]:g}), case {case} '
            '(mech_balance.balancing.redistribution.optimize)')


def cmd_record(args):
    """Write the recording and say where it is and how to open it."""
    from mech_balance.cli import main as cli
    from mech_balance import schema as scene
    from mech_balance.viz import recording
    given = {'--weights': args.weights is not None, '--case': args.case is not None}
    margin = _margin(args)
    for option, was_given in given.items():
        allowed = args.balance or (option == '--weights' and args.counterweights is not None)
        if was_given and not allowed:
            also = ' or --counterweights' if option == '--weights' else ''
            raise ValueError(f'{option} applies with --balance{also} only, expected '
                             f'--balance{also} or no {option}')
    out = cli.writable_path('--out', args.out, OUT_SUFFIXES, create_parent=True)
    sc = scene.load(args.scene)
    balanced, source = None, None
    spheres = None   # a spatial counterweight design's spheres (their collisions drawn)
    if args.design is not None:
        balanced = scene.load(args.design)
        source = f'scene file {balanced.source}'
        if any(getattr(lk, 'counterweights', ()) for lk in balanced.links):
            from mech_balance.analysis import clearance
            source += clearance_note(clearance.of_design(sc, balanced, args.samples,
                                                         margin))
    elif args.counterweights is not None:
        from mech_balance import balancing as front
        from mech_balance.balancing.clearance_design import NoClearDesign
        weights = defaults.DEFAULT_WEIGHTS if args.weights is None else tuple(args.weights)
        # the design `mech-balance balance --counterweights LINKS --weights W1 W2` prints:
        # the same options by the same table (balancing.options), the clearance on
        try:
            design = front.balance(sc, 'counterweights', **options.from_args(
                args, 'counterweights', ('links', 'weights', 'clearance_margin_m',
                                         'clearance')))
        except NoClearDesign as exc:
            why = exc.result.clearance_design.lines() if exc.result is not None else \
                str(exc).split('; ')
            print('\n'.join(why), file=sys.stderr)
            print('error: no collision-free counterweight design within the bounds; nothing '
                  'recorded', file=sys.stderr)
            return cli_balance.EXIT_NO_CLEAR_DESIGN
        balanced = design.scene
        clear = getattr(design.result, 'clearance', None)   # planar: over the cycle
        if clear is None and isinstance(design.report.get('options'), dict):
            spheres = design.report['options'].get('counterweights') or None
            if spheres:   # a spatial design's spheres, checked at the recorded angles
                from mech_balance.analysis import spatial_clearance
                from mech_balance.core.rig import rig_for
                clear = spatial_clearance.check(rig_for(sc), spheres, args.samples, margin)
        margin = margin if clear is None else clear.margin_m
        source = (f'add-only counterweights on {args.counterweights}, (w1, w2) = '
                  f'({weights[0]:g}, {weights[1]:g}) (mech_balance.balancing.counterweights)'
                  + ('' if clear is None else clearance_note(clear)))
    elif args.balance:
        cli.requires(sc, 'mass_redistribution', **given)
        balanced, source = balanced_design(
            sc, defaults.DEFAULT_WEIGHTS if args.weights is None else tuple(args.weights),
            DEFAULT_CASE if args.case is None else args.case)
    summary = recording.record(out, sc, balanced, cycles=args.cycles, samples=args.samples,
                               balanced_source=source, field='--out',
                               clearance_margin_m=margin, spheres=spheres)
    path = summary.path.resolve()
    print(f'wrote {path}')
    print(f'  {sc.name}: {" vs ".join(summary.variants)}; {summary.samples_per_cycle} '
          f'samples x {summary.cycles} turn(s); {summary.size_bytes / 1e6:.2f} MB in '
          f'{summary.seconds:.2f} s')
    if source:
        print(f'  balanced design: {source}')
    print(f'open it with:  {_viewer()} {path}')
    print('  (the viewer comes with rerun-sdk; it plays the crank_angle_deg timeline in a '
          'loop)')
    sys.stdout.flush()
    return 0


def _margin(args):
    """Return the clearance margin of a design (m; 0 with --no-clearance), checked."""
    if args.no_clearance:
        if args.clearance_margin != options.BY_KEY['clearance_margin_m'].default:
            raise ValueError('--clearance-margin: no clearance is asked for with '
                             '--no-clearance; expected one of them')
        return 0.0
    if args.counterweights is None and args.design is None and \
            args.clearance_margin != options.BY_KEY['clearance_margin_m'].default:
        raise ValueError('--clearance-margin applies with --counterweights or --design only, '
                         'expected one of them or no --clearance-margin')
    options.check_args(args, ('clearance_margin_m',))
    return float(args.clearance_margin)


def clearance_note(clear):
    """
    Print a design's least clearance (each collision once, as a warning) and return it.

    The text returned is what the recording's info panel shows after the design's source.
    """
    text = clear.lines()[0]   # the line `mech-balance balance` prints
    print(f'  {text}')
    for line in clear.warnings():
        print(f'warning: {line}', file=sys.stderr)
    marks = ''.join(f'; COLLISION: {c.body_a} and {c.body_b} overlap by '
                    f'{-c.clearance_m * 1e3:.3g} mm at crank angle {c.crank_angle_deg:.2f} deg'
                    for c in clear.collisions)
    return f'; {text}{marks}'


def _viewer():
    """Return how to call the rerun viewer: on PATH, else next to this Python (a venv)."""
    if shutil.which('rerun'):
        return 'rerun'
    beside = Path(sys.executable).parent / 'rerun'
    return str(beside) if beside.exists() else 'rerun'
