"""``mech-balance identify``: a rig's inertial parameters from a recording of its sensors."""

import math
import time


MAX_COUNTS_PER_TURN = 1e9
"""``--counts-per-turn``: at most this many counts (a step of 6e-9 rad)."""
OUTPUT_SUFFIXES = ('.yaml', '.yml')
"""``--output``: what the calibrated scene's file name ends in (so that it loads as a scene)."""
RATIO_DEFAULT = 2.0
"""``--max-residual-ratio``'s default (``identify.FIT_RATIO_MAX``, not imported here so that
the parser stays light; a test holds them equal)."""
MAX_RATIO = 1e6
"""``--max-residual-ratio``: at most this."""


def register(subparsers):
    """Add the ``identify`` verb."""
    from mech_balance.ros import names
    p = subparsers.add_parser(
        'identify', help="identify a rig's link inertias from a recording of its encoder and "
                         'force sensor',
        description='Read a rosbag2 recording (MCAP or sqlite3) or a CSV of the crank encoder '
                    "and the force sensor and solve for the links' inertial parameters and the "
                    'sensor bias; prints the identifiable combinations with standard errors '
                    'and the residuals, writes the calibrated scene with --output '
                    '(docs/identification.md).')
    p.add_argument('--scene', required=True,
                   help='the rig: built-in scene name (see `mech-balance scenes`) or YAML file')
    p.add_argument('--bag', required=True, metavar='PATH',
                   help='rosbag2 directory (or a file in it) or a .csv file (columns: see '
                        'docs/identification.md)')
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
    p.add_argument('--counts-per-turn', type=float, default=None, metavar='N',
                   help="the encoder's counts per crank turn (default: estimated from the "
                        "positions' increments, with a confidence, or 'not quantized')")
    p.add_argument('--sensor-xyz', type=float, nargs=3, default=None, metavar=('X', 'Y', 'Z'),
                   help="the force sensor's origin in the rig frame, m (default: from "
                        '/tf_static in the bag, rig frame to the wrench frame_id, else 0 0 0)')
    p.add_argument('--sensor-rpy', type=float, nargs=3, default=None,
                   metavar=('ROLL', 'PITCH', 'YAW'),
                   help="the sensor's orientation in the rig frame, rad, ROS fixed axes "
                        '(default: from /tf_static, else 0 0 0)')
    p.add_argument('--sensor-convention', default=None, choices=('load_on_sensor', 'reaction'),
                   help='what the sensor reports: the load the rig exerts on it '
                        '(load_on_sensor, the default) or the support reaction on the rig')
    p.add_argument('--encoder-unit', default='auto', choices=('auto', 'rad', 'deg'),
                   help="the encoder positions' unit (default auto: rad, or degrees when "
                        'they wrap at 360)')
    p.add_argument('--wrench-frame-id', default=None, metavar='FRAME',
                   help='use only the wrench messages of this frame_id (a bag whose '
                        '--wrench-topic carries several sensors is refused without it)')
    p.add_argument('--max-residual-ratio', type=float, default=None, metavar='R',
                   help="refuse a fit whose residual RMS is above R times the recording's "
                        'noise floor in any channel (default: %g)' % RATIO_DEFAULT)
    p.add_argument('--rig-frame', default=names.DEFAULT_FRAME_ID, metavar='FRAME',
                   help='the rig frame in /tf_static (default: %(default)s)')
    p.add_argument('--output', default=None, metavar='CALIBRATED.yaml',
                   help='write the calibrated scene (loadable by every other command) to a '
                        'file in an existing directory; checked before the bag is read')
    p.add_argument('--json', action='store_true', help='print the report as JSON')
    p.set_defaults(func=cmd_identify)


def sensor_pose(args, rec):
    """
    Return ``(SensorPose or None, description)`` of the force sensor for a recording.

    The options win; else the recording's /tf_static pose; else None (the rig frame).
    """
    from mech_balance.ros import sensor
    tf = rec.sensor_tf
    given = args.sensor_xyz is not None or args.sensor_rpy is not None
    convention = args.sensor_convention or sensor.CONVENTIONS[0]
    if given or tf is None:
        xyz = tuple(args.sensor_xyz or (0.0, 0.0, 0.0))
        rpy = tuple(args.sensor_rpy or (0.0, 0.0, 0.0))
        source = 'options' if given else 'the rig frame (no /tf_static pose, no --sensor-*)'
    else:
        xyz, rpy = tf[:3], tf[3:6]
        source = f'/tf_static {tf[6]} -> {tf[7]}'
    pose = sensor.SensorPose(*xyz, *rpy, convention=convention)
    text = (f'pose from {source}: xyz ({xyz[0]:.6g}, {xyz[1]:.6g}, {xyz[2]:.6g}) m, rpy '
            f'({rpy[0]:.6g}, {rpy[1]:.6g}, {rpy[2]:.6g}) rad, convention {convention}')
    if pose == sensor.SensorPose():
        return None, text
    return pose, text


