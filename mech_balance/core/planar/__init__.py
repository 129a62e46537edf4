"""
Any single-input planar linkage (``kind: planar``): kinematics, dynamics, the Rig.

The modules and what each holds: docs/design.md#layers.
"""

__all__ = ['algebra', 'drawn', 'dyads', 'dynamics', 'kinematics', 'rates', 'rig', 'skeleton',
           'tree']
