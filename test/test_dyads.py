"""The closed-form dyad positions and 2 x 2 block solves against the Newton and LU path."""

import cmath
import math
import os
import sys
import warnings

from mech_balance import schema as scene
from mech_balance.bench import chains as chain
from mech_balance.conventions import cycle_angles
from mech_balance.core import linalg
from mech_balance.core.linalg import blocks
from mech_balance.core.planar import dyads, kinematics
from mech_balance.core.planar.rig import PlanarRig
import numpy as np
from numpy.testing import assert_allclose
import pytest

sys.path.insert(0, os.path.dirname(__file__))
import test_extreme as extreme  # noqa: E402, I100

OUTPUTS = ('shaking_wrench', 'driving_torque', 'bearing_reactions')


def _pair(sc, monkeypatch):
    """Return ``(closed form rig, Newton rig)`` of one scene, neither cached."""
    fast = PlanarRig(sc, cache=False)
    with monkeypatch.context() as m:
        m.setattr(dyads, 'plan', lambda linkage: None)
        slow = PlanarRig(sc, cache=False)
    assert fast.linkage.dyads is not None and fast.linkage.block is not None
    assert slow.linkage.dyads is None and slow.linkage.block is None
    return fast, slow


def _agree(fast, slow, psi, speed=1.7, accel=-0.6):
    """Check that every output of the two rigs agrees to the solver's reported accuracy."""
    s1, w1 = fast.evaluate(psi, OUTPUTS, speed, accel)
    s2, w2 = slow.evaluate(psi, OUTPUTS, speed, accel)
    assert np.all(s1.iterations == 0) and np.max(s1.residual) <= kinematics.NEWTON_TOL
    # the positions err by about cond x the residual; rates and loads by cond^2 of that
    kappa = max(float(np.max(s2.cond)), 1.0)
    tol = 1e-13 * kappa * kappa
    for a, b in ((s1.q, s2.q), (s1.qd, s2.qd), (s1.qdd, s2.qdd), (s1.pose.origin, s2.pose.origin),
                 (s1.vel, s2.vel), (s1.acc, s2.acc), (w1.driving_torque, w2.driving_torque),
                 (w1.shaking_force, w2.shaking_force), (w1.shaking_moment, w2.shaking_moment)):
        assert_allclose(a, b, rtol=0, atol=tol * max(float(np.max(np.abs(b))), 1e-300))
    assert_allclose(s1.cond, s2.cond, rtol=1e-9 * kappa)
    for name in w2.reaction_force:
        f = w2.reaction_force[name]
        assert_allclose(w1.reaction_force[name], f, rtol=0,
                        atol=tol * max(float(np.max(np.abs(f))), 1e-300))
    return s1, s2


def _random_point(rng):
    return complex(*rng.uniform(-1.0, 1.0, 2))


