"""The options of add-only counterweight balancing: checked where they are read."""

from dataclasses import dataclass
import math

from mech_balance import schema
from mech_balance.balancing import checks, clearance_design
from mech_balance.balancing.defaults import check_counterweight_option, \
    DEFAULT_DENSITY_KG_M3, DEFAULT_MAX_GYRATION_FACTOR, DEFAULT_MAX_MASS_FACTOR, \
    DEFAULT_MAX_RADIUS_FACTOR, DEFAULT_MAX_THICKNESS_M, DEFAULT_WEIGHTS
from mech_balance.schema.scene import MAX_PLANE_OFFSET_M
import numpy as np


class CounterweightError(checks.BalanceError):
    """A counterweight problem has a bad option or cannot be solved."""


@dataclass(frozen=True)
class CounterweightOptions:
    """The plain options of :func:`balance_with_counterweights` (what a node passes)."""

    links: tuple
    weights: tuple = DEFAULT_WEIGHTS
    density_kg_m3: float = DEFAULT_DENSITY_KG_M3
    max_thickness_m: float = DEFAULT_MAX_THICKNESS_M
    max_radius_factor: float = DEFAULT_MAX_RADIUS_FACTOR
    max_mass_factor: float = DEFAULT_MAX_MASS_FACTOR
    max_gyration_factor: float = DEFAULT_MAX_GYRATION_FACTOR
    torque_weight: float = 0.0
    reaction_weight: float = 0.0
    samples: int = None
    tie_break: bool = True
    planes: tuple = ()                  # ((link, plane_m), ...): a disc's plane (clearance)
    max_rim_radius_factor: float = None  # disc inside F x joint reach of its link's origin
    clearance_margin_m: float = clearance_design.DEFAULT_CLEARANCE_MARGIN_M  # None: off
    disc_side: str = 'auto'             # where the discs' layers go (clearance_design.SIDES)
    max_overhang_m: float = None        # a disc's outer face at most this beyond the linkage

    def to_dict(self):
        """Return the options as a plain dict."""
        out = dict(self.__dict__)
        out['planes'] = {str(k): float(v) for k, v in dict(self.planes).items()}
        return schema.plain(out)


