"""
URDF of a rig's spanning tree and the tree's joint positions from the core's state.

numpy only.  A closed linkage is opened into the spanning tree the core solves.  Link
frames, the zero convention, limits and inertials: `docs/rviz_launch.md` (*Links*, *Zero
convention*, *URDF frames of spatial rigs*).
"""

from dataclasses import dataclass, field, replace
import math
import os
import xml.etree.ElementTree as ET

from mech_balance import schema
from mech_balance.conventions import cycle_angles
from mech_balance.core.planar import kinematics
from mech_balance.core.planar.drawn import bar_edges, BAR_THICKNESS, BAR_WIDTH, BLOCK_SIZE, \
    LAYER, PIN_LENGTH, PIN_RADIUS
from mech_balance.core.planar.rig import linkage_for
from mech_balance.ros.joint_ranges import angle_limits, cycle_ranges, LIMIT_MARGIN, \
    RANGE_SAMPLES
from mech_balance.ros.names import DEFAULT_FRAME_ID
from mech_balance.rotations import axis_angle_matrix, matrix_rpy, rpy_matrix, wrap_angle
from mech_balance.schema.scene import FRAME
import numpy as np

ROD_RADIUS = 0.01
"""Spatial rigs: rod radius of the drawn links as a fraction of the linkage's length scale."""
PIN_RADIUS_3D = 0.02
"""Spatial rigs: sphere radius of the drawn joint points as a fraction of the length scale."""
PALETTE = (
    (0.95, 0.55, 0.10, 1.0), (0.20, 0.45, 0.85, 1.0), (0.25, 0.70, 0.30, 1.0),
    (0.80, 0.25, 0.25, 1.0), (0.60, 0.35, 0.75, 1.0), (0.10, 0.70, 0.70, 1.0),
    (0.85, 0.75, 0.15, 1.0), (0.55, 0.40, 0.25, 1.0),
)
"""Link colours (rgba), in body order; the frame is grey."""
FRAME_COLOUR = (0.6, 0.6, 0.6, 1.0)
WEIGHT_COLOUR = (0.25, 0.25, 0.25, 1.0)


class UrdfError(ValueError):
    """A scene cannot be written as a URDF (a name clash, an impossible body, a bad state)."""


@dataclass(frozen=True)
class UrdfJoint:
    """
    One URDF joint: where it sits on its parent, how it moves, its zero and its limits.

    ``xyz``, ``rpy``: the joint frame in the parent's; ``axis`` in the joint frame; ``offset``
    (rad) subtracted before wrapping; ``lower``/``upper`` None for ``continuous``.
    """

    name: str
    joint_type: str
    parent: str
    child: str
    xyz: tuple
    rpy: tuple
    axis: tuple
    offset: float = 0.0
    lower: float = None
    upper: float = None
    velocity: float = 0.0


@dataclass(frozen=True)
class TreeModel:
    """
    The URDF's joints of one scene geometry, built once (:func:`tree_model`).

    ``coordinates(tree, state)`` returns the tree joints' ``(q, qd, angular)``; ``linkage``
    the compiled planar linkage (or None); ``cuts`` the ``(name, joint_type)`` the core closes;
    ``state_of(data)`` the state :func:`joint_positions` reads from a rig's RigData.
    """

    coordinates: object
    joints: tuple
    linkage: object = None
    cuts: tuple = ()
    state_of: object = field(default=None, compare=False, repr=False)

    @property
    def names(self):
        """Return the joint names, in :func:`joint_positions` order."""
        return tuple(j.name for j in self.joints)


def urdf_rpy(matrix):
    """Return the URDF ``(roll, pitch, yaw)`` floats of one rotation matrix (3, 3)."""
    return tuple(float(v) for v in matrix_rpy(matrix))


def _joint_specs(chains, lower, upper, turns, rate_max, length_scale):
    """Return the :class:`UrdfJoint` of each ``(name, type, parent, child, xyz, rpy, axis)``."""
    joints = []
    margin = LIMIT_MARGIN * length_scale
    for i, (name, jtype, parent, child, xyz, rpy, axis) in enumerate(chains):
        if jtype == 'prismatic':
            joints.append(UrdfJoint(name, 'prismatic', parent, child, xyz, rpy, axis, 0.0,
                                    float(lower[i] - margin), float(upper[i] + margin),
                                    float(rate_max[i])))
        else:
            joints.append(_revolute_spec(name, parent, child, xyz, rpy, axis, lower[i],
                                         upper[i], turns[i], float(rate_max[i])))
    return tuple(joints)