def random_four_bar(rng, upper, name):
    """Return a random Grashof crank-rocker, points off the link lines, either branch."""
    while True:
        b, c, d = rng.uniform(2.0, 5.0, 3)
        if 1.0 + max(b, c, d) <= b + c + d - max(b, c, d) - 0.3:
            break
    o1 = _random_point(rng)
    o3 = o1 + d * cmath.exp(1j * rng.uniform(-math.pi, math.pi))
    local = {}
    for link, length, names in (('crank', 1.0, ('O1', 'A')), ('coupler', b, ('A', 'B')),
                                ('rocker', c, ('O3', 'B'))):
        p = _random_point(rng)
        local[link] = {names[0]: p, names[1]: p + length * cmath.exp(1j * rng.uniform(-3, 3))}
    psi0 = rng.uniform(-math.pi, math.pi)
    cr = local['crank']
    pa = o1 + cmath.exp(1j * psi0) * (cr['A'] - cr['O1'])
    v = o3 - pa
    dist = abs(v)
    x = (b * b - c * c + dist * dist) / (2.0 * dist)
    h = math.sqrt(b * b - x * x)
    pb = pa + v / dist * complex(x, h if upper else -h)
    co, ro = local['coupler'], local['rocker']
    phi_c = cmath.phase(pb - pa) - cmath.phase(co['B'] - co['A'])
    phi_r = cmath.phase(pb - o3) - cmath.phase(ro['B'] - ro['O3'])
    links = {}
    for link, pts in local.items():
        com = _random_point(rng)
        links[link] = {'points': {k: [p.real, p.imag] for k, p in pts.items()},
                       'mass_kg': float(rng.uniform(0.5, 2.0)), 'com_m': [com.real, com.imag],
                       'inertia_com_kg_m2': float(rng.uniform(0.01, 0.5))}
    data = {
        'name': name, 'kind': 'planar',
        'crank': {'joint': 'O1', 'speed_rad_s': 1.0},
        'frame': {'points': {'O1': [o1.real, o1.imag], 'O3': [o3.real, o3.imag]}},
        'links': links,
        'joints': {'O1': {'type': 'revolute', 'a': 'frame.O1', 'b': 'crank.O1'},
                   'A': {'type': 'revolute', 'a': 'crank.A', 'b': 'coupler.A'},
                   'B': {'type': 'revolute', 'a': 'coupler.B', 'b': 'rocker.B'},
                   'O3': {'type': 'revolute', 'a': 'frame.O3', 'b': 'rocker.O3'}},
        'assembly': {'crank_angle_deg': math.degrees(psi0),
                     'link_angles_deg': {'coupler': math.degrees(phi_c),
                                         'rocker': math.degrees(phi_r)}},
        'outputs': list(OUTPUTS),
    }
    return scene.from_dict(data, source='test')


@pytest.mark.parametrize('seed', range(6))
@pytest.mark.parametrize('upper', [True, False])
def test_random_four_bar_closed_form_agrees_with_newton_on_both_branches(seed, upper,
                                                                         monkeypatch):
    rng = np.random.default_rng(seed)
    sc = random_four_bar(rng, upper, f'random_four_bar_{seed}_{upper}')
    fast, slow = _pair(sc, monkeypatch)
    psi = np.concatenate([cycle_angles(180), rng.uniform(-20.0, 20.0, 40)])
    _agree(fast, slow, psi)
    # the branch sign is the assembly mode's: B to the left of A -> O3 on the upper branch
    assert fast.linkage.dyads.steps[0].sign == (1.0 if upper else -1.0)


def test_both_assembly_modes_give_mirror_branches(monkeypatch):
    rng = np.random.default_rng(11)
    up = PlanarRig(random_four_bar(np.random.default_rng(11), True, 'up'), cache=False)
    down = PlanarRig(random_four_bar(np.random.default_rng(11), False, 'down'), cache=False)
    assert up.linkage.dyads.steps[0].sign == -down.linkage.dyads.steps[0].sign
    psi = cycle_angles(90) + rng.uniform()
    s_up, _ = up.evaluate(psi, ('kinematics',))
    s_down, _ = down.evaluate(psi, ('kinematics',))
    assert np.min(np.abs(s_up.pose.origin[2:] - s_down.pose.origin[2:]).max(axis=0)) > 1e-3


@pytest.mark.parametrize('name', ['hoeken', 'carpet_scraper'])
def test_builtin_dyad_rigs_agree_with_newton(name, monkeypatch):
    sc = scene.load(name).with_outputs(scene.OUTPUTS)
    fast, slow = _pair(sc, monkeypatch)
    s1, _ = _agree(fast, slow, np.concatenate([cycle_angles(360), np.linspace(-9.0, 15.0, 77)]))
    # every loop a dyad, solved in closed form (no Newton iteration) at every angle
    assert len(fast.linkage.dyads.steps) == {'hoeken': 1, 'carpet_scraper': 3}[name]
    assert s1.iterations.shape == (437,) and np.all(s1.iterations == 0)


