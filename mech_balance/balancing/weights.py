"""
Balancing weights (seed 002): force balance, then the least RMS shaking moment.

The method ``weights`` for a spatial rig whose scene lists ``balancing_weights`` (the RGGR);
docs/balancing.md, "Hedaya: balancing weights".
"""

from dataclasses import dataclass, replace
import itertools
import math
import time

from mech_balance.conventions import rms
from mech_balance.core import regressor
import numpy as np

FORCE_BALANCED_REL = 1e-9
"""The weights' force balance must leave at most this fraction of the RMS shaking force."""
CYLINDER_INERTIA_FACTOR = 1.5
"""A solid cylinder of radius r about one of its generators: m r^2 / 2 + m r^2 (eq. 14)."""
METRIC_KEYS = ('shaking_force_rms', 'shaking_force_max', 'shaking_moment_rms',
               'shaking_moment_max', 'driving_torque_rms', 'driving_torque_max')
"""Keys of one row of the report's table (units in the report's ``units``)."""
ROWS = ('unbalanced', 'force-balanced', 'optimized')
"""The report's rows: the scene, the force balance (products zero), the optimum."""


class WeightsError(ValueError):
    """The scene's balancing weights cannot balance its rig."""


@dataclass(frozen=True)
class Pivot:
    """A weighted link: its body index, pivot point and axes (u, v, w) in its own axes."""

    spec: object            # schema.spatial.WeightSpec
    index: int
    point_m: np.ndarray     # (3,) the pivot on the link, link axes
    axes: np.ndarray        # (3, 3) columns u, v, w in link axes (w the joint's axis)


def _unit(v, where):
    v = np.asarray(v, dtype=float)
    n = float(np.linalg.norm(v))
    if not n > 0.0:
        raise WeightsError(f'{where}: got a zero axis, expected a direction')
    return v / n


def pivots_of(rig):
    """Return the :class:`Pivot` of every link the scene's ``balancing_weights`` name."""
    sc = rig.scene
    specs = getattr(sc, 'balancing_weights', ())
    if not specs:
        raise WeightsError(f'balancing_weights: scene {sc.name!r} lists none, expected '
                           '{LINK: {mass_kg | density_length_kg_m2}} for the method weights')
    names = [b.name for b in rig.drawing.bodies]
    joints = {j.name: j for j in sc.joints}
    out = []
    for spec in specs:
        jt, link = joints[spec.joint], sc.link(spec.link)
        on_b = jt.link_b == spec.link
        point = np.asarray(link.points[jt.point_b if on_b else jt.point_a], dtype=float)
        axis = jt.axis_b if on_b and jt.axis_b is not None else jt.axis
        w = _unit(axis, f'joints.{jt.name}.axis')
        # u towards the link's farthest other joint point (seed 002: towards the pin)
        others = [np.asarray(p, dtype=float) - point for p in link.points.values()]
        radial = [r - (r @ w) * w for r in others]
        far = max(radial, key=lambda r: float(np.linalg.norm(r)))
        if np.linalg.norm(far) <= 1e-12 * max(1.0, float(np.linalg.norm(point))):
            far = np.eye(3)[int(np.argmin(np.abs(w)))]
            far = far - (far @ w) * w
        u = _unit(far, f'links.{spec.link}.points')
        out.append(Pivot(spec, names.index(spec.link), point, np.column_stack(
            [u, np.cross(w, u), w])))
    return out


def pivot_quantities(theta_k, pivot):
    """Return ``(m, g (3,), sigma = int r r^T dm (3, 3))`` about the pivot in its axes."""
    m = float(theta_k[0])
    h = np.asarray(theta_k[1:4], dtype=float)
    i_o = regressor.inertia_matrix(theta_k[4:10])
    sigma_o = 0.5 * np.trace(i_o) * np.eye(3) - i_o
    p = pivot.point_m
    g = h - m * p
    sigma = sigma_o - np.outer(p, h) - np.outer(h, p) + m * np.outer(p, p)
    r = pivot.axes
    return m, r.T @ g, r.T @ sigma @ r


