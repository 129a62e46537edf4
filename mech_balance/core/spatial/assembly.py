"""
The assembly of a spatial linkage from its scene's stated poses, and the check that it holds.

A scene's ``assembly.poses`` state, approximately, where every link is at the crank angle
``assembly.crank_angle_deg``; they choose the assembly branch (a closed linkage has several
assemblies at one crank angle: a rocker on either side, a coupler flipped about its line
through a universal joint).  :func:`initial` reads the tree coordinates from them (the
inverse of the zero convention of :mod:`.kinematics`), Levenberg-Marquardt closes the loops
from there (:meth:`~kinematics.Linkage._assemble`), and :func:`pose_mismatch` compares every
stated link's solved pose with its stated one: a link off by more than
:data:`~mech_balance.schema.spatial.POSE_TOL_DEG` or
:data:`~mech_balance.schema.spatial.POSE_TOL_REL` of the linkage's size is refused, naming
the link, the angle and the distance, and the pose it was solved at, so that no figure ever
describes an assembly the scene did not state.  A link held only by two spherical joints
(an idle spin, fixed by convention) is compared by its S-S line and its first ball centre.
"""

import math

from mech_balance.conventions import crank_angle_text
from mech_balance.schema.spatial import POSE_TOL_DEG, POSE_TOL_REL
import numpy as np