@pytest.mark.parametrize('loops, skew', [(1, 0.0), (4, 0.03), (9, 0.11)])
def test_chains_agree_with_newton(loops, skew, monkeypatch):
    fast, slow = _pair(chain.dyad_chain(loops, skew=skew), monkeypatch)
    assert len(fast.linkage.dyads.steps) == loops
    _agree(fast, slow, cycle_angles(120) + 0.3)


def test_carpet_scraper_has_both_kinds_of_dyad():
    lk = PlanarRig(scene.load('carpet_scraper'), cache=False).linkage
    kinds = [s.beta_at_x for s in lk.dyads.steps]
    assert True in kinds and False in kinds


def test_prismatic_rigs_keep_newton():
    lk = PlanarRig(scene.load('slider_crank'), cache=False).linkage
    assert lk.dyads is None and lk.block is None


def test_near_singular_four_bar_is_flagged_on_the_closed_form_path(monkeypatch):
    # a stretched change point 1e-8 away: the condition number passes COND_WARN near 180 deg
    a, b, c, d = 1.0, 3.0, 2.5, 4.5 - 1e-8
    sc = extreme.four_bar(a, b, c, d)              # the change-point tests' four-bar
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', RuntimeWarning)
        fast, slow = _pair(sc, monkeypatch)
    psi = cycle_angles(3600)
    with pytest.warns(RuntimeWarning, match=r'crank angle 1[78]\d\.\d+ deg: near-singular'):
        s1, _ = fast.evaluate(psi, ('kinematics',))
    assert np.max(s1.cond) > kinematics.COND_WARN
    assert np.all(s1.iterations == 0)
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', RuntimeWarning)
        s2, _ = slow.evaluate(psi, ('kinematics',))
    kappa = float(np.max(s2.cond))
    assert_allclose(s1.pose.origin, s2.pose.origin, rtol=0, atol=1e-13 * kappa * d)
    assert_allclose(s1.cond, s2.cond, rtol=1e-13 * kappa * kappa)


def test_closed_form_falls_back_to_newton_where_it_fails(monkeypatch):
    rig = PlanarRig(chain.dyad_chain(3), cache=False)
    lk = rig.linkage
    psi = cycle_angles(30) + 0.1
    good, _ = rig.evaluate(psi, ('kinematics',))
    solve = lk.dyads.solve

    def broken(psi, q_pred, signs=None):
        q, rot, origin, joint_at = solve(psi, q_pred, signs)
        q[1:, 7] = np.nan                        # one angle without an intersection
        rot[1:, 7] = origin[1:, 7] = joint_at[1:, 7] = np.nan
        return q, rot, origin, joint_at

    monkeypatch.setattr(lk.dyads, 'solve', broken)
    state, _ = rig.evaluate(psi, ('kinematics',))
    assert state.iterations.max() >= 1          # Newton took over
    assert_allclose(state.q, good.q, rtol=0, atol=1e-12)


def test_a_dyad_whose_sign_changes_on_the_skeleton_drops_the_plan():
    lk = PlanarRig(scene.load('hoeken'), cache=False).linkage
    plan = dyads.plan(lk)
    sk = lk.skeleton
    real = plan.signs_at

    def flipping(linkage, pose):
        s = real(linkage, pose)
        s[0, 3] *= -1.0
        return s

    plan.signs_at = flipping
    assert dyads.attach_signs(plan, lk, sk) is None
    assert dyads.attach_signs(None, lk, sk) is None


@pytest.mark.parametrize('name, tree_like',
                         [('chain', True), ('chain', False), ('carpet_scraper', False)])
