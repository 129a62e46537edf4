"""
Balancing of spatial rigs: complete force balance, certified redistribution, counterweights.

Generic over every rig with the ``'body_kinematics'`` capability: the shaking wrench is
linear in each body's ten inertial parameters (:mod:`mech_balance.core.regressor`), so
:func:`force_balance` (:mod:`.null_space`) is the null space of the force map,
:func:`redistribute` (:mod:`.redistribution`) a certified cone program over realizable bodies
and :func:`counterweights` (:mod:`.spheres`) certified add-only sphere clusters.  The
primal value is the core's evaluation of the written design.  The derivations:
docs/balancing.md, "Spatial rigs".
"""

from mech_balance.balancing.spatial.model import parameter_model, PARAMETER_MODELS, \
    SpatialBalanceError
from mech_balance.balancing.spatial.null_space import force_balance, ForceBalance, \
    format_conditions
from mech_balance.balancing.spatial.redistribution import redistribute
from mech_balance.balancing.spatial.result import SpatialResult, write_scene
from mech_balance.balancing.spatial.spheres import counterweights

__all__ = ['counterweights', 'force_balance', 'ForceBalance', 'format_conditions',
           'parameter_model', 'PARAMETER_MODELS', 'redistribute', 'SpatialBalanceError',
           'SpatialResult', 'write_scene']
