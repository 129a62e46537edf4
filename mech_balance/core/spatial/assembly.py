"""Spatial assembly from the stated poses, and its check: docs/core.md, "The stated assembly"."""

import math

from mech_balance.conventions import crank_angle_text
from mech_balance.core.planar.kinematics import NEWTON_TOL
from mech_balance.core.spatial.branch import SpatialError
from mech_balance.core.spatial.closure import Rows
from mech_balance.core.spatial.vectors import cross
from mech_balance.rotations import axis_angle_matrix, matrix_rpy
from mech_balance.schema.spatial import POSE_TOL_DEG, POSE_TOL_REL
import numpy as np

RANK_RTOL = 1e-9
"""Singular values below this fraction of the largest count as zero (rank, null space)."""
ASSEMBLY_MAX_ITER = 200
"""Levenberg-Marquardt iterations allowed to assemble the linkage from the scene's poses."""
IDLE_INERTIA_RTOL = 1e-9
"""Inertia about an S-S line, relative to m L^2 + trace(I), below which it counts as zero."""


def _normal(axis):
    """Return a unit vector normal to the unit ``axis``."""
    v = np.cross(axis, np.eye(3)[int(np.argmin(np.abs(axis)))])
    return v / np.linalg.norm(v)


def twist_about(axis, rot):
    """Return the angle (rad) of ``rot`` about the unit ``axis`` (swing-twist split)."""
    ref = _normal(axis)
    v = rot @ ref
    return math.atan2(float(axis @ np.cross(ref, v)), float(ref @ v))


def tree_values(t, rel, d):
    """Return a (non-spherical) tree joint's coordinates from the child's pose in the parent."""
    jt = t.joint_type
    if jt == 'prismatic':
        return [float(d @ t.axis)]
    if jt == 'universal':
        e = t.fixed @ t.axis_child
        v = rel @ t.axis_child
        theta = math.atan2(float(t.axis @ np.cross(e, v)), float(e @ v))
        rest = t.fixed.T @ axis_angle_matrix(t.axis, -theta) @ rel
        return [theta, twist_about(t.axis_child, rest)]
    theta = twist_about(t.axis, rel @ t.fixed.T)
    if jt == 'revolute':
        return [theta]
    return [theta, float(d @ t.axis)]


def stated(scene):
    """Return ``{link: (rotation (3, 3), origin (3,))}`` of the links with a stated pose."""
    return {name: (pose.rotation(), np.array(pose.origin_m, dtype=float))
            for name, pose in scene.assembly_poses.items()}


def initial(linkage):
    """Return the tree coordinates ``(1, ndof)`` and spherical rotations read from the poses."""
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
    return [float(v) for v in matrix_rpy(rot, degrees=True)]


def _angle(rot_a, rot_b):
    """Return the angle (rad) of the rotation taking ``rot_a`` to ``rot_b``."""
    rel = rot_a.T @ rot_b
    vee = 0.5 * np.array([rel[2, 1] - rel[1, 2], rel[0, 2] - rel[2, 0], rel[1, 0] - rel[0, 1]])
    return math.atan2(float(np.linalg.norm(vee)), 0.5 * (float(np.trace(rel)) - 1.0))


def pose_errors(linkage, fr):
    """Return ``[(link, angle rad, distance m)]`` of the solved poses from the stated ones."""
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
    """Return why an assembly's solved poses are not the stated ones, or None if they are."""
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


def spherical_zeros(linkage, fr):
    """Return ``{joint name: A}``, the relative rotation of each spherical joint at assembly."""
    idx = {n: i for i, n in enumerate(linkage.body_names)}
    out = {}
    for jt in linkage.scene.joints:
        if jt.joint_type == 'spherical':
            ra, rb = fr.rot[0, idx[jt.link_a]], fr.rot[0, idx[jt.link_b]]
            out[jt.name] = ra.T @ rb
    return out


