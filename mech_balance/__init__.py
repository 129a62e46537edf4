"""
Digital twin of a balanced mechanism test rig.

The public face: a scene file becomes a rig; a rig is evaluated, analysed, balanced and
simulated; the same objects feed the ROS 2 node and the recordings::

    import mech_balance as mb
    sc = mb.load_scene('hoeken')                 # config/hoeken.yaml, or any path
    rig = mb.rig_for(sc)                         # the Rig protocol, any kind of rig
    data = rig.at([0.0, 0.1], speed=10.0)        # RigData: joints, shaking wrench, ...
    design = mb.balance(rig)                     # certified optimum (method by capability)
    print(design.masses_kg)                      # the balanced design, per link, kg

The same lines run on every built-in (``examples/quickstart.py``).  Every verb
(``run_cycle``, ``summarize``, ``balance``, ``identify``, ``simulate``) takes a rig or a scene
of any kind, and refuses a missing capability in one line (:class:`CapabilityError`).  Layers:
docs/design.md.  Names are imported on first use, so ``import mech_balance`` costs nothing.
"""

import importlib

__version__ = '0.1.0'

_PUBLIC = {
    'load_scene': ('mech_balance.schema', 'load'),
    'scene_to_yaml': ('mech_balance.schema', 'to_yaml'),
    'SceneError': ('mech_balance.schema', 'SceneError'),
    'Rig': ('mech_balance.core.rig', 'Rig'),
    'RigData': ('mech_balance.core.rig', 'RigData'),
    'rig_for': ('mech_balance.core.rig', 'rig_for'),
    'CapabilityError': ('mech_balance.core.rig', 'CapabilityError'),
    'PlanarRig': ('mech_balance.core.planar.rig', 'PlanarRig'),
    'SpatialRig': ('mech_balance.core.spatial.rig', 'SpatialRig'),
    'run_cycle': ('mech_balance.analysis.cycle', 'run_cycle'),
    'summarize': ('mech_balance.analysis.cycle', 'summarize'),
    'balance': ('mech_balance.balancing', 'balance'),
    'Design': ('mech_balance.balancing', 'Design'),
    'simulate': ('mech_balance.analysis.simulation', 'simulate'),
    'identify': ('mech_balance.analysis.identify', 'identify'),
}
__all__ = sorted(_PUBLIC) + ['__version__']


def __getattr__(name):
    """Return a public name (module docstring), importing its module on first use."""
    try:
        module, attr = _PUBLIC[name]
    except KeyError:
        raise AttributeError(f'module mech_balance has no attribute {name!r}') from None
    value = getattr(importlib.import_module(module), attr)
    globals()[name] = value
    return value


def __dir__():
    """List the public names."""
    return __all__
