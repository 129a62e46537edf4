"""
The field validators every scene kind, ``drive:`` and the node's parameters share.

Each takes the value, its path (``links.crank.mass_kg``) and the error type (default
:class:`SceneError`); it returns the checked value or raises naming path, value, expectation.
"""

import math

from mech_balance import conventions

MAX_ABS_VALUE = 1e18
"""Larger magnitudes in any numeric field are rejected (their squares would overflow soon)."""


class SceneError(ValueError):
    """A scene field is missing, has the wrong type or an impossible value."""


def require(mapping, key, where, error=SceneError):
    """Return ``mapping[key]``; a missing key is an error naming ``where.key``."""
    if key not in mapping:
        path = f'{where}.{key}' if where else key
        raise error(f'{path}: missing, expected a value')
    return mapping[key]


def known_keys(mapping, allowed, where, error=SceneError):
    """Refuse a key of ``mapping`` that is not in ``allowed``, naming it and the choices."""
    unknown = sorted(str(k) for k in set(mapping) - set(allowed))
    if unknown:
        path = f'{where}.{unknown[0]}' if where else unknown[0]
        raise error(
            f'{path}: unknown field, expected one of {", ".join(sorted(allowed))}')


def mapping(value, where, error=SceneError):
    """Return ``value`` if it is a mapping with text keys."""
    if not isinstance(value, dict):
        raise error(f'{where}: got {value!r}, expected a mapping')
    for k in value:
        if not isinstance(k, str):
            raise error(f'{where}: key {k!r} is not text, expected names')
    return value


def string(value, where, error=SceneError):
    """Return ``value`` if it is non-empty text."""
    if not isinstance(value, str) or not value:
        raise error(f'{where}: got {value!r}, expected a non-empty name')
    return value


def text(value, where, error=SceneError):
    """Return ``value`` if it is a string, possibly empty."""
    if not isinstance(value, str):
        raise error(f'{where}: got {type(value).__name__}, expected text')
    return value


def number(value, where, error=SceneError):
    """Return ``value`` as a float if it is a finite number of magnitude <= MAX_ABS_VALUE."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise error(f'{where}: got {value!r}, expected a number')
    try:
        value = float(value)
    except OverflowError:
        raise error(f'{where}: got an integer of {len(str(abs(value)))} digits, expected a '
                    f'magnitude <= {MAX_ABS_VALUE:g}') from None
    if not math.isfinite(value):
        raise error(f'{where}: got {value!r}, expected a finite number')
    if abs(value) > MAX_ABS_VALUE:
        raise error(f'{where}: got {value!r}, expected a magnitude <= {MAX_ABS_VALUE:g}')
    return value


def positive(value, where, error=SceneError):
    """Return ``value`` if it is a number > 0."""
    value = number(value, where, error)
    if value <= 0.0:
        raise error(f'{where}: got {value!r}, expected a number > 0')
    return value


def nonneg(value, where, error=SceneError):
    """Return ``value`` if it is a number >= 0."""
    value = number(value, where, error)
    if value < 0.0:
        raise error(f'{where}: got {value!r}, expected a number >= 0')
    return value


def nonzero(value, where, error=SceneError):
    """Return ``value`` if it is a number other than 0."""
    value = number(value, where, error)
    if value == 0.0:
        raise error(f'{where}: got {value!r}, expected a nonzero number')
    return value


def vector(value, where, size=2, error=SceneError):
    """Return ``value`` as a tuple of ``size`` numbers (``[x, y]`` or ``[u, v, w]``)."""
    if not isinstance(value, (list, tuple)) or len(value) != size:
        names = {2: '[x, y]', 3: '[x, y, z]'}.get(size, f'{size} numbers')
        raise error(f'{where}: got {value!r}, expected {names}')
    return tuple(number(v, f'{where}[{i}]', error) for i, v in enumerate(value))


def points(value, where, error=SceneError, size=2):
    """Return a non-empty mapping of named points of ``size`` coordinates."""
    value = mapping(value, where, error)
    if not value:
        raise error(f'{where}: got an empty mapping, expected named points'
                    + (' [x, y, z]' if size == 3 else ''))
    at_most(value, conventions.MAX_POINTS, where, 'points', 'MAX_POINTS', error)
    return {k: vector(v, f'{where}.{k}', size, error) for k, v in value.items()}


def joint_ends(spec, where, all_points):
    """Return ``[(link, point), (link, point)]`` of a joint's ``a`` and ``b`` (two links)."""
    ends = []
    for key in ('a', 'b'):
        ref = string(require(spec, key, where), f'{where}.{key}')
        link, _, point = ref.partition('.')
        if link not in all_points:
            raise SceneError(
                f'{where}.{key}: got {ref!r}, expected "link.point" with link one of '
                f'{", ".join(all_points)}')
        if point not in all_points[link]:
            raise SceneError(
                f'{where}.{key}: got {ref!r}, link {link!r} has no point {point!r} (it has '
                f'{", ".join(all_points[link]) or "none"})')
        ends.append((link, point))
    if ends[0][0] == ends[1][0]:
        raise SceneError(f'{where}: both ends are on link {ends[0][0]!r}, expected two links')
    return ends


def crank_joint(crank, joints):
    """Return ``(name, joint)`` of ``crank.joint``, one of ``joints``."""
    name = string(require(crank, 'joint', 'crank'), 'crank.joint')
    by_name = {j.name: j for j in joints}
    if name not in by_name:
        raise SceneError(f'crank.joint: got {name!r}, expected one of the joints '
                         f'({", ".join(by_name)})')
    return name, by_name[name]


def integer(value, where, minimum=None, maximum=None, error=SceneError):
    """Return ``value`` if it is an int (not a bool) within the given bounds."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise error(f'{where}: got {value!r}, expected an integer')
    if minimum is not None and value < minimum:
        raise error(f'{where}: got {value!r}, expected an integer >= {minimum}')
    if maximum is not None and value > maximum:
        raise error(f'{where}: got {value!r}, expected an integer <= {maximum}')
    return value


def at_most(items, limit, where, what, name, error=SceneError):
    """Refuse more than ``limit`` entries (``name``: the limit's constant in conventions)."""
    if len(items) > limit:
        raise error(f'{where}: got {len(items)} {what}, expected at most {limit} '
                    '(a fixed limit of mech_balance)')


def check_connected(links, joints, frame):
    """Raise :class:`SceneError` naming the moving links no chain of joints joins to ``frame``."""
    adj = {lk.name: set() for lk in links}
    adj[frame] = set()
    for jt in joints:
        adj[jt.link_a].add(jt.link_b)
        adj[jt.link_b].add(jt.link_a)
    seen, todo = {frame}, [frame]
    while todo:
        for nb in adj[todo.pop()]:
            if nb not in seen:
                seen.add(nb)
                todo.append(nb)
    loose = [lk.name for lk in links if lk.name not in seen]
    if loose:
        raise SceneError(f'joints: link(s) {", ".join(loose)} are not connected to the frame, '
                         'expected every moving link joined to the frame through other links')
