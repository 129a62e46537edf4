"""
Certified optimal add-only counterweights of a spatial rig: clusters of hollow spheres.

The convex set is exactly what they realize (docs/balancing.md, "Spatial rigs").
"""

import math
import time

from mech_balance.balancing.certificate import SVEC
from mech_balance.balancing.defaults import DEFAULT_DENSITY_KG_M3, DEFAULT_MAX_MASS_FACTOR, \
    DEFAULT_MAX_RADIUS_FACTOR, DEFAULT_WEIGHTS
from mech_balance.balancing.spatial.model import check_samples, check_weights, maps_of, \
    parameter_model, SpatialBalanceError, units_of
from mech_balance.balancing.spatial.program import ConeProgram, SIGMA_ENTRIES, \
    SIGMA_TO_INERTIA
from mech_balance.balancing.spatial.result import best_certified, check_run, finish
from mech_balance.core import regressor
import numpy as np

CLUSTER_SPREAD_REL = 1e-6
"""Eigenvalues of a counterweight's spread below this x dm reach^2 get no sphere pair."""


def counterweights(rig, links, weights=DEFAULT_WEIGHTS, samples=None, *,
                   density_kg_m3=DEFAULT_DENSITY_KG_M3, max_mass_factor=DEFAULT_MAX_MASS_FACTOR,
                   max_radius_factor=DEFAULT_MAX_RADIUS_FACTOR):
    """Return the certified optimal add-only spheres on the listed bodies (a SpatialResult)."""
    t_start = time.perf_counter()
    w = check_weights(weights)
    model = parameter_model(rig)
    samples = check_samples(samples, rig)
    if isinstance(links, str):
        links = [part for part in links.split(',') if part]
    if not links:
        raise SpatialBalanceError('links: got none, expected at least one body for a '
                                  'counterweight')
    idx = []
    for name in links:
        k = model.index(name, 'links')
        if model.bodies[k].counterweights is not True:
            raise SpatialBalanceError(f'links: got {name!r}: {model.bodies[k].counterweights}')
        if k not in idx:
            idx.append(k)
    for value, option in ((density_kg_m3, 'density_kg_m3'),
                          (max_mass_factor, 'max_mass_factor'),
                          (max_radius_factor, 'max_radius_factor')):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or \
                not (math.isfinite(value) and value > 0.0):
            raise SpatialBalanceError(f'{option}: got {value!r}, expected a finite number > 0')
    units = units_of(rig, model)
    maps = maps_of(rig, samples)
    k_sphere = (3.0 / (4.0 * math.pi * density_kg_m3)) ** (2.0 / 3.0) / 5.0
    prog = _counterweight_program(model, maps, units, idx, w, max_mass_factor,
                                  max_radius_factor, k_sphere)
    run = prog.solve()
    check_run(run, rig, units)

    def design(run):
        x = np.asarray(run.sol.x)
        added, spheres, violation = {}, {}, 0.0
        theta = model.theta.copy()
        for j, k in enumerate(idx):
            body = model.bodies[k]
            dm, dh, sigma, s = prog.counterweight(x, j)
            hi = max_mass_factor * model.theta[10 * k]
            viol, (dm, dh, sigma, s) = _repaired_counterweight(
                dm, dh, sigma, s, k_sphere, hi, (max_radius_factor * body.reach_m) ** 2)
            violation = max(violation, viol / max(model.theta[10 * k], 1e-300))
            if dm <= MIN_COUNTERWEIGHT_REL * model.theta[10 * k]:
                continue
            cluster = sphere_cluster(dm, dh, sigma, s, density_kg_m3, body.reach_m)
            spheres[body.name] = cluster
            added[body.name] = cluster_theta(cluster)
            theta[10 * k:10 * k + 10] += added[body.name]
        extra = {'links': [model.bodies[k].name for k in idx], 'density_kg_m3': density_kg_m3,
                 'max_mass_factor': max_mass_factor, 'max_radius_factor': max_radius_factor,
                 **cluster_entries(spheres)}
        return finish(rig, model, units, maps, prog, run, theta, model.add(added, spheres), w,
                      samples, violation, 0.0, t_start,
                      'counterweights (add-only spheres, SOCP+SDP)', extra)
    return best_certified(prog, run, design)