def _turn(axis, angle):
    """Return the rotation (3, 3) by ``angle`` (rad) about the unit ``axis`` (Rodrigues)."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]],
                  [-axis[1], axis[0], 0.0]])
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)


def _normal(axis):
    """Return a unit vector normal to the unit ``axis``."""
    v = np.cross(axis, np.eye(3)[int(np.argmin(np.abs(axis)))])
    return v / np.linalg.norm(v)


def twist_about(axis, rot):
    """
    Return the angle (rad) of the rotation ``rot`` (3, 3) about the unit ``axis``.

    The twist of the swing-twist split: the signed angle about ``axis`` from a unit vector
    ``r`` normal to it to ``rot r`` (its part normal to ``axis``).  Exact for a rotation
    about ``axis`` whatever its angle, and for an approximate one (a guessed pose) the turn
    about ``axis`` that best explains it; the rotation vector (``kinematics.angle_about``)
    would mix in any turn about another axis.
    """
    ref = _normal(axis)
    v = rot @ ref
    return math.atan2(float(axis @ np.cross(ref, v)), float(ref @ v))


def tree_values(t, rel, d):
    """
    Return the coordinates of a (non-spherical) tree joint ``t`` from a relative pose.

    ``rel`` is the child's rotation in the parent's axes and ``d`` the child's joint point
    from the parent's, parent axes.  The inverse of the zero convention (kinematics module
    docstring): revolute and cylindrical ``theta`` is the turn about ``a`` of ``rel Z^T``;
    a universal's first angle is the turn about ``a`` taking ``U b`` (normal to ``a``) onto
    ``rel b``, which does not depend on its second angle, and the second is the turn about
    ``b`` of ``U^T Rot(a, -theta1) rel``; a slide is ``d . a``.
    """
    jt = t.joint_type
    if jt == 'prismatic':
        return [float(d @ t.axis)]
    if jt == 'universal':
        e = t.fixed @ t.axis_child
        v = rel @ t.axis_child
        theta = math.atan2(float(t.axis @ np.cross(e, v)), float(e @ v))
        rest = t.fixed.T @ _turn(t.axis, -theta) @ rel
        return [theta, twist_about(t.axis_child, rest)]
    theta = twist_about(t.axis, rel @ t.fixed.T)
    if jt == 'revolute':
        return [theta]
    return [theta, float(d @ t.axis)]


def stated(scene):
    """
    Return ``{link: (rotation (3, 3), origin (3,))}`` of the links with a stated pose.

    The frame's pose is the identity (it is the world).
    """
    return {name: (pose.rotation(), np.array(pose.origin_m, dtype=float))
            for name, pose in scene.assembly_poses.items()}


def initial(linkage):
    """
    Return the tree coordinates ``(1, ndof)`` and spherical rotations read from the poses.

    A link without a stated pose is guessed at the frame's pose; the crank coordinate is the
    scene's ``assembly.crank_angle_deg`` (a prismatic input: its slide there).
    """
    sc = linkage.scene
    poses = stated(sc)
    rot, org = [np.eye(3)], [np.zeros(3)]
    for lk in sc.links:
        r, o = poses.get(lk.name, (np.eye(3), np.zeros(3)))
        rot.append(r)
        org.append(o)
    q = np.zeros((1, linkage.ndof))
    sph = np.zeros((1, len(linkage.sph_index), 3, 3))
    si = 0
    for t in linkage.tree:
        rel = rot[t.parent].T @ rot[t.child]
        d = rot[t.parent].T @ (org[t.child] + rot[t.child] @ t.s_child - org[t.parent]) \
            - t.s_parent
        if t.joint_type == 'spherical':
            sph[0, si] = rel
            si += 1
            continue
        q[0, list(t.dofs)] = tree_values(t, rel, d)
    q[0, 0] = linkage.input_coordinate(sc.assembly_crank_angle_rad, 0.0, 0.0)[0]
    return q, sph


def rpy_deg(rot):
    """Return the URDF ``[roll, pitch, yaw]`` (deg) of a rotation (3, 3): Rz Ry Rx."""
    return [math.degrees(math.atan2(rot[2, 1], rot[2, 2])),
            math.degrees(math.atan2(-rot[2, 0], math.hypot(rot[0, 0], rot[1, 0]))),
            math.degrees(math.atan2(rot[1, 0], rot[0, 0]))]


def _angle(rot_a, rot_b):
    """Return the angle (rad) of the rotation taking ``rot_a`` to ``rot_b``."""
    rel = rot_a.T @ rot_b
    vee = 0.5 * np.array([rel[2, 1] - rel[1, 2], rel[0, 2] - rel[2, 0], rel[1, 0] - rel[0, 1]])
    return math.atan2(float(np.linalg.norm(vee)), 0.5 * (float(np.trace(rel)) - 1.0))


def pose_errors(linkage, fr):
    """
    Return ``[(link, angle rad, distance m)]``: each stated link's solved pose against it.

    ``fr`` holds the solved poses at the assembly (batch of one).  An idle-spin link
    (spin fixed by convention) is compared by its S-S line's direction and its first
    ball's centre, which do not depend on the spin.
    """
    idle = {name: (ul, x0) for name, _, _, ul, x0 in getattr(linkage, 'idle_lines', ())}
    out = []
    for name, (rot_s, org_s) in stated(linkage.scene).items():
        k = linkage.body_names.index(name)
        rot, org = fr.rot[0, k], fr.origin[0, k]
        if name in idle:
            ul, x0 = idle[name]
            u, us = rot @ ul, rot_s @ ul
            angle = math.atan2(float(np.linalg.norm(np.cross(u, us))), float(u @ us))
            dist = float(np.linalg.norm(org + rot @ x0 - org_s - rot_s @ x0))
        else:
            angle = _angle(rot_s, rot)
            dist = float(np.linalg.norm(org - org_s))
        out.append((name, angle, dist))
    return out


def pose_mismatch(linkage, fr):
    """
    Return why an assembly's solved poses are not the stated ones, or None if they are.

    The text (the linkage raises it) names every link off by more than the tolerances, the
    angle and the distance, and the pose the linkage closed at (to state it, if it is the
    intended assembly).
    """
    tol_m = POSE_TOL_REL * linkage.length_scale
    bad = [(name, a, d) for name, a, d in pose_errors(linkage, fr)
           if math.degrees(a) > POSE_TOL_DEG or d > tol_m]
    if not bad:
        return None
    parts = []
    for name, angle, dist in bad:
        k = linkage.body_names.index(name)
        origin = [float(f'{v:.6g}') for v in fr.origin[0, k]]
        rpy = [round(v, 3) for v in rpy_deg(fr.rot[0, k])]
        parts.append(f'{name} closed {math.degrees(angle):.3g} deg and {dist:.3g} m from '
                     f'assembly.poses.{name} (there: origin_m {origin}, rpy_deg {rpy})')
    angle = crank_angle_text(linkage.scene.assembly_crank_angle_rad, 4)
    return (
        f'assembly: at crank angle {angle} deg the linkage does not close at the stated '
        f'poses: {"; ".join(parts)}; expected every stated link within {POSE_TOL_DEG:g} deg '
        f'and {tol_m:.3g} m ({POSE_TOL_REL:g} x the linkage size) of its solved pose: the '
        'stated poses select another assembly branch than the solver can reach from them, '
        'or do not fit the joints (axes, angle_deg, link points); state the poses of the '
        'intended assembly more closely, or, if the pose reached is the intended one, '
        'state it')
