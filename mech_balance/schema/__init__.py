"""
The scene file: read, validated and written here, for every kind of rig.

``schema.load('hoeken')`` (a built-in name or a .yaml path); ``schema.to_yaml(sc)`` round-trips
it.  Every error is a :class:`SceneError` (a ``ValueError``); the schema: docs/scenes.md.
"""

import importlib

_LAZY = {name: module for module, names in (
    ('scene', ('add_counterweights', 'builtin_scenes', 'Counterweight', 'DEFAULT_OUTPUTS',
               'FRAME', 'INERTIA_ROUNDOFF', 'Joint', 'Link', 'load_data', 'needs',
               'Normalization', 'OUTPUTS', 'parse_yaml', 'Recording', 'RECORDING_STREAMS',
               'resolve', 'Scene', 'SCHEMA_VERSION', 'SERIES')),
    ('drive', ('Drive', 'drive_from_dict', 'DriveError')),
    ('fields', ('MAX_ABS_VALUE', 'SceneError')),
    ('registry', ('from_dict', 'kind_of', 'KINDS', 'to_dict')),
    ('identification', ('identification_from_dict', 'identification_to_dict',
                        'IdentificationError')),
) for name in names}
"""The public names of the schema's modules -> their module, imported on first use (so that
a command line parser that needs one constant does not load the loaders)."""


def __getattr__(name):
    """Return a public name of the schema (module docstring), importing its module."""
    try:
        module = _LAZY[name]
    except KeyError:
        raise AttributeError(f'module mech_balance.schema has no attribute {name!r}') from None
    value = getattr(importlib.import_module(f'mech_balance.schema.{module}'), name)
    globals()[name] = value
    return value


def load(name_or_path):
    """Load and validate a scene of any kind by built-in name or path."""
    from mech_balance.schema.registry import from_dict
    from mech_balance.schema.scene import load_data
    data, path = load_data(name_or_path)
    return from_dict(data, source=str(path))


def to_yaml(sc, provenance=None):
    """
    Return a scene as YAML text that :func:`load` reads back bit for bit.

    ``provenance`` (a plain mapping, e.g. a balancing run's summary) goes under ``balance``.
    """
    import yaml
    from mech_balance.schema.registry import to_dict
    data = to_dict(sc)
    if provenance is not None:
        data['balance'] = provenance
    return yaml.safe_dump(plain(data), sort_keys=False, default_flow_style=None, width=99)


def plain(obj):
    """Return ``obj`` with numpy scalars and tuples turned into YAML-safe Python types."""
    import numpy as np
    if isinstance(obj, dict):
        return {str(k): plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, np.ndarray)):
        return [plain(v) for v in obj]
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj)
    return obj


__all__ = sorted(set(_LAZY) | {'load', 'plain', 'to_yaml'}, key=str.lower)
