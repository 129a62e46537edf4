"""Velocity and acceleration analysis of a solved planar pose (a mixin of ``Linkage``)."""

from mech_balance.core import linalg
from mech_balance.core.planar.algebra import cross as _cross
import numpy as np

_1J = np.array(1j)   # (0-d: quicker as a ufunc operand than the Python scalar)


class RateAnalysis:
    """The rates of :class:`~mech_balance.core.planar.kinematics.Linkage` at a pose."""

    def rates(self, pose, psi_d, psi_dd, jac=None, need_acc=True):
        """
        Return joint and link rates at a solved pose (seed 000 eqs. 28-36).

        ``jac``: the scaled loop Jacobian at ``pose`` if already known.  Returns a dict with
        ``qd``, ``omega``, ``vel``, ``jac_factors``, ``cond``, ``det_sign``, ``jac`` (None where
        J_u is kept sparse), ``jac_psi`` and, if ``need_acc``, ``qdd``, ``alpha``, ``acc``.
        """
        p = pose.phi.shape[1]
        if not isinstance(psi_d, float) and np.ndim(psi_d):
            psi_d = np.broadcast_to(psi_d, (p,))
        if not isinstance(psi_dd, float) and np.ndim(psi_dd):
            psi_dd = np.broadcast_to(psi_dd, (p,))
        unknown = self.unknown_rows
        if (self.sparse_jac or self.block is not None) and jac is None:
            fac, jac_psi = self.factored(pose)
        else:
            if jac is None:
                jac = self.jacobian(pose)
            fac = linalg.Factored(jac[:, unknown], self.lu)
            jac_psi = jac[:, 0]
        cond = fac.cond()
        sign = fac.sign()
        scale_d = -self.col_scale[:, None] * psi_d if self.has_pri else -psi_d
        qd = np.empty((self.nt, p))
        qd[0] = psi_d
        # q_u' = -J_u^-1 J_psi psi' (seed 000 eq. 32, generalized)
        np.multiply(fac.solve(jac_psi), scale_d, out=qd[unknown])
        omega = np.dot(self.anc_rev, qd) if self.dense_tree else self._down_rev(qd)
        origin, J = pose.origin, pose.joint_at
        # v = i V, V = omega O - S with S the sum over the joints above of qd_t J_t
        # (+ prismatic slides)
        if self.has_pri:
            vel = omega * origin
            vel -= self._down(qd * J * self.rev_col + 1j * qd * pose.axis)
            vel *= _1J
        else:
            s_v = self._down(qd * J)
            v_rel = omega * origin
            v_rel -= s_v
            vel = _1J * v_rel
        out = {'qd': qd, 'omega': omega, 'vel': vel, 'cond': cond, 'jac': jac,
               'jac_psi': jac_psi, 'det_sign': sign, 'jac_factors': fac}
        if not need_acc:
            return out
        # velocity-product part of the link accelerations (all joint accelerations zero):
        # each joint's point moves at v_J = v_parent + i omega_parent (J - O_parent)
        par = self.par
        omega_par = omega.take(par, axis=0)
        if self.has_pri:
            v_joint = J - origin.take(par, axis=0)
            v_joint *= _1J * omega_par
            v_joint += vel.take(par, axis=0)
            acc_v = omega * vel
            acc_v -= self._down(qd * v_joint * self.rev_col - qd * omega_par * pose.axis)
            acc_v *= _1J
        else:
            # revolute only: v_J = i W with W = omega_parent J - S_parent, so
            # a_v = i (omega v - sum qd_t v_J) = sum qd_t W_t - omega V: no products with i
            w_rel = omega_par * J
            w_rel -= s_v.take(par, axis=0)
            acc_v = self._down(qd * w_rel)
            acc_v -= omega * v_rel
        gamma = self._cut_bias(pose, omega, vel, acc_v)
        if not isinstance(psi_dd, float) or psi_dd != 0.0:
            gamma += jac_psi * psi_dd
        qdd = np.empty((self.nt, p))
        qdd[0] = psi_dd
        # J_u q_u'' = -(gamma + J_psi psi'')
        if self.has_pri:
            np.multiply(fac.solve(gamma), -self.col_scale[:, None], out=qdd[unknown])
        else:
            np.negative(fac.solve(gamma), out=qdd[unknown])
        alpha = np.dot(self.anc_rev, qdd) if self.dense_tree else self._down_rev(qdd)
        acc = alpha * origin
        if self.has_pri:
            acc -= self._down(qdd * J * self.rev_col + 1j * qdd * pose.axis)
        else:
            acc -= self._down(qdd * J)
        acc *= _1J
        acc += acc_v
        out.update(qdd=qdd, alpha=alpha, acc=acc)
        return out

    def _cut_bias(self, pose, omega, vel, acc_v):
        """Return the scaled loop-equation accelerations with all joint accelerations zero."""
        if not self.m:
            return np.zeros((0, pose.phi.shape[1]))
        self.cut_points(pose)
        pa, pb, ra, rb = pose.cut_points[:4]
        ia, ib = self.cut_a, self.cut_b
        # acceleration of each cut end: a_O - omega^2 r (no angular acceleration here)
        n = len(self.cuts)
        w = omega.take(self.cut_ab, axis=0)
        w *= w
        ends = acc_v.take(self.cut_ab, axis=0)
        ends -= w * pose.cut_points[4]
        d = ends[n:] - ends[:n]
        nr = self.nr
        if not self.npc:
            return self.scaled_rows(d)
        rows = [d.real[:nr], d.imag[:nr]]
        ia, ib = ia[nr:], ib[nr:]
        n = pose.rot[ia] * self.cut_axis
        dist = pb[nr:] - pa[nr:]
        dist_d = (vel[ib] + 1j * omega[ib] * rb[nr:]) - (vel[ia] + 1j * omega[ia] * ra[nr:])
        n_d = 1j * omega[ia] * n
        n_dd = -omega[ia] ** 2 * n
        rows += [np.zeros((self.npc, d.shape[1])),
                 _cross(n_dd, dist) + 2.0 * _cross(n_d, dist_d) + _cross(n, d[nr:])]
        return np.concatenate(rows) * self.row_scale[:, None]
