"""
Balancing of spatial rigs: complete force balance, certified redistribution, counterweights.

Generic over every rig with the ``'body_kinematics'`` capability (the general ``kind:
spatial``, the RGGR of seed 002 among its scenes): the shaking wrench is linear in the ten
inertial parameters of each moving body (:mod:`mech_balance.core.regressor`), so

* **complete force balance** (:func:`force_balance`, :mod:`.null_space`): the null space of
  the force map, and the least change of the free bodies that meets it;
* **optimal redistribution** (:func:`redistribute`, :mod:`.redistribution`): minimize
  ``w1 f~ + w2 n~`` over the free bodies' parameters, each body physically realizable (PSD
  pseudo-inertia), with mass and extent bounds;
* **counterweights** (:func:`counterweights`, :mod:`.spheres`): add-only clusters of steel
  spheres on the listed bodies, certified the same way.

The modules: :mod:`.model` (parameter models, units, RMS maps, option checks),
:mod:`.program` (the cone program), :mod:`.repair` (the constraints at a design and the
repair of round-off), :mod:`.result` (evaluation, certificate, table, scene writer).  Every
program carries the safe lower bound of
:func:`mech_balance.balancing.certificate.folded_lower_bound`; the primal value is the core's
evaluation (``rig.at``) of the written design, and the design satisfies every constraint.
The derivations: docs/balancing.md, "Spatial rigs".
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