def _revolute_spec(name, parent, child, xyz, rpy, axis, lower, upper, turns, rate_max):
    """Return the :class:`UrdfJoint` of a revolute joint with the cycle's range."""
    if turns != 0:
        return UrdfJoint(name, 'continuous', parent, child, xyz, rpy, axis, 0.0, None, None,
                         rate_max)
    offset, lo, hi = angle_limits(lower, upper)
    if offset:  # the joint origin turned by the offset about the joint axis
        if rpy[:2] == (0.0, 0.0) and tuple(axis) == (0.0, 0.0, 1.0):
            rpy = (0.0, 0.0, rpy[2] + offset)
        else:
            rpy = urdf_rpy(rpy_matrix(rpy) @ axis_angle_matrix(axis, offset))
    return UrdfJoint(name, 'revolute', parent, child, xyz, rpy, axis, offset, lo, hi,
                     rate_max)


_MODELS = {}
_MODELS_MAX = 64


def tree_model(scene_or_linkage):
    """Return the (cached) :class:`TreeModel` of a scene, a planar Linkage or a TreeModel."""
    if isinstance(scene_or_linkage, TreeModel):
        return scene_or_linkage
    key = id(scene_or_linkage)
    hit = _MODELS.get(key)
    if hit is not None and hit[0] is scene_or_linkage:
        return hit[1]
    if isinstance(scene_or_linkage, kinematics.Linkage):
        model = planar_tree(scene_or_linkage)
    else:
        try:
            kind = schema.kind_of(scene_or_linkage)
        except TypeError:
            raise UrdfError(f'scene: got {type(scene_or_linkage).__name__}, expected a planar '
                            'or spatial scene, a kinematics.Linkage or a TreeModel') from None
        model = kind.implementation('urdf_tree')(scene_or_linkage)
    if len(_MODELS) >= _MODELS_MAX:
        _MODELS.clear()
    _MODELS[key] = (scene_or_linkage, model)
    linkage = getattr(model, 'linkage', None)
    if linkage is not None:   # the URDF of a planar twin asks by its linkage: no second cycle
        _MODELS[id(linkage)] = (linkage, model)
    return model


def _frame_offsets(linkage):
    """Return each body's URDF frame offset p_j (link coordinates, complex); frame: 0."""
    offset = [0j] * linkage.nb
    for tj in linkage.tree:
        offset[tj.child] = tj.p_child
    return offset


def planar_tree(linkage):
    """Return the :class:`TreeModel` of a planar scene or its compiled Linkage."""
    if not isinstance(linkage, kinematics.Linkage):
        linkage = linkage_for(linkage)
    sc = linkage.scene
    linkage.skeleton  # noqa: B018 - assemble and trace the branch: fail early
    names = linkage.body_names
    offset = _frame_offsets(linkage)
    prismatic = linkage.is_prismatic

    def coordinates(psi):
        return linkage.solve(psi, 1.0, 0.0, need_acc=False).q

    psi = cycle_angles(RANGE_SAMPLES, sc.assembly_crank_angle_rad)
    rates = linkage.solve(psi, 1.0, 0.0, need_acc=False).qd
    rate_max = np.max(np.abs(rates), axis=1) * abs(sc.crank_speed_rad_s)
    lower, upper, turns = cycle_ranges(coordinates, sc.assembly_crank_angle_rad, ~prismatic)
    turns[0] = 1.0  # the crank turns fully by construction
    chains = []
    for tj in linkage.tree:
        p = tj.p_parent - offset[tj.parent]
        turn, axis = 0.0, (0.0, 0.0, 1.0)
        if tj.prismatic:  # the child turns by +-angle against the parent; the slide axis in
            # the child's (= joint frame's) axes (kinematics.Linkage.pose)
            if tj.axis_on_parent:
                turn, a = tj.angle, tj.axis * complex(math.cos(-tj.angle), math.sin(-tj.angle))
            else:
                turn, a = -tj.angle, -tj.axis
            axis = (a.real, a.imag, 0.0)
        chains.append((tj.name, 'prismatic' if tj.prismatic else 'revolute', names[tj.parent],
                       names[tj.child], (p.real, p.imag, 0.0), (0.0, 0.0, turn), axis))
    joints = _joint_specs(chains, lower, upper, turns, rate_max, linkage.length_scale)
    cuts = tuple((c.name, c.joint_type) for c in linkage.cuts)
    return TreeModel(_planar_coordinates, joints, linkage, cuts, _planar_state)


