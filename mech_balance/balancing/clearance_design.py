"""
Collision-free counterweights: the certified convex optimum moved into layers of its own.

Where no layer arrangement is clear, the discs are searched in the plane (SLSQP); ``z - z_lb``
is the price of clearance (docs/build.md, "Collision-free by default").
"""

from dataclasses import dataclass, field, replace
import itertools
import math

from mech_balance.analysis import clearance as clearance_mod, layers as layer_model
from mech_balance.balancing.checks import BalanceError
from mech_balance.balancing.defaults import DEFAULT_CLEARANCE_MARGIN_M, \
    MAX_CLEARANCE_MARGIN_M, SIDES  # the options' home (balancing.options); read here too
from mech_balance.conventions import cycle_angles
from mech_balance.core.planar.rig import PlanarRig
from mech_balance.schema.scene import add_counterweights, MAX_PLANE_OFFSET_M
import numpy as np

MAX_ENUMERATED = 4
"""Up to this many discs every assignment of sides and orders is tried (2^n n! of them)."""
STARTS = 3
"""The local search starts from this many of the least colliding arrangements."""
SEARCH_CUSHION = 0.02
"""The local search asks the sampled clearance for margin x (1 + this)."""
CLEAR_ROWS = 8
"""The local search constrains this many of the least pairs' clearances."""
SEARCH_MAX_ITER = 200
"""Iteration limit of one local search (SLSQP)."""
BOUND_ACTIVE_REL = 1e-4
"""A disc bound is reported active when met within this fraction."""


class NoClearDesign(BalanceError):
    """No collision-free counterweight design within the bounds (``result``: the solver's)."""

    def __init__(self, message, result=None):
        super().__init__(message)
        self.result = result


@dataclass
class ClearanceReport:
    """What the collision-free design cost and how clear it is (SI; objective normalized)."""

    status: str                 # 'collision-free' | 'none' | 'off'
    margin_m: float
    side: str
    objective: float            # z of the design given (or of the best attempt, for 'none')
    convex_objective: float     # z of the certified convex optimum
    lower_bound: float          # the convex program's safe lower bound
    least_clearance_m: float
    least_pair: tuple = ()
    moved_in_plane: bool = False
    arrangements_tried: int = 0
    layers: list = field(default_factory=list)   # per disc: link, side, plane_m, z_m, mount
    binding: list = field(default_factory=list)  # the bounds active at the best attempt
    best_attempt: list = field(default_factory=list)

    @property
    def price(self):
        """Return the price of clearance ``z - z_lb`` (>= 0)."""
        return self.objective - self.lower_bound

    def to_dict(self):
        """Return the report as a plain dict."""
        lb = self.lower_bound
        return {'status': self.status, 'margin_m': float(self.margin_m), 'side': self.side,
                'objective': float(self.objective),
                'convex_objective': float(self.convex_objective),
                'lower_bound': float(lb), 'price_of_clearance': float(self.price),
                'price_of_clearance_rel': float(self.price / lb) if lb > 0.0 else None,
                'least_clearance_m': None if not math.isfinite(self.least_clearance_m)
                else float(self.least_clearance_m),
                'least_pair': list(self.least_pair), 'moved_in_plane': self.moved_in_plane,
                'arrangements_tried': int(self.arrangements_tried), 'layers': self.layers,
                'binding_bounds': list(self.binding), 'best_attempt': self.best_attempt}

    def lines(self):
        """Return the report as text: the objective beside the bound, the clearance."""
        lc = self.least_clearance_m
        clear = 'no body within reach' if not math.isfinite(lc) else f'{lc * 1e3:.4g} mm'
        if self.status == 'off':
            return [f'clearance design off: the certified convex optimum as is (least '
                    f'clearance {clear})']
        head = (('best attempt' if self.status == 'none' else 'price of clearance')
                + f': objective z = {self.objective:.6g} beside the convex '
                f'lower bound {self.lower_bound:.6g} (convex optimum '
                f'{self.convex_objective:.6g}): {self.price:.3g}'
                + (f' ({self.price / self.lower_bound * 100.0:.3g}%)'
                   if self.lower_bound > 0.0 else ''))
        if self.status == 'none':
            return [f'NO collision-free design within the bounds: least clearance reached '
                    f'{clear} < margin {self.margin_m * 1e3:.3g} mm'
                    + (f' ({self.least_pair[0]} and {self.least_pair[1]})'
                       if self.least_pair else ''),
                    'bounds active at the best attempt: '
                    + (', '.join(self.binding) or 'none (a local optimum)'), head]
        spheres = self.side == 'spheres'   # a spatial design (balancing.sphere_clearance)
        kept = ' (the convex optimum kept)' if spheres else \
            ' (layers only; the convex optimum kept)'
        out = [f'collision-free: least clearance {clear} >= margin {self.margin_m * 1e3:.3g} '
               'mm over the cycle' + ((' (spheres moved)' if spheres else
                                       ' (discs moved in the plane)')
                                      if self.moved_in_plane else kept), head]
        for e in self.layers:
            out.append(f"  {e['link']} disc: {e['side']} the linkage, mid-plane z "
                       f"{e['z_m'] * 1e3:.4g} mm (plane_m {e['plane_m'] * 1e3:+.4g} mm), on "
                       f"a shaft at joint point {e['mount']}")
        return out


