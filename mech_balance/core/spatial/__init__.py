"""
Any single-input spatial linkage (``kind: spatial``): kinematics, dynamics, the Rig.

The modules and what each holds: docs/design.md#layers.
"""

__all__ = ['assembly', 'branch', 'closure', 'coordinates', 'dynamics', 'kinematics', 'rig',
           'vectors']