def _planar_coordinates(tree, state):
    if not hasattr(state, 'q') or state.qd is None:
        raise UrdfError(f'state: got {type(state).__name__} without rates, expected a '
                        'KinematicState solved with rates (Linkage.solve)')
    if state.q.shape[0] != len(tree.joints):
        raise UrdfError(f'state: got {state.q.shape[0]} tree coordinates, expected '
                        f'{len(tree.joints)} (the linkage of this scene)')
    return state.q, state.qd, ~tree.linkage.is_prismatic


def _planar_state(data):
    """Return the planar kinematic state of a :class:`RigData` (solved with rates)."""
    state = data.state
    if state is None:
        raise UrdfError('data: got a RigData without a planar kinematic state, expected the '
                        "evaluation of this scene's planar rig (rig.at)")
    return state


def joint_positions(model, state):
    """
    Return ``(names, positions, velocities)`` of the URDF joints at the core's state.

    ``model``: as :func:`tree_model` takes; ``state``: :meth:`TreeModel.state_of` of a rig's
    evaluation (planar: a KinematicState with rates).  ``(n, n_joints)`` arrays, rad or m,
    revolute positions wrapped to (-pi, pi], no -0.0.
    """
    tree = tree_model(model)
    names = tree.names
    q, qd, angular = tree.coordinates(tree, state)
    offset = np.array([j.offset for j in tree.joints])[:, None]
    positions = np.where(angular[:, None], wrap_angle(q - offset), q + 0.0)
    return names, positions.T + 0.0, np.asarray(qd, dtype=float).T + 0.0


def rig_joint_positions(model, data):
    """Return :func:`joint_positions` at ``data``, a RigData of the scene's rig (any design)."""
    tree = tree_model(model)
    return joint_positions(tree, tree.state_of(data))


def thin_plate_inertia(link):
    """
    Return ``(mass, com_xy, (ixx, iyy, izz, ixy))`` of a planar link about its mass centre.

    A thin plate with ixx = iyy = izz / 2, plus the link's counterweight discs.
    """
    mass, com, izz = float(link.mass_kg), tuple(link.com_m), float(link.inertia_com_kg_m2)
    discs = tuple(getattr(link, 'counterweights', ()) or ())
    own = getattr(link, 'own', None)
    if not discs or own is None:
        return mass, com, (0.5 * izz, 0.5 * izz, izz, 0.0)
    parts = [(own[0], own[1], 0.5 * own[2], 0.5 * own[2])]
    for cw in discs:
        r, t = float(cw.radius_m), float(cw.thickness_m)
        i_d = cw.mass_kg * (3.0 * r * r + t * t) / 12.0  # a disc about a diameter
        parts.append((float(cw.mass_kg), tuple(cw.centre_m), i_d, i_d))
    ixx = iyy = ixy = 0.0
    for m, (x, y), i_x, i_y in parts:
        dx, dy = x - com[0], y - com[1]
        ixx += i_x + m * dy * dy
        iyy += i_y + m * dx * dx
        ixy -= m * dx * dy
    return mass, com, (ixx, iyy, izz, ixy)


def _num(x):
    """Return the shortest exact text of a float (no -0)."""
    return repr(float(x) + 0.0)


def _vec(values):
    return ' '.join(_num(v) for v in values)


def _origin(parent, xyz, rpy=(0.0, 0.0, 0.0)):
    ET.SubElement(parent, 'origin', xyz=_vec(xyz), rpy=_vec(rpy))


def _shape(parent, name, material, xyz, rpy, geometry, collide=True):
    """Add a ``<visual>`` (and the same ``<collision>``) named ``name`` to a link."""
    tags = ('visual', 'collision') if collide else ('visual',)
    for tag in tags:
        el = ET.SubElement(parent, tag, name=name)
        _origin(el, xyz, rpy)
        geo = ET.SubElement(el, 'geometry')
        kind, attrs = geometry
        ET.SubElement(geo, kind, **attrs)
        if tag == 'visual':
            ET.SubElement(el, 'material', name=material)


