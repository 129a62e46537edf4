"""One disc per listed link as a cone program: docs/balancing.md#counterweights-add-only-discs."""

from dataclasses import dataclass, field
import math

import clarabel
from mech_balance import conic, schema
from mech_balance.analysis import clearance as clearance_mod, linear_maps
from mech_balance.balancing import certificate, conditioning, redistribution
from mech_balance.balancing.counterweight_options import CounterweightError, \
    CounterweightOptions, joint_reach_m
from mech_balance.schema.scene import Counterweight
import numpy as np
import scipy.sparse as sp

MIN_MASS_REL = 1e-7
"""An optimal disc mass below this fraction of its link's mass is omitted (solver noise)."""
FREE_INERTIA_REL = 1e-12
"""A link's inertia column below this fraction of a term's map: the inertia enters no term."""


@dataclass
class CounterweightDesign:
    """One counterweight as built: a disc on its link (SI; angle in deg, link frame)."""

    link: str
    mass_kg: float
    centre_m: tuple
    centre_radius_m: float
    centre_angle_deg: float
    radius_m: float
    thickness_m: float
    density_kg_m3: float
    inertia_com_kg_m2: float
    max_centre_radius_m: float
    max_mass_kg: float
    plane_m: float = 0.0        # the disc's plane: offset along z from its link's plane
    mount: str = ''             # the link's point whose shaft carries it ('' nearest)

    def counterweight(self):
        """Return the scene's :class:`~mech_balance.schema.scene.Counterweight` of this disc."""
        return Counterweight(self.mass_kg, tuple(self.centre_m), self.radius_m,
                             self.thickness_m, self.density_kg_m3, self.plane_m, self.mount)

    def to_dict(self):
        """Return the design as a plain dict."""
        return schema.plain(self.__dict__)


