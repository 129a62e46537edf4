"""
Balancing of spatial rigs: complete force balance, certified redistribution, counterweights.

For every rig with ``'body_kinematics'`` (docs/balancing.md, "Spatial rigs").
"""

from mech_balance.balancing.spatial.model import parameter_model, SpatialBalanceError
from mech_balance.balancing.spatial.null_space import force_balance, format_conditions
from mech_balance.balancing.spatial.redistribution import redistribute
from mech_balance.balancing.spatial.result import SpatialResult, write_scene
from mech_balance.balancing.spatial.spheres import counterweights

__all__ = ['counterweights', 'force_balance', 'format_conditions', 'parameter_model',
           'redistribute', 'SpatialBalanceError', 'SpatialResult', 'write_scene']
