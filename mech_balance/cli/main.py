"""
The ``mech-balance`` command line: thin verbs over the numerical core.

A bad scene, field or option prints one line naming it, its value and what was expected,
and exits with status 2.
"""

import argparse
import importlib
import math
import os
import signal
import sys
import textwrap
import warnings

from mech_balance import atomic, conventions, paths, threads
from mech_balance.cli import jsonout
from mech_balance.schema.fields import MAX_ABS_VALUE

EXIT_USAGE = 2
EXIT_BENCH_FAILED = 3
"""Exit status of ``mech-balance bench`` when a table printed a FAIL verdict."""
SCENE_NAME_WIDTH = 18
"""``mech-balance scenes``: width of the name column; the description wraps after it."""
LINE_WIDTH = 99
"""Width of printed text: ``mech-balance scenes`` wraps its descriptions to it at word breaks."""

EXTENSIONS = ('mech_balance.cli.balance', 'mech_balance.cli.record', 'mech_balance.cli.simulate',
              'mech_balance.cli.identify', 'mech_balance.cli.urdf')
"""Modules that add verbs: each has ``register(subparsers)`` adding its parser(s) with
``set_defaults(func=...)``; a verb module owns its parser, handler and help text."""


INTERRUPTING_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Interrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM received while a verb runs (a KeyboardInterrupt, as Ctrl-C is)."""

    def __init__(self, signum):
        """Keep the signal's number."""
        super().__init__(signum)
        self.signum = signum

    def __str__(self):
        """Return the signal's name."""
        return signal.Signals(self.signum).name


FINALIZER_RESEND_S = 0.05
"""A signal arriving in a ``__del__`` (where an exception is printed and dropped) is sent
again after this many seconds instead of raised there."""


def _raise_interrupted(signum, frame):
    if atomic.defer_signal(signum):   # raised again once the file is listed or renamed
        return
    while frame is not None:
        if frame.f_code.co_name == '__del__':
            import threading
            timer = threading.Timer(FINALIZER_RESEND_S, os.kill, (os.getpid(), signum))
            timer.daemon = True
            timer.start()
            return
        frame = frame.f_back
    raise Interrupted(signum)


def _interrupted(verb, exc, mark):
    """Report an interrupted verb on stderr; return its status (0 if every file was written)."""
    signum = getattr(exc, 'signum', signal.SIGINT)
    name = signal.Signals(signum).name
    atomic.discard_pending()
    written = [os.fsdecode(p) for p in atomic.written_since(mark)]
    removed = [os.fsdecode(p) for p in atomic.discarded_since(mark)]
    line = f'mech-balance{" " + verb if verb else ""}: interrupted ({name})'
    if written:
        line += f'; written completely: {", ".join(written)}'
    if removed:
        line += ('; not written, its partial file removed: '
                 f'{", ".join(removed)}')
    print(line, file=sys.stderr)
    return 0 if written and not removed else 128 + signum


class Parser(argparse.ArgumentParser):
    """ArgumentParser whose usage errors are one line naming the verb; exits :data:`EXIT_USAGE`."""

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


def int_at_least(lowest, highest=None, limit=None):
    """
    Return an argparse ``type`` that accepts integers >= ``lowest`` (and <= ``highest``).

    ``limit`` names the constant of ``highest`` in the error (``conventions.MAX_SAMPLES``).
    """
    def parse(text):
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f'got {text!r}, expected an integer >= {lowest}') from None
        if value < lowest:
            raise argparse.ArgumentTypeError(f'got {value}, expected an integer >= {lowest}')
        if highest is not None and value > highest:
            raise argparse.ArgumentTypeError(
                f'got {value}, expected an integer <= {highest}'
                + (f' ({limit})' if limit else ''))
        return value
    parse.__name__ = f'integer >= {lowest}'
    return parse


def number_between(lowest, highest, limit=None):
    """Return an argparse ``type``: a finite number ``lowest <= x <= highest``."""
    def parse(text):
        try:
            value = float(text)
        except ValueError:
            value = None
        if value is None or not lowest <= value <= highest:  # also refuses nan
            raise argparse.ArgumentTypeError(
                f'got {text!r}, expected a number {lowest:g} <= x <= {highest:g}'
                + (f' ({limit})' if limit else ''))
        return value
    parse.__name__ = f'number in [{lowest:g}, {highest:g}]'
    return parse