def test_block_factored_agrees_with_lapack(name, tree_like, monkeypatch):
    sc = chain.dyad_chain(6) if name == 'chain' else scene.load(name)
    rig = PlanarRig(sc, cache=False)
    lk = rig.linkage
    assert lk.block.tree_like == (name == 'chain')
    # the linear-time norm of the inverse (one earlier unknown per block) or the full one
    monkeypatch.setattr(lk.block, 'tree_like', tree_like)
    st, _ = rig.evaluate(cycle_angles(12) + 0.4, ('kinematics',))
    values, _ = lk.jacobian_values(st.pose)
    rng = np.random.default_rng(3)
    values = values * rng.uniform(0.5, 1.5, values.shape)    # other matrices, same pattern
    fac = linalg.BlockFactored(lk.block, values)
    stack = np.moveaxis(fac.mat, -1, 0)
    b = rng.normal(size=(lk.nu, values.shape[1]))
    x = np.linalg.solve(stack, b.T[:, :, None])[:, :, 0].T
    xt = np.linalg.solve(np.transpose(stack, (0, 2, 1)), b.T[:, :, None])[:, :, 0].T
    assert_allclose(fac.solve(b), x, rtol=1e-10, atol=1e-12)
    assert_allclose(fac.solve_t(b), xt, rtol=1e-10, atol=1e-12)
    assert_allclose(fac.cond(), [np.linalg.cond(m, 1) for m in stack], rtol=1e-10)
    inv, _ = fac.inverse()
    assert_allclose(np.moveaxis(inv, -1, 0), np.linalg.inv(stack), rtol=1e-9, atol=1e-12)
    assert np.array_equal(fac.sign(), np.sign(np.linalg.det(stack)))


def test_single_block_agrees_with_lapack_and_singular_is_infinite():
    lk = PlanarRig(scene.load('hoeken'), cache=False).linkage
    assert lk.block.single
    rng = np.random.default_rng(5)
    values = rng.normal(size=(4, 20))
    values[:, 3] = [1.0, 2.0, 2.0, 4.0]          # singular
    fac = linalg.BlockFactored(lk.block, values)
    stack = np.moveaxis(fac.mat, -1, 0)
    ok = np.arange(20) != 3
    b = rng.normal(size=(2, 20))
    x = np.linalg.solve(stack[ok], b.T[ok][:, :, None])[:, :, 0].T
    assert_allclose(fac.solve(b)[:, ok], x, rtol=1e-10, atol=1e-12)
    xt = np.linalg.solve(np.transpose(stack[ok], (0, 2, 1)), b.T[ok][:, :, None])[:, :, 0].T
    assert_allclose(fac.solve_t(b)[:, ok], xt, rtol=1e-10, atol=1e-12)
    cond = fac.cond()
    assert_allclose(cond[ok], [np.linalg.cond(m, 1) for m in stack[ok]], rtol=1e-12)
    assert cond[3] == np.inf
    assert np.array_equal(fac.sign()[ok], np.sign(np.linalg.det(stack[ok])))


def test_block_plan_refuses_what_is_not_block_triangular():
    with pytest.raises(ValueError, match='above the diagonal blocks'):
        linalg.BlockPlan(4, [0, 1, 0, 1, 2, 3, 2, 3, 0], [0, 0, 1, 1, 2, 2, 3, 3, 2],
                         [((0, 1), (0, 1)), ((2, 3), (2, 3))])
    with pytest.raises(ValueError, match='diagonal block entry is missing'):
        linalg.BlockPlan(2, [0, 1, 0], [0, 0, 1], [((0, 1), (0, 1))])
    with pytest.raises(ValueError, match='exactly one block'):
        linalg.BlockPlan(2, [0, 1, 0, 1], [0, 0, 1, 1], [((0, 0), (0, 1))])