def pivot_theta(m, g, sigma, pivot):
    """Return theta (10,) about the link origin of ``(m, g, sigma)`` about the pivot (u, v, w)."""
    r = pivot.axes
    g_l, sigma_l = r @ g, r @ sigma @ r.T
    p = pivot.point_m
    h = g_l + m * p
    sigma_o = sigma_l + np.outer(p, g_l) + np.outer(g_l, p) + m * np.outer(p, p)
    i_o = np.trace(sigma_o) * np.eye(3) - sigma_o
    return np.array([m, *h, i_o[0, 0], i_o[0, 1], i_o[1, 1], i_o[0, 2], i_o[1, 2], i_o[2, 2]])


def pivot_fill(m, g, i_ww, p_wu, p_vw, where):
    """Return the second moments (3, 3) about the pivot: the given I_ww, products, least rest."""
    spread = i_ww - (g[0] ** 2 + g[1] ** 2) / m
    b = np.array([p_wu, p_vw]) - g[2] * g[:2] / m
    scale = max(abs(i_ww), 1e-300)
    if spread < -1e-12 * scale or (spread <= 1e-12 * scale and np.any(np.abs(b) > 1e-12 * scale)):
        raise WeightsError(f'{where}: the link with its weight has I_ww {i_ww:.6g} kg m^2 and '
                           f'products ({p_wu:.6g}, {p_vw:.6g}) kg m^2, which no mass '
                           'distribution has; expected a larger I_ww (a wider weight)')
    spread = max(spread, 0.0)
    s = np.outer(g, g) / m
    s[0, 0] += 0.5 * spread
    s[1, 1] += 0.5 * spread
    s[0, 2] = s[2, 0] = p_wu
    s[1, 2] = s[2, 1] = p_vw
    s[2, 2] += float(b @ b) / (0.5 * spread) if spread > 0.0 else 0.0
    return s


@dataclass
class Weight:
    """One designed balancing weight, about its link's pivot in the link's (u, v, w) axes."""

    link: str
    mass_kg: float
    centre_uvw_m: np.ndarray
    radius_m: float
    inertia_ww_kg_m2: float
    product_wu_kg_m2: float = 0.0
    product_vw_kg_m2: float = 0.0
    cylinder: bool = False
    alpha_rad: float = None
    gamma_rad: float = None


@dataclass
class WeightsResult:
    """The force-balanced and optimized scenes, the weights and the least-squares optimum."""

    scene: object
    force_balanced_scene: object
    balanced_scene: object
    weights: list
    link_products_kg_m2: np.ndarray   # J: (I_wu, I_vw) of each weighted link, with weight
    moment_rms_optimal_Nm: float
    moment_rms_lower_bound_Nm: float
    normal_equation_residual: float
    rank: int
    samples: int
    force_residual_rel: float
    solve_time_s: float

    def summary(self):
        """Return the provenance stored with the balanced scene (``balance`` key)."""
        from mech_balance import schema
        return schema.plain({
            'source_scene': self.scene.name, 'method': 'weights',
            'weights': {w.link: {'mass_kg': w.mass_kg, 'centre_uvw_m': list(w.centre_uvw_m),
                                 'product_wu_kg_m2': w.product_wu_kg_m2,
                                 'product_vw_kg_m2': w.product_vw_kg_m2}
                        for w in self.weights},
            'shaking_moment_rms_Nm': self.moment_rms_optimal_Nm,
            'lower_bound_Nm': self.moment_rms_lower_bound_Nm})


