"""
Any single-input spatial linkage (``kind: spatial``): kinematics, dynamics, the Rig.

:mod:`.kinematics` (spanning tree, Newton, rates, evaluation), :mod:`.closure` (the cut
joints' closure rows), :mod:`.branch` (the traced branch, its limits and predictor),
:mod:`.assembly` (the stated assembly: tree coordinates from the poses, Levenberg-Marquardt,
idle spins, the check that the poses hold), :mod:`.vectors` (stack vector helpers),
:mod:`.coordinates` (the joints' published coordinates), :mod:`.dynamics` (shaking wrench,
driving torque, bearing reactions) and :mod:`.rig` (:class:`~.rig.SpatialRig`, the Rig
protocol).
"""

__all__ = ['assembly', 'branch', 'closure', 'coordinates', 'dynamics', 'kinematics', 'rig',
           'vectors']
