"""
The spatial joints' coordinates from body poses (zero convention: kinematics docstring).

Every joint (tree or cut) is read from the relative pose of its two links, so a joint's
published value does not depend on where the spanning tree was cut: ``M = R_a^T R_b`` and
``d = R_a^T (x_b - x_a)`` (b's joint point from a's, in a's axes); rates from the relative
angular velocity ``R_a^T (omega_b - omega_a)`` and the relative point velocity.
"""

import math

from mech_balance.core.spatial.kinematics import cross, min_rotation, mv, perp_pair, \
    rot_axis, skew
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


def _functionals(jt, ax, bx, fixed, zero):
    """
    Return the ``(9, k)`` linear functionals of a joint's relative rotation it reads.

    Every published angle is an ``arctan2`` of linear functionals of ``M = R_a^T R_b``
    (``sum(M * W)``): revolute and cylindrical ``vee(M Z^T) . a`` and ``tr(M Z^T)``
    (:func:`~kinematics.angle_about`); spherical the five entries of ``M A^T`` that
    :func:`rpy_of` reads; universal ``b_in_a = M b`` against ``e`` and ``a x e``, then the
    second angle's ``vee`` and trace terms of ``U^T Rot(a, -theta1) M``, each split into its
    ``M``, ``K M`` and ``K^2 M`` parts (K the cross matrix of a).  Built once per joint.
    """
    t = jt.joint_type
    if t == 'prismatic':
        return np.zeros((9, 0))
    if t == 'spherical':
        # m = M A^T: m_ij = sum_k M_ik A_jk
        cols = []
        for i, j in ((1, 0), (0, 0), (2, 0), (2, 1), (2, 2)):
            w = np.zeros((3, 3))
            w[i] = zero[j]
            cols.append(w)
        return np.stack(cols, -1).reshape(9, -1)
    if t in ('revolute', 'cylindrical'):
        return np.stack([0.5 * skew(ax) @ fixed, fixed], -1).reshape(9, -1)
    e = fixed @ bx
    k = skew(ax)
    cb = 0.5 * skew(bx)
    # b_in_a . (a x e) (= cross(e, b_in_a) . a) and b_in_a . e; b_in_a = M b
    cols = [np.outer(cross(ax, e), bx), np.outer(e, bx)]
    # rest = U^T (M - s K M + (1 - c) K^2 M): sum(rest * G) = sum(M * (K^p)^T U G), p = 0, 1, 2
    for g in (cb, np.eye(3)):
        ug = fixed @ g
        cols += [ug, k.T @ ug, k.T @ k.T @ ug]
    return np.stack(cols, -1).reshape(9, -1)


def _constants(linkage):
    """Return (and cache on the linkage) each joint's bodies, points and functionals."""
    cached = getattr(linkage, '_joint_constants', None)
    if cached is None:
        sc = linkage.scene
        idx = {n: i for i, n in enumerate(linkage.body_names)}
        per_joint, blocks, at = [], [], 0
        for jt in sc.joints:
            ax, bx, fixed = joint_frames(sc, jt)
            w = _functionals(jt, ax, bx, fixed, linkage.sph_zero.get(jt.name))
            per_joint.append((jt, ax, bx, fixed, at))
            blocks.append(w)
            at += w.shape[1]
        # every joint's functionals as one block-diagonal (9 nj, K) matrix: one product
        big = np.zeros((9 * len(blocks), at))
        col = 0
        for i, w in enumerate(blocks):
            big[9 * i:9 * i + 9, col:col + w.shape[1]] = w
            col += w.shape[1]
        stacked = (np.array([idx[jt.link_a] for jt in sc.joints], dtype=int),
                   np.array([idx[jt.link_b] for jt in sc.joints], dtype=int),
                   np.array([linkage._points[jt.link_a][jt.point_a]
                             for jt in sc.joints]).reshape(-1, 3),
                   np.array([linkage._points[jt.link_b][jt.point_b]
                             for jt in sc.joints]).reshape(-1, 3),
                   any(jt.joint_type in ('prismatic', 'cylindrical') for jt in sc.joints),
                   big)
        cached = (per_joint, stacked)
        linkage._joint_constants = cached
    return cached