def with_discs(scene, designs, name=None):
    """Return ``scene`` with the disc of each design added to its link."""
    by = {d.link: d for d in designs}
    return scene.with_links([lk if lk.name not in by else
                             add_counterweights(lk, [by[lk.name].counterweight()])
                             for lk in scene.links], name=name)


def least_pair(clear):
    """Return the two bodies of a clearance check's least pair (() when none)."""
    return () if clear.least is None else (clear.least.body_a, clear.least.body_b)


def check_margin(value, name='clearance_margin_m'):
    """Return a margin (m) in [0, MAX_CLEARANCE_MARGIN_M], or None (the design off)."""
    if value is None:
        return None
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f'{name}: got {value!r}, expected a number of metres') from None
    if not (math.isfinite(v) and 0.0 <= v <= MAX_CLEARANCE_MARGIN_M):
        raise ValueError(f'{name}: got {v:g}, expected 0 <= margin <= '
                         f'{MAX_CLEARANCE_MARGIN_M:g} m')
    return v


def check_side(value, name='disc_side'):
    """Return a side of :data:`SIDES`."""
    if value not in SIDES:
        raise ValueError(f'{name}: got {value!r}, expected one of {", ".join(SIDES)}')
    return value


class _Search:
    """The arrangement and in-plane searches of one convex optimum."""

    def __init__(self, scene, prob, designs, margin_m, max_overhang_m):
        self.scene, self.prob, self.margin = scene, prob, margin_m
        self.designs = list(designs)
        self.rig = PlanarRig(scene)
        self.layers = layer_model.Layers.of(scene, self.rig.linkage)
        self.sweep = clearance_mod.Sweep(self.rig, cycle_angles(prob.opt.samples))
        self.max_overhang = MAX_PLANE_OFFSET_M if max_overhang_m is None else max_overhang_m
        self.tried = 0
        self._mounts = {}

    def gaps(self, designs):
        """Return (least sampled clearance per pair, body list, pairs) of a design."""
        rig = self.rig.with_scene(with_discs(self.scene, designs))
        body_list = clearance_mod.bodies(rig, self.layers)
        todo = clearance_mod.pairs(body_list, self.margin)
        if not todo:
            return np.zeros(0), body_list, todo
        return self.sweep.gaps(body_list, todo).min(axis=1), body_list, todo

    def least(self, designs):
        g, _, _ = self.gaps(designs)
        return float(g.min()) if g.size else math.inf

    def arrange(self, sides, order):
        """Return the designs with their planes: ``sides`` per disc, ``order`` innermost first."""
        out = {}
        for side in (1, -1):
            items = [(k, self.designs[k].thickness_m) for k in order if sides[k] == side]
            for k, z in layer_model.stack(self.layers, items, side, self.margin).items():
                out[k] = replace(self.designs[k], mount=self.mount(k, side),
                                 plane_m=float(z - self.layers.z_m(self.designs[k].link)))
        return [out[k] for k in range(len(self.designs))]

    def mount(self, k, side):
        """Return the link point whose shaft keeps disc k (``side`` +1 above) clearest."""
        key = (k, side)
        if key not in self._mounts:
            d = self.designs[k]
            link = self.scene.link(d.link)
            z = layer_model.stack(self.layers, [(k, d.thickness_m)], side, self.margin)[k]
            near = layer_model.mount_point(link, d.centre_m)[0]
            best = None
            for name in [near] + [p for p in link.points if p != near]:
                trial = replace(d, mount=name, plane_m=float(z - self.layers.z_m(d.link)))
                value = self.least([trial])
                if best is None or value > best[0] + 1e-12:
                    best = (value, name)
            self._mounts[key] = best[1]
        return self._mounts[key]

    def arrangements(self, side):
        """Yield (sides, order) to try: all of them up to MAX_ENUMERATED discs."""
        n = len(self.designs)
        choices = {'above': [(1,) * n], 'below': [(-1,) * n]}.get(side)
        if n <= MAX_ENUMERATED:
            for sides in choices or itertools.product((1, -1), repeat=n):
                for order in itertools.permutations(range(n)):
                    yield sides, order
            return
        # many discs: each on the side nearer its link's layer, innermost the nearest
        lo, hi = self.layers.extent()
        zs = [self.layers.z_m(d.link) for d in self.designs]
        sides = choices[0] if choices else tuple(1 if hi - z <= z - lo else -1 for z in zs)
        yield sides, tuple(sorted(range(n), key=lambda k: -sides[k] * zs[k]))

    def best_arrangements(self, side):
        scored = []
        for sides, order in self.arrangements(side):
            designs = self.arrange(sides, order)
            self.tried += 1
            over = max(abs(d.plane_m) + 0.5 * d.thickness_m for d in designs)
            if over > self.max_overhang:
                continue
            scored.append((min(self.least(designs), 1e300), over, designs, sides))
        # clear ones first (least overhang), then the least colliding
        scored.sort(key=lambda s: (s[0] < self.margin, s[1] if s[0] >= self.margin
                                   else -s[0]))
        return scored

    def stuck(self, designs):
        """Return the first 'shaft meets the linkage or a shaft' within the margin, or ''."""
        g, body_list, todo = self.gaps(designs)
        for value, (i, j) in sorted(zip(g, todo)):
            if value >= self.margin:
                break
            a, b = body_list[i], body_list[j]
            shapes = {a.shape, b.shape}
            if 'shaft' in shapes and (not (a.added and b.added) or shapes == {'shaft'}):
                shaft, other = (a, b) if a.shape == 'shaft' else (b, a)
                return (f'{shaft.name} crosses the layer of {other.name} '
                        f'(clearance {value * 1e3:.3g} mm)')
        return ''

    def _designs(self, x, template):
        out = []
        for k, d in enumerate(template):
            dm, cx, cy, radius = x[4 * k:4 * k + 4]
            dm, radius = max(dm, 1e-300), max(radius, 1e-300)
            t = dm / (d.density_kg_m3 * math.pi * radius * radius)
            out.append(replace(d, mass_kg=float(dm), centre_m=(float(cx), float(cy)),
                               centre_radius_m=float(math.hypot(cx, cy)),
                               centre_angle_deg=math.degrees(math.atan2(cy, cx)) % 360.0,
                               radius_m=float(radius), thickness_m=float(t),
                               inertia_com_kg_m2=float(0.5 * dm * radius * radius)))
        return out

    def local(self, template):
        """Return (designs, least sampled clearance): SLSQP in the plane, layers fixed."""
        prob = self.prob
        slots = [d.thickness_m for d in template]
        x0 = np.concatenate([[d.mass_kg, d.centre_m[0], d.centre_m[1], d.radius_m]
                             for d in template])
        z0 = max(prob.z(y_of(prob, template)), 1e-300)
        scale = np.concatenate([[d.max_mass_kg, d.max_centre_radius_m, d.max_centre_radius_m,
                                 d.max_centre_radius_m] for d in template])
        kmax = [prob.k_max[prob.opt.links.index(d.link)] * prob.units.length_m
                for d in template]
        rim = None if prob.rho is None else \
            [prob.rho[prob.opt.links.index(d.link)] * prob.units.length_m for d in template]
        ref = self.layers.pin_radius_m

        def unpack(u):
            return self._designs(u * scale, template)

        def objective(u):
            return prob.z(y_of(prob, unpack(u))) / z0

        def disc_bounds(u):
            out = []
            for k, d in enumerate(unpack(u)):
                c, radius, dm = d.centre_radius_m, d.radius_m, d.mass_kg
                out += [(slots[k] - d.thickness_m) / slots[k],
                        (d.max_centre_radius_m - c) / d.max_centre_radius_m,
                        (kmax[k] ** 2 - c * c - 0.5 * radius * radius) / kmax[k] ** 2,
                        (d.max_mass_kg - dm) / d.max_mass_kg]
                if rim is not None:
                    out.append((rim[k] - c - radius) / rim[k])
            return np.array(out)

        def clear(u):
            # the CLEAR_ROWS least pairs' clearances, in order (a fixed count: the pairs that
            # can meet change with the design; order statistics are continuous)
            g, _, _ = self.gaps(unpack(u))
            g = np.sort(np.concatenate([g, np.full(CLEAR_ROWS, 1e3 * ref)]))[:CLEAR_ROWS]
            return (g - self.margin * (1.0 + SEARCH_CUSHION)) / ref

        from scipy import optimize   # only when a search runs (record --balance never)
        u0 = x0 / scale
        bounds = [(1e-9, None), (-1.0, 1.0), (-1.0, 1.0), (1e-6, 10.0)] * len(template)
        res = optimize.minimize(objective, u0, method='SLSQP', bounds=bounds,
                                constraints=[{'type': 'ineq', 'fun': disc_bounds},
                                             {'type': 'ineq', 'fun': clear}],
                                options={'maxiter': SEARCH_MAX_ITER, 'ftol': 1e-10})
        designs = unpack(res.x)
        return designs, self.least(designs), self._active(res.x, disc_bounds, template)

    def _active(self, u, disc_bounds, template):
        names = ('thickness <= its layer', 'centre radius <= max', 'gyration <= max',
                 'mass <= max')
        b = disc_bounds(u)
        per = len(b) // len(template)
        out = []
        for k, d in enumerate(template):
            for j in range(per):
                if b[k * per + j] <= BOUND_ACTIVE_REL:
                    out.append(f'{d.link}: ' + (names[j] if j < len(names) else
                                                'rim radius <= max'))
        return out