FIXED_LIMIT = 'a fixed limit of mech_balance'
"""What an option's range error says of a limit no option or field raises."""
cycles = int_at_least(1, conventions.MAX_CYCLES, FIXED_LIMIT)
"""An argparse ``type``: crank turns, 1 <= n <= MAX_CYCLES."""
repeats = int_at_least(1, conventions.MAX_REPEAT, FIXED_LIMIT)
"""An argparse ``type``: timed runs of a benchmark, 1 <= n <= MAX_REPEAT."""
weight = number_between(0.0, conventions.MAX_WEIGHT, FIXED_LIMIT)
"""An argparse ``type``: an objective weight, 0 <= w <= MAX_WEIGHT."""


def progress(text):
    """Print a verb's progress on stderr (stdout holds its result)."""
    print(text, file=sys.stderr, flush=True)


def writable_path(option, text, suffixes, create_parent=False):
    """Return the output file of ``option``, checked before any computation (paths.py)."""
    return paths.check_output_path(text, option, suffixes, create_dir=create_parent)


def requires(sc, capability, **given):
    """
    Raise ValueError when an option in ``given`` was set for a rig lacking ``capability``.

    ``given`` maps each option (``--design``) to whether it was set; the message names the kinds.
    """
    from mech_balance.schema import registry
    kind = registry.kind_of(sc)
    if capability in kind.rig_factory().capabilities:
        return
    able = ' and '.join(k.name for k in registry.KINDS.values()
                        if capability in k.rig_factory().capabilities)
    for option, was_given in given.items():
        if was_given:
            raise ValueError(f'{option} applies to {able} scenes only, got scene {sc.name!r} '
                             f'of kind {kind.name}; expected no {option}')


def add_units(p):
    """Add ``--normalized`` and ``--si`` (SI is the default of every verb; ``--si`` accepted)."""
    g = p.add_mutually_exclusive_group()
    g.add_argument('--normalized', action='store_true',
                   help="print in the papers' normalized units (m1, a1, omega) recorded in the "
                        'scene (default: SI)')
    g.add_argument('--si', action='store_true',
                   help='print SI values (the default; kept for scripts that pass it)')


_samples = int_at_least(4, conventions.MAX_SAMPLES, FIXED_LIMIT)


def _design(text):
    try:
        values = [float(v) for v in text.replace(' ', '').split(',') if v]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f'got {text!r}, expected comma-separated numbers m11,m12,m13,l11,...') from None
    if not values or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f'got {text!r}, expected finite numbers')
    if max(abs(v) for v in values) > MAX_ABS_VALUE:  # the magnitude limit of scene files
        raise argparse.ArgumentTypeError(
            f'got {text!r}, expected numbers of magnitude <= {MAX_ABS_VALUE:g} '
            '(the limit of numbers in scene files)')
    return values


def build_parser():
    """Return the argument parser of ``mech-balance``."""
    from mech_balance.analysis import timing
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
    p.add_argument('--scene', default='hoeken',
                   help='built-in scene name (see `mech-balance scenes`) or path to a YAML '
                        'file (default: %(default)s)')
    add_units(p)
    p.add_argument('--samples', type=_samples, default=None,
                   help="crank angles per revolution (default: the scene's, usually 360)")
    p.add_argument('--design', type=_design, default=None, metavar='X1,X2,...',
                   help='evaluate a Chaudhary & Saha design vector [m_i1,m_i2,m_i3,l_i1 per '
                        'link]; normalized units if the scene records a normalization, else SI; '
                        'write --design=-3.5,2.3,... when it starts with a minus sign')
    p.add_argument('--json', action='store_true', help='print the table as JSON')
    p.set_defaults(func=cmd_analyze)

    p = sub.add_parser('scenes', help='list the built-in scenes',
                       description='List the scenes shipped in config/.')
    p.add_argument('--convert', default=None, metavar='OLD.yaml',
                   help='instead, write this scene as its kind reads it now (a former kind: '
                        'rggr file as its kind: spatial scene) to --out')
    p.add_argument('--out', default=None, metavar='NEW.yaml', help='--convert: the file')
    p.set_defaults(func=cmd_scenes)

    p = sub.add_parser('bench', help='timings of the core (median of repeated runs)',
                       description='Time a full cycle (position, velocity, acceleration, '
                                   'inverse dynamics, bearing reactions, shaking wrench) of '
                                   'every built-in scene: median after warm-up.')
    p.add_argument('--scene', action='append', default=None,
                   help='time only this scene (repeatable; default: all built-in)')
    p.add_argument('--samples', type=_samples, default=360,
                   help='crank angles per cycle (default: %(default)s)')
    p.add_argument('--repeat', type=repeats, default=timing.DEFAULT_REPEAT,
                   help='timed runs per figure, an integer >= 1 (default: %(default)s)')
    p.add_argument('--section', action='append', default=None, metavar='NAME',
                   help='print only this table (repeatable): core, or a section of the bench '
                        '(balancing, counterweights, recording, node, live_view, faults, '
                        'identify_stamps, cell, identify, spatial; default: every table)')
    p.add_argument('--compare', choices=['mujoco'], default=None,
                   help='instead, run Hoeken and generated 4-40 link chains through this '
                        'package and through MuJoCo side by side: agreement, us per angle, '
                        'scaling (needs the optional mujoco package: make bench-mujoco)')
    p.set_defaults(func=cmd_bench)
    for name in EXTENSIONS:
        importlib.import_module(name).register(sub)
    return parser


