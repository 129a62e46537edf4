"""
The ``mech-balance`` command line: thin verbs over the numerical core.

Every verb validates its input at the boundary; a bad scene, field or option prints one
line naming the field, the value and what was expected, and exits with status 2.
"""

import argparse
import json
import os
import sys
import textwrap

from mech_balance import paths
import numpy as np

EXIT_USAGE = 2
EXIT_INTERRUPTED = 130
SCENE_NAME_WIDTH = 18
"""``mech-balance scenes``: width of the name column; the description wraps after it."""
LINE_WIDTH = 99
"""Width of printed text: ``mech-balance scenes`` wraps its descriptions to it at word breaks."""

EXTENSIONS = ('mech_balance.cli_balance', 'mech_balance.cli_record', 'mech_balance.cli_sim',
              'mech_balance.cli_urdf')
"""Modules that add verbs: each has ``register(subparsers)`` adding its parser(s) with
``set_defaults(func=...)``; a verb module owns its parser, handler and help text."""


class Parser(argparse.ArgumentParser):
    """
    ArgumentParser whose usage errors are one line: verb, message and where the help is.

    Subparsers inherit the class (``add_subparsers`` makes them of the parent's type), so every
    verb prints ``mech-balance VERB: error: MESSAGE (see mech-balance VERB --help)`` and exits
    with :data:`EXIT_USAGE`, without the usage block argparse prints first.
    """

    def error(self, message):
        """Print one line naming the verb and the problem to stderr; exit with status 2."""
        self.exit(EXIT_USAGE, f'{self.prog}: error: {message} (see {self.prog} --help)\n')

    def parse_args(self, args=None, namespace=None):
        """Parse like argparse; an unknown option is reported by the verb it was given to."""
        args, extras = self.parse_known_args(args, namespace)
        if extras:
            verbs = next((a.choices for a in self._actions
                          if isinstance(a, argparse._SubParsersAction)), {})
            verb = verbs.get(getattr(args, 'command', None), self)
            verb.error(f'unrecognized arguments: {" ".join(extras)}')
        return args


def int_at_least(lowest):
    """Return an argparse ``type`` that accepts integers >= ``lowest``."""
    def parse(text):
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f'got {text!r}, expected an integer >= {lowest}') from None
        if value < lowest:
            raise argparse.ArgumentTypeError(f'got {value}, expected an integer >= {lowest}')
        return value
    parse.__name__ = f'integer >= {lowest}'
    return parse


positive_int = int_at_least(1)
"""An argparse ``type``: an integer >= 1."""


def writable_path(option, text, suffixes, create_parent=False):
    """Return the output file of ``option``, checked before any computation (paths.py)."""
    return paths.check_output_path(text, option, suffixes, create_dir=create_parent)


def planar_only(sc, **given):
    """
    Raise ValueError when an option that only planar scenes use was given for another kind.

    ``given`` maps each option (``--design``) to whether the command line set it.
    """
    kind = getattr(sc, 'kind', 'planar')
    if kind == 'planar':
        return
    for option, was_given in given.items():
        if was_given:
            raise ValueError(f'{option} applies to planar scenes only, got scene {sc.name!r} '
                             f'of kind {kind}; expected no {option}')


def _add_scene(p):
    p.add_argument('--scene', default='hoeken',
                   help='built-in scene name (see `mech-balance scenes`) or path to a YAML '
                        'file (default: %(default)s)')


_samples = int_at_least(4)


def _design(text):
    try:
        values = [float(v) for v in text.replace(' ', '').split(',') if v]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f'got {text!r}, expected comma-separated numbers m11,m12,m13,l11,...') from None
    if not values or not all(np.isfinite(values)):
        raise argparse.ArgumentTypeError(f'got {text!r}, expected finite numbers')
    return values


