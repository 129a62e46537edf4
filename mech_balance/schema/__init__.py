"""
The scene file: read, validated and written here, for every kind of rig.

The public face of the schema layer::

    from mech_balance import schema
    sc = schema.load('hoeken')            # a built-in name or a path to a .yaml file
    text = schema.to_yaml(sc)             # what load() reads back, bit for bit

The planar schema is documented in the README (section *Scenes*) and enforced by
:mod:`mech_balance.schema.scene`; the RGGR's by :mod:`mech_balance.schema.rggr`; ``drive:``
by :mod:`mech_balance.schema.drive`; the field checks all of them share are in
:mod:`mech_balance.schema.fields`; the kinds are registered in
:mod:`mech_balance.schema.registry`.  Every error is a :class:`SceneError` (a
``ValueError``) naming the field, the bad value and what was expected.
"""

from mech_balance.schema.drive import Drive, drive_from_dict, DriveError
from mech_balance.schema.fields import MAX_ABS_VALUE, SceneError
from mech_balance.schema.registry import from_dict, kind_of, KINDS, to_dict
from mech_balance.schema.rggr import RggrScene
from mech_balance.schema.scene import add_counterweights, builtin_scenes, Counterweight, \
    DEFAULT_OUTPUTS, FRAME, INERTIA_ROUNDOFF, Joint, Link, load_data, needs, Normalization, \
    OUTPUTS, parse_yaml, Recording, RECORDING_STREAMS, resolve, Scene, SCHEMA_VERSION, SERIES
import numpy as np
import yaml


def load(name_or_path):
    """Load and validate a scene of any kind by built-in name or path."""
    data, path = load_data(name_or_path)
    return from_dict(data, source=str(path))


def to_yaml(sc, provenance=None):
    """
    Return a scene as YAML text that :func:`load` reads back bit for bit.

    Floats are written with their shortest exact representation.  ``provenance`` (a plain
    mapping, e.g. the summary of a balancing run) is stored under the scene's ``balance``
    key.
    """
    data = to_dict(sc)
    if provenance is not None:
        data['balance'] = provenance
    return yaml.safe_dump(plain(data), sort_keys=False, default_flow_style=None, width=99)


def plain(obj):
    """Return ``obj`` with numpy scalars and tuples turned into YAML-safe Python types."""
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


__all__ = ['add_counterweights', 'builtin_scenes', 'Counterweight', 'DEFAULT_OUTPUTS', 'Drive',
           'drive_from_dict', 'DriveError', 'FRAME', 'from_dict', 'INERTIA_ROUNDOFF', 'Joint',
           'KINDS', 'kind_of', 'Link', 'load', 'load_data', 'MAX_ABS_VALUE', 'needs',
           'Normalization', 'OUTPUTS', 'parse_yaml', 'plain', 'Recording', 'RECORDING_STREAMS',
           'resolve', 'RggrScene', 'Scene', 'SceneError', 'SCHEMA_VERSION', 'SERIES', 'to_dict',
           'to_yaml']
