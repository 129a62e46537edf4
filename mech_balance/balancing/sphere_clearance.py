"""
Collision-free sphere counterweights of spatial rigs: the convex optimum, then a local search.

``z - z_lb`` is the price of clearance (docs/build.md, "Spatial rigs: sphere counterweights").
"""

from dataclasses import dataclass, replace
import math

from mech_balance.analysis import spatial_clearance
from mech_balance.balancing import spatial
from mech_balance.balancing.clearance_design import check_margin, ClearanceReport, \
    least_pair, NoClearDesign
from mech_balance.balancing.spatial import model as spatial_model, result as spatial_result, \
    spheres as sphere_clusters
from mech_balance.balancing.spatial.program import SIGMA_ENTRIES
from mech_balance.conventions import cycle_angles
from mech_balance.core import regressor
import numpy as np
from scipy import optimize

SIDE = 'spheres'
"""The ``side`` of a spatial report (the spheres have no layers)."""
STARTS = 4
"""The local search starts from the convex optimum and from this many more (module text)."""
START_SHRINK = (0.5, 0.25)
"""Starts with every sphere's mass scaled by these factors (smaller spheres clear sooner)."""
CLEAR_ROWS = 12
"""The local search constrains this many of the least pairs' sampled clearances."""
SEARCH_CUSHION = 0.05
"""The search asks the sampled clearance for margin x (1 + this), then x (1 + 2 this)."""
SEARCH_MAX_ITER = 300
"""Iteration limit of one local search (SLSQP)."""
SEARCH_ANGLES = 120
"""Crank angles the local search samples the clearance at (every 3 deg)."""
VERIFY_ANGLES = 3600
"""Crank angles of the final check of a design found by the search."""
BOUND_ACTIVE_REL = 1e-4
"""A bound is reported active when met within this fraction."""
MIN_MASS_SHARE = 1e-6
"""A sphere's mass stays above this share of its body's largest counterweight mass."""


@dataclass
class NoSphereDesign:
    """The answer when no sphere design is clear: the report (``to_dict``) and why."""

    report: dict
    clearance_design: ClearanceReport

    def to_dict(self):
        """Return the report of the convex optimum with the reason (``clearance_design``)."""
        return self.report


def _theta_jac(mass_kg, centre_m, spread_kg_m2):
    """Return d theta / d (centre, mass) of one hollow sphere (spread ~ mass^(5/3)), (10, 4)."""
    c = centre_m
    out = np.zeros((10, 4))
    for j in range(3):
        e = np.zeros(3)
        e[j] = 1.0
        out[1 + j, j] = mass_kg
        d_io = mass_kg * (2.0 * c[j] * np.eye(3) - np.outer(e, c) - np.outer(c, e))
        out[4:, j] = [d_io[a, b] for a, b in SIGMA_ENTRIES]
    d_io = 2.0 * (5.0 / 3.0) * spread_kg_m2 / mass_kg * np.eye(3) + \
        (np.dot(c, c) * np.eye(3) - np.outer(c, c))
    out[0, 3] = 1.0
    out[1:4, 3] = c
    out[4:, 3] = [d_io[a, b] for a, b in SIGMA_ENTRIES]
    return out


def _hollow(mass_kg, ratio, density_kg_m3):
    """Return (outer, inner, spread) of a hollow sphere of inner/outer radius ``ratio``."""
    shell = 1.0 - ratio ** 3
    outer = (3.0 * mass_kg / (4.0 * math.pi * density_kg_m3 * shell)) ** (1.0 / 3.0)
    spread = density_kg_m3 * 4.0 / 15.0 * math.pi * outer ** 5 * (1.0 - ratio ** 5)
    return outer, ratio * outer, spread


