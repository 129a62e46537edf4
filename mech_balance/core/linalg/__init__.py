"""Batched small square solves, batch last: :mod:`.ordering`, :mod:`.lu`, :mod:`.blocks`."""

from mech_balance.core.linalg.blocks import BlockFactored, BlockPlan
from mech_balance.core.linalg.lu import det_sign, Factored, inverse, matvec, matvec_t, solve
from mech_balance.core.linalg.ordering import block_triangular_order, LUPlan, static_plan

__all__ = ['BlockFactored', 'BlockPlan', 'Factored', 'LUPlan', 'block_triangular_order',
           'det_sign', 'inverse', 'matvec', 'matvec_t', 'solve', 'static_plan']