def cmd_identify(args):
    """Identify the scene's inertial parameters from a recording; print and write the result."""
    from mech_balance.ros import bags
    from mech_balance import atomic, schema as scene_mod
    from mech_balance.analysis import identify
    from mech_balance.cli import jsonout, main as cli
    if args.output:
        cli.writable_path('--output', args.output, OUTPUT_SUFFIXES)
    sc = scene_mod.load(args.scene)
    identify.check_identifiable(sc)   # before the recording is read
    if args.window is not None and (args.window < identify.MIN_WINDOW or args.window % 2 == 0):
        raise identify.IdentifyError(f'--window: got {args.window}, expected an odd number of '
                                     f'samples >= {identify.MIN_WINDOW}')
    cpt = args.counts_per_turn
    if cpt is not None and not (math.isfinite(cpt) and 1.0 <= cpt <= MAX_COUNTS_PER_TURN):
        raise identify.IdentifyError(f'--counts-per-turn: got {cpt!r}, expected a number of '
                                     f'counts from 1 to {MAX_COUNTS_PER_TURN:g}')
    for option, values in (('--sensor-xyz', args.sensor_xyz), ('--sensor-rpy', args.sensor_rpy)):
        if values is not None and not all(math.isfinite(v) for v in values):
            raise identify.IdentifyError(f'{option}: got {values}, expected finite numbers')
    ratio = RATIO_DEFAULT if args.max_residual_ratio is None else args.max_residual_ratio
    if not (math.isfinite(ratio) and 1.0 <= ratio <= MAX_RATIO):
        raise identify.IdentifyError(f'--max-residual-ratio: got {ratio!r}, expected a number '
                                     f'from 1 to {MAX_RATIO:g}')
    cli.progress(f'mech-balance identify: reading {args.bag} ...')
    t0 = time.perf_counter()
    rec = bags.read(args.bag, args.encoder_topic, args.wrench_topic, args.joint,
                    progress=cli.progress, default_joint=sc.crank_joint,
                    rig_frame=args.rig_frame, wrench_frame_id=args.wrench_frame_id)
    read_s = time.perf_counter() - t0
    cli.progress(f'  {rec.position_rad.size} encoder and {rec.wrench_t_s.size} wrench samples '
                 f'(joint {rec.joint!r}) in {read_s:.2f} s; identifying ...')
    pose, pose_text = sensor_pose(args, rec)
    wrench = rec.planar_wrench
    if pose is not None:
        from mech_balance.core.rig import rig_for
        wrench = pose.to_rig(rec.wrench[:, :3], rec.wrench[:, 3:],
                             rig_for(sc).moment_point_m)[:, [0, 1, 5]]
    t0 = time.perf_counter()
    try:
        result = identify.identify(sc, rec.encoder_t_s, rec.position_rad, rec.wrench_t_s,
                                   wrench, effort=rec.effort_Nm, window=args.window,
                                   counts_per_turn=cpt, encoder_unit=args.encoder_unit,
                                   max_residual_ratio=ratio)
    except identify.IdentifyError as exc:
        raise identify.IdentifyError(f'--bag {args.bag}: {exc}') from None
    result.source = rec.source
    solve_s = time.perf_counter() - t0
    if args.json:
        report = result.to_dict()
        report.update(source=rec.source, joint=rec.joint, read_time_s=read_s,
                      identify_time_s=solve_s, sensor_pose=pose_text,
                      output=args.output if args.output and result.realizable
                      and not result.refusals else None)
        print(jsonout.dumps(report))
    else:
        print(f'sensor: {pose_text}')
        print(identify.format_report(result))
        print(f'\nread {read_s:.2f} s, identified in {solve_s:.2f} s')
    if result.refusals:
        raise identify.IdentifyError(
            f'--bag {args.bag}: refused, ' + ('no calibrated scene written (' + args.output
                                              + ' untouched): ' if args.output else '')
            + ' | '.join(f.describe() for f in result.refusals))
    if args.output:
        text = identify.calibrated_yaml(result, source=rec.source)   # raises if unrealizable
        atomic.write_text_atomic(args.output, text)
        if not args.json:
            print(f'calibrated scene written to {args.output}')
    return 0