class _Search:
    """The spheres of a convex optimum, their clearance over the cycle and the objective."""

    def __init__(self, rig, result, margin_m):
        self.rig, self.result, self.margin = rig, result, margin_m
        opts = result.options
        self.density = float(opts['density_kg_m3'])
        self.model = spatial.parameter_model(rig)
        self.units = spatial_model.units_of(rig, self.model)
        self.maps = spatial_model.maps_of(rig, result.samples)
        self.w = tuple(result.weights)
        names = [b.name for b in self.model.bodies]
        self.spheres = [(body, dict(s)) for body, cluster in opts['counterweights'].items()
                        for s in cluster]
        self.body_index = {n: names.index(n) for n in opts['counterweights']}
        self.ratio = [s['inner_radius_m'] / s['outer_radius_m'] if s['outer_radius_m'] > 0.0
                      else 0.0 for _, s in self.spheres]
        self.mass_max = {n: float(opts['max_mass_factor']) * float(self.model.theta[10 * k])
                         for n, k in self.body_index.items()}
        self.rms_max = {n: float(opts['max_radius_factor']) * self.model.bodies[k].reach_m
                        for n, k in self.body_index.items()}
        self.poses = None
        self.set_angles(cycle_angles(SEARCH_ANGLES))

    def set_angles(self, psi):
        """Pose every body and solid at the crank angles ``psi`` (the clearance's samples)."""
        poses = self.rig.at(psi).bodies
        self.origin, self.rot = poses.origin_m, poses.rotation
        self.index = {n: k for k, n in enumerate(poses.names)}
        solids = spatial_clearance.solids(self.rig)
        k = np.array([self.index[body] for _, body, _, _, _ in solids])
        a = np.array([a for _, _, a, _, _ in solids])
        b = np.array([b for _, _, _, b, _ in solids])
        # (n, S, 3) world ends of every solid's segment, its radius and its body
        self.seg_a = self.origin[:, k] + np.einsum('nsij,sj->nsi', self.rot[:, k], a)
        self.seg_b = self.origin[:, k] + np.einsum('nsij,sj->nsi', self.rot[:, k], b)
        self.seg_r = np.array([r for _, _, _, _, r in solids])
        self.seg_body = np.array([body for _, body, _, _, _ in solids])
        d = self.seg_b - self.seg_a
        self.seg_d, self.seg_den = d, np.maximum(np.sum(d * d, axis=-1), 1e-300)
        bodies = [body for body, _ in self.spheres]
        self.sphere_k = np.array([self.index[body] for body in bodies])
        # the pairs that can meet: a sphere and a solid of another body, two spheres of two
        self.other = np.array([[body != sb for sb in self.seg_body] for body in bodies])
        self.apart = np.array([[bi != bj and j > i for j, bj in enumerate(bodies)]
                               for i, bi in enumerate(bodies)])

    def pack(self, spheres):
        """Return the variables of ``[(body, sphere)]``: centre (3) and mass per sphere."""
        return np.concatenate([[*s['centre_m'], s['mass_kg']] for _, s in spheres])

    def scale(self):
        """Return the variables' scales: each body's RMS radius bound and mass bound."""
        return np.concatenate([[self.rms_max[b]] * 3 + [self.mass_max[b]]
                               for b, _ in self.spheres])

    def unpack(self, x):
        """Return ``[(body, sphere dict)]`` of the variables (each sphere hollow, its ratio)."""
        out = []
        for i, (body, _) in enumerate(self.spheres):
            c, mass = x[4 * i:4 * i + 3], max(float(x[4 * i + 3]), 1e-300)
            outer, inner, spread = _hollow(mass, self.ratio[i], self.density)
            out.append((body, {'mass_kg': mass, 'centre_m': [float(v) for v in c],
                               'spread_kg_m2': float(spread), 'outer_radius_m': float(outer),
                               'inner_radius_m': float(inner)}))
        return out

    def clusters(self, spheres):
        """Return ``{body: [sphere, ...]}`` (the report's and the check's form)."""
        out = {}
        for body, s in spheres:
            out.setdefault(body, []).append(s)
        return out

    def theta(self, spheres):
        """Return the parameters (10 nb,) of the rig with the spheres added."""
        t = self.model.theta.copy()
        for body, s in spheres:
            k = self.body_index[body]
            t[10 * k:10 * k + 10] += regressor.parameters(
                s['mass_kg'], s['centre_m'], 2.0 * s['spread_kg_m2'] * np.eye(3))
        return t

    def z(self, spheres):
        """Return the objective of the linear maps (normalized, as the certificate's)."""
        t = self.theta(spheres)
        return self.w[0] * np.linalg.norm(self.maps.force @ t) / self.units.force_N + \
            self.w[1] * np.linalg.norm(self.maps.moment @ t) / self.units.moment_Nm

    def z_grad(self, spheres):
        """Return the objective and its derivative by the variables (centre, mass each)."""
        t = self.theta(spheres)
        f, m = self.maps.force @ t, self.maps.moment @ t
        nf, nm = np.linalg.norm(f), np.linalg.norm(m)
        uf, um = self.units.force_N, self.units.moment_Nm
        z = self.w[0] * nf / uf + self.w[1] * nm / um
        dz = np.zeros_like(t)
        if self.w[0] and nf > 0.0:
            dz += self.w[0] / (uf * nf) * (self.maps.force.T @ f)
        if self.w[1] and nm > 0.0:
            dz += self.w[1] / (um * nm) * (self.maps.moment.T @ m)
        grad = []
        for body, s in spheres:
            k = self.body_index[body]
            grad.append(dz[10 * k:10 * k + 10] @ _theta_jac(
                s['mass_kg'], np.asarray(s['centre_m']), s['spread_kg_m2']))
        return z, np.concatenate(grad)

    def bounds(self, spheres):
        """Return the convex program's bounds as values >= 0 (scaled), and their names."""
        out, names = [], []
        for body in self.body_index:
            mine = [s for b, s in spheres if b == body]
            dm = sum(s['mass_kg'] for s in mine)
            trace = sum(s['mass_kg'] * float(np.dot(s['centre_m'], s['centre_m']))
                        + 3.0 * s['spread_kg_m2'] for s in mine)
            out += [(self.mass_max[body] - dm) / self.mass_max[body],
                    (dm * self.rms_max[body] ** 2 - trace)
                    / (self.mass_max[body] * self.rms_max[body] ** 2)]
            names += [f'{body}: added mass <= {self.mass_max[body]:.4g} kg',
                      f'{body}: RMS distance of the added mass <= {self.rms_max[body]:.4g} m']
        return np.array(out), names

    def gaps(self, spheres, jacobian=False):
        """Return the least sampled clearance (m) of each sphere-body pair (and its jacobian)."""
        local = np.array([s['centre_m'] for _, s in spheres])           # (P, 3)
        radii = np.array([s['outer_radius_m'] for _, s in spheres])
        mass = np.array([s['mass_kg'] for _, s in spheres])
        k = self.sphere_k
        rot = self.rot[:, k]                                              # (n, P, 3, 3)
        centres = self.origin[:, k] + np.einsum('npij,pj->npi', rot, local)
        rel = centres[:, :, None, :] - self.seg_a[:, None]                # (n, P, S, 3)
        t = np.clip(np.sum(rel * self.seg_d[:, None], axis=-1) / self.seg_den[:, None],
                    0.0, 1.0)
        diff = rel - t[..., None] * self.seg_d[:, None]
        dist = np.linalg.norm(diff, axis=-1)
        at = dist.argmin(axis=0)                                          # (P, S)
        solid = np.take_along_axis(dist, at[None], axis=0)[0] - radii[:, None] - \
            self.seg_r[None, :]
        between = centres[:, :, None] - centres[:, None]                  # (n, P, P, 3)
        pdist = np.linalg.norm(between, axis=-1)
        pat = pdist.argmin(axis=0)
        pair = np.take_along_axis(pdist, pat[None], axis=0)[0] - radii[:, None] - \
            radii[None, :]
        values = np.concatenate([solid[self.other], pair[self.apart]])
        if not jacobian:
            return values
        n_p = len(spheres)
        drad = radii / (3.0 * mass)                     # d outer radius / d mass
        idx = np.arange(n_p)
        # sphere to solid: d/dc = R(t*)^T u, d/dmu = -dR/dmu
        v = np.take_along_axis(diff, at[None, ..., None], axis=0)[0]     # (P, S, 3)
        u = v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-300)
        grad_c = np.einsum('psji,psj->psi', rot[at, idx[:, None]], u)
        ii, jj = np.nonzero(self.other)
        jac_s = np.zeros((ii.size, n_p, 4))
        jac_s[np.arange(ii.size), ii, :3] = grad_c[ii, jj]
        jac_s[np.arange(ii.size), ii, 3] = -drad[ii]
        # sphere to sphere: +u for i, -u for j
        ai, aj = np.nonzero(self.apart)
        kt = pat[ai, aj]
        v = between[kt, ai, aj]
        u = v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-300)
        jac_p = np.zeros((ai.size, n_p, 4))
        rows_p = np.arange(ai.size)
        jac_p[rows_p, ai, :3] = np.einsum('kji,kj->ki', rot[kt, ai], u)
        jac_p[rows_p, aj, :3] = -np.einsum('kji,kj->ki', rot[kt, aj], u)
        jac_p[rows_p, ai, 3] = -drad[ai]
        jac_p[rows_p, aj, 3] = -drad[aj]
        return values, np.concatenate([jac_s.reshape(-1, 4 * n_p),
                                       jac_p.reshape(-1, 4 * n_p)])

    def local(self, start, cushion):
        """Return (spheres, least sampled clearance, active bounds) of one SLSQP run."""
        scale = self.scale()
        ref = max(self.rms_max.values())
        mass_lo = [MIN_MASS_SHARE * self.mass_max[b] / s for (b, _), s in
                   zip(self.spheres, scale[3::4])]

        def spheres_of(u):
            return self.unpack(u * scale)

        z0 = max(self.z(self.unpack(start)), 1e-300)

        def rows(u):
            g, jac = self.gaps(spheres_of(u), True)
            g = np.concatenate([g, np.full(CLEAR_ROWS, ref)])
            jac = np.vstack([jac, np.zeros((CLEAR_ROWS, jac.shape[1]))])
            keep = np.argsort(g, kind='stable')[:CLEAR_ROWS]
            return g[keep], jac[keep]

        def clear(u):
            return (rows(u)[0] - self.margin * (1.0 + cushion)) / ref

        def clear_jac(u):
            return rows(u)[1] * scale[None, :] / ref

        bounds = []
        for i in range(len(self.spheres)):
            bounds += [(-2.0, 2.0)] * 3 + [(mass_lo[i], 1.0)]
        constraints = [{'type': 'ineq', 'fun': lambda u: self.bounds(spheres_of(u))[0]},
                       {'type': 'ineq', 'fun': clear, 'jac': clear_jac}]

        def objective(u):
            z, grad = self.z_grad(spheres_of(u))
            return z / z0, grad * scale / z0

        res = optimize.minimize(
            objective, start / scale, method='SLSQP', jac=True,
            bounds=bounds, constraints=constraints,
            options={'maxiter': SEARCH_MAX_ITER, 'ftol': 1e-10})
        found = spheres_of(res.x)
        values, names = self.bounds(found)
        active = [n for v, n in zip(values, names) if v <= BOUND_ACTIVE_REL]
        gaps = self.gaps(found)
        return found, float(gaps.min()) if gaps.size else math.inf, active

    def starts(self):
        """Yield the starts: the convex optimum, its spheres lighter, and pushed out."""
        x0 = self.pack(self.spheres)
        yield x0
        for share in START_SHRINK[:STARTS]:
            x = x0.copy()
            x[3::4] *= share
            yield x
        # each sphere pushed along its body's first axis normal to its centre
        x = x0.copy()
        for i, (body, _) in enumerate(self.spheres):
            x[4 * i + 2] += (1.0 if i % 2 == 0 else -1.0) * 0.5 * self.rms_max[body]
        yield x


