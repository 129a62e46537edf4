"""Any single-input spatial linkage (``kind: spatial``); docs/design.md#layers."""

__all__ = ['assembly', 'branch', 'closure', 'coordinates', 'dynamics', 'kinematics', 'rig',
           'vectors']
