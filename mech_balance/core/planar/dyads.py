"""Closed-form positions of linkages of RRR dyads: docs/core.md#the-planar-core-coreplanar."""

import numpy as np

TWO_PI = 2.0 * np.pi
_TWO_PI, _INV_TWO_PI, _HALF = np.array(TWO_PI), np.array(1.0 / TWO_PI), np.array(0.5)
"""The constants as 0-d arrays: a ufunc takes those a third quicker than Python scalars."""
_TINY = 1e-150
"""Smallest squared distance P Q divided by without an errstate (its inverse stays finite)."""
NODE_AGREEMENT = 1e-8
"""Largest difference (rad) of the closed form from the traced nodes for the plan to be used."""


class Step:
    """One dyad: ``alpha`` turns about P and carries X, ``beta`` carries X and Q."""

    def __init__(self, cut, joints, ends, bodies, local, beta_at_x, rel, x_src):
        self.cut, self.joints = cut, joints
        self.p_src, self.q_src = ends      # (body, local point) of P and of Q
        self.alpha, self.beta = bodies
        lp, lx_a, lx_b, lq = local
        va, vb = lx_a - lp, lx_b - lq
        r1, r2 = abs(va), abs(vb)
        # (0-d arrays: quicker as ufunc operands than Python scalars)
        self.c_alpha = np.array(np.conj(va) / (r1 * r1))
        self.neg_c_beta = np.array(-np.conj(vb) / (r2 * r2))
        self.half_k, self.r1_sq = np.array(0.5 * (r1 * r1 - r2 * r2)), np.array(r1 * r1)
        self.beta_at_x = beta_at_x       # beta hangs from its tree joint at X (else at Q)
        self.rel, self.x_src = rel, x_src   # rows (tree joint, child, parent); X's source
        self.sign = 0.0                     # +1: X to the left of P -> Q (from the skeleton)


