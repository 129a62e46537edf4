"""
Any single-input spatial linkage (``kind: spatial``): kinematics, dynamics, the Rig.

:mod:`.kinematics` (spanning tree, cut joints, Newton, branch), :mod:`.assembly` (the stated
assembly: tree coordinates from the poses, the check that they hold), :mod:`.coordinates` (the
joints' published coordinates), :mod:`.dynamics` (shaking wrench, driving torque, bearing
reactions) and :mod:`.rig` (:class:`~.rig.SpatialRig`, the Rig protocol).
"""

__all__ = ['assembly', 'coordinates', 'dynamics', 'kinematics', 'rig']
