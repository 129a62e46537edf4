"""
The numerical core of mech_balance (numpy and scipy only; docs/design.md has the layers).

:mod:`.rig` (the Rig protocol all kinds implement), :mod:`.planar` and :mod:`.spatial` (the
two kinds' kinematics, dynamics and rigs), :mod:`.linalg` (batched small solves, used by
both), :mod:`.continuation` (the branch tracer, used by both), :mod:`.forward` and
:mod:`.integrators` (forward dynamics), :mod:`.equimomental` and :mod:`.regressor` (link
mass parameters).
"""

__all__ = ['continuation', 'equimomental', 'forward', 'integrators', 'linalg', 'planar',
           'regressor', 'rig', 'spatial']