def _box(size):
    return 'box', {'size': _vec(size)}


def _cylinder(radius, length):
    return 'cylinder', {'radius': _num(radius), 'length': _num(length)}


def _inertial(link_el, mass, xyz, tensor):
    """Add ``<inertial>``; ``tensor`` is (ixx, iyy, izz, ixy, ixz, iyz)."""
    el = ET.SubElement(link_el, 'inertial')
    _origin(el, xyz)
    ET.SubElement(el, 'mass', value=_num(mass))
    ixx, iyy, izz, ixy, ixz, iyz = tensor
    ET.SubElement(el, 'inertia', ixx=_num(ixx), ixy=_num(ixy), ixz=_num(ixz), iyy=_num(iyy),
                  iyz=_num(iyz), izz=_num(izz))


def _joint_element(robot, spec):
    el = ET.SubElement(robot, 'joint', name=spec.name, type=spec.joint_type)
    _origin(el, spec.xyz, spec.rpy)
    ET.SubElement(el, 'parent', link=spec.parent)
    ET.SubElement(el, 'child', link=spec.child)
    ET.SubElement(el, 'axis', xyz=_vec(spec.axis))
    if spec.joint_type != 'continuous':
        ET.SubElement(el, 'limit', lower=_num(spec.lower), upper=_num(spec.upper),
                      effort='0.0', velocity=_num(spec.velocity))
    return el


def _link_colours(scene_name, names):
    """Return ``(material, rgba)`` of the frame and each moving link, in body order."""
    return [(f'{scene_name}/{FRAME}', FRAME_COLOUR)] + [
        (f'{scene_name}/{n}', PALETTE[(i - 1) % len(PALETTE)]) for i, n in enumerate(names)
        if i > 0]


def _materials(robot, colours):
    for name, rgba in colours:
        ET.SubElement(ET.SubElement(robot, 'material', name=name), 'color', rgba=_vec(rgba))


def _check_names(frame_id, link_names):
    if not isinstance(frame_id, str) or not frame_id:
        raise UrdfError(f'frame_id: got {frame_id!r}, expected a non-empty frame name')
    if frame_id in link_names:
        raise UrdfError(f'frame_id: got {frame_id!r}, which is also a link of the scene '
                        f'({", ".join(link_names)}); expected another root link name')


def _source(scene):
    """Return the scene file's name (not its directory: the URDF is the same everywhere)."""
    return os.path.basename(str(getattr(scene, 'source', ''))) or '<dict>'


def _header(robot, text):
    robot.append(ET.Comment(' ' + ' '.join(text.split()) + ' '))


def _cut_header(robot, cut_lines):
    _header(robot, 'Cut joints (closed by the core, not part of the URDF tree; points in '
                   'the URDF frames of their links): ' + ('; '.join(cut_lines) or 'none'))


def urdf_xml(scene, frame_id=DEFAULT_FRAME_ID, linkage=None):
    """Return the URDF (text) of a scene (any kind); ``frame_id`` names the root link."""
    robot = schema.kind_of(scene).implementation('urdf')(scene, frame_id, linkage)
    ET.indent(robot, space='  ')
    return '<?xml version="1.0"?>\n' + ET.tostring(robot, encoding='unicode') + '\n'