MIN_COUNTERWEIGHT_REL = 1e-9
"""A counterweight lighter than this fraction of its body's mass is none (round-off)."""


def _counterweight_program(model, maps, units, idx, w, max_mass_factor, max_radius_factor,
                           k_sphere):
    """Return the :class:`~.program.ConeProgram` of the counterweights on the bodies ``idx``."""
    # variables per counterweight (11): dm, dh (3), Sigma (6), s; in units of m0 and r0
    nvar = 11 * len(idx)
    nb = len(model.bodies)
    basis = np.zeros((10 * nb, nvar))
    for j, k in enumerate(idx):
        m0, r0 = float(model.theta[10 * k]), model.bodies[k].reach_m
        block = np.zeros((10, 11))
        block[0, 0] = m0
        block[1:4, 1:4] = m0 * r0 * np.eye(3)
        block[4:10, 4:10] = m0 * r0 * r0 * SIGMA_TO_INERTIA
        basis[10 * k:10 * k + 10, 11 * j:11 * j + 11] = block
    prog = ConeProgram(basis, model.theta.copy(), units)
    prog.epigraphs(maps, w)
    fr2 = max_radius_factor ** 2
    hi = max_mass_factor
    for j, k in enumerate(idx):
        m0, r0 = float(model.theta[10 * k]), model.bodies[k].reach_m
        c = 11 * j
        mass = np.zeros((2, prog.nx))
        mass[:, c] = (-1.0, 1.0)
        prog.add('nonneg', mass, [0.0, hi])
        lin = np.zeros((10, prog.nx))
        for row, (a, b) in enumerate(SVEC):
            f = 1.0 if a == b else math.sqrt(2.0)
            if b < 3:
                lin[row, c + 4 + SIGMA_ENTRIES.index((a, b))] = f
                if a == b:
                    lin[row, c + 10] = -1.0
            elif a < 3:
                lin[row, c + 1 + a] = f
            else:
                lin[row, c] = 1.0
        prog.add('psd', -lin, np.zeros(10))
        ext = np.zeros(prog.nx)
        ext[[c + 4, c + 6, c + 9]] = 1.0            # tr(Sigma) <= dm (f r0)^2
        ext[c] = -fr2
        prog.add('nonneg', [ext], [0.0])
        # s >= k dm^(5/3)  <=>  (s / u, 1, dm) in K_pow(3/5): (s / u)^(3/5) >= |dm|, u the
        # spread of a solid sphere of mass m0 (units m0 r0^2)
        spread_unit = k_sphere * m0 ** (5.0 / 3.0) / (m0 * r0 * r0)
        pw = np.zeros((3, prog.nx))
        pw[0, c + 10] = -1.0 / spread_unit
        pw[2, c] = -1.0
        prog.add('pow', pw, [0.0, 1.0, 0.0])
        # the box every feasible point lies in: |dh_i| <= dm f r0,
        # |Sigma_ij| <= tr Sigma <= dm (f r0)^2, s <= tr Sigma / 3
        prog.box_lo[c:c + 11] = [0.0] + [-hi * max_radius_factor] * 3 + [-hi * fr2] * 6 + [0.0]
        prog.box_hi[c:c + 11] = [hi] + [hi * max_radius_factor] * 3 + [hi * fr2] * 6 \
            + [hi * fr2 / 3.0]
        prog.cw.append((c, m0, r0))
    return prog


def _repaired_counterweight(dm, dh, sigma, s, k_sphere, mass_hi, radius2):
    """Return (worst violation in kg-units, repaired (dm, dh, Sigma, s)) of a counterweight."""
    viol = max(-dm, dm - mass_hi, 0.0)
    dm = min(max(dm, 0.0), mass_hi)
    if dm <= 0.0:
        return viol, (0.0, np.zeros(3), np.zeros((3, 3)), 0.0)
    s_min = k_sphere * dm ** (5.0 / 3.0)
    viol = max(viol, (s_min - s) / radius2)
    viol = max(viol, (np.trace(sigma) - dm * radius2) / radius2)
    s_new = max(s, s_min * (1.0 + 1e-12))
    sigma = sigma + (s_new - s) * np.eye(3) if s_new > s else sigma
    spread = sigma - s_new * np.eye(3) - np.outer(dh, dh) / dm
    low = float(np.linalg.eigvalsh(spread)[0])
    viol = max(viol, -low / radius2)
    if low < 0.0:
        sigma = sigma + (-low) * (1.0 + 1e-9) * np.eye(3)
    return viol, (dm, dh, sigma, s_new)


