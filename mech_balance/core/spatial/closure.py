"""Closure rows of a spatial linkage: docs/core.md#the-spatial-formulation."""

from dataclasses import dataclass

from mech_balance.core.spatial.coordinates import joint_frames
from mech_balance.core.spatial.vectors import cross_c, dot, dot_c, mv, perp_pair
import numpy as np


@dataclass
class Rows:
    """The closure rows of one group, as index and local-vector arrays (module docstring)."""

    form: str
    body_b: np.ndarray
    body_a: np.ndarray
    vec_b: np.ndarray     # points: s_b; dots: u_b; lines: s_b; spin: v
    vec_a: np.ndarray     # points: s_a; dots: w_a; lines: s_a; spin: n (world)
    extra: np.ndarray     # lines: w_a; others: unused
    joint: tuple          # the joint name of each row (spin rows: 'spin:<link>')

    @property
    def size(self):
        """Return the number of rows."""
        return self.body_b.size * (3 if self.form == 'point' else 1)

    @property
    def ends(self):
        """Return the b bodies then the a bodies (the stacked passes over both ends)."""
        both = getattr(self, '_ends', None)
        if both is None:
            both = self._ends = np.concatenate([self.body_b, self.body_a])
        return both


class ClosureRows:
    """The closure rows of :class:`~mech_balance.core.spatial.kinematics.Linkage` (a mixin)."""

    def _build_rows(self, body, cuts):
        sc = self.scene
        pts, dots, lines = [], [], []
        for ji in cuts:
            jt = sc.joints[ji]
            a, b = body[jt.link_a], body[jt.link_b]
            sa = self._points[jt.link_a][jt.point_a]
            sb = self._points[jt.link_b][jt.point_b]
            t = jt.joint_type
            if t in ('revolute', 'universal', 'spherical'):
                pts.append((b, a, sb, sa, jt.name))
            if t == 'spherical':
                continue
            ax, bx, fixed = joint_frames(jt)
            if t == 'universal':
                dots.append((b, bx, a, ax, jt.name))
                continue
            e1, e2 = perp_pair(ax)
            dots.append((b, bx, a, e1, jt.name))
            dots.append((b, bx, a, e2, jt.name))
            if t in ('cylindrical', 'prismatic'):
                lines.append((b, a, sb, sa, e1, jt.name))
                lines.append((b, a, sb, sa, e2, jt.name))
            if t == 'prismatic':
                dots.append((b, fixed.T @ e1, a, e2, jt.name))
        self.rows = []
        if pts:
            self.rows.append(Rows('point', np.array([p[0] for p in pts]),
                                  np.array([p[1] for p in pts]), np.array([p[2] for p in pts]),
                                  np.array([p[3] for p in pts]), None,
                                  tuple(p[4] for p in pts for _ in range(3))))
        if dots:
            self.rows.append(Rows('dot', np.array([p[0] for p in dots]),
                                  np.array([p[2] for p in dots]),
                                  np.array([p[1] for p in dots]),
                                  np.array([p[3] for p in dots]), None,
                                  tuple(p[4] for p in dots)))
        if lines:
            self.rows.append(Rows('line', np.array([p[0] for p in lines]),
                                  np.array([p[1] for p in lines]),
                                  np.array([p[2] for p in lines]),
                                  np.array([p[3] for p in lines]),
                                  np.array([p[4] for p in lines]), tuple(p[5] for p in lines)))
        self._finish_rows()

    def _finish_rows(self):
        self.m = sum(r.size for r in self.rows)
        scale = []
        for r in self.rows:
            scale += [1.0 / self.length_scale if r.form in ('point', 'line') else 1.0] * r.size
        self.row_scale = np.array(scale)
        self.col_scale = np.where(self.dof_slide, self.length_scale, 1.0)
        self.row_joint = tuple(j for r in self.rows for j in r.joint)
        bodies_b, bodies_a = [], []
        for r in self.rows:
            rep = 3 if r.form == 'point' else 1
            bodies_b += list(np.repeat(r.body_b, rep))
            bodies_a += list(np.repeat(r.body_a, rep))
        self.row_b = np.array(bodies_b, dtype=int)
        self.row_a = np.array(bodies_a, dtype=int)
        self.mask_b = self.path[:, self.row_b].T  # (m, ndof)
        self.mask_a = self.path[:, self.row_a].T
        # per group, per joint (k, ndof, 1): which coordinates move its b and its a body
        self._row_masks = [self.path[:, r.body_b].T[:, :, None] for r in self.rows]
        self._row_masks_a = [self.path[:, r.body_a].T[:, :, None] for r in self.rows]
        self.square = self.m == self.nu
        self.js_scale = self.row_scale[:, None] * self.col_scale[self.unknown]

    def _row_parts(self, fr):
        """Return per group the world quantities the rows need (cached on ``fr``)."""
        if fr.parts is None:
            fr.parts = list(self._row_parts_of(fr))
        return fr.parts

    def _row_parts_of(self, fr):
        """Yield per group the world quantities the rows need."""
        for r in self.rows:
            rb, ra = fr.rot[:, r.body_b], fr.rot[:, r.body_a]
            if r.form == 'spin':
                yield r, rb, ra, mv(rb, r.vec_b), r.vec_a
                continue
            vb = mv(rb, r.vec_b)
            va = mv(ra, r.vec_a)
            if r.form in ('point', 'line'):
                vb = vb + fr.origin[:, r.body_b]
                va = va + fr.origin[:, r.body_a]
            yield r, rb, ra, vb, va

    def residual(self, fr):
        """Return the closure residuals ``(n, m)`` (SI: m for point and line rows)."""
        out = []
        for r, rb, ra, vb, va in self._row_parts(fr):
            if r.form == 'point':
                out.append((vb - va).reshape(vb.shape[0], -1))
            elif r.form == 'dot':
                out.append(dot(vb, va))
            elif r.form == 'line':
                w = mv(ra, r.extra)
                out.append(dot(vb - va, w))
            else:
                out.append(dot(vb, va))
        return np.concatenate(out, axis=1) if out else np.zeros((fr.rot.shape[0], 0))

    @property
    def wrench_rows(self):
        """Return the first row of each row wrench (a coincident point's three rows: one)."""
        cached = getattr(self, '_wrench_rows', None)
        if cached is None or cached[0] != self.m:
            rows, at = [], 0
            for r in self.rows:
                step = 3 if r.form == 'point' else 1
                rows += list(range(at, at + r.size, step))
                at += r.size
            cached = (self.m, np.array(rows, dtype=int))
            self._wrench_rows = cached
        return cached[1]

    def row_wrenches(self, fr, lam):
        """
        Return ``(W_b, W_a)`` ``(6, q, n)``: the closure rows' wrenches on their b and a bodies.

        Moment about the frame origin and force for multipliers ``lam`` ``(n, m)``, in
        :attr:`wrench_rows` order (a coincident point's three rows: one force at the point).
        """
        n = lam.shape[0]
        lam_t = lam.T
        wb, wa = [], []
        at = 0
        for r, rb, ra, vb, va in self._row_parts(fr):
            k = r.body_b.size
            xb = vb.transpose(2, 1, 0)                     # (3, k, n)
            lr = lam_t[at:at + r.size]
            at += r.size
            if r.form == 'point':
                f = lr.reshape(k, 3, n).transpose(1, 0, 2)  # (3, k, n): the force on b
                wb.append(np.concatenate([cross_c(xb, f), f]))
                wa.append(-np.concatenate([cross_c(va.transpose(2, 1, 0), f), f]))
                continue
            zero = np.zeros((3, k, n))
            if r.form == 'spin':
                wb.append(np.concatenate([cross_c(xb, r.vec_a.T[:, :, None]) * lr, zero]))
                wa.append(np.zeros((6, k, n)))
                continue
            xa = va.transpose(2, 1, 0)
            if r.form == 'dot':
                c = cross_c(xb, xa) * lr
                wb.append(np.concatenate([c, zero]))
                wa.append(np.concatenate([-c, zero]))
                continue
            w = mv(ra, r.extra).transpose(2, 1, 0) * lr
            wb.append(np.concatenate([cross_c(xb, w), w]))
            wa.append(np.concatenate([cross_c(w, xb - xa) - cross_c(xa, w), -w]))
        if not wb:
            return np.zeros((6, 0, n)), np.zeros((6, 0, n))
        return np.concatenate(wb, axis=1), np.concatenate(wa, axis=1)

    def jacobian(self, fr):
        """Return the closure Jacobian ``(n, m, ndof)``: a view of the component-major stack."""
        n = fr.rot.shape[0]
        if not self.m:
            return np.zeros((n, 0, self.ndof))
        c = fr.cols_c
        om, vel = c[:3, None], c[3:, None]           # (3, 1, ndof, n)
        out = []
        at = 0
        for r, rb, ra, vb, va in self._row_parts(fr):
            size = r.size
            mb, ma = self._row_masks[at], self._row_masks_a[at]
            at += 1
            xb = vb.transpose(2, 1, 0)[:, :, None]     # (3, k, 1, n)
            if r.form == 'point':
                jb = cross_c(om, xb)
                jb += vel
                ja = cross_c(om, va.transpose(2, 1, 0)[:, :, None])
                ja += vel
                j = jb * mb - ja * ma                    # (3, k, ndof, n)
                out.append(j.transpose(1, 0, 2, 3).reshape(size, self.ndof, n))
                continue
            if r.form == 'spin':
                g = cross_c(xb, r.vec_a.T[:, :, None, None])
                out.append(dot_c(g, om) * mb)
                continue
            xa = va.transpose(2, 1, 0)[:, :, None]
            if r.form == 'dot':
                out.append(dot_c(cross_c(xb, xa), om) * (mb - ma))
                continue
            w = mv(ra, r.extra).transpose(2, 1, 0)[:, :, None]
            jb = dot_c(cross_c(xb, w), om) + dot_c(w, vel)
            ja = dot_c(cross_c(w, xb - xa) - cross_c(xa, w), om) - dot_c(w, vel)
            out.append(jb * mb + ja * ma)
        return np.concatenate(out, axis=0).transpose(2, 0, 1)

    def bias(self, fr, twist, acc0):
        """Return the rows' second time derivatives ``(m, n)`` at accelerations ``acc0``."""
        out = []
        n = twist.shape[-1]
        for r, rb, ra, vb, va in self._row_parts(fr):
            k = r.body_b.size
            vb = vb.transpose(2, 1, 0)                    # (3, k, n) views
            if r.form == 'spin':
                w, al = twist[:3, r.body_b], acc0[:3, r.body_b]
                ddu = cross_c(al, vb)
                ddu += cross_c(w, cross_c(w, vb))
                out.append(dot_c(ddu, r.vec_a.T[:, :, None]))
                continue
            va = va.transpose(2, 1, 0)
            t, a = twist[:, r.ends], acc0[:, r.ends]       # (6, 2k, n): b ends, then a ends
            x = np.concatenate([vb, va], axis=1)
            w = t[:3]
            if r.form == 'point':
                acc = a[3:] + cross_c(a[:3], x)
                acc += cross_c(w, t[3:] + cross_c(w, x))
                out.append((acc[:, :k] - acc[:, k:]).transpose(1, 0, 2).reshape(3 * k, n))
            elif r.form == 'dot':
                du = cross_c(w, x)
                ddu = cross_c(a[:3], x)
                ddu += cross_c(w, du)
                out.append(dot_c(ddu[:, :k], va) + 2.0 * dot_c(du[:, :k], du[:, k:])
                           + dot_c(vb, ddu[:, k:]))
            else:
                wl = mv(ra, r.extra).transpose(2, 1, 0)
                vel = t[3:] + cross_c(w, x)
                acc = a[3:] + cross_c(a[:3], x)
                acc += cross_c(w, vel)
                wa, ala = w[:, k:], a[:3, k:]
                dw = cross_c(wa, wl)
                ddw = cross_c(ala, wl)
                ddw += cross_c(wa, dw)
                out.append(dot_c(acc[:, :k] - acc[:, k:], wl)
                           + 2.0 * dot_c(vel[:, :k] - vel[:, k:], dw)
                           + dot_c(vb - va, ddw))
        return np.concatenate(out, axis=0) if out else np.zeros((0, n))
