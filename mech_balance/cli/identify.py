"""
``mech-balance identify``: a rig's inertial parameters from a recording of its sensors.

A thin verb over :mod:`mech_balance.bags` (rosbag2 MCAP or sqlite3, or CSV) and
:mod:`mech_balance.identify` (encoder smoothing, regressor, base parameters, calibrated
scene).  The calibrated scene it writes loads in every other command and in the node.
"""

import json
import math
import sys
import time


OUTPUT_SUFFIXES = ('.yaml', '.yml')
"""``--output``: what the calibrated scene's file name ends in (so that it loads as a scene)."""


def register(subparsers):
    """Add the ``identify`` verb."""
    from mech_balance.ros import names
    p = subparsers.add_parser(
        'identify', help="identify a rig's link inertias from a recording of its encoder and "
                         'force sensor',
        description='Read a rosbag2 recording (MCAP or sqlite3) or a CSV of the crank encoder '
                    '(sensor_msgs/JointState) and the force sensor (geometry_msgs/'
                    'WrenchStamped: rig frame, about the crank pivot, the load the rig exerts '
                    'on its frame), estimate the crank angle, speed and acceleration from the '
                    'encoder by a Savitzky-Golay fit, and solve the linear least-squares '
                    "problem for the links' inertial parameters and the sensor bias. Prints "
                    'the rank, condition number, identifiable combinations (base parameters) '
                    'with standard errors, the bias and the residual RMS before and after; '
                    'writes the calibrated scene with --output.')
    p.add_argument('--scene', required=True,
                   help='the rig: built-in scene name (see `mech-balance scenes`) or YAML file')
    p.add_argument('--bag', required=True, metavar='PATH',
                   help='rosbag2 directory (or a file in it) or a .csv file (columns: see '
                        'README, section Identification)')
    p.add_argument('--encoder-topic', default=names.ENCODER_TOPIC, metavar='TOPIC',
                   help=f'JointState topic of the crank encoder (default: {names.ENCODER_TOPIC})')
    p.add_argument('--wrench-topic', default=names.WRENCH_TOPIC, metavar='TOPIC',
                   help=f'WrenchStamped topic of the sensor (default: {names.WRENCH_TOPIC})')
    p.add_argument('--joint', default=None, metavar='NAME',
                   help="the crank's name in the JointState (default: the scene's crank "
                        'joint if the message carries it, else its only joint)')
    p.add_argument('--window', type=int, default=None, metavar='SAMPLES',
                   help='encoder smoothing window, an odd number of samples (default: chosen '
                        'from the quantization step, the rate and the crank speed)')
    p.add_argument('--output', default=None, metavar='CALIBRATED.yaml',
                   help='write the calibrated scene (loadable by every other command) to a '
                        'file in an existing directory; checked before the bag is read')
    p.add_argument('--json', action='store_true', help='print the report as JSON')
    p.set_defaults(func=cmd_identify)


def _progress(text):
    print(text, file=sys.stderr, flush=True)


def cmd_identify(args):
    """Identify the scene's inertial parameters from a recording; print and write the result."""
    from mech_balance.ros import bags
    from mech_balance import atomic, schema as scene_mod
    from mech_balance.analysis import identify
    from mech_balance.cli import main as cli
    if args.output:
        cli.writable_path('--output', args.output, OUTPUT_SUFFIXES)
    sc = scene_mod.load(args.scene)
    if 'identification' not in scene_mod.kind_of(sc).rig_factory().capabilities:
        raise identify.IdentifyError(f'--scene: got {sc.name!r} of kind '
                                     f'{scene_mod.kind_of(sc).name}, expected a planar scene '
                                     '(identification of the RGGR is not implemented)')
    if args.window is not None and (args.window < identify.MIN_WINDOW or args.window % 2 == 0):
        raise identify.IdentifyError(f'--window: got {args.window}, expected an odd number of '
                                     f'samples >= {identify.MIN_WINDOW}')
    _progress(f'mech-balance identify: reading {args.bag} ...')
    t0 = time.perf_counter()
    rec = bags.read(args.bag, args.encoder_topic, args.wrench_topic, args.joint,
                    progress=_progress, default_joint=sc.crank_joint)
    read_s = time.perf_counter() - t0
    _progress(f'  {rec.position_rad.size} encoder and {rec.wrench_t_s.size} wrench samples '
              f'(joint {rec.joint!r}) in {read_s:.2f} s; identifying ...')
    t0 = time.perf_counter()
    try:
        result = identify.identify(sc, rec.encoder_t_s, rec.position_rad, rec.wrench_t_s,
                                   rec.planar_wrench, effort=rec.effort_Nm,
                                   window=args.window)
    except identify.IdentifyError as exc:
        raise identify.IdentifyError(f'--bag {args.bag}: {exc}') from None
    solve_s = time.perf_counter() - t0
    if args.json:
        report = result.to_dict()
        report.update(source=rec.source, joint=rec.joint, read_time_s=read_s,
                      identify_time_s=solve_s,
                      output=args.output if args.output and result.realizable else None)
        print(json.dumps(_finite(report), indent=2))
    else:
        print(identify.format_report(result))
        print(f'\nread {read_s:.2f} s, identified in {solve_s:.2f} s')
    if args.output:
        text = identify.calibrated_yaml(result, source=rec.source)   # raises if unrealizable
        atomic.write_text_atomic(args.output, text)
        if not args.json:
            print(f'calibrated scene written to {args.output}')
    return 0


def _finite(obj):
    """Return ``obj`` with NaN and infinities as None (JSON has neither)."""
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


if __name__ == '__main__':  # pragma: no cover - use `mech-balance identify`
    from mech_balance.cli import main as cli
    sys.exit(cli.main(['identify', *sys.argv[1:]]))
