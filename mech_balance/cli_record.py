"""
The ``mech-balance record`` verb: a rerun recording of a rig, original against balanced.

The verb is thin: it loads the scenes, finds the balanced design (a scene file, or the
balancing of :mod:`mech_balance.balancing` / :mod:`mech_balance.rggr`) and hands both to
:func:`mech_balance.recording.record`.  Its bench section times that call.
"""

import argparse
from pathlib import Path
import shutil
import sys
import tempfile
import time

from mech_balance import balancing, cli_balance
from mech_balance.cli_balance import DEFAULT_CASE

HOEKEN_A2_DESIGN = (-4.8784, 0.7227, 5.1566, 0.5886, 5.2843, -1.3781, 3.1938, 1.7240,
                    -5.1095, 8.0046, -0.9951, 0.8759)
"""Seed 001 Table 5, case a(2), (w1, w2) = (0.5, 0.5): the bench's balanced Hoeken design."""
BENCH_SAMPLES = 360
BENCH_REPEAT_MAX = 20
"""The bench records at most this many times (each run writes a file)."""
OUT_SUFFIXES = ('.rrd',)
"""``--out``: what the recording's file name ends in."""


def _samples(text):
    try:
        value = int(text)
    except ValueError:
        value = None
    if value is None or value < 4 or 360 % value:
        raise argparse.ArgumentTypeError(
            f'got {text!r}, expected a divisor of 360 that is >= 4 (the crank_angle timeline '
            'counts whole degrees)')
    return value


def register(subparsers):
    """Add the ``record`` verb to the ``mech-balance`` sub-parsers."""
    from mech_balance import cli
    p = subparsers.add_parser(
        'record', help='write a rerun recording (.rrd) of the rig, original vs balanced',
        description='Write an offline rerun recording of a scene: the rig moving (links, '
                    'joints, mass centres, equimomental point masses), the shaking force '
                    'and moment drawn at the crank pivot, and time series of |shaking '
                    'force|, shaking moment and driving torque for the original and the '
                    'balanced design, on the timelines crank_angle (degrees) and time (s). '
                    'Open the file with `rerun FILE.rrd`.')
    p.add_argument('--scene', default='hoeken',
                   help='built-in scene name (see `mech-balance scenes`) or path to a YAML '
                        'file (default: %(default)s)')
    which = p.add_mutually_exclusive_group()
    which.add_argument('--design', metavar='BALANCED.yaml', default=None,
                       help='balanced scene file: the same geometry with other inertias '
                            '(e.g. written by `mech-balance balance --output`)')
    which.add_argument('--balance', action='store_true',
                       help='balance the scene first: seed 001 optimization for planar '
                            'scenes (mech_balance.balancing.optimize), seed 002 force '
                            'balance and minimum RMS shaking moment for the RGGR')
    cli_balance.add_weight_and_case(p, when='with --balance (planar): ')
    p.add_argument('--cycles', type=cli.cycles, default=1,
                   help='crank turns to record, at most conventions.MAX_CYCLES '
                        '(default: %(default)s)')
    p.add_argument('--samples', type=_samples, default=None,
                   help="samples per crank turn, a divisor of 360 (default: the scene's, "
                        'usually 360)')
    p.add_argument('--out', required=True, metavar='FILE.rrd',
                   help='the recording to write (its directory is created if needed)')
    p.set_defaults(func=cmd_record)


def balanced_design(sc, weights=balancing.DEFAULT_WEIGHTS, case=DEFAULT_CASE):
    """
    Return ``(balanced_scene, description)`` for ``--balance``.

    Planar scenes use :func:`mech_balance.balancing.optimize` with ``weights`` and ``case``;
    RGGR scenes :func:`mech_balance.rggr.balance_scene` (force balance, then minimum RMS
    moment), which takes neither.
    """
    if getattr(sc, 'kind', 'planar') == 'rggr':
        from mech_balance import rggr
        return (rggr.balance_scene(sc).design.scene,
                'seed 002 complete force balance with the minimum RMS shaking moment '
                '(rggr.balance_scene)')
    result = balancing.optimize(sc, weights=tuple(weights), case=case)
    return (result.balanced_scene,
            f'seed 001 optimum, (w1, w2) = ({weights[0]:g}, {weights[1]:g}), case {case} '
            '(mech_balance.balancing.optimize)')


