"""
Batched solves of many small square systems, batch on the last axis (both cores use it).

:mod:`.ordering` (static orders, the symbolic :class:`LUPlan`), :mod:`.lu` (:class:`Factored`,
:func:`solve`, :func:`inverse`, :func:`det_sign`) and :mod:`.blocks` (:class:`BlockFactored`,
the RRR dyads' Jacobian).
"""

from mech_balance.core.linalg.blocks import BlockFactored, BlockPlan
from mech_balance.core.linalg.lu import det_sign, Factored, inverse, matvec, matvec_t, solve
from mech_balance.core.linalg.ordering import block_triangular_order, LUPlan, pivot_order

__all__ = ['BlockFactored', 'BlockPlan', 'Factored', 'LUPlan', 'block_triangular_order',
           'det_sign', 'inverse', 'matvec', 'matvec_t', 'pivot_order', 'solve']