def hollow_sphere(mass_kg, spread_kg_m2, density_kg_m3):
    """Return (outer, inner) radii, m, of a hollow sphere of the mass and spread int(x^2 dm)."""
    from scipy.optimize import brentq
    a = 3.0 * mass_kg / (4.0 * math.pi * density_kg_m3)
    b = 15.0 * spread_kg_m2 / (4.0 * math.pi * density_kg_m3)
    if b <= a ** (5.0 / 3.0):
        return a ** (1.0 / 3.0), 0.0

    def excess(r):
        return (a + r ** 3) ** (5.0 / 3.0) - r ** 5 - b
    hi = max(b ** 0.2, a ** (1.0 / 3.0))
    while excess(hi) < 0.0:
        hi *= 2.0
    r = brentq(excess, 0.0, hi, xtol=1e-15 * hi, rtol=1e-15, maxiter=200)
    return (a + r ** 3) ** (1.0 / 3.0), r


def sphere_cluster(dm, dh, sigma, s, density_kg_m3, reach_m):
    """
    Return the spheres realizing a counterweight (dm, dh, Sigma about the origin, spread s).

    Each entry: mass_kg, centre_m (body axes), spread_kg_m2, outer_radius_m, inner_radius_m.
    """
    c = np.asarray(dh, dtype=float) / dm
    spread = np.asarray(sigma, dtype=float) - s * np.eye(3) - dm * np.outer(c, c)
    vals, vecs = np.linalg.eigh(0.5 * (spread + spread.T))
    keep = vals > CLUSTER_SPREAD_REL * dm * reach_m ** 2
    r = int(np.sum(keep))
    points = [(c, dm)] if r == 0 else []
    for val, vec in zip(vals[keep], vecs.T[keep]):
        off = math.sqrt(r * val / dm) * vec
        points += [(c + off, dm / (2 * r)), (c - off, dm / (2 * r))]
    out = []
    for p, mu in points:
        spread_i = s * mu / dm
        outer, inner = hollow_sphere(mu, spread_i, density_kg_m3)
        out.append({'mass_kg': float(mu), 'centre_m': [float(x) for x in p],
                    'spread_kg_m2': float(spread_i), 'outer_radius_m': float(outer),
                    'inner_radius_m': float(inner)})
    return out


def cluster_overlap_m(cluster):
    """Return the largest overlap of two spheres, m: sum of outer radii - distance (<= 0: none)."""
    worst = -math.inf
    for i, a in enumerate(cluster):
        for b in cluster[i + 1:]:
            gap = np.linalg.norm(np.subtract(a['centre_m'], b['centre_m']))
            worst = max(worst, a['outer_radius_m'] + b['outer_radius_m'] - float(gap))
    return float(worst) if math.isfinite(worst) else 0.0


def cluster_entries(clusters):
    """Return the report's ``counterweights``, ``added_mass_kg``, ``sphere_overlap_m``."""
    return {'counterweights': clusters,
            'added_mass_kg': {n: float(sum(c['mass_kg'] for c in cl))
                              for n, cl in clusters.items()},
            'sphere_overlap_m': {n: cluster_overlap_m(cl) for n, cl in clusters.items()}}


def cluster_theta(cluster):
    """Return theta (10,) of a list of spheres (their inertia 2 x spread about the centre)."""
    return sum(regressor.parameters(c['mass_kg'], c['centre_m'],
                                    2.0 * c['spread_kg_m2'] * np.eye(3)) for c in cluster)


__all__ = ['cluster_entries', 'cluster_overlap_m', 'cluster_theta', 'counterweights',
           'hollow_sphere', 'MIN_COUNTERWEIGHT_REL', 'sphere_cluster']
