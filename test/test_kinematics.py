"""Branch following: the batched solve, its fallback, the other assembly mode, the solves."""

import copy

from mech_balance import schema as scene
from mech_balance.analysis import cycle as analysis
from mech_balance.bench import chains as chain
from mech_balance.conventions import cycle_angles
from mech_balance.core import linalg
from mech_balance.core.planar import algebra, kinematics, tree
from mech_balance.core.planar.rig import PlanarRig
import numpy as np
from numpy.testing import assert_allclose
import pytest


def test_retrace_fallback_agrees_with_batched_newton(monkeypatch):
    rig = analysis.Rig(scene.load('carpet_scraper'))
    psi = cycle_angles(40) + 0.013
    fast, _ = rig.evaluate(psi, ('kinematics',))
    # every predictor correction now counts as 'too large': all angles are re-traced step by
    # step from the nearest branch node, the slow path used near trouble
    monkeypatch.setattr(kinematics, 'EVAL_TRUST', -1.0)
    slow, _ = rig.evaluate(psi, ('kinematics',))
    assert_allclose(slow.q, fast.q, rtol=0, atol=1e-12)
    assert np.max(slow.residual) < 1e-12


def test_mirrored_branch_is_a_mirror_image():
    data, _ = scene.load_data('hoeken')
    mirrored = copy.deepcopy(data)
    mirrored['assembly']['link_angles_deg'] = {'coupler': -77.0, 'rocker': -103.0}
    up = analysis.Rig(scene.load('hoeken'))
    down = analysis.Rig(scene.from_dict(mirrored, source='mirrored'))
    psi = cycle_angles(72)
    s_up, w_up = up.evaluate(psi)
    s_down, w_down = down.evaluate(-psi)              # the mirror image turns the other way
    assert_allclose(s_down.pose.origin, np.conj(s_up.pose.origin), atol=1e-14)
    assert_allclose(w_down.shaking_force, np.conj(w_up.shaking_force), atol=1e-14)
    assert_allclose(w_down.shaking_moment, -w_up.shaking_moment, atol=1e-14)
    # a different branch, not the same one found again
    assert np.max(np.abs(s_down.pose.origin - s_up.pose.origin)) > 0.05


def test_each_angle_reports_residual_condition_and_iterations():
    rig = analysis.Rig(scene.load('slider_crank'))
    psi = cycle_angles(360)
    state, _ = rig.evaluate(psi)
    assert state.residual.shape == state.cond.shape == state.iterations.shape == (360,)
    assert np.all(state.residual < 1e-12)
    assert np.all((state.cond >= 1.0) & (state.cond < kinematics.COND_WARN))
    assert np.all(state.iterations <= 2)


def test_non_finite_angle_is_rejected():
    rig = analysis.Rig(scene.load('hoeken'))
    with pytest.raises(ValueError, match='crank_angle_rad: got a non-finite value'):
        rig.evaluate(np.array([0.0, np.nan]))


# ----------------------------------------------------------------------------- structured solves


def _block_bidiagonal(rng, blocks, p, width=2):
    """Return a pattern and a batch of matrices: 2 x 2 diagonal blocks, one coupling each."""
    k = width * blocks
    pattern = np.zeros((k, k), dtype=bool)
    for b in range(blocks):
        s = slice(width * b, width * b + width)
        pattern[s, s] = True
        if b:
            pattern[s, width * b - 1] = True          # the previous block's last unknown
    perm_r, perm_c = rng.permutation(k), rng.permutation(k)   # hide the structure
    pattern = pattern[perm_r][:, perm_c]
    mat = np.where(pattern[:, :, None], rng.normal(size=(k, k, p)), 0.0)
    mat += 3.0 * np.eye(k)[perm_r][:, perm_c][:, :, None]     # well conditioned
    return pattern, mat


def test_block_triangular_order_finds_the_blocks_without_fill():
    rng = np.random.default_rng(7)
    pattern, mat = _block_bidiagonal(rng, 12, 1)
    rows, cols = linalg.block_triangular_order(pattern, mat[:, :, 0])
    permuted = pattern[rows][:, cols]
    # block lower triangular with 2 x 2 diagonal blocks: nothing right of each block
    for b in range(12):
        assert not permuted[2 * b:2 * b + 2, 2 * b + 2:].any()
    plan = linalg.LUPlan(pattern, rows, cols)
    assert plan.nnz <= pattern.sum() + 12           # at most one fill-in per block coupling
    # a structurally singular pattern has no perfect matching
    singular = pattern.copy()
    singular[:, cols[0]] = False
    assert linalg.block_triangular_order(singular, mat[:, :, 0]) is None


