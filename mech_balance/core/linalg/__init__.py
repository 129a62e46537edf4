"""
Batched solves of many small square systems, batch on the last axis (both cores use it).

:mod:`.ordering` (a static row and column order per sparsity pattern, the symbolic LU
:class:`LUPlan`), :mod:`.lu` (:class:`Factored`, :func:`solve`, :func:`inverse`,
:func:`det_sign`: closed form for k <= 2, the static-order sparse LU above, LAPACK where its
pivots are weak) and :mod:`.blocks` (:class:`BlockFactored`: 2 x 2 diagonal blocks in closed
form, the RRR dyads' Jacobian).
"""

from mech_balance.core.linalg.blocks import BlockFactored, BlockPlan
from mech_balance.core.linalg.lu import det_sign, Factored, inverse, matvec, matvec_t, solve
from mech_balance.core.linalg.ordering import block_triangular_order, LUPlan, pivot_order

__all__ = ['BlockFactored', 'BlockPlan', 'Factored', 'LUPlan', 'block_triangular_order',
           'det_sign', 'inverse', 'matvec', 'matvec_t', 'pivot_order', 'solve']