def cmd_scenes(args):
    """List the built-in scenes (or convert one scene file: ``--convert``)."""
    from mech_balance import schema as scene
    if (args.convert is None) != (args.out is None):
        raise ValueError('--convert and --out: got one of them, expected both or neither')
    if args.convert is not None:
        writable_path('--out', args.out, ('.yaml', '.yml'))
        text = scene.to_yaml(scene.load(args.convert))
        atomic.write_text_atomic(args.out, f'# converted by mech-balance scenes from '
                                           f'{args.convert}\n' + text)
        print(f'scene written to {args.out}')
        return 0
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
    from mech_balance import schema as scene
    sc = scene.load(args.scene)
    requires(sc, 'mass_redistribution', **{'--design': args.design is not None})
    report = scene.kind_of(sc).implementation('analyze')(sc, args.samples, args.normalized,
                                                         args.design)
    print(jsonout.dumps(report.data) if args.json else report.text)
    for text in report.warnings:
        print(f'warning: {text}', file=sys.stderr)
    return 0


def cmd_bench(args):
    """Print core timings."""
    if args.compare == 'mujoco':
        from mech_balance.bench import mujoco as bench_mujoco
        return bench_mujoco.cmd_compare(args, progress)
    from mech_balance.bench import core as bench
    wanted = None if args.section is None else set(args.section)
    names = {bench.section_name(name): name for name in bench.SECTIONS}
    unknown = sorted((wanted or set()) - set(names) - {'core'})
    if unknown:
        raise ValueError(f'--section: got {unknown[0]!r}, expected core or one of '
                         f'{", ".join(names)}')
    from mech_balance.bench import settle
    printed = []
    if wanted is None or 'core' in wanted:
        print(f'mech-balance bench: median of {args.repeat} runs after {bench.WARMUP} '
              f'warm-up runs, {args.samples} crank angles per cycle', flush=True)
        rows = bench.run(args.scene, args.samples, args.repeat, progress=progress)
        printed.append(bench.format_rows(rows))
        print(printed[-1], flush=True)
    for short, name in names.items():
        if wanted is not None and short not in wanted:
            continue
        module, _, function = name.partition(':')
        print()
        if printed:   # not in the wake of the previous section
            print(f'{short}: {settle.settle()}', flush=True)
        printed.append(getattr(importlib.import_module(module), function)(args, progress))
        print(printed[-1], flush=True)
    return EXIT_BENCH_FAILED if settle.report_failures('mech-balance bench', printed) else 0


def main(argv=None):
    """
    Run ``mech-balance``; return the exit status.

    SIGINT/SIGTERM remove a file being written and exit 130/143 (0 if all files were written,
    :func:`_interrupted`); with ``argv`` given, the previous handlers are restored on return.
    """
    mark = atomic.write_count()
    previous = _install_signal_handlers()
    try:
        return _run(argv, mark)
    except KeyboardInterrupt as exc:   # in parsing, before a verb runs
        return _interrupted(None, exc, mark)
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, signal.SIG_IGN if argv is None else handler)


def _install_signal_handlers():
    """Make SIGINT and SIGTERM raise :class:`Interrupted`; return the previous handlers."""
    import threading
    if threading.current_thread() is not threading.main_thread():
        return {}   # only the main thread can set handlers
    return {s: signal.signal(s, _raise_interrupted) for s in INTERRUPTING_SIGNALS
            if signal.getsignal(s) is not signal.SIG_IGN}   # a background job's stays ignored


def _run(argv, mark):
    """Parse ``argv`` and run its verb; return the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        threads.limit_blas_threads()
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
    except KeyboardInterrupt as exc:
        return _interrupted(args.command, exc, mark)


if __name__ == '__main__':
    sys.exit(main())