class Assembling:
    """The assembly of :class:`~mech_balance.core.spatial.kinematics.Linkage` (a mixin)."""

    def _assemble(self):
        """Assemble the linkage (Levenberg-Marquardt), find idle spins and redundancy."""
        if not self.m and self.nu:
            raise SpatialError(
                f'joints: the linkage is an open chain (no closed loop) with {self.nu} '
                f'degree(s) of freedom besides the crank joint {self.scene.crank_joint!r}; '
                'expected a single-input linkage')
        q, sph = initial(self)
        lam = 1e-3
        fr = self.frames(q, sph)
        g = self.residual(fr) * self.row_scale
        cost = float(np.sum(g * g))
        for _ in range(ASSEMBLY_MAX_ITER):
            if not self.m or np.max(np.abs(g)) <= NEWTON_TOL:
                break
            js = self.scaled(self.jacobian(fr))[0]
            a = js.T @ js
            rhs = js.T @ g[0]
            while True:
                step = -np.linalg.solve(a + lam * np.diag(np.diag(a) + 1e-12), rhs)
                q2, sph2 = self._update(q, sph, (step * self.col_scale[self.unknown])[None])
                fr2 = self.frames(q2, sph2)
                g2 = self.residual(fr2) * self.row_scale
                cost2 = float(np.sum(g2 * g2))
                if cost2 < cost:
                    q, sph, fr, g, cost = q2, sph2, fr2, g2, cost2
                    lam = max(lam / 3.0, 1e-12)
                    break
                lam *= 4.0
                if lam > 1e12:
                    break
            if lam > 1e12:
                break
        if self.m and np.max(np.abs(g)) > 1e-10:
            raise SpatialError(
                f'assembly: the linkage cannot be closed at crank angle '
                f'{crank_angle_text(self.scene.assembly_crank_angle_rad, 4)} deg from '
                f'assembly.poses (largest '
                f'scaled closure residual {np.max(np.abs(g)):.3e} after '
                f'{ASSEMBLY_MAX_ITER} iterations); expected poses near an assembled position')
        self._find_idle(q, sph, fr)
        q, sph, fr, res, ok = self.newton(q, sph)
        if not ok[0]:
            raise SpatialError(f'assembly: Newton did not converge (residual {res[0]:.3e})')
        mismatch = pose_mismatch(self, fr)
        if mismatch:
            raise SpatialError(mismatch)
        self.q0, self.sph0 = q, sph
        self.sph_zero = spherical_zeros(self, fr)
        js = self.scaled(self.jacobian(fr))
        _, cond, rank, sign = self._solver(js)
        self.rank = int(rank[0])
        self.redundant = self.m - self.rank
        self.branch_sign = float(sign[0])
        if self.rank < self.nu:
            raise SpatialError(
                f'joints: the linkage has {self.nu - self.rank} degree(s) of freedom besides '
                f'the crank joint {self.scene.crank_joint!r} (Jacobian rank {self.rank} of '
                f'{self.nu} unknown coordinates) that are not idle spins of S-S links; '
                'expected a single-input linkage')

    def _find_idle(self, q, sph, fr):
        """Detect idle spins from the Jacobian's null space; add the spin rows (or refuse)."""
        if not self.nu:
            return
        js = self.scaled(self.jacobian(fr))[0] if self.m else np.zeros((0, self.nu))
        if js.shape[0]:
            _, s, vt = np.linalg.svd(js)
            s_full = np.zeros(self.nu)
            s_full[:s.size] = s
            null = vt[s_full <= RANK_RTOL * max(s_full[0], 1.0)] if s.size else vt
        else:
            null = np.eye(self.nu)
        if not null.shape[0]:
            return
        # the body twists of each null direction
        qd = np.zeros((null.shape[0], self.ndof))
        qd[:, self.unknown] = null * self.col_scale[self.unknown]
        cols = np.broadcast_to(fr.cols[0], (null.shape[0],) + fr.cols.shape[1:])
        tw = np.einsum('nds,nd,dk->nks', cols, qd, self.path).reshape(null.shape[0], -1)
        spins = []
        sc = self.scene
        for k in range(1, self.nb):
            name = self.body_names[k]
            mine = [j for j in sc.joints if name in (j.link_a, j.link_b)]
            sph_j = [j for j in mine if j.joint_type == 'spherical']
            if len(mine) != 2 or len(sph_j) != 2:
                continue
            x = [fr.origin[0, k] + fr.rot[0, k] @ self._points[name][
                j.point_a if j.link_a == name else j.point_b] for j in sph_j]
            line = x[1] - x[0]
            if np.linalg.norm(line) < 1e-12 * self.length_scale:
                continue
            u = line / np.linalg.norm(line)
            e = np.zeros((self.nb, 6))
            e[k, :3], e[k, 3:] = u, cross(x[0], u)
            e = e.ravel()
            coef, *_ = np.linalg.lstsq(tw.T, e, rcond=None)
            if np.linalg.norm(tw.T @ coef - e) > 1e-6 * np.linalg.norm(e):
                continue
            spins.append((k, sph_j, x, u))
        if len(spins) < null.shape[0]:
            return  # the rank check after assembly names the extra freedoms
        self.idle_lines = []
        for k, sph_j, x, u in spins:
            name = self.body_names[k]
            rl = fr.rot[0, k]
            x0 = self._points[name][sph_j[0].point_a if sph_j[0].link_a == name
                                    else sph_j[0].point_b]
            self.idle_lines.append((name, sph_j[0].name, sph_j[1].name, rl.T @ u, x0))
            n_ref = np.eye(3)[int(np.argmin(np.abs(u)))]
            v = cross(u, n_ref)
            v /= np.linalg.norm(v)
            self.rows.append(Rows('spin', np.array([k]), np.array([0]), (rl.T @ v)[None],
                                  n_ref[None], None, (f'spin:{name}',)))
            self.idle_spins = getattr(self, 'idle_spins', ()) + (
                (name, sph_j[0].name, sph_j[1].name),)
        self.check_idle_inertia(self.scene)
        self._finish_rows()

    def check_idle_inertia(self, scene):
        """Refuse a design whose S-S link has inertia about its S-S line (the spin convention)."""
        for name, j1, j2, ul, x0 in getattr(self, 'idle_lines', ()):
            lk = scene.link(name)
            c = np.array(lk.com_m) - x0
            inertia = np.array(lk.inertia_matrix())
            about = float(ul @ inertia @ ul + lk.mass_kg * np.sum(cross(c, ul) ** 2))
            # the magnitudes: a design that is no body (a least-change force balance may
            # give a negative-definite inertia) must not make the scale vanish or go negative
            scale = abs(lk.mass_kg) * self.length_scale ** 2 + float(np.abs(inertia).sum())
            if about > IDLE_INERTIA_RTOL * max(scale, 1e-300):
                raise SpatialError(
                    f'links.{name}: held only by the spherical joints {j1} and {j2}, it '
                    'spins freely about the line through them (an idle freedom of the '
                    f'Jacobian), and its inertia about that line is {about:.6g} kg m^2; '
                    'expected 0 (a slender rod on that line, whose spin is then fixed by '
                    'convention) - or replace one S by a U (universal joint) to hold the spin')