class DyadPlan:
    """The dyads of a linkage in solving order, with the branch sign of each."""

    def __init__(self, linkage, steps):
        self.steps = steps
        self.nt = linkage.nt
        crank = linkage.tree[0]
        self.crank_body = crank.child
        self.crank_anchor_world = crank.p_parent     # on the frame: world coordinates
        # (tree joint, child body, parent body) in solving order: each tree joint but the crank's
        self.rows = []
        for s in steps:
            self.rows += s.rel
        if sorted(r[0] for r in self.rows) != list(range(1, self.nt)):
            raise ValueError('dyad plan: the dyads do not cover each tree joint once')
        # one dyad: its two relative rotations directly; more: differences of the body angles
        self.per_step_rel = len(steps) == 1
        by_joint = sorted(self.rows)
        self.rel_child = np.array([c for _, c, _ in by_joint], dtype=np.intp)
        self.rel_parent = np.array([par for _, _, par in by_joint], dtype=np.intp)
        self.nb = linkage.nb
        self.children = linkage.ch
        # each moving body's anchor (its parent tree joint) in its own frame
        local = np.zeros(linkage.nb, dtype=complex)
        for tj in linkage.tree:
            local[tj.child] = tj.p_child
        # the bodies whose origin is not at their anchor (often none)
        self.offset_bodies = np.flatnonzero(local != 0.0)
        self.offset_local = local[self.offset_bodies][:, None]
        # P and Q per step: (body, offset from its anchor as a 0-d array), or (0, world point)
        for st in steps:
            st.p_at, st.q_at = ((body, point if body == 0 else np.array(point - local[body]))
                                for body, point in (st.p_src, st.q_src))

    def solve(self, psi, ref, signs=None):
        """
        Return ``(q, rot, origin, joint_at)``: tree coordinates ``(nt, p)`` and the poses.

        ``ref`` ``(nt - 1, p)`` (within pi of the result) only fixes the whole turns; ``signs``
        default to the traced branch's.  Where two circles do not meet the results are ``nan``.
        """
        # up to two dyads: checked (cheaper than an errstate), redone under one where that fails
        placed = self._place(psi, signs, checked=True) if len(self.steps) <= 2 else None
        if placed is None:
            with np.errstate(invalid='ignore', divide='ignore', over='ignore'):
                placed = self._place(psi, signs, checked=False)
        rot, anchor, rel = placed
        p = psi.shape[0]
        if rel is not None:
            ang = np.arctan2(rel.imag, rel.real)
        else:
            body_ang = np.empty((self.nb, p))
            body_ang[0] = 0.0                          # the frame
            np.arctan2(rot.imag[1:], rot.real[1:], out=body_ang[1:])
            ang = body_ang.take(self.rel_child, axis=0)
            ang -= body_ang.take(self.rel_parent, axis=0)
        # whole turns from the reference: q = angle + 2 pi round((ref - angle) / 2 pi)
        turns = np.subtract(ref, ang)
        turns *= _INV_TWO_PI
        np.rint(turns, out=turns)
        turns *= _TWO_PI
        q = np.empty((self.nt, p))
        q[0] = psi
        np.add(ang, turns, out=q[1:])
        joint_at = anchor.take(self.children, axis=0)
        origin = anchor
        if self.offset_bodies.size:
            rows = self.offset_bodies
            origin[rows] -= rot.take(rows, axis=0) * self.offset_local
        return q, rot, origin, joint_at

    def _place(self, psi, signs, checked):
        """Return ``(rot, anchor, rel)`` of :meth:`solve` (``checked``: ``None`` before a nan)."""
        p = psi.shape[0]
        rot = np.empty((self.nb, p), dtype=complex)
        anchor = np.empty((self.nb, p), dtype=complex)   # each body's parent tree joint
        rot[0] = 1.0
        anchor[0] = 0.0
        c = self.crank_body
        np.cos(psi, out=rot.real[c])
        np.sin(psi, out=rot.imag[c])
        anchor[c] = self.crank_anchor_world
        per_step = self.per_step_rel
        rel = np.empty((len(self.rows), p), dtype=complex) if per_step else None
        w = np.empty(p, dtype=complex)
        tmp = np.empty(p)
        for k, s in enumerate(self.steps):
            sign = s.sign if signs is None else signs[k]
            big_p, big_q = _placed(rot, anchor, s.p_at), _placed(rot, anchor, s.q_at)
            d = big_q - big_p
            inv = np.multiply(d.real, d.real, out=tmp)
            inv += d.imag * d.imag
            if checked and np.count_nonzero(inv >= _TINY) != p:
                return None                            # P on Q (or nan): not here
            np.divide(1.0, inv, out=inv)
            # X - P = d (u + i sign h) with u = 1/2 + k/(2 D^2), h^2 = r1^2/D^2 - u^2
            u = np.multiply(inv, s.half_k, out=w.real)
            u += _HALF
            h = np.multiply(inv, s.r1_sq, out=w.imag)
            h -= u * u
            if checked and np.count_nonzero(h < 0.0):
                return None                            # circles that do not meet
            np.sqrt(h, out=h)
            if sign < 0.0:
                np.negative(h, out=h)
            dw = d * w                                 # X - P
            np.multiply(dw, s.c_alpha, out=rot[s.alpha])
            d -= dw                                    # Q - X
            np.multiply(d, s.neg_c_beta, out=rot[s.beta])  # (X - Q) conj(v_b) / r2^2
            anchor[s.alpha] = big_p
            if s.beta_at_x:
                np.add(dw, big_p, out=anchor[s.beta])  # X
            else:
                anchor[s.beta] = big_q
            if not per_step:
                continue
            for joint, child, parent in s.rel:    # row joint - 1: the tree order
                if parent == 0:
                    rel[joint - 1] = rot[child]
                else:
                    np.multiply(rot[child], rot[parent].conjugate(), out=rel[joint - 1])
        return rot, anchor, rel

    def signs_at(self, linkage, pose):
        """Return ``(n_dyads, p)``: the side of P Q on which each dyad's X lies, at ``pose``."""
        out = []
        for s in self.steps:
            pts = []
            for body, point in (s.p_src, s.q_src, s.x_src):
                pts.append(pose.origin[body] + pose.rot[body] * point)
            d = pts[1] - pts[0]
            out.append(np.sign((np.conj(d) * (pts[2] - pts[0])).imag))
        return np.array(out)