def _fold(rig, model, pivots, weights, where):
    """Return theta of the whole rig with the weights folded into their links."""
    theta = model.theta.copy()
    for pv, wt in zip(pivots, weights):
        k = pv.index
        m0, g0, s0 = pivot_quantities(model.theta[10 * k:10 * k + 10], pv)
        m = m0 + wt.mass_kg
        g = g0 + wt.mass_kg * wt.centre_uvw_m
        i_ww = s0[0, 0] + s0[1, 1] + wt.inertia_ww_kg_m2
        sigma = pivot_fill(m, g, i_ww, s0[0, 2] + wt.product_wu_kg_m2,
                           s0[1, 2] + wt.product_vw_kg_m2, f'{where}.{wt.link}')
        theta[10 * k:10 * k + 10] = pivot_theta(m, g, sigma, pv)
    return theta


def balance_weights(rig, samples=None):
    """Return the :class:`WeightsResult` of a rig whose scene lists balancing weights."""
    from mech_balance.balancing.spatial import model as spatial_model
    start = time.perf_counter()
    samples = spatial_model.check_samples(samples, rig)
    pivots = pivots_of(rig)
    model = spatial_model.parameter_model(rig)
    psi = spatial_model.cycle_of(rig, samples)
    y = regressor.wrench_regressor(rig.body_kinematics(psi), rig.moment_point_m)   # (n, 6, 10 nb)
    n = psi.size
    force = y[:, :3].reshape(3 * n, -1)
    moment = y[:, 3:].reshape(3 * n, -1)

    # 1. force balance: the radial first moments (u, v) of each weight about its pivot
    nb = len(model.bodies)
    design = force @ _columns(pivots, nb, [(np.eye(3)[j], np.zeros((3, 3))) for j in range(2)])
    target = -force @ model.theta
    g_radial = np.linalg.lstsq(design, target, rcond=None)[0].reshape(-1, 2)
    before = float(np.linalg.norm(target))
    left = float(np.linalg.norm(design @ g_radial.ravel() - target))
    residual_rel = left / before if before > 0.0 else 0.0
    if residual_rel > FORCE_BALANCED_REL:
        raise WeightsError(
            f'balancing_weights: weights on {", ".join(p.spec.link for p in pivots)} leave '
            f'{residual_rel:.2e} of the RMS shaking force; expected a complete force balance '
            '(a weight on every link that turns about a fixed axis of a four-bar)')
    weights = []
    for pv, gr in zip(pivots, g_radial):
        _, g0, _ = pivot_quantities(model.theta[10 * pv.index:10 * pv.index + 10], pv)
        g = np.array([gr[0], gr[1], 0.0 - g0[2]])             # seed 002 eqs. 6-8, 9-11
        radial = math.hypot(gr[0], gr[1])
        spec = pv.spec
        if spec.mass_kg is not None:
            m = spec.mass_kg
        else:
            if radial == 0.0:
                raise WeightsError(f'balancing_weights.{spec.link}: the link needs no weight '
                                   '(radial first moment 0), expected a nonzero one for the '
                                   'cylinder of Hedaya eqs. 13-14')
            m = (spec.density_length_kg_m2 * math.pi * radial ** 2) ** (1.0 / 3.0)  # eq. 13
        centre = g / m
        r = radial / m                                                     # eq. 14
        factor = 1.0 if spec.mass_kg is not None else CYLINDER_INERTIA_FACTOR
        weights.append(Weight(spec.link, float(m), centre, float(r), factor * m * r * r,
                              cylinder=spec.mass_kg is None))
    theta_fb = _fold(rig, model, pivots, weights, 'balancing_weights')

    # 2. least RMS shaking moment over the products of each weighted link (eqs. 89-95)
    unit_products = []
    for a in (0, 1):                        # (u, w), (v, w)
        ds = np.zeros((3, 3))
        ds[a, 2] = ds[2, a] = 1.0
        unit_products.append((np.zeros(3), ds))
    jmap = moment @ _columns(pivots, nb, unit_products)
    rest = -moment @ theta_fb
    dj, _, rank, _ = np.linalg.lstsq(jmap, rest, rcond=None)
    resid = jmap @ dj - rest
    columns = np.column_stack([-rest, jmap])
    gram = columns.T @ columns / n                                        # eq. 93
    normal = gram[1:, 1:] @ dj + gram[1:, 0]                              # eq. 94
    scale = float(np.max(np.abs(gram[1:, 1:]))) or 1.0
    optimal = float(math.sqrt(resid @ resid / n))
    lower = min(least_squares_lower_bound(jmap, rest, resid) / math.sqrt(n), optimal)
    products = []
    for k, (pv, wt) in enumerate(zip(pivots, weights)):
        wt.product_wu_kg_m2, wt.product_vw_kg_m2 = float(dj[2 * k]), float(dj[2 * k + 1])
        _, _, s0 = pivot_quantities(model.theta[10 * pv.index:10 * pv.index + 10], pv)
        products += [s0[0, 2] + wt.product_wu_kg_m2, s0[1, 2] + wt.product_vw_kg_m2]
        if wt.cylinder:
            wt.alpha_rad, wt.gamma_rad = end_faces(wt)
    theta_opt = _fold(rig, model, pivots, weights, 'balancing_weights')
    sc = rig.scene
    # the designs carry their weights in their links: none left to add
    fb = replace(model.build(theta_fb, f'{sc.name}_force_balanced'), balancing_weights=())
    opt = replace(model.build(theta_opt, f'{sc.name}_balanced'), balancing_weights=())
    return WeightsResult(
        scene=sc, force_balanced_scene=fb, balanced_scene=opt, weights=weights,
        link_products_kg_m2=np.array(products), moment_rms_optimal_Nm=optimal,
        moment_rms_lower_bound_Nm=lower,
        normal_equation_residual=float(np.max(np.abs(normal)) / scale), rank=int(rank),
        samples=n, force_residual_rel=residual_rel,
        solve_time_s=time.perf_counter() - start)


