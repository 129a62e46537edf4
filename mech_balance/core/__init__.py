"""
The numerical core of mech_balance (numpy and scipy only).

The modules and what each holds: docs/design.md#layers.
"""

__all__ = ['continuation', 'equimomental', 'forward', 'integrators', 'linalg', 'planar',
           'regressor', 'rig', 'spatial']