def _placed(rot, anchor, point):
    """Return the world position of ``(body, offset from its anchor)`` (body 0: world)."""
    body, at = point
    if not body:
        return at
    x = np.multiply(rot[body], at)
    x += anchor[body]
    return x


def plan(linkage):
    """Return the :class:`DyadPlan` of an all-revolute linkage (signs unset), or ``None``."""
    lk = linkage
    if lk.has_pri or lk.npc or not lk.nu:
        return None
    known = {0}
    pj = lk.parent_joint
    pending = list(range(len(lk.cuts)))
    steps = []
    while pending:
        for c in pending:
            step = _dyad(lk, c, known, pj)
            if step is not None:
                steps.append(step)
                known.update(step.joints)
                pending.remove(c)
                break
        else:
            return None
    if known != set(range(lk.nt)):
        return None
    return DyadPlan(lk, steps)


def _dyad(lk, c, known, pj):
    """Return the :class:`Step` closing cut ``c`` given the ``known`` tree joints, or None."""
    cut = lk.cuts[c]
    a, b = cut.a, cut.b
    anc_a, anc_b = lk.anc[a], lk.anc[b]
    if not (anc_a & anc_b) <= known:
        return None
    unk = [t for t in (anc_a ^ anc_b) if t not in known]
    if len(unk) != 2:
        return None
    tree = lk.tree
    ta, tb = pj[a], pj[b]
    if ta in unk and tb in unk:        # X = the cut point; a turns about J_ta, b about J_tb
        return Step(c, (ta, tb), ((tree[ta].parent, tree[ta].p_parent),
                                  (tree[tb].parent, tree[tb].p_parent)), (a, b),
                    (tree[ta].p_child, cut.p_a, cut.p_b, tree[tb].p_child), False,
                    [(ta, a, tree[ta].parent), (tb, b, tree[tb].parent)], (a, cut.p_a))
    for low, p_low, other, p_other in ((a, cut.p_a, b, cut.p_b), (b, cut.p_b, a, cut.p_a)):
        t2 = pj[low]
        if t2 is None or t2 not in unk:
            continue
        u = tree[t2].parent
        t1 = pj[u]
        if t1 is None or t1 not in unk:
            continue
        # alpha = u turns about J_t1 and carries X = J_t2; beta = low carries X and Q
        return Step(c, (t1, t2), ((tree[t1].parent, tree[t1].p_parent), (other, p_other)),
                    (u, low), (tree[t1].p_child, tree[t2].p_parent, tree[t2].p_child, p_low),
                    True, [(t1, u, tree[t1].parent), (t2, low, u)], (u, tree[t2].p_parent))
    return None


def attach_signs(dyad_plan, linkage, skeleton):
    """Set the dyads' branch signs from the skeleton; return the plan, or None if unusable."""
    if dyad_plan is None:
        return None
    pose = linkage.pose(skeleton.q)
    signs = dyad_plan.signs_at(linkage, pose)
    first = signs[:, :1]
    if not (np.all(signs == first) and np.all(first != 0.0)):
        return None
    for s, sign in zip(dyad_plan.steps, first[:, 0]):
        s.sign = float(sign)
    q = dyad_plan.solve(skeleton.q[0], skeleton.q[1:])[0]
    if not np.max(np.abs(q - skeleton.q)) <= NODE_AGREEMENT:   # also False on nan
        return None
    return dyad_plan