@dataclass
class Problem:
    """The counterweight SOCP of one scene: variables, cones, stages."""

    scene: object
    maps: object
    opt: CounterweightOptions
    units: object
    norms: list = field(default_factory=list)   # (G (k, 4L), c (k,)) per objective term
    _static: tuple = None                       # the shared cones, built once

    def __post_init__(self):
        maps, opt, u = self.maps, self.opt, self.units
        names = [lk.name for lk in self.scene.links]
        n = len(names)
        ms, ls = u.mass_kg, u.length_m
        self.scale = np.tile([ms, ms * ls, ms * ls, ms * ls * ls], n)
        self.idx = [names.index(nm) for nm in opt.links]
        t0 = maps.theta_original.reshape(-1, 4)
        m0 = t0[self.idx, 0]
        l0 = np.sqrt(t0[self.idx, 3] / m0)
        # variables y per listed link, in units of the link: dm = m0 y_m, dh = m0 l0 y_h, ...
        self.m0, self.l0 = m0, l0
        self.cols = np.concatenate([np.arange(4 * i, 4 * i + 4) for i in self.idx])
        reach = np.array([joint_reach_m(self.scene, nm) for nm in opt.links])   # m
        self.r_max = opt.max_radius_factor * reach / ls
        self.k_max = opt.max_gyration_factor * reach / ls
        self.dsc = np.column_stack([m0, m0 * l0, m0 * l0, m0 * l0 * l0]).ravel()
        self.m_max = np.array([opt.max_mass_factor * self.scene.link(nm).own_mass_kg / ms
                               for nm in opt.links])
        # the rim bound rho (normalized), None without max_rim_radius_factor
        self.rho = None if opt.max_rim_radius_factor is None else \
            opt.max_rim_radius_factor * reach / ls
        self.plane = dict(opt.planes)
        # c = 2 pi rho t_max (kg/m^2), normalized: kg/m^2 * ls^2 / ms
        self.c_disc = 2.0 * math.pi * opt.density_kg_m3 * opt.max_thickness_m * ls * ls / ms
        w1, w2 = opt.weights
        self.weights4 = np.array([w1, w2, opt.torque_weight, opt.reaction_weight])
        theta0 = maps.theta_original
        mats = [maps.force, maps.moment]
        self.term_of = [0, 1]
        if opt.torque_weight:
            mats.append(maps.torque)
            self.term_of.append(2)
        if opt.reaction_weight:
            for r in maps.reactions.values():
                mats.append(r)
                self.term_of.append(3)
        self.norms = [(mat[:, self.cols] * self.dsc, mat @ theta0) for mat in mats]
        # a link whose inertia enters no term (a crank at constant speed) gets t = t_max
        col = [max(np.linalg.norm(g[:, 4 * i + 3]) / max(np.linalg.norm(g), 1e-300)
                   for g, _ in self.norms) for i in range(len(opt.links))]
        self.inertia_free = [v <= FREE_INERTIA_REL for v in col]
        self.nl = len(opt.links)
        self.ny = 4 * self.nl
        self.nx = self.ny + self.nl + len(self.norms)   # y | s (aux) | t (epigraphs)

    def weights_vector(self):
        q = np.zeros(self.nx)
        for k, term in enumerate(self.term_of):
            q[self.ny + self.nl + k] = self.weights4[term]
        return q

    def unit(self, k):
        q = np.zeros(self.nx)
        q[self.ny + self.nl + k] = 1.0
        return q

    def mass_vector(self):
        q = np.zeros(self.nx)
        q[0:self.ny:4] = self.m0
        return q

    def blame(self):
        """Return the scene values that make the program ill-posed (:mod:`.conditioning`)."""
        sc = self.scene
        return conditioning.blame(sc, None if sc.normalization is None else self.units,
                                  sc.crank_speed_rad_s)

    def norm(self, k, y):
        g, c = self.norms[k]
        return float(np.linalg.norm(g @ y + c))

    def z(self, y):
        return float(sum(self.weights4[t] * self.norm(k, y) for k, t in enumerate(self.term_of)))

    def secondary(self):
        """Return the index of the tie-break norm (0 force, 1 moment) or None."""
        return redistribution.tie_break_term(self.weights4)

    def _row_space(self, g):
        u, sv, vt = np.linalg.svd(g, full_matrices=False)
        if not sv.size or sv[0] == 0.0:
            return u[:, :0], sv[:0], vt[:0]
        r = int(np.sum(sv > linear_maps.RANK_REL_TOL * sv[0]))
        return u[:, :r], sv[:r], vt[:r]

    def pin(self, k, y, exact):
        """Return (rows, target): the optimal set of a single-norm stage (``exact``: map 0)."""
        g, c = self.norms[k]
        u, sv, vt = self._row_space(g)
        if not sv.size:        # the term does not depend on the counterweights at all
            return vt, np.zeros(0)
        if exact:
            return vt, -(u.T @ c) / sv
        # rows weighted by their singular values: the equality residual in units of the norm
        rows = vt * (sv / sv[0])[:, None]
        return rows, rows @ y

    def merged(self, pins, y):
        """Return the pins as one orthonormal row set at the latest optimum ``y``."""
        if not pins:
            return []
        rows = np.vstack([p[0] for p in pins])
        _, sv, vt = self._row_space(rows)
        if not sv.size:
            return []
        rows = vt * (sv / sv[0])[:, None]
        return [(rows, rows @ y)]

    def project_force_balance(self, y):
        """Return ``y`` moved onto the exact force balance (orthogonal projection)."""
        rows, target = self.pin(0, y, True)
        return y - rows.T @ (rows @ y - target)

    def run(self, q, pins, bound=None, caps=()):
        nx, ny, nl = self.nx, self.ny, self.nl
        a_blocks, b_blocks, cones = [], [], []

        def add(cone, a, b):
            a_blocks.append(np.atleast_2d(a))
            b_blocks.append(np.asarray(b, dtype=float).ravel())
            cones.append(cone(a_blocks[-1].shape[0]))

        # 0 <= dm <= max_mass_factor m_link (in link units: 0 <= y_m <= m_max / m0), and
        # dI <= k_max^2 dm (radius of gyration about the link origin <= k_max)
        a = np.zeros((3 * nl, nx))
        b = np.zeros(3 * nl)
        for i in range(nl):
            a[3 * i, 4 * i] = -1.0
            a[3 * i + 1, 4 * i] = 1.0
            b[3 * i + 1] = self.m_max[i] / self.m0[i]
            a[3 * i + 2, 4 * i] = -(self.k_max[i] / self.l0[i]) ** 2
            a[3 * i + 2, 4 * i + 3] = 1.0
        extra = [(self.weights_vector(), bound)] if bound is not None else []
        for row, value in extra + list(caps):   # the objective's bound, then the caps
            a = np.vstack([a, row])
            b = np.append(b, value)
        add(clarabel.NonnegativeConeT, a, b)
        for rows, target in pins:
            if not rows.shape[0]:
                continue
            a = np.zeros((rows.shape[0], nx))
            a[:, :ny] = rows
            add(clarabel.ZeroConeT, a, target)
        dynamic = len(a_blocks)
        if self._static is None:
            self._add_cones(add)
            self._static = (sp.csc_matrix(np.vstack(a_blocks[dynamic:])),
                            np.concatenate(b_blocks[dynamic:]),
                            [blk.shape[0] for blk in a_blocks[dynamic:]])
        a_static, b_static, sizes = self._static
        a_all = sp.vstack([sp.csc_matrix(np.vstack(a_blocks[:dynamic])), a_static],
                          format='csc')
        b_all = np.concatenate(b_blocks[:dynamic] + [b_static])
        cones = cones[:dynamic] + [clarabel.SecondOrderConeT(k) for k in sizes]
        run = conic.run_solver(q, a_all, b_all, cones)
        if not np.all(np.isfinite(np.asarray(run.sol.x))):
            raise CounterweightError(f'solver: {run.why()} (counterweight problem); no '
                                     f'design{self.blame()}')
        x = np.array(run.sol.x)
        return certificate.Stage(x[:ny], float(q @ x), run)

    def box(self, level=None, q=None):
        """Return (lo, hi): the variables' bounds (link units), epigraphs capped by ``level``."""
        nx, ny, nl = self.nx, self.ny, self.nl
        lo, hi = np.zeros(nx), np.zeros(nx)
        used = None if q is None else \
            [k for k in range(len(self.norms)) if q[ny + nl + k] != 0.0]
        for i in range(nl):
            m_hi = self.m_max[i] / self.m0[i]
            h_hi = self.r_max[i] / self.l0[i] * m_hi
            i_hi = (self.k_max[i] / self.l0[i]) ** 2 * m_hi
            # the rim cuts y_I + a |y_h| <= b y_m (a >= 0, y_I >= 0) bound both
            margin = 1.0 + 8.0 * certificate.UNIT_ROUNDOFF
            for a, b in self._rim_cuts(i):
                i_hi = min(i_hi, b * m_hi * margin)
                if a > 0.0:
                    h_hi = min(h_hi, b / a * m_hi * margin)
            if used is not None and all(not np.any(self.norms[k][0][:, 4 * i + 3])
                                        for k in used):
                kappa = self.m0[i] / (self.c_disc * self.l0[i] ** 2)
                i_hi = min(i_hi, ((self.r_max[i] / self.l0[i]) ** 2 * m_hi
                                  + kappa * m_hi * m_hi) * (1.0 + 8.0 * certificate.UNIT_ROUNDOFF))
            lo[4 * i:4 * i + 4] = (0.0, -h_hi, -h_hi, 0.0)
            hi[4 * i:4 * i + 4] = (m_hi, h_hi, h_hi, i_hi)
            hi[ny + i] = i_hi
        weights = self.weights_vector()
        for k, (g, c) in enumerate(self.norms):
            it = ny + nl + k
            cap = certificate.norm_bound(g, c, lo[:ny], hi[:ny])
            if level is not None and weights[it] > 0.0:
                cap = min(cap, level / weights[it] * (1.0 + 4.0 * certificate.UNIT_ROUNDOFF))
            hi[it] = cap
        return lo, hi

    def lower_bound(self, stage, level):
        """Return the safe lower bound (:mod:`.certificate`) of a solved stage."""
        run = stage.run
        lo, hi = self.box(level, run.q if level is not None else None)
        return certificate.safe_lower_bound(run.q, run.a, run.b, run.cones, run.sol.z, lo, hi)

    def _rim_cuts(self, i):
        """Return the rim cuts of listed link i in link units, ``y_I + a |y_h| <= b y_m``."""
        if self.rho is None:
            return []
        l0 = self.l0[i]
        return [(c_h / l0, c_m / (l0 * l0)) for c_h, c_m in clearance_mod.rim_cuts(self.rho[i])]

    def anchor(self):
        """Return a strictly feasible point of the disc constraints (centred small discs)."""
        y = np.zeros(self.ny)
        for i in range(self.nl):
            g2 = min([(self.k_max[i] / self.l0[i]) ** 2] + [b for _, b in self._rim_cuts(i)])
            kappa = self.m0[i] / (self.c_disc * self.l0[i] ** 2)
            a = min(0.5 * self.m_max[i] / self.m0[i], 0.5 * g2 / kappa)
            y[4 * i] = a
            y[4 * i + 3] = 0.5 * (kappa * a * a + g2 * a)
        return y

    def repair(self, y):
        """Return ``y`` with each disc moved onto its constraints by the least local change."""
        y = np.array(y, dtype=float)
        shrink = 1.0 - 16.0 * certificate.UNIT_ROUNDOFF
        for i in range(self.nl):
            im = 4 * i
            ym = min(y[im], self.m_max[i] / self.m0[i] * shrink)
            if ym <= 0.0:
                continue
            y[im] = ym
            h = math.hypot(y[im + 1], y[im + 2])
            h_max = self.r_max[i] / self.l0[i] * ym * shrink
            if h > h_max:
                y[im + 1:im + 3] *= h_max / h
                h = math.hypot(y[im + 1], y[im + 2])
            kappa = self.m0[i] / (self.c_disc * self.l0[i] ** 2)
            g2 = (self.k_max[i] / self.l0[i]) ** 2
            room = ym * ym * (g2 - kappa * ym)   # the largest |h|^2 the gyration bound leaves
            if room > 0.0 and h * h > room * shrink:
                y[im + 1:im + 3] *= math.sqrt(room * shrink) / h * shrink
                h = math.hypot(y[im + 1], y[im + 2])
            cuts = self._rim_cuts(i)
            for a, b in cuts:   # the rim: h^2/ym + a h + kappa ym^2 - b ym <= 0 leaves h <= root
                c0 = kappa * ym * ym - b * ym
                disc = a * a - 4.0 * c0 / ym
                root = 0.5 * ym * (math.sqrt(disc) - a) if disc >= 0.0 else -1.0
                if 0.0 <= root < h:
                    y[im + 1:im + 3] *= root * shrink / h
                    h = math.hypot(y[im + 1], y[im + 2])
            i_lo = (h * h / ym + kappa * ym * ym) / shrink
            i_hi = min([g2 * ym] + [b * ym - a * h for a, b in cuts]) * shrink
            if i_lo <= i_hi:
                y[im + 3] = min(max(y[im + 3], i_lo), i_hi)
        return y

    def feasible(self, y, worst):
        """Return (y, pull): ``y`` repaired (:meth:`repair`), else moved towards :meth:`anchor`."""
        return redistribution.pull_inside(y, worst, lambda v: self.discs(v)[2], self.repair,
                                          self.anchor)

    def _add_cones(self, add):
        """Add the cones every stage shares: the discs' and the objective terms' epigraphs."""
        nx, ny, nl = self.nx, self.ny, self.nl
        for i in range(nl):
            im, ix, iy, ii, i_s = 4 * i, 4 * i + 1, 4 * i + 2, 4 * i + 3, ny + i
            # |dh| <= r_max dm  ->  |y_h| <= (r_max / l0) y_m
            a = np.zeros((3, nx))
            a[0, im] = -self.r_max[i] / self.l0[i]
            a[1, ix] = a[2, iy] = -1.0
            add(clarabel.SecondOrderConeT, a, np.zeros(3))
            # |dh|^2 <= dm (dI - s): ||(2 y_h, y_m - y_I + y_s)|| <= y_m + y_I - y_s
            a = np.zeros((4, nx))
            a[0, [im, ii, i_s]] = (-1.0, -1.0, 1.0)
            a[1, ix] = a[2, iy] = -2.0
            a[3, [im, ii, i_s]] = (-1.0, 1.0, -1.0)
            add(clarabel.SecondOrderConeT, a, np.zeros(4))
            # s >= dm^2 / c  ->  y_m^2 <= y_s / kappa, kappa = m0 / (c l0^2):
            # ||(2 y_m, y_s - 1/kappa)|| <= y_s + 1/kappa
            inv_kappa = self.c_disc * self.l0[i] ** 2 / self.m0[i]
            a = np.zeros((3, nx))
            a[0, i_s] = a[2, i_s] = -1.0
            a[1, im] = -2.0
            add(clarabel.SecondOrderConeT, a, [inv_kappa, 0.0, -inv_kappa])
            if self.rho is not None:   # the disc inside rho: dI + c_h |dh| <= c_m dm
                l0 = self.l0[i]
                for c_h, c_m in clearance_mod.rim_cuts(self.rho[i]):
                    a = np.zeros((3, nx))
                    a[0, [im, ii]] = (-c_m / (l0 * l0), 1.0)
                    a[1, ix] = a[2, iy] = -c_h / l0
                    add(clarabel.SecondOrderConeT, a, np.zeros(3))
        for k, (g, c) in enumerate(self.norms):
            a = np.zeros((1 + g.shape[0], nx))
            a[0, ny + nl + k] = -1.0
            a[1:, :ny] = -g
            add(clarabel.SecondOrderConeT, a, np.concatenate([[0.0], c]))

    def discs(self, y):
        """Return (designs, omitted links, worst constraint violation in units of the link)."""
        u, opt = self.units, self.opt
        ms, ls = u.mass_kg, u.length_m
        d = (y * self.dsc).reshape(-1, 4)
        designs, omitted, worst = [], [], 0.0
        rho = opt.density_kg_m3
        for i, name in enumerate(opt.links):
            own = self.scene.link(name).own_mass_kg
            dm = d[i, 0] * ms
            dh = complex(d[i, 1], d[i, 2]) * ms * ls
            d_i = d[i, 3] * ms * ls * ls
            r_max = self.r_max[i] * ls
            if dm <= MIN_MASS_REL * own:   # built as no disc: feasible
                omitted.append(name)
                continue
            r = dh / dm
            i_min = dm * dm / (2.0 * math.pi * rho * opt.max_thickness_m)
            i_c = d_i - abs(dh) ** 2 / dm
            k_max = self.k_max[i] * ls
            i_c = i_min if self.inertia_free[i] else max(i_c, i_min)   # t <= t_max
            # violations of the disc as built, in units of the link (own mass, reach)
            i_ref = own * r_max ** 2
            worst = max(worst, (abs(r) - r_max) * dm / (own * r_max),
                        (i_c + dm * abs(r) ** 2 - k_max ** 2 * dm) / i_ref,
                        (dm - self.m_max[i] * ms) / own)
            radius = math.sqrt(2.0 * i_c / dm)
            if self.rho is not None:   # the rim bound, in units of the largest centre radius
                worst = max(worst, (abs(r) + radius - self.rho[i] * ls) / r_max)
            thickness = dm * dm / (2.0 * math.pi * rho * i_c)
            designs.append(CounterweightDesign(
                link=name, mass_kg=float(dm), centre_m=(float(r.real), float(r.imag)),
                centre_radius_m=float(abs(r)),
                centre_angle_deg=math.degrees(math.atan2(r.imag, r.real)) % 360.0,
                radius_m=float(radius), thickness_m=float(thickness), density_kg_m3=rho,
                inertia_com_kg_m2=float(0.5 * dm * radius ** 2),
                max_centre_radius_m=float(r_max), max_mass_kg=float(self.m_max[i] * ms),
                plane_m=float(self.plane.get(name, 0.0))))
        return designs, omitted, float(max(worst, 0.0))