def positive(value, name):
    """Return ``value`` as a finite float > 0, else :class:`CounterweightError` naming it."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise CounterweightError(f'{name}: got {value!r}, expected a number > 0') from None
    if not (math.isfinite(v) and v > 0.0):
        raise CounterweightError(f'{name}: got {v:g}, expected a finite number > 0')
    return v


def nonnegative(value, name):
    """Return ``value`` as a finite float >= 0, else :class:`CounterweightError` naming it."""
    try:
        return checks.check_nonneg(value, name)
    except checks.BalanceError as exc:
        raise CounterweightError(str(exc)) from None


def link_list(links, scene, name='counterweight_links'):
    """Return the listed link names (text 'a,b' or a sequence), checked against the scene."""
    if isinstance(links, str):
        links = [v.strip() for v in links.split(',')]
    try:
        links = [str(v) for v in links]
    except TypeError:
        raise CounterweightError(f'{name}: got {links!r}, expected link names') from None
    names = [lk.name for lk in scene.links]
    out = []
    for v in links:
        if v not in names:
            raise CounterweightError(f'{name}: got {v!r}, expected link names from '
                                     f'{", ".join(names)}')
        if v not in out:
            out.append(v)
    if not out:
        raise CounterweightError(f'{name}: got none, expected at least one link from '
                                 f'{", ".join(names)}')
    return tuple(out)


def check_options(scene, options):
    """Return validated :class:`CounterweightOptions` (errors name the option)."""
    kind = schema.kind_of(scene)
    if 'counterweights' not in kind.rig_factory().capabilities:
        raise CounterweightError(f'scene {scene.name!r}: kind {kind.name!r}, expected a '
                                 'planar scene')
    try:
        w1, w2 = (float(v) for v in options.weights)
    except (TypeError, ValueError):
        raise CounterweightError(f'weights: got {options.weights!r}, expected two numbers '
                                 '(w1, w2)') from None
    w1, w2 = nonnegative(w1, 'weights (w1)'), nonnegative(w2, 'weights (w2)')
    tw = nonnegative(options.torque_weight, 'torque_weight')
    rw = nonnegative(options.reaction_weight, 'reaction_weight')
    if w1 + w2 + tw + rw == 0.0:
        raise CounterweightError('weights: got all zero, expected at least one positive weight')
    samples = scene.samples if options.samples is None else options.samples
    if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) or samples < 4:
        raise CounterweightError(f'samples: got {samples!r}, expected an integer >= 4')
    return CounterweightOptions(
        links=link_list(options.links, scene), weights=(w1, w2),
        **{key: _ranged(getattr(options, key), key) for key in (
            'density_kg_m3', 'max_thickness_m', 'max_radius_factor', 'max_mass_factor',
            'max_gyration_factor')},
        torque_weight=tw, reaction_weight=rw, samples=int(samples),
        tie_break=bool(options.tie_break), planes=plane_list(options.planes, options.links,
                                                             scene),
        max_rim_radius_factor=None if options.max_rim_radius_factor is None else
        _ranged(options.max_rim_radius_factor, 'max_rim_radius_factor'),
        **_clearance_options(options))


def _clearance_options(options):
    """Return the checked clearance options (errors name the option)."""
    try:
        over = options.max_overhang_m
        return {'clearance_margin_m': clearance_design.check_margin(options.clearance_margin_m),
                'disc_side': clearance_design.check_side(options.disc_side),
                'max_overhang_m': None if over is None else
                min(positive(over, 'max_overhang_m'), MAX_PLANE_OFFSET_M)}
    except ValueError as exc:
        raise CounterweightError(str(exc)) from None


def plane_list(planes, links, scene, name='planes'):
    """Return ``((link, plane_m), ...)`` of a mapping, pairs or text 'crank=-0.03,rocker=0.03'."""
    listed = link_list(links, scene)
    if isinstance(planes, str):
        items = []
        for part in (v.strip() for v in planes.split(',')):
            if not part:
                continue
            link, sep, value = part.partition('=')
            if not sep:
                raise CounterweightError(f'{name}: got {part!r}, expected LINK=Z_M (a link and '
                                         "its disc's plane offset in m)")
            items.append((link.strip(), value.strip()))
    else:
        try:
            items = list(dict(planes or ()).items())
        except (TypeError, ValueError):
            raise CounterweightError(f'{name}: got {planes!r}, expected link: plane_m '
                                     'pairs') from None
    out = {}
    for link, value in items:
        if link not in listed:
            raise CounterweightError(f'{name}: got link {link!r}, expected one of the '
                                     f'counterweight links {", ".join(listed)}')
        if link in out:
            raise CounterweightError(f'{name}: got {link!r} twice, expected one plane per link')
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise CounterweightError(f'{name}.{link}: got {value!r}, expected a number '
                                     '(m)') from None
        if not (math.isfinite(v) and abs(v) <= MAX_PLANE_OFFSET_M):
            raise CounterweightError(f'{name}.{link}: got {v:g}, expected a plane offset '
                                     f'within +-{MAX_PLANE_OFFSET_M:g} m')
        out[link] = v + 0.0
    return tuple(out.items())


def _ranged(value, option):
    """Return an option checked against :data:`.defaults.COUNTERWEIGHT_RANGES`."""
    positive(value, option)
    try:
        return check_counterweight_option(option, value)
    except ValueError as exc:
        raise CounterweightError(str(exc)) from None


def joint_reach_m(scene, link_name):
    """Return the distance from a link's origin to its farthest joint point (m)."""
    lk = scene.link(link_name)
    used = {j.point_a for j in scene.joints if j.link_a == link_name} | \
        {j.point_b for j in scene.joints if j.link_b == link_name}
    return max(math.hypot(*lk.points[p]) for p in used)
