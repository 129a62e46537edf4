"""
The ``build:`` section of a planar scene: the rig as built, layer by layer along the joint axes.

Every field optional (docs/build.md#the-layered-model); used by
:class:`mech_balance.analysis.layers.Layers`.
"""

from mech_balance.schema.fields import known_keys, mapping, number, positive, SceneError

BUILD_KEYS = ('layer_pitch_m', 'bar_width_m', 'bar_thickness_m', 'pin_radius_m',
              'boss_length_m', 'layers')
"""The fields of ``build:``."""
LAYER_KEYS = ('z_m', 'thickness_m', 'bar_width_m')
"""The fields of one body's entry in ``build.layers``."""
MAX_BUILD_SIZE_M = 100.0
"""Largest size or |z| accepted in ``build:`` (m): a larger one is a typo (mm for m)."""


def build_from_dict(data, bodies, where='build'):
    """
    Return the ``build:`` section checked, as a plain dict of floats (missing fields absent).

    ``bodies``: the frame and link names (the keys ``layers`` may use); raises SceneError.
    """
    if data is None:
        return None
    mapping(data, where)
    known_keys(data, BUILD_KEYS, where)
    out = {}
    for key in BUILD_KEYS[:-1]:
        if key in data:
            out[key] = _size(data[key], f'{where}.{key}')
    if 'layers' in data:
        layers = mapping(data['layers'], f'{where}.layers')
        out['layers'] = {}
        for body, spec in layers.items():
            path = f'{where}.layers.{body}'
            if body not in bodies:
                raise SceneError(f'{path}: unknown body, expected one of '
                                 f'{", ".join(bodies)}')
            mapping(spec, path)
            known_keys(spec, LAYER_KEYS, path)
            entry = {}
            if 'z_m' in spec:
                z = number(spec['z_m'], f'{path}.z_m') + 0.0
                if abs(z) > MAX_BUILD_SIZE_M:
                    raise SceneError(f'{path}.z_m: got {z!r}, expected |z| <= '
                                     f'{MAX_BUILD_SIZE_M:g} m')
                entry['z_m'] = z
            for key in LAYER_KEYS[1:]:
                if key in spec:
                    entry[key] = _size(spec[key], f'{path}.{key}')
            out['layers'][body] = entry
    return out


def _size(value, where):
    """Return a size (m): a number > 0 and at most :data:`MAX_BUILD_SIZE_M`."""
    v = positive(value, where)
    if v > MAX_BUILD_SIZE_M:
        raise SceneError(f'{where}: got {v!r}, expected a size <= {MAX_BUILD_SIZE_M:g} m')
    return v