def planar_robot(sc, frame_id, linkage=None):
    """Return the URDF element tree of a planar scene (the kind registry's ``urdf``)."""
    linkage = linkage_for(sc) if linkage is None else linkage
    model = tree_model(linkage)
    names = linkage.body_names
    _check_names(frame_id, names[1:])
    L = linkage.length_scale
    offset = _frame_offsets(linkage)
    urdf_name = {FRAME: frame_id, **{n: n for n in names[1:]}}
    robot = ET.Element('robot', name=sc.name)
    _header(robot, f'Generated by mech_balance.ros.urdf from scene {sc.name!r} '
                   f'({_source(sc)}): the spanning tree of the linkage the core solves; joint '
                   'positions in the zero '
                   'convention of mech_balance.ros.urdf (revolute: relative angle of the link '
                   'frames minus the joint origin yaw, wrapped to (-pi, pi]; prismatic: slide '
                   'from the parent point). SI units, z out of the plane of motion.')
    cut_lines = []
    for c in linkage.cuts:
        pa, pb = c.p_a - offset[c.a], c.p_b - offset[c.b]
        jt = next(j for j in sc.joints if j.name == c.name)
        cut_lines.append(
            f'{c.name}: {c.joint_type}, closes {names[c.a]}.{jt.point_a} ({_num(pa.real)}, '
            f'{_num(pa.imag)}) with {names[c.b]}.{jt.point_b} ({_num(pb.real)}, '
            f'{_num(pb.imag)})')
    _cut_header(robot, cut_lines)
    colours = _link_colours(sc.name, names)
    if any(getattr(lk, 'counterweights', ()) for lk in sc.links):
        colours.append((f'{sc.name}/counterweight', WEIGHT_COLOUR))
    _materials(robot, colours)
    points = {FRAME: sc.frame_points, **{lk.name: lk.points for lk in sc.links}}
    links = {lk.name: lk for lk in sc.links}
    width, thick, pin_r = BAR_WIDTH * L, BAR_THICKNESS * L, PIN_RADIUS * L
    rails = {tj.name: model.joints[t] for t, tj in enumerate(linkage.tree) if tj.prismatic}
    for bi, body in enumerate(names):
        el = ET.SubElement(robot, 'link', name=urdf_name[body])
        material = f'{sc.name}/{body}'
        z = LAYER * L * bi
        local = {k: complex(*v) - offset[bi] for k, v in points[body].items()}
        if bi > 0:
            mass, com, (ixx, iyy, izz, ixy) = thin_plate_inertia(links[body])
            _inertial(el, mass, (com[0] - offset[bi].real, com[1] - offset[bi].imag, 0.0),
                      (ixx, iyy, izz, ixy, 0.0, 0.0))
        for a, b in bar_edges(local):
            d = local[b] - local[a]
            if abs(d) == 0.0:  # two names of one point (the frame may have them)
                continue
            mid = 0.5 * (local[a] + local[b])
            _shape(el, f'bar_{a}_{b}', material, (mid.real, mid.imag, z),
                   (0.0, 0.0, math.atan2(d.imag, d.real)), _box((abs(d), width, thick)))
        if bi > 0 and len(local) == 1:
            p = next(iter(local.values()))
            size = (BLOCK_SIZE[0] * L, BLOCK_SIZE[1] * L, thick)
            _shape(el, 'block', material, (p.real, p.imag, z), (0.0, 0.0, 0.0), _box(size))
        for k, p in local.items():
            _shape(el, f'pin_{k}', material, (p.real, p.imag, z), (0.0, 0.0, 0.0),
                   _cylinder(pin_r, PIN_LENGTH * thick), collide=False)
        for i, cw in enumerate(getattr(links.get(body), 'counterweights', ()) or ()):
            c = complex(*cw.centre_m) - offset[bi]
            _shape(el, f'counterweight_{i}', f'{sc.name}/counterweight',
                   (c.real, c.imag, z + getattr(cw, 'plane_m', 0.0)),
                   (0.0, 0.0, 0.0), _cylinder(cw.radius_m, cw.thickness_m))
        for jt in sc.joints:
            spec = rails.get(jt.name)
            if spec is None or jt.link_a != body:
                continue
            p, axis = local[jt.point_a], complex(*jt.axis)
            lo, hi = spec.lower, spec.upper
            centre = p + 0.5 * (lo + hi) * axis
            _shape(el, f'rail_{jt.name}', material, (centre.real, centre.imag, z - thick),
                   (0.0, 0.0, math.atan2(axis.imag, axis.real)),
                   _box((hi - lo + BLOCK_SIZE[0] * L, 0.5 * width, 0.5 * thick)))
    for spec in model.joints:
        _joint_element(robot, replace(spec, parent=urdf_name[spec.parent],
                                      child=urdf_name[spec.child]))
    return robot


def _rod(parent, name, material, start, end, radius):
    """Add a cylinder from ``start`` to ``end`` (3-vectors in the link frame)."""
    start, end = np.asarray(start, dtype=float), np.asarray(end, dtype=float)
    d = end - start
    length = float(np.linalg.norm(d))
    # a URDF cylinder lies along z: turn z onto d (pitch about y, then yaw about z)
    pitch = math.atan2(math.hypot(d[0], d[1]), d[2])
    yaw = math.atan2(d[1], d[0])
    _shape(parent, name, material, tuple(0.5 * (start + end)), (0.0, pitch, yaw),
           _cylinder(radius, length))