def _columns(pivots, nb, moments):
    """Return (10 nb, len(pivots) len(moments)): theta of each ``(g, sigma)`` about each pivot."""
    out = np.zeros((10 * nb, len(pivots) * len(moments)))
    for k, (pv, (g, sigma)) in enumerate(itertools.product(pivots, moments)):
        out[10 * pv.index:10 * pv.index + 10, k] = pivot_theta(0.0, g, sigma, pv)
    return out


def end_faces(weight):
    """Return ``(alpha, gamma)`` (rad) of a cylinder weight's end faces (seed 002 eqs. 96-103)."""
    ub, vb, wb = weight.centre_uvw_m
    m, r = weight.mass_kg, weight.radius_m
    iwu_c = weight.product_wu_kg_m2 - m * wb * ub                           # eq. 96
    ivw_c = weight.product_vw_kg_m2 - m * vb * wb                           # eq. 97
    magnitude = math.hypot(iwu_c, ivw_c)
    alpha = math.atan2(m * r ** 2, 4.0 * magnitude)                          # eq. 102
    gamma = math.atan2(-ivw_c, -iwu_c) % (2.0 * math.pi) if magnitude > 0.0 else 0.0
    return alpha, gamma


def least_squares_lower_bound(design, target, residual):
    """Return a safe lower bound on ``min_J ||design J - target||`` (:mod:`.certificate`)."""
    from mech_balance.balancing import certificate
    rows, cols = design.shape
    norm_r = float(np.linalg.norm(residual))
    if norm_r == 0.0:
        return 0.0
    q = np.zeros(cols + 1)
    q[cols] = 1.0
    a = np.zeros((rows + 1, cols + 1))
    a[0, cols] = -1.0
    a[1:, :cols] = design
    b = np.concatenate([[0.0], target])
    z = np.concatenate([[1.0], residual / norm_r])   # -(target - design J) / ||r||
    lo, hi = np.full(cols + 1, -np.inf), np.full(cols + 1, np.inf)
    lo[:cols], hi[:cols], _ = certificate.level_set_bounds(
        design, norm_r + float(np.linalg.norm(target)), lo[:cols], hi[:cols])
    lo[cols], hi[cols] = 0.0, norm_r * (1.0 + 4.0 * certificate.UNIT_ROUNDOFF)
    bound = certificate.safe_lower_bound(q, a, b, [('soc', rows + 1)], z, lo, hi)
    return max(bound.value, 0.0)