@pytest.mark.parametrize('from_values', [False, True])
def test_factored_agrees_with_lapack(from_values):
    rng = np.random.default_rng(11)
    pattern, mat = _block_bidiagonal(rng, 7, 50)
    rows, cols = linalg.block_triangular_order(pattern, mat[:, :, 0])
    plan = linalg.LUPlan(pattern, rows, cols)
    # make the static pivot of one angle vanish: that angle must go to LAPACK (weak)
    first = (rows[0], cols[0])
    mat[first[0], first[1], 3] = 1e-9
    if from_values:
        r, c = np.nonzero(pattern)
        plan.set_entries(r, c)
        fac = linalg.Factored(None, plan, values=mat[r, c])
    else:
        fac = linalg.Factored(mat, plan)
    assert fac.weak[3] and fac.weak.sum() < 5
    b = rng.normal(size=(14, 50))
    stack = np.moveaxis(mat, -1, 0)
    x = np.linalg.solve(stack, b.T[:, :, None])[:, :, 0].T
    xt = np.linalg.solve(np.transpose(stack, (0, 2, 1)), b.T[:, :, None])[:, :, 0].T
    assert_allclose(fac.solve(b), x, rtol=1e-11, atol=1e-12)
    assert_allclose(fac.solve_t(b), xt, rtol=1e-11, atol=1e-12)
    cond = np.array([np.linalg.cond(m, 1) for m in stack])
    assert_allclose(fac.cond(), cond, rtol=1e-11)
    inv, cond2 = fac.inverse()
    assert_allclose(np.moveaxis(inv, -1, 0), np.linalg.inv(stack), rtol=1e-10, atol=1e-12)
    assert_allclose(cond2, cond, rtol=1e-11)
    assert np.array_equal(fac.sign(), np.sign(np.linalg.det(stack)))


def test_chain_jacobian_is_kept_sparse_and_agrees_with_dense_lapack():
    rig = analysis.Rig(chain.dyad_chain(19))
    lk = rig.linkage
    assert lk.sparse_jac and lk.lu.nnz <= 1.5 * lk._jacobian_pattern().sum()  # no fill
    psi = cycle_angles(24) + 0.2
    st, w = rig.evaluate(psi, ('bearing_reactions',))
    assert st.jac is None
    dense = lk.jacobian(st.pose)                       # (m, nt, p), the dense reference
    ju = np.moveaxis(dense[:, 1:], -1, 0)
    qd_u = np.linalg.solve(ju, -dense[:, 0].T[:, :, None])[:, :, 0].T * st.psi_d
    assert_allclose(st.qd[1:], qd_u, rtol=0, atol=1e-12 * np.max(np.abs(qd_u)))
    assert_allclose(st.cond, [np.linalg.cond(m, 1) for m in ju], rtol=1e-10)
    assert_allclose(st.jac_inv, np.moveaxis(np.linalg.inv(ju), 0, -1), rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize('name', ['slider_crank', 'carpet_scraper', 'hoeken'])
def test_tree_level_sums_agree_with_dense_ancestry_products(name, monkeypatch):
    sc = scene.load(name).with_outputs(scene.OUTPUTS)
    psi = cycle_angles(36) + 0.05
    dense = analysis.Rig(sc, cache=False)
    assert dense.linkage.dense_tree
    monkeypatch.setattr(tree, 'DENSE_TREE_MAX_BODIES', 0)   # force the level sums
    levels = analysis.Rig(sc, cache=False)
    assert not levels.linkage.dense_tree
    s1, w1 = dense.evaluate(psi, speed=2.3, accel=-1.1)
    s2, w2 = levels.evaluate(psi, speed=2.3, accel=-1.1)
    for a, b in ((s1.pose.origin, s2.pose.origin), (s1.vel, s2.vel), (s1.acc, s2.acc),
                 (w1.shaking_force, w2.shaking_force), (w1.driving_torque, w2.driving_torque)):
        assert_allclose(b, a, rtol=0, atol=1e-13 * np.max(np.abs(a)))
    for joint, force in w1.reaction_force.items():
        assert_allclose(w2.reaction_force[joint], force, rtol=0,
                        atol=1e-13 * np.max(np.abs(force)))
        moment = w1.reaction_moment[joint]
        assert_allclose(w2.reaction_moment[joint], moment, rtol=0,
                        atol=1e-13 * max(np.max(np.abs(moment)), 1.0))


@pytest.mark.parametrize('name', ['hoeken', 'carpet_scraper', 'slider_crank'])
def test_batch_size_changes_and_large_batches_give_the_same_figures(name):
    """The constant columns are tiled per batch size (``algebra.Tiles``), up to a limit."""
    rig = PlanarRig(scene.load(name), cache=False)
    nb = rig.linkage.nb
    p_large = algebra.TILE_LIMIT // nb + 7               # beyond the limit: the columns
    psi = np.linspace(-7.0, 7.0, p_large)
    whole, w_whole = rig.evaluate(psi)
    for part in (psi[:5], psi[5:360], psi[:5], psi[-1:]):   # the batch size changing back
        state, w = rig.evaluate(part)
        at = np.searchsorted(psi, part)
        assert_allclose(state.q, whole.q[:, at], rtol=0, atol=1e-12)
        scale = np.max(np.abs(w_whole.shaking_force))
        assert_allclose(w.shaking_force, w_whole.shaking_force[at], rtol=0, atol=1e-12 * scale)
        assert_allclose(w.driving_torque, w_whole.driving_torque[at], rtol=0,
                        atol=1e-12 * np.max(np.abs(w_whole.driving_torque)))