def _evaluate(rig, result, search, spheres):
    """Return a :class:`~.spatial.SpatialResult` of the moved spheres (the core's figures)."""
    clusters = search.clusters(spheres)
    added = {b: sphere_clusters.cluster_theta(cl) for b, cl in clusters.items()}
    balanced = search.model.add(added, clusters)
    theta = search.theta(spheres)
    data = rig.with_scene(balanced).at(search.maps.angles)
    base = rig.at(search.maps.angles)
    units = search.units
    f, n = spatial_result.normalized_rms(data, units)
    w = search.w
    objective = dict(result.objective, z=w[0] * f + w[1] * n, shaking_force_rms=f,
                     shaking_moment_rms=n, z_convex=result.objective['z'])
    options = dict(result.options, **sphere_clusters.cluster_entries(clusters))
    return replace(result, balanced_scene=balanced, objective=objective, options=options,
                   bodies=spatial_result.body_rows(search.model, theta), theta=theta,
                   table=spatial_result.before_after(rig, balanced, result.samples, units,
                                                     (base, data)))


def design(rig, result, samples, margin_m):
    """
    Return ``(result, report entries)``: the convex sphere optimum made collision-free.

    ``margin_m`` None: the check only.  Raises :class:`NoClearDesign` when no design is clear.
    """
    margin = check_margin(margin_m)
    cert = result.certificate
    spheres = result.options['counterweights']
    p = result.samples if samples is None else samples
    clear = spatial_clearance.check(rig, spheres, p, margin or 0.0)
    least = clear.least_clearance_m
    z_convex = result.objective['z']
    report = ClearanceReport('collision-free', margin or 0.0, SIDE, z_convex, z_convex,
                             cert.lower_bound, least, least_pair(clear))
    if margin is None:
        report.status = 'off'
    if margin is None or least >= margin or not spheres:
        return result, _entries(clear, report)
    search = _Search(rig, result, margin)
    clear_ones, failed = [], []
    for cushion in (SEARCH_CUSHION, 2.0 * SEARCH_CUSHION):
        for start in search.starts():
            report.arrangements_tried += 1
            found, value, active = search.local(start, cushion)
            if value >= margin:   # sampled: checked again at VERIFY_ANGLES
                value = spatial_clearance.check(rig, search.clusters(found), VERIFY_ANGLES,
                                                margin).least_clearance_m
            if value >= margin:   # the first clear design (the convex optimum's start first)
                clear_ones.append((search.z(found), found, value))
                break
            failed.append((value, found, active))
        if clear_ones:
            break
    if clear_ones:
        _, found, dense = min(clear_ones, key=lambda a: a[0])
        moved = _evaluate(rig, result, search, found)
        check = spatial_clearance.check(rig, moved.options['counterweights'], p, margin)
        report.objective = moved.objective['z']
        report.least_clearance_m = min(check.least_clearance_m, dense)
        report.least_pair = least_pair(check)
        report.moved_in_plane = True
        return moved, _entries(check, report)
    # none clear: the best attempt (the largest least clearance reached) says why
    value, found, active = max(failed, key=lambda a: a[0])
    tried = spatial_clearance.check(rig, search.clusters(found), p, margin)
    report.status = 'none'
    report.objective = search.z(found)
    report.least_clearance_m = min(value, tried.least_clearance_m)
    report.least_pair = least_pair(tried)
    report.moved_in_plane = True
    report.binding = active or [f'the clearance over the cycle (a local optimum from '
                                f'{report.arrangements_tried} starts)']
    report.best_attempt = [dict(s, body=b) for b, s in found]
    out = dict(result.to_dict(), **_entries(clear, report))
    raise NoClearDesign('; '.join(report.lines()) + f' ({len(clear.collisions)} colliding '
                        'pairs at the convex optimum, clearance_margin_m None gives the '
                        'optimum as is)', NoSphereDesign(out, report))


def _entries(clear, report):
    return {'clearance': clear.to_dict(), 'warnings': clear.warnings(),
            'clearance_design': report.to_dict()}