def cmd_record(args):
    """Write the recording and say where it is and how to open it."""
    from mech_balance import cli, recording, scene
    given = {'--weights': args.weights is not None, '--case': args.case is not None}
    for option, was_given in given.items():
        if was_given and not args.balance:
            raise ValueError(f'{option} applies with --balance only, expected --balance or '
                             f'no {option}')
    out = cli.writable_path('--out', args.out, OUT_SUFFIXES, create_parent=True)
    sc = scene.load(args.scene)
    balanced, source = None, None
    if args.design is not None:
        balanced = scene.load(args.design)
        source = f'scene file {balanced.source}'
    elif args.balance:
        cli.planar_only(sc, **given)
        balanced, source = balanced_design(
            sc, balancing.DEFAULT_WEIGHTS if args.weights is None else tuple(args.weights),
            DEFAULT_CASE if args.case is None else args.case)
    summary = recording.record(out, sc, balanced, cycles=args.cycles, samples=args.samples,
                               balanced_source=source, field='--out')
    path = summary.path.resolve()
    print(f'wrote {path}')
    print(f'  {sc.name}: {" vs ".join(summary.variants)}; {summary.samples_per_cycle} '
          f'samples x {summary.cycles} turn(s); {summary.size_bytes / 1e6:.2f} MB in '
          f'{summary.seconds:.2f} s')
    if source:
        print(f'  balanced design: {source}')
    print(f'open it with:  {_viewer()} {path}')
    print('  (the viewer comes with rerun-sdk; it plays the crank_angle timeline in a loop)')
    sys.stdout.flush()
    return 0


def _viewer():
    """Return how to call the rerun viewer: on PATH, else next to this Python (a venv)."""
    if shutil.which('rerun'):
        return 'rerun'
    beside = Path(sys.executable).parent / 'rerun'
    return str(beside) if beside.exists() else 'rerun'


def bench_section(args, progress):
    """Return the timing of one Hoeken recording (original + seed 001 a(2), 360 samples)."""
    from mech_balance import bench, equimomental, recording, scene
    sc = scene.load('hoeken')
    balanced = equimomental.apply_design(sc, HOEKEN_A2_DESIGN, normalized=True)
    asked = int(getattr(args, 'repeat', BENCH_REPEAT_MAX))
    repeat = min(asked, BENCH_REPEAT_MAX)
    progress('  timing record hoeken (original + a(2)) ...')
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / 'hoeken.rrd'
        t0 = time.perf_counter()
        recording.record(path, sc, balanced, cycles=1, samples=BENCH_SAMPLES)
        cold = time.perf_counter() - t0
        warm = bench.median_seconds(
            lambda: recording.record(path, sc, balanced, cycles=1, samples=BENCH_SAMPLES),
            repeat=repeat)
        size = path.stat().st_size
    lines = [f'record (rerun file): hoeken original + seed 001 a(2), 1 turn at {BENCH_SAMPLES} '
             'samples;', f'median of {repeat} runs after {bench.WARMUP} warm-up runs'
             + (f' (--repeat {asked} capped at {BENCH_REPEAT_MAX}: each run writes a file)'
                if asked > repeat else ''),
             f'{"scene":<16}{"first run s":>14}{"median s":>12}{"file MB":>10}',
             '-' * 52,
             f'{"hoeken":<16}{cold:>14.3f}{warm:>12.3f}{size / 1e6:>10.3f}']
    return '\n'.join(lines)
