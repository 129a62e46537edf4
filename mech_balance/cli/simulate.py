"""The ``simulate`` and ``accuracy`` verbs of ``mech-balance`` (registered in cli.EXTENSIONS)."""

import argparse
import math
import sys

from mech_balance import conventions
from mech_balance.analysis import studies
from mech_balance.cli import jsonout, main as cli
from mech_balance.core import integrators


def _positive_float(text):
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'got {text!r}, expected a number > 0') from None
    if not math.isfinite(value) or value <= 0.0:
        raise argparse.ArgumentTypeError(f'got {text!r}, expected a finite number > 0')
    return value


_rows = cli.int_at_least(2, conventions.MAX_TABLE_ROWS, cli.FIXED_LIMIT)


def _sections(text):
    names = [s for s in text.replace(' ', '').split(',') if s]
    bad = [s for s in names if s not in studies.SECTIONS]
    if bad or not names:
        raise argparse.ArgumentTypeError(
            f'got {text!r}, expected a comma-separated list from '
            f'{",".join(studies.SECTIONS)}')
    return tuple(names)


def register(sub):
    """Add the ``simulate`` and ``accuracy`` parsers to the ``mech-balance`` subparsers."""
    p = sub.add_parser(
        'simulate', help='forward dynamics: start-up and steady state with motor and damping',
        description='Integrate the equation of motion of a rig of any kind (Sinatra & '
                    "Angeles eq. 39) with the scene's drive: section; prints the method and "
                    'why, the speed ripple, driving effort, shaking wrench and energy balance '
                    'over time. A scene without a drive coasts (docs/simulation.md).')
    p.add_argument('--scene', default='slider_crank',
                   help='built-in scene name or path to a YAML file (default: %(default)s)')
    p.add_argument('--duration', type=_positive_float, required=True, metavar='T',
                   help='simulated time in seconds')
    p.add_argument('--method', default='auto', choices=('auto',) + integrators.METHODS,
                   help='integrator; auto picks Radau for stiff rigs, else DOP853 '
                        '(default: %(default)s)')
    p.add_argument('--rtol', type=_positive_float, default=integrators.DEFAULT_RTOL,
                   help='relative tolerance (absolute tolerances scale with the rig; '
                        'default: %(default)g)')
    p.add_argument('--rhs', default='table', choices=('table', 'direct'),
                   help="right-hand side from checked Fourier tables of the rig's inverse "
                        'dynamics (fast) or the rig at every call (default: %(default)s)')
    p.add_argument('--rows', type=_rows, default=20,
                   help='rows of the time table (default: %(default)s)')
    p.add_argument('--json', action='store_true', help='print the summary as JSON')
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser(
        'accuracy', help='error against run time: RMS vs samples, integrators, Newton, '
                         'balancing',
        description='Error against run time for one scene: RMS against crank samples, '
                    'integrators, Newton residuals, the balancing certificate '
                    '(docs/simulation.md#the-accuracy-studies).')
    p.add_argument('--scene', default='hoeken',
                   help='built-in scene name or path to a YAML file (default: %(default)s)')
    p.add_argument('--duration', type=_positive_float, default=None, metavar='T',
                   help='simulated time of the integrator study in seconds (default: '
                        f'{studies.ACCURACY_TURNS:g} crank turns at the operating speed)')
    p.add_argument('--sections', type=_sections, default=studies.SECTIONS,
                   metavar='LIST',
                   help=f'which studies, comma-separated (default: '
                        f'{",".join(studies.SECTIONS)})')
    p.add_argument('--json', action='store_true', help='print the studies as JSON')
    p.set_defaults(func=cmd_accuracy)


def cmd_simulate(args):
    """Run a simulation and print its report."""
    from mech_balance.analysis import simulation
    rep = simulation.simulate(args.scene, args.duration, method=args.method, rtol=args.rtol,
                              rhs=args.rhs)
    if args.json:
        print(jsonout.dumps(rep.summary))
    else:
        print(simulation.format_report(rep, rows=args.rows))
    rig = rep.simulation.model.rig
    texts = getattr(rig, 'warnings', None) or getattr(getattr(rig, 'linkage', None),
                                                      'warnings', ())
    for text in texts:
        print(f'warning: {text}', file=sys.stderr)
    return 0


def cmd_accuracy(args):
    """Run the accuracy studies and print their tables."""
    from mech_balance import schema
    from mech_balance.bench import accuracy
    from mech_balance.core.rig import require
    if args.sections != studies.SECTIONS:   # sections asked for by name: refused up front
        sc = schema.load(args.scene)
        for name in args.sections:
            if name in accuracy.SECTION_CAPABILITY:
                require(sc, accuracy.SECTION_CAPABILITY[name], f'accuracy --sections {name}')
    result = accuracy.run(args.scene, args.sections, args.duration, progress=cli.progress)
    if args.json:
        print(jsonout.dumps(accuracy.to_jsonable(result)))
    else:
        print(accuracy.format_tables(result))
    return 0