def design(scene, prob, designs, lower_bound, margin_m=DEFAULT_CLEARANCE_MARGIN_M,
           side='auto', max_overhang_m=None, fixed_planes=False):
    """Return ``(designs, ClearanceReport)``: the convex optimum ``designs`` made clear."""
    z_convex = prob.z(y_of(prob, designs))
    report = ClearanceReport('collision-free', margin_m, side, z_convex, z_convex, lower_bound,
                             math.inf)
    if not designs:
        return list(designs), report
    search = _Search(scene, prob, designs, margin_m, max_overhang_m)
    if fixed_planes:
        scored = [(search.least(designs), 0.0, list(designs), None)]
        search.tried = 1
    else:
        scored = search.best_arrangements(side)
    report.arrangements_tried = search.tried
    if not scored:
        report.status = 'none'
        report.binding = [f'max overhang {search.max_overhang:g} m (no arrangement fits)']
        return [], report
    best = scored[0]
    chosen, least = best[2], best[0]
    if least < margin_m:
        attempts = []
        fixed = []
        for entry in scored[:STARTS]:
            stuck = search.stuck(entry[2])
            if stuck:   # a shaft meets the linkage: no move of a disc in the plane frees it
                fixed.append((entry[0], entry[2], stuck))
                continue
            moved, value, active = search.local(entry[2])
            attempts.append((value, moved, active))
            if value >= margin_m:
                break
        if not attempts:
            value, moved, stuck = fixed[0]
            _final(search, report, moved)
            return _none(report, moved, [
                f'the layers: {stuck} in every arrangement of sides, orders and mounts '
                f'({search.tried} tried; the shaft stands at a joint, so no move of a disc in '
                'the plane frees it)'])
        value, moved, active = max(attempts, key=lambda a: a[0])
        report.moved_in_plane = True
        if value >= margin_m:
            chosen, least = moved, value
        else:
            report.objective = prob.z(y_of(prob, moved))
            _final(search, report, moved)
            return _none(report, moved, active)
    report.objective = prob.z(y_of(prob, chosen))
    _final(search, report, chosen)
    if report.least_clearance_m < margin_m:   # the refined minimum fell below the margin
        return _none(report, chosen, ['the clearance between crank-angle samples'])
    return chosen, report