def joint_values(linkage, state):
    """Return ``(names, slides, position (n, k), velocity (n, k))`` of every joint coordinate."""
    fr, tw = state.frames, state.twist
    names, slides, pos, vel = [], [], [], []
    per_joint, (ia, ib, pa, pb, slide, big) = _constants(linkage)
    # every joint at once (n, nj, ...): relative rotation, angular velocity, point offsets
    n = fr.rot.shape[0]
    ra = fr.rot[:, ia]
    ra_t = np.ascontiguousarray(np.swapaxes(ra, -1, -2))   # matmul is slow on transposed views
    # every functional at once, component-major (K, n): contiguous rows for the finishing
    f = big.T @ np.matmul(ra_t, fr.rot[:, ib]).reshape(n, -1).T
    wa = tw[:, ia, :3]
    w_rels = np.ascontiguousarray(mv(ra_t, tw[:, ib, :3] - wa).T)   # (3, nj, n)
    if slide:
        rb = fr.rot[:, ib]
        xa = fr.origin[:, ia] + mv(ra, pa)
        xb = fr.origin[:, ib] + mv(rb, pb)
        va = tw[:, ia, 3:] + cross(wa, xa)
        vb = tw[:, ib, 3:] + cross(tw[:, ib, :3], xb)
        ds = np.ascontiguousarray(mv(ra_t, xb - xa).T)
        dds = np.ascontiguousarray(mv(ra_t, vb - va - cross(wa, xb - xa)).T)
    for i, (jt, ax, bx, fixed, c) in enumerate(per_joint):
        wx, wy, wz = w_rels[:, i]
        t = jt.joint_type
        if t in ('prismatic', 'cylindrical'):
            d = ds[0, i] * ax[0] + ds[1, i] * ax[1] + ds[2, i] * ax[2]
            dd = dds[0, i] * ax[0] + dds[1, i] * ax[1] + dds[2, i] * ax[2]
        if t == 'spherical':
            m10, m00, m20, m21, m22 = f[c:c + 5]
            yaw = np.arctan2(m10, m00)
            pitch = np.arctan2(-m20, np.hypot(m00, m10))
            roll = np.arctan2(m21, m22)
            cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
            # omega = yaw' z + pitch' Rz y + roll' Rz Ry x (a's axes), solved in closed form
            roll_rate = (cy * wx + sy * wy) / cp
            vals = [yaw, pitch, roll]
            rts = [wz + sp * roll_rate, cy * wy - sy * wx, roll_rate]
        elif t == 'prismatic':
            vals, rts = [d], [dd]
        elif t in ('revolute', 'cylindrical'):
            vals = [np.arctan2(f[c], 0.5 * (f[c + 1] - 1.0))]
            rts = [wx * ax[0] + wy * ax[1] + wz * ax[2]]
            if t == 'cylindrical':
                vals.append(d)
                rts.append(dd)
        else:
            th1 = np.arctan2(f[c], f[c + 1])
            s1, c1 = np.sin(th1), 1.0 - np.cos(th1)
            vee = f[c + 2] - s1 * f[c + 3] + c1 * f[c + 4]
            tr = f[c + 5] - s1 * f[c + 6] + c1 * f[c + 7]
            th2 = np.arctan2(vee, 0.5 * (tr - 1.0))
            bia = mv(np.matmul(ra_t[:, i], fr.rot[:, ib[i]]), bx)
            vals = [th1, th2]
            rts = [wx * ax[0] + wy * ax[1] + wz * ax[2],
                   wx * bia[:, 0] + wy * bia[:, 1] + wz * bia[:, 2]]
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