class ReportView:
    """SI values or the papers' dimensionless view (by the scene's normalization)."""

    def __init__(self, scene, normalized):
        norm = scene.normalization
        self.normalized = bool(normalized) and norm is not None
        ms, ls, w = (norm.mass_kg, norm.length_m, norm.omega_rad_s) if self.normalized else \
            (1.0, 1.0, 1.0)
        self.scale = {'mass': ms, 'length': ls, 'inertia': ms * ls ** 2,
                      'force': ms * ls * w ** 2, 'moment': ms * ls ** 2 * w ** 2}

    def units(self):
        """Return the unit of each kind of value."""
        if self.normalized:
            return {'mass': 'm', 'length': 'l', 'inertia': 'm l^2', 'force': 'm l omega^2',
                    'moment': 'm l^2 omega^2', 'torque': 'm l^2 omega^2', 'angle': 'deg'}
        return {'mass': 'kg', 'length': 'm', 'inertia': 'kg m^2', 'force': 'N',
                'moment': 'N m', 'torque': 'N m', 'angle': 'deg'}

    def __call__(self, kind, x):
        """Return a value of ``kind`` (a key of ``scale``) in the view's unit (array or float)."""
        out = np.asarray(x, dtype=float) / self.scale[kind]
        return out if out.ndim else float(out)


def metrics(data, view, crank_index):
    """Return the RMS and largest |shaking force|, |shaking moment| and |driving torque|."""
    force, moment = view('force', data.force_N), view('moment', data.moment_Nm)
    torque = view('moment', data.joint_effort[:, crank_index])
    return {'shaking_force_rms': float(rms(force)),
            'shaking_force_max': float(np.max(np.linalg.norm(force, axis=1))),
            'shaking_moment_rms': float(rms(moment)),
            'shaking_moment_max': float(np.max(np.linalg.norm(moment, axis=1))),
            'driving_torque_rms': float(rms(torque)),
            'driving_torque_max': float(np.max(np.abs(torque)))}


def balance_report(rig, result, normalized=False):
    """Return the weights' report as a plain dict (SI, or normalized by the scene's units)."""
    sc = rig.scene
    view = ReportView(sc, normalized)
    from mech_balance.balancing.spatial import model as spatial_model, result as spatial_result
    psi = spatial_model.cycle_of(rig, result.samples)
    rows = []
    for label, scene in zip(ROWS, (sc, result.force_balanced_scene, result.balanced_scene)):
        data = rig.with_scene(scene).at(psi)
        rows.append({'rig': label, **metrics(data, view, rig.crank_index)})
    weights = {}
    for wt in result.weights:
        entry = {'mass': view('mass', wt.mass_kg),
                 'centre_uvw': view('length', wt.centre_uvw_m).tolist(),
                 'radius': view('length', wt.radius_m),
                 'inertia_ww': view('inertia', wt.inertia_ww_kg_m2),
                 'product_wu': view('inertia', wt.product_wu_kg_m2),
                 'product_vw': view('inertia', wt.product_vw_kg_m2),
                 'cylinder': wt.cylinder}
        if wt.cylinder:
            entry.update(alpha_deg=math.degrees(wt.alpha_rad),
                         gamma_deg=math.degrees(wt.gamma_rad))
        weights[wt.link] = entry
    products = {f'{wt.link}.{name}': view('inertia', result.link_products_kg_m2[2 * k + j])
                for k, wt in enumerate(result.weights) for j, name in enumerate(('I_wu', 'I_vw'))}
    norm = sc.normalization
    return {
        'scene': sc.name, 'source': sc.source, 'command': 'balance', 'method': 'weights',
        'samples': int(result.samples), 'normalized': view.normalized, 'units': view.units(),
        'normalization': None if norm is None else dict(norm.items()),
        'crank_speed_rad_s': sc.crank_speed_rad_s,
        'weights': weights, 'link_products': products, 'rigs': rows,
        'table': spatial_result.before_after(
            rig, result.balanced_scene, result.samples,
            spatial_model.units_of(rig, spatial_model.parameter_model(rig))),
        'optimum': {'shaking_moment_rms': view('moment', result.moment_rms_optimal_Nm),
                    'shaking_moment_rms_lower_bound':
                        view('moment', result.moment_rms_lower_bound_Nm),
                    'moment_rms_lower_bound_Nm': result.moment_rms_lower_bound_Nm,
                    'normal_equation_residual': result.normal_equation_residual,
                    'rank': result.rank},
        'force_residual_rel': result.force_residual_rel,
        'solve_time_s': result.solve_time_s}


