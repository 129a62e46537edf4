"""Branch following: the batched solve, its fallback, and the other assembly mode."""

import copy

from mech_balance import schema as scene
from mech_balance.analysis import cycle as analysis
from mech_balance.conventions import cycle_angles
from mech_balance.core.planar import kinematics
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
