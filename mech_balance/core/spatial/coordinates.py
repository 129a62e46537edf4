"""The spatial joints' coordinates from body poses (docs/core.md#the-spatial-formulation)."""

import math

from mech_balance.core.spatial.vectors import cross, cross_c, perp_pair, unit
from mech_balance.rotations import min_rotation, rot_axis, skew
import numpy as np

SUFFIXES = {'revolute': ('',), 'prismatic': ('',), 'cylindrical': ('_turn', '_slide'),
            'universal': ('_1', '_2'), 'spherical': ('_yaw', '_pitch', '_roll')}
"""The published coordinates of each joint type (joint name + suffix)."""
SLIDES = {'revolute': (False,), 'prismatic': (True,), 'cylindrical': (False, True),
          'universal': (False, False), 'spherical': (False, False, False)}
"""Which of them slide (m) rather than turn (rad)."""


def joint_frames(jt, flipped=False):
    """Return a joint's unit axes ``(a, b)`` and fixed rotation (``flipped``: seen from b)."""
    if jt.axis is None:
        return None, None, None
    a, b = unit(jt.axis), unit(jt.axis if jt.axis_b is None else jt.axis_b)
    if flipped:
        a, b = b, a
    if jt.joint_type == 'universal':
        e = b - (b @ a) * a
        e = perp_pair(a)[0] if np.linalg.norm(e) < 1e-12 else e / np.linalg.norm(e)
        return a, b, min_rotation(b, e)
    fixed = min_rotation(b, a)
    if jt.joint_type == 'prismatic':
        angle = math.radians(jt.angle_deg or 0.0) * (-1.0 if flipped else 1.0)
        fixed = rot_axis(a, np.array([angle]))[0] @ fixed
    return a, b, fixed


def _functionals(jt, ax, bx, fixed, zero):
    """Return the ``(9, k)`` linear functionals of ``M = R_a^T R_b`` that a joint reads."""
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
    cols += [np.outer(np.eye(3)[i], bx) for i in range(3)]   # b_in_a itself (the rate)
    # rest = U^T (M - s K M + (1 - c) K^2 M): sum(rest * G) = sum(M * (K^p)^T U G), p = 0, 1, 2
    for g in (cb, np.eye(3)):
        ug = fixed @ g
        cols += [ug, k.T @ ug, k.T @ k.T @ ug]
    return np.stack(cols, -1).reshape(9, -1)


_GROUPS = ('angle', 'slide', 'spherical', 'universal')
"""The joint coordinate groups evaluated together (:func:`joint_values`)."""


_GROUP_OF = {'revolute': ('angle',), 'prismatic': ('slide',), 'cylindrical': ('angle', 'slide'),
             'spherical': ('spherical',), 'universal': ('universal',)}
"""The groups of each joint type's coordinates (published order)."""


def _constants(linkage):
    """Return (cached) the joints' bodies, points and functionals per coordinate group."""
    cached = getattr(linkage, '_joint_constants', None)
    if cached is not None:
        return cached
    sc = linkage.scene
    idx = {n: i for i, n in enumerate(linkage.body_names)}
    frames = [joint_frames(jt) for jt in sc.joints]
    members = {g: [] for g in _GROUPS}        # (joint index, published column)
    col = 0
    for i, jt in enumerate(sc.joints):
        for g in _GROUP_OF[jt.joint_type]:
            members[g].append((i, col))
            col += 3 if g == 'spherical' else 2 if g == 'universal' else 1
    groups = {}
    for g in _GROUPS:
        mem = members[g]
        if not mem:
            continue
        ji = np.array([m[0] for m in mem], dtype=int)
        cols = np.array([m[1] for m in mem], dtype=int)
        zero = np.zeros(3)   # spherical joints have no axes
        ax = np.array([zero if frames[i][0] is None else frames[i][0] for i in ji])
        bx = np.array([zero if frames[i][1] is None else frames[i][1] for i in ji])
        w = None
        if g != 'slide':
            w = np.array([_functionals(sc.joints[i], *frames[i],
                                       linkage.sph_zero.get(sc.joints[i].name)) for i in ji])
            w = np.ascontiguousarray(w.transpose(0, 2, 1))   # (count, k, 9)
        groups[g] = (ji, cols, ax.T[:, :, None].copy(), bx.T[:, :, None].copy(), w)
    out = {
        'ia': np.array([idx[jt.link_a] for jt in sc.joints], dtype=int),
        'ib': np.array([idx[jt.link_b] for jt in sc.joints], dtype=int),
        'pa': np.array([linkage._points[jt.link_a][jt.point_a]
                        for jt in sc.joints]).reshape(-1, 3),
        'pb': np.array([linkage._points[jt.link_b][jt.point_b]
                        for jt in sc.joints]).reshape(-1, 3),
        'pa_c': np.array([linkage._points[jt.link_a][jt.point_a]
                          for jt in sc.joints]).reshape(-1, 3).T[:, :, None].copy(),
        'pb_c': np.array([linkage._points[jt.link_b][jt.point_b]
                          for jt in sc.joints]).reshape(-1, 3).T[:, :, None].copy(),
        'off_frame': np.flatnonzero([idx[jt.link_a] != 0 for jt in sc.joints]),
        'groups': groups, 'size': col,
        'names': joint_names(sc)}
    linkage._joint_constants = out
    return out