# The URDF frames and joints of spatial scenes: docs/rviz_launch.md, "URDF frames of spatial
# rigs".
def _spatial_parts(sc):
    """Return the linkage, ``K`` and ``s_b`` of every body, and the URDF joint specs."""
    from mech_balance.core.spatial.rig import linkage_for as spatial_linkage
    lk = spatial_linkage(sc)
    lk.skeleton  # noqa: B018 - assemble and trace the branch: fail early
    names = lk.body_names
    k_of = {0: np.eye(3)}
    s_of = {0: np.zeros(3)}
    chains = []
    for t in lk.tree:
        jt = sc.joints[t.joint]
        if t.flipped and t.joint_type == 'universal':
            raise UrdfError(
                f'joints.{t.name}: a universal joint whose end a ({jt.link_a}) hangs below '
                f'its end b ({jt.link_b}) in the spanning tree; expected a: on the side of '
                'the frame (swap a and b, and axis and axis_b)')
        sign = -1.0 if t.flipped else 1.0
        kp, sp = k_of[t.parent], s_of[t.parent]
        xyz = tuple(float(v) for v in kp @ (t.s_parent - sp))
        rpy = urdf_rpy(kp)
        parent, child = names[t.parent], names[t.child]
        if t.joint_type == 'spherical':
            a_rot = lk.sph_zero[t.name]
            if t.flipped:   # M_pc = A^T Rx(-r) Ry(-p) Rz(-y)
                rpy = urdf_rpy(kp @ a_rot.T)
                order = (('_roll', (-1.0, 0.0, 0.0)), ('_pitch', (0.0, -1.0, 0.0)),
                         ('_yaw', (0.0, 0.0, -1.0)))
                k_child = np.eye(3)
            else:
                order = (('_yaw', (0.0, 0.0, 1.0)), ('_pitch', (0.0, 1.0, 0.0)),
                         ('_roll', (1.0, 0.0, 0.0)))
                k_child = a_rot
            links = [f'{t.name}_link{i}' for i in (1, 2)] + [child]
            chains.append((t.name + order[0][0], 'revolute', parent, links[0], xyz, rpy,
                           order[0][1]))
            for i in (1, 2):
                chains.append((t.name + order[i][0], 'revolute', links[i - 1], links[i],
                               (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), order[i][1]))
        else:
            axis = tuple(float(sign * v) for v in t.axis)
            if t.joint_type == 'revolute':
                chains.append((t.name, 'revolute', parent, child, xyz, rpy, axis))
                k_child = t.fixed
            elif t.joint_type == 'prismatic':
                chains.append((t.name, 'prismatic', parent, child, xyz, rpy, axis))
                k_child = t.fixed
            elif t.joint_type == 'cylindrical':
                mid = f'{t.name}_link'
                chains.append((t.name + '_turn', 'revolute', parent, mid, xyz, rpy, axis))
                chains.append((t.name + '_slide', 'prismatic', mid, child, (0.0, 0.0, 0.0),
                               (0.0, 0.0, 0.0), axis))
                k_child = t.fixed
            else:
                mid = f'{t.name}_link'
                chains.append((t.name + '_1', 'revolute', parent, mid, xyz, rpy, axis))
                chains.append((t.name + '_2', 'revolute', mid, child, (0.0, 0.0, 0.0),
                               urdf_rpy(t.fixed), tuple(float(v) for v in t.axis_child)))
                k_child = np.eye(3)
        k_of[t.child] = k_child
        s_of[t.child] = t.s_child
    return lk, k_of, s_of, chains