def format_report(report):
    """Return a weights report as a readable fixed-width text table."""
    u = report['units']
    lines = [f"balancing weights (Hedaya) of '{report['scene']}' ({report['source']}): "
             f"crank {report['crank_speed_rad_s']:g} rad/s, {report['samples']} angles"]
    if report['normalized']:
        n = report['normalization']
        lines.append(f"normalized by m = {n['mass_kg']:g} kg, l = {n['length_m']:g} m, "
                     f"omega = {n['omega_rad_s']:g} rad/s")
    lines.append(f"units: force {u['force']}; moment, torque {u['moment']}; "
                 f"mass {u['mass']}; length {u['length']}; inertia {u['inertia']}")
    head = (f"{'rig':<16}{'|f| rms':>12}{'|f| max':>12}{'|n| rms':>12}{'|n| max':>12}"
            f"{'tau rms':>12}{'|tau| max':>12}")
    lines += ['', head, '-' * len(head)]
    for row in report['rigs']:
        lines.append(f"{row['rig']:<16}" + ''.join(f'{row[k]:>12.5g}' for k in METRIC_KEYS))
    lines.append('')
    lines.append('weights (about the pivot, link axes u towards the pin, w the axis):')
    for link, w in report['weights'].items():
        lines.append(f"  {link}: mass {w['mass']:.5g}, centre (u, v, w) "
                     + ' '.join(f'{x:.5g}' for x in w['centre_uvw'])
                     + f", r {w['radius']:.5g}, I_ww {w['inertia_ww']:.5g}")
        text = f"    products I_wu {w['product_wu']:.5g}, I_vw {w['product_vw']:.5g}"
        if w['cylinder']:
            text += f"; end faces alpha {w['alpha_deg']:.3f} deg, gamma {w['gamma_deg']:.3f} deg"
        lines.append(text)
    products = report['link_products']
    lines.append('optimal products J (links with weights, about their pivots):')
    for link in report['weights']:
        lines.append(f"  {link}: I_wu {products[f'{link}.I_wu']:.5g}, I_vw "
                     f"{products[f'{link}.I_vw']:.5g}")
    opt = report['optimum']
    lines.append(f"least-squares optimum: |n| rms {opt['shaking_moment_rms']:.6g} (safe lower "
                 f"bound {opt['shaking_moment_rms_lower_bound']:.6g}), normal-equation "
                 f"residual {opt['normal_equation_residual']:.2e}, rank {opt['rank']}")
    lines.append(f"force balance: RMS shaking force left {report['force_residual_rel']:.1e} of "
                 f"the unbalanced; solve time {report['solve_time_s'] * 1e3:.1f} ms")
    return '\n'.join(lines)


__all__ = ['balance_report', 'balance_weights', 'format_report', 'WeightsError', 'WeightsResult']
