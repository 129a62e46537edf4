"""
Any single-input spatial linkage (``kind: spatial``): kinematics, dynamics, the Rig.

:mod:`.kinematics` (spanning tree, cut joints, Newton, branch), :mod:`.coordinates` (the
joints' published coordinates), :mod:`.dynamics` (shaking wrench, driving torque, bearing
reactions) and :mod:`.rig` (:class:`~.rig.SpatialRig`, the Rig protocol).
"""

__all__ = ['coordinates', 'dynamics', 'kinematics', 'rig']
