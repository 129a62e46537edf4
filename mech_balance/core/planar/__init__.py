"""Any single-input planar linkage (``kind: planar``); docs/design.md#layers."""

__all__ = ['algebra', 'drawn', 'dyads', 'dynamics', 'kinematics', 'rates', 'rig', 'skeleton',
           'tree']
