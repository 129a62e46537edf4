"""
Any single-input planar linkage (``kind: planar``): kinematics, dynamics, the Rig.

:mod:`.kinematics` (positions: Newton, the dyads' closed form, the traced branch),
:mod:`.tree` (the spanning tree and its sums), :mod:`.rates` (velocities and
accelerations), :mod:`.skeleton` (the branch's nodes and predictor), :mod:`.dyads` (the RRR
dyads' closed form), :mod:`.algebra` (complex-coded planar vectors), :mod:`.dynamics`
(shaking wrench, driving torque, bearing reactions), :mod:`.drawn` (drawn sizes) and
:mod:`.rig` (:class:`~.rig.PlanarRig`, the Rig protocol).
"""

__all__ = ['algebra', 'drawn', 'dyads', 'dynamics', 'kinematics', 'rates', 'rig', 'skeleton',
           'tree']