def spatial_tree(sc):
    """Return the :class:`TreeModel` of a spatial scene (the kind registry's ``urdf_tree``)."""
    from mech_balance.core.rig import rig_for
    lk, _, _, chains = _spatial_parts(sc)
    rig = rig_for(sc)
    names = tuple(c[0] for c in chains)
    rows = [rig.joint_names.index(n) for n in names]
    slides = np.array([c[1] == 'prismatic' for c in chains])

    def values(psi):
        return rig.at(psi, 1.0, 0.0, outputs=('kinematics',)).joint_position[:, rows].T

    start = sc.assembly_crank_angle_rad
    lower, upper, turns = cycle_ranges(values, start, ~slides)
    psi = cycle_angles(RANGE_SAMPLES, start)
    rates = rig.at(psi, 1.0, 0.0, outputs=('kinematics',)).joint_velocity[:, rows]
    rate_max = np.max(np.abs(rates), axis=0) * abs(sc.crank_speed_rad_s)
    turns = np.where(np.array(names) == sc.crank_joint, 1.0, turns)
    joints = _joint_specs(chains, lower, upper, turns, rate_max, lk.length_scale)
    cuts = tuple((sc.joints[ji].name, sc.joints[ji].joint_type) for ji in lk.cut_joints)

    def coordinates(tree, state):
        if not hasattr(state, 'joint_names'):
            raise UrdfError(f'state: got {type(state).__name__}, expected the RigData of '
                            "this spatial scene's rig (rig.at)")
        idx = [state.joint_names.index(j.name) for j in tree.joints]
        return state.joint_position[:, idx].T, state.joint_velocity[:, idx].T, ~slides

    return TreeModel(coordinates, joints, None, cuts, lambda data: data)


def _edges3(points):
    """Return the bars of a link: a shortest spanning tree over its 3-D points (Prim)."""
    names = list(points)
    inside, edges = {names[0]}, []
    while len(inside) < len(names):
        best = min(((float(np.linalg.norm(points[a] - points[b])), a, b) for a in inside
                    for b in names if b not in inside), key=lambda e: e[0])
        edges.append((best[1], best[2]))
        inside.add(best[2])
    return edges


def spatial_robot(sc, frame_id, linkage=None):
    """Return the URDF element tree of a spatial scene (the kind registry's ``urdf``)."""
    lk, k_of, s_of, chains = _spatial_parts(sc)
    model = tree_model(sc)
    names = lk.body_names
    helpers = sorted({c[3] for c in chains if c[3] not in names})
    _check_names(frame_id, list(names[1:]) + helpers)
    robot = ET.Element('robot', name=sc.name)
    _header(robot, f'Generated by mech_balance.ros.urdf from spatial scene {sc.name!r} '
                   f'({_source(sc)}): the spanning tree of the linkage the core solves; '
                   'spherical joints as three revolute joints (z, y, x) on massless links, '
                   "universal and cylindrical joints as two; joint values are the rig's "
                   'joint coordinates of the same names. SI units.')
    cut_lines = []
    for ji in lk.cut_joints:
        jt = sc.joints[ji]
        ia, ib = names.index(jt.link_a), names.index(jt.link_b)
        pa = k_of[ia] @ (lk._points[jt.link_a][jt.point_a] - s_of[ia])
        pb = k_of[ib] @ (lk._points[jt.link_b][jt.point_b] - s_of[ib])
        cut_lines.append(f'{jt.name}: {jt.joint_type}, closes {jt.link_a}.{jt.point_a} '
                         f'({_vec(pa)}) with {jt.link_b}.{jt.point_b} ({_vec(pb)})')
    _cut_header(robot, cut_lines)
    _materials(robot, _link_colours(sc.name, names))
    rod = ROD_RADIUS * lk.length_scale
    pin = PIN_RADIUS_3D * lk.length_scale
    for bi, body in enumerate(names):
        el = ET.SubElement(robot, 'link', name=frame_id if bi == 0 else body)
        material = f'{sc.name}/{body}'
        kb, sb = k_of[bi], s_of[bi]
        local = {p: kb @ (v - sb) for p, v in lk._points[body].items()}
        if bi > 0:
            link = sc.link(body)
            centre = kb @ (np.array(link.com_m) - sb)
            inertia = kb @ np.array(link.inertia_matrix()) @ kb.T
            _inertial(el, link.mass_kg, tuple(centre),
                      (inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1],
                       inertia[0, 2], inertia[1, 2]))
        for a, b in _edges3(local):
            if np.linalg.norm(local[b] - local[a]) > 0.0:
                _rod(el, f'bar_{a}_{b}', material, local[a], local[b], rod)
        for p, x in local.items():
            _shape(el, f'pin_{p}', material, tuple(x), (0.0, 0.0, 0.0),
                   ('sphere', {'radius': _num(pin)}), collide=False)
    for name in helpers:
        ET.SubElement(robot, 'link', name=name)
    for spec in model.joints:
        _joint_element(robot, replace(spec, parent=frame_id if spec.parent == FRAME
                                      else spec.parent))
    return robot