def joint_values(linkage, state):
    """Return ``(names, slides, position (n, k), velocity (n, k))`` of every joint coordinate."""
    c = _constants(linkage)
    ia, ib, groups = c['ia'], c['ib'], c['groups']
    rot, org, tw = state.component_major()     # (3, 3, nb, n), (3, nb, n), (6, nb, n)
    n = rot.shape[-1]
    # component-major (.., nj, n): every joint's relative rotation and rate at once
    ra, rb = rot[:, :, ia], rot[:, :, ib]
    rel = rb.copy()                          # R_a = I for a joint on the frame
    w_rels = tw[:3, ib]                      # R_a^T (omega_b - omega_a), in a's axes
    on = c['off_frame']                      # the joints whose a is a moving link
    if on.size:
        ro = ra[:, :, on]
        # (R_a^T R_b)_ij = sum_k R_a,ki R_b,kj: one broadcast product and one sum
        rel[:, :, on] = (ro[:, :, None] * rb[:, None, :, on]).sum(0)
        w_rels[:, on] = (ro * (w_rels[:, on] - tw[:3, ia[on]])[:, None]).sum(0)
    rel9 = rel.reshape(9, ia.size, n)

    def functionals(ji, w):
        """Return the group's functionals ``(k, count, n)``: small products, no BLAS threads."""
        return np.matmul(w, rel9[:, ji].transpose(1, 0, 2)).transpose(1, 0, 2)

    pos, vel = np.empty((c['size'], n)), np.empty((c['size'], n))
    if 'slide' in groups:
        ji, cols, ax, _, _ = groups['slide']
        pa, pb = c['pa_c'][:, ji], c['pb_c'][:, ji]
        ra_s, rb_s = ra[:, :, ji], rb[:, :, ji]
        xa = org[:, ia[ji]] + ra_s[:, 0] * pa[0] + ra_s[:, 1] * pa[1] + ra_s[:, 2] * pa[2]
        xb = org[:, ib[ji]] + rb_s[:, 0] * pb[0] + rb_s[:, 1] * pb[1] + rb_s[:, 2] * pb[2]
        ta, tb = tw[:, ia[ji]], tw[:, ib[ji]]
        va = ta[3:] + cross_c(ta[:3], xa)
        vb = tb[3:] + cross_c(tb[:3], xb)
        d = xb - xa
        dd = vb - va - cross_c(ta[:3], d)
        # along the a-axis in a's axes: (R_a^T d) . a = d . (R_a a)
        axw = ra_s[:, 0] * ax[0] + ra_s[:, 1] * ax[1] + ra_s[:, 2] * ax[2]
        pos[cols] = (d * axw).sum(0)
        vel[cols] = (dd * axw).sum(0)
    if 'angle' in groups:
        ji, cols, ax, _, w = groups['angle']
        f = functionals(ji, w)
        pos[cols] = np.arctan2(f[0], 0.5 * (f[1] - 1.0))
        vel[cols] = (w_rels[:, ji] * ax).sum(0)
    if 'spherical' in groups:
        ji, cols, _, _, w = groups['spherical']
        m10, m00, m20, m21, m22 = functionals(ji, w)
        r = np.hypot(m00, m10)
        yaw = np.arctan2(m10, m00)
        pitch = np.arctan2(-m20, r)
        if r.all():  # their cosines and sines algebraically (no transcendental calls)
            cy, sy = m00 / r, m10 / r
            rp = np.hypot(r, m20)
            cp, sp = r / rp, -m20 / rp
        else:        # pitch +-90 deg somewhere: yaw there is 0 by arctan2's convention
            cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
        # omega = yaw' z + pitch' Rz y + roll' Rz Ry x (a's axes), solved in closed form
        wx, wy, wz = w_rels[:, ji]
        roll_rate = (cy * wx + sy * wy) / cp
        pos[cols], pos[cols + 1], pos[cols + 2] = yaw, pitch, np.arctan2(m21, m22)
        vel[cols], vel[cols + 1], vel[cols + 2] = wz + sp * roll_rate, cy * wy - sy * wx, \
            roll_rate
    if 'universal' in groups:
        ji, cols, ax, _, w = groups['universal']
        g = functionals(ji, w)
        th1 = np.arctan2(g[0], g[1])
        s1, c1 = np.sin(th1), 1.0 - np.cos(th1)
        vee = g[5] - s1 * g[6] + c1 * g[7]
        tr = g[8] - s1 * g[9] + c1 * g[10]
        wr = w_rels[:, ji]
        pos[cols], pos[cols + 1] = th1, np.arctan2(vee, 0.5 * (tr - 1.0))
        vel[cols], vel[cols + 1] = (wr * ax).sum(0), (wr * g[2:5]).sum(0)
    names, slides = c['names']
    return names, slides, np.ascontiguousarray(pos.T), np.ascontiguousarray(vel.T)


def joint_names(scene):
    """Return the published joint coordinate names and which slide (without solving)."""
    names, slides = [], []
    for jt in scene.joints:
        for sfx, sl in zip(SUFFIXES[jt.joint_type], SLIDES[jt.joint_type]):
            names.append(jt.name + sfx)
            slides.append(sl)
    return tuple(names), tuple(slides)