def _none(report, attempt, binding):
    """Return ``([], report)``: no clear design, ``binding`` why, ``attempt`` the best."""
    report.status, report.binding = 'none', binding
    report.best_attempt = [d.to_dict() for d in attempt]
    return [], report


def _final(search, report, designs):
    """Fill the report's least clearance (refined, :func:`clearance`) and layers."""
    clear = clearance_mod.clearance(search.rig.with_scene(with_discs(search.scene, designs)),
                                    search.prob.opt.samples, search.margin, search.sweep)
    report.least_clearance_m = clear.least_clearance_m
    report.least_pair = least_pair(clear)
    report.layers = []
    for d in designs:
        z = search.layers.z_m(d.link) + d.plane_m
        lo, hi = search.layers.extent()
        report.layers.append({
            'link': d.link, 'plane_m': float(d.plane_m), 'z_m': float(z),
            'side': 'above' if z > hi else 'below' if z < lo else 'within',
            'mount': layer_model.mount_point(search.scene.link(d.link), d.centre_m,
                                             d.mount)[0]})


def y_of(prob, designs):
    """Return the program's variables (link units) of SI disc designs (omitted: zero)."""
    ms, ls = prob.units.mass_kg, prob.units.length_m
    y = np.zeros(prob.ny)
    by = {d.link: d for d in designs}
    for i, name in enumerate(prob.opt.links):
        d = by.get(name)
        if d is None:
            continue
        dm, c = d.mass_kg, complex(*d.centre_m)
        d_i = dm * (abs(c) ** 2 + 0.5 * d.radius_m ** 2)
        y[4 * i:4 * i + 4] = (dm / ms, dm * c.real / (ms * ls), dm * c.imag / (ms * ls),
                              d_i / (ms * ls * ls))
    return y / prob.dsc