def build_parser():
    """Return the argument parser of ``mech-balance``."""
    from mech_balance import bench
    parser = Parser(
        prog='mech-balance',
        description='Kinematics, inverse dynamics, shaking wrench and balancing of '
                    'single-input linkages (seeds 000-002).')
    sub = parser.add_subparsers(dest='command', metavar='COMMAND')
    sub.required = True

    p = sub.add_parser('analyze', help='RMS and extreme values of one crank revolution',
                       description='Analyze one revolution of a scene: bearing reactions, '
                                   'driving torque, shaking force and moment (RMS and max), '
                                   'worst Newton residual and Jacobian condition number.')
    _add_scene(p)
    p.add_argument('--normalized', action='store_true',
                   help="print in the papers' units (m1, a1, omega) recorded in the scene")
    p.add_argument('--samples', type=_samples, default=None,
                   help="crank angles per revolution (default: the scene's, usually 360)")
    p.add_argument('--design', type=_design, default=None, metavar='X1,X2,...',
                   help='evaluate a seed-001 design vector [m_i1,m_i2,m_i3,l_i1 per link]; '
                        'normalized units if the scene records a normalization, else SI; '
                        'write --design=-3.5,2.3,... when it starts with a minus sign')
    p.add_argument('--json', action='store_true', help='print the table as JSON')
    p.set_defaults(func=cmd_analyze)

    p = sub.add_parser('scenes', help='list the built-in scenes',
                       description='List the scenes shipped in config/.')
    p.set_defaults(func=cmd_scenes)

    p = sub.add_parser('bench', help='timings of the core (median of repeated runs)',
                       description='Time a full cycle (position, velocity, acceleration, '
                                   'inverse dynamics, bearing reactions, shaking wrench) of '
                                   'every built-in scene: median after warm-up.')
    p.add_argument('--scene', action='append', default=None,
                   help='time only this scene (repeatable; default: all built-in)')
    p.add_argument('--samples', type=_samples, default=360,
                   help='crank angles per cycle (default: %(default)s)')
    p.add_argument('--repeat', type=positive_int, default=bench.DEFAULT_REPEAT,
                   help='timed runs per figure, an integer >= 1 (default: %(default)s)')
    p.add_argument('--compare', choices=['mujoco'], default=None,
                   help='instead, run Hoeken and generated 4-20 link chains through this '
                        'package and through MuJoCo side by side: agreement, us per angle, '
                        'scaling (needs the optional mujoco package: make bench-mujoco)')
    p.set_defaults(func=cmd_bench)
    import importlib
    for name in EXTENSIONS:
        importlib.import_module(name).register(sub)
    return parser


def cmd_scenes(args):
    """List the built-in scenes."""
    from mech_balance import scene
    indent = ' ' * (SCENE_NAME_WIDTH + 1)
    for name, path in scene.builtin_scenes().items():
        data, _ = scene.load_data(path)
        text = ' '.join(str(data.get('description', '')).split())
        print(textwrap.fill(text, LINE_WIDTH, initial_indent=f'{name:<{SCENE_NAME_WIDTH}} ',
                            subsequent_indent=indent, break_long_words=False,
                            break_on_hyphens=False) if text else name)
    return 0


def cmd_analyze(args):
    """Analyze one revolution of a scene."""
    from mech_balance import analysis, equimomental, scene
    sc = scene.load(args.scene)
    planar_only(sc, **{'--design': args.design is not None})
    if getattr(sc, 'kind', 'planar') == 'rggr':
        from mech_balance import rggr
        report = rggr.analyze_report(sc, args.samples or rggr.DEFAULT_SAMPLES,
                                     args.normalized)
        print(json.dumps(report, indent=2) if args.json else rggr.format_report(report))
        return 0
    if args.design is not None:
        sc = equimomental.apply_design(sc, args.design,
                                       normalized=sc.normalization is not None)
    rig = analysis.Rig(sc)
    cycle = analysis.run_cycle(rig, args.samples)
    rows = analysis.summarize(cycle, args.normalized)
    if args.json:
        print(json.dumps({'scene': sc.name, 'samples': int(cycle.psi.size),
                          'crank_speed_rad_s': sc.crank_speed_rad_s,
                          'crank_acceleration_rad_s2': sc.crank_acceleration_rad_s2,
                          'outputs': list(sc.outputs),
                          'normalized': bool(args.normalized),
                          'rows': [r.__dict__ for r in rows],
                          'worst_residual': float(np.max(cycle.state.residual)),
                          'worst_condition': float(np.max(cycle.state.cond))}, indent=2))
    else:
        print(analysis.format_table(cycle, rows, args.normalized))
    for text in rig.linkage.warnings:
        print(f'warning: {text}', file=sys.stderr)
    return 0


def cmd_bench(args):
    """Print core timings."""
    if args.compare == 'mujoco':
        from mech_balance import bench_mujoco
        return bench_mujoco.cmd_compare(args)
    from mech_balance import bench
    print(f'mech-balance bench: median of {args.repeat} runs after {bench.WARMUP} warm-up '
          f'runs, {args.samples} crank angles per cycle', flush=True)
    progress = lambda s: print(s, file=sys.stderr, flush=True)  # noqa: E731
    rows = bench.run(args.scene, args.samples, args.repeat, progress=progress)
    print(bench.format_rows(rows), flush=True)
    import importlib
    for name in bench.SECTIONS:
        print()
        print(importlib.import_module(name).bench_section(args, progress), flush=True)
    return 0


def main(argv=None):
    """Run ``mech-balance``; return the exit status."""
    import warnings
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter('ignore', RuntimeWarning)  # reported in the tables
            return args.func(args)
    except ValueError as exc:
        print(f'mech-balance {args.command}: error: {exc}', file=sys.stderr)
        return EXIT_USAGE
    except OSError as exc:   # a file the verb reads or writes
        reason = exc.strerror or str(exc)
        if exc.filename is not None:
            reason = f'{os.fsdecode(exc.filename)}: {reason}'
        print(f'mech-balance {args.command}: error: {reason}', file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print('mech-balance: interrupted', file=sys.stderr)
        return EXIT_INTERRUPTED


if __name__ == '__main__':
    sys.exit(main())