@pytest.mark.parametrize('case', ['hoeken', 'carpet_scraper', 'chain', 0, 1, 2, 3])
def test_whole_turns_from_the_line_the_table_and_the_predictor_agree(case):
    if case == 'chain':
        sc = chain.dyad_chain(6)
    elif isinstance(case, str):
        sc = scene.load(case)
    else:
        sc = random_four_bar(np.random.default_rng(case), case % 2 == 0, f'turns_{case}')
    lk = PlanarRig(sc, cache=False).linkage
    sk = lk.skeleton
    rng = np.random.default_rng(7)
    psi = np.concatenate([cycle_angles(360), rng.uniform(-60.0, 60.0, 200),
                          sk.psi[0] + np.arange(-3, 4) * 2 * math.pi])   # the turn's ends
    results = {}
    line, table = lk.turn_line, lk.turn_table_ok
    try:
        for name, settings in (('line', (line, False)), ('table', (None, True)),
                               ('predictor', (None, False))):
            if name == 'line' and line is None or name == 'table' and not table:
                continue   # this rig's references stray too far: not used (below)
            lk.turn_line, lk.turn_table_ok = settings
            q, _, res, iters, ok, _ = lk.closed_form(psi)
            assert ok.all() and not iters.any()
            results[name] = q
    finally:
        lk.turn_line, lk.turn_table_ok = line, table
    for name, q in results.items():
        assert np.array_equal(q, results['predictor']), name
    # a reference is used only within CHORD_TRUST of the predictor (well below pi)
    assert (line is not None) == (sk.affine_reference()[2] <= kinematics.CHORD_TRUST)
    assert table == (sk.turn_table_error() <= kinematics.CHORD_TRUST)


def test_single_block_takes_an_errstate_only_where_a_block_is_singular(monkeypatch):
    lk = PlanarRig(scene.load('hoeken'), cache=False).linkage
    rng = np.random.default_rng(11)
    entered = []
    real = np.errstate

    def counting(**kw):
        entered.append(kw)
        return real(**kw)

    monkeypatch.setattr(blocks.np, 'errstate', counting)
    values = rng.normal(size=(4, 9))
    with warnings.catch_warnings():
        warnings.simplefilter('error')                # no RuntimeWarning either way
        fac = linalg.BlockFactored(lk.block, values)
        assert not entered                            # nonsingular: no errstate
        stack = np.moveaxis(fac.mat, -1, 0)
        assert_allclose(fac.cond(), [np.linalg.cond(m, 1) for m in stack], rtol=1e-12)
        values[:, 6] = [1.0, 2.0, 2.0, 4.0 * (1.0 + 1e-15)]   # nearly singular
        fac = linalg.BlockFactored(lk.block, values)
        assert not entered and 1e14 < fac.cond()[6] < np.inf
        values[:, 2] = 0.0                            # 0/0
        values[:, 5] = [1e-80, 0.0, 0.0, 1e-80]       # |det| below the threshold, fine
        fac = linalg.BlockFactored(lk.block, values)
        assert entered
    cond = fac.cond()
    assert cond[2] == np.inf and cond[5] == 1.0 and 1e14 < cond[6] < np.inf
    ok = ~np.isin(np.arange(9), [2, 5, 6])
    stack = np.moveaxis(fac.mat, -1, 0)
    assert_allclose(cond[ok], [np.linalg.cond(m, 1) for m in stack[ok]], rtol=1e-12)


def test_dyads_that_do_not_close_give_nan_without_warnings():
    lk = PlanarRig(scene.load('hoeken'), cache=False).linkage
    plan, psi = lk.dyads, cycle_angles(8)
    ref = np.zeros((lk.nt - 1, psi.size))
    step = plan.steps[0]
    saved = step.r1_sq
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        assert plan._place(psi, None, checked=True) is not None
        assert np.isfinite(plan.solve(psi, ref)[0]).all()
        try:
            step.r1_sq = np.array(0.0)     # a link of no length: the circles never meet
            assert plan._place(psi, None, checked=True) is None
            q, rot, origin, joint_at = plan.solve(psi, ref)
        finally:
            step.r1_sq = saved
    assert np.isnan(q[1:]).all() and np.isnan(rot[step.alpha]).all()
    assert np.array_equal(q[0], psi)


@pytest.mark.parametrize('name', ['hoeken', 'carpet_scraper', 'slider_crank'])
def test_the_core_evaluates_an_empty_batch(name):
    rig = PlanarRig(scene.load(name), cache=False)
    state, w = rig.evaluate(np.array([]))
    assert state.q.shape == (rig.linkage.nt, 0) and state.cond.shape == (0,)
    assert w.shaking_force.shape == (0,) and w.consistency == 0.0
    assert all(f.shape == (0,) for f in w.reaction_force.values())
