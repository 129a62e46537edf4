"""
The spatial joints' coordinates from body poses (zero convention: kinematics docstring).

Every joint (tree or cut) is read from the relative pose of its two links, so a joint's
published value does not depend on where the spanning tree was cut: ``M = R_a^T R_b`` and
``d = R_a^T (x_b - x_a)`` (b's joint point from a's, in a's axes); rates from the relative
angular velocity ``R_a^T (omega_b - omega_a)`` and the relative point velocity.
"""

import math

from mech_balance.core.spatial.kinematics import angle_about, cross, min_rotation, mv, \
    perp_pair, rot_axis
import numpy as np

SUFFIXES = {'revolute': ('',), 'prismatic': ('',), 'cylindrical': ('_turn', '_slide'),
            'universal': ('_1', '_2'), 'spherical': ('_yaw', '_pitch', '_roll')}
"""The published coordinates of each joint type (joint name + suffix)."""
SLIDES = {'revolute': (False,), 'prismatic': (True,), 'cylindrical': (False, True),
          'universal': (False, False), 'spherical': (False, False, False)}
"""Which of them slide (m) rather than turn (rad)."""


def joint_frames(scene, jt):
    """Return a joint's constants: unit axes in a and b, and its fixed rotation (or None)."""
    if jt.axis is None:
        return None, None, None
    a = np.asarray(jt.axis, dtype=float)
    a = a / np.linalg.norm(a)
    b = np.asarray(jt.axis if jt.axis_b is None else jt.axis_b, dtype=float)
    b = b / np.linalg.norm(b)
    if jt.joint_type == 'universal':
        e = b - (b @ a) * a
        if np.linalg.norm(e) < 1e-12:
            e = perp_pair(a)[0]
        return a, b, min_rotation(b, e / np.linalg.norm(e))
    fixed = min_rotation(b, a)
    if jt.joint_type == 'prismatic':
        fixed = rot_axis(a, np.array([math.radians(jt.angle_deg or 0.0)]))[0] @ fixed
    return a, b, fixed


def rpy_of(rot):
    """Return (yaw, pitch, roll) ``(n,)`` each with ``rot = Rz(yaw) Ry(pitch) Rx(roll)``."""
    yaw = np.arctan2(rot[:, 1, 0], rot[:, 0, 0])
    pitch = np.arctan2(-rot[:, 2, 0], np.hypot(rot[:, 0, 0], rot[:, 1, 0]))
    roll = np.arctan2(rot[:, 2, 1], rot[:, 2, 2])
    return yaw, pitch, roll


def _constants(linkage):
    """Return (and cache on the linkage) each joint's bodies, points and axis constants."""
    cached = getattr(linkage, '_joint_constants', None)
    if cached is None:
        sc = linkage.scene
        idx = {n: i for i, n in enumerate(linkage.body_names)}
        per_joint = [(jt, idx[jt.link_a], idx[jt.link_b],
                      linkage._points[jt.link_a][jt.point_a],
                      linkage._points[jt.link_b][jt.point_b], joint_frames(sc, jt))
                     for jt in sc.joints]
        # the same as stacked index arrays: every joint's relative pose in one pass
        stacked = (np.array([c[1] for c in per_joint], dtype=int),
                   np.array([c[2] for c in per_joint], dtype=int),
                   np.array([c[3] for c in per_joint]).reshape(-1, 3),
                   np.array([c[4] for c in per_joint]).reshape(-1, 3),
                   any(jt.joint_type in ('prismatic', 'cylindrical') for jt in sc.joints))
        cached = (per_joint, stacked)
        linkage._joint_constants = cached
    return cached


def joint_values(linkage, state):
    """Return ``(names, slides, position (n, k), velocity (n, k))`` of every joint coordinate."""
    fr, tw = state.frames, state.twist
    names, slides, pos, vel = [], [], [], []
    per_joint, (ia, ib, pa, pb, slide) = _constants(linkage)
    # every joint at once (n, nj, ...): relative rotation, angular velocity, point offsets
    ra, rb = fr.rot[:, ia], fr.rot[:, ib]
    ra_t = np.swapaxes(ra, -1, -2)
    rels = np.matmul(ra_t, rb)
    wa = tw[:, ia, :3]
    w_rels = mv(ra_t, tw[:, ib, :3] - wa)
    if slide:
        xa = fr.origin[:, ia] + mv(ra, pa)
        xb = fr.origin[:, ib] + mv(rb, pb)
        va = tw[:, ia, 3:] + cross(wa, xa)
        vb = tw[:, ib, 3:] + cross(tw[:, ib, :3], xb)
        ds = mv(ra_t, xb - xa)
        dds = mv(ra_t, vb - va - cross(wa, xb - xa))
    for i, (jt, _, _, _, _, (ax, bx, fixed)) in enumerate(per_joint):
        rel, w_rel = rels[:, i], w_rels[:, i]
        t = jt.joint_type
        if t in ('prismatic', 'cylindrical'):
            d, dd = ds[:, i], dds[:, i]
        if t == 'spherical':
            m = rel @ linkage.sph_zero[jt.name].T
            yaw, pitch, roll = rpy_of(m)
            cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
            # omega = yaw' z + pitch' Rz y + roll' Rz Ry x (a's axes), solved in closed form
            wx, wy, wz = w_rel[:, 0], w_rel[:, 1], w_rel[:, 2]
            roll_rate = (cy * wx + sy * wy) / cp
            rates = np.stack([wz + sp * roll_rate, cy * wy - sy * wx, roll_rate], -1)
            vals, rts = [yaw, pitch, roll], [rates[:, 0], rates[:, 1], rates[:, 2]]
        elif t == 'prismatic':
            vals, rts = [d @ ax], [dd @ ax]
        elif t in ('revolute', 'cylindrical'):
            vals = [angle_about(ax, rel @ fixed.T)]
            rts = [w_rel @ ax]
            if t == 'cylindrical':
                vals.append(d @ ax)
                rts.append(dd @ ax)
        else:
            e = fixed @ bx
            bia = rel @ bx
            th1 = np.arctan2(cross(e, bia) @ ax, bia @ e)
            rest = np.einsum('ij,njk->nik', fixed.T, rot_axis(ax, -th1) @ rel)
            th2 = angle_about(bx, rest)
            vals, rts = [th1, th2], [w_rel @ ax, np.einsum('ni,ni->n', w_rel, bia)]
        for sfx, sl, v, r in zip(SUFFIXES[t], SLIDES[t], vals, rts):
            names.append(jt.name + sfx)
            slides.append(sl)
            pos.append(v)
            vel.append(r)
    return tuple(names), tuple(slides), np.stack(pos, -1), np.stack(vel, -1)


def joint_names(scene):
    """Return the published joint coordinate names and which slide (without solving)."""
    names, slides = [], []
    for jt in scene.joints:
        for sfx, sl in zip(SUFFIXES[jt.joint_type], SLIDES[jt.joint_type]):
            names.append(jt.name + sfx)
            slides.append(sl)
    return tuple(names), tuple(slides)
