"""The ``mech-balance urdf`` verb: a rig's URDF (:func:`mech_balance.ros.urdf.urdf_xml`)."""

import sys


OUT_SUFFIXES = ('.urdf', '.xml')
"""``--out``: what the URDF's file name ends in."""


def register(subparsers):
    """Add the ``urdf`` verb to the ``mech-balance`` sub-parsers."""
    from mech_balance.ros import names
    p = subparsers.add_parser(
        'urdf', help="write the URDF of the rig's spanning tree (RViz, robot_state_publisher)",
        description="Write the URDF of a scene: a root link named after the rig node's "
                    'frame_id, one link per moving link with its inertial and visuals, one '
                    'joint per joint of the spanning tree, named as on joint_states '
                    '(docs/rviz_launch.md).')
    p.add_argument('--scene', default='hoeken',
                   help='built-in scene name (see `mech-balance scenes`) or path to a YAML '
                        'file (default: %(default)s)')
    p.add_argument('--design', metavar='BALANCED.yaml', default=None,
                   help='a scene of the same geometry with other inertias (e.g. written by '
                        '`mech-balance balance --output`, counterweights included): the '
                        'URDF carries its inertials')
    p.add_argument('--frame-id', default=names.DEFAULT_FRAME_ID,
                   help="name of the root link: the rig node's frame_id (default: "
                        '%(default)s)')
    p.add_argument('--out', default=None, metavar='F.urdf',
                   help='write the URDF to this file (atomically; its directory must exist); '
                        'default: print it on stdout')
    p.set_defaults(func=cmd_urdf)


def cmd_urdf(args):
    """Print or write the URDF of the scene (or of its design)."""
    from mech_balance import atomic, identifiers, schema as scene
    from mech_balance.cli import main as cli
    from mech_balance.ros import urdf
    from mech_balance.schema import registry
    identifiers.check_frame_id(args.frame_id, '--frame-id')  # the node's frame_id check
    out = None if args.out is None else cli.writable_path('--out', args.out, OUT_SUFFIXES)
    sc = scene.load(args.scene)
    if args.design is not None:
        design = scene.load(args.design)
        registry.same_geometry(sc, design, '--design')
        sc = design
    text = urdf.urdf_xml(sc, frame_id=args.frame_id)
    if out is None:
        sys.stdout.write(text)
        sys.stdout.flush()
        return 0
    atomic.write_text_atomic(out, text)
    print(f'wrote {out.resolve()} ({sc.name}: root link {args.frame_id!r}, joints '
          f'{", ".join(urdf.tree_model(sc).names)})')
    return 0
