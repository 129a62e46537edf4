"""The numerical core of mech_balance (numpy and scipy only); docs/design.md#layers."""

__all__ = ['continuation', 'equimomental', 'forward', 'integrators', 'linalg', 'planar',
           'regressor', 'rig', 'spatial']
