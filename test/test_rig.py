"""The Rig protocol: one model for every kind of rig, and what it computes only when asked."""

import json
import math

from mech_balance import schema
from mech_balance.analysis import cycle as analysis
from mech_balance.cli import main as cli
from mech_balance.conventions import cycle_angles
from mech_balance.core.rig import rig_for
from mech_balance.schema.scene import SERIES
import numpy as np
from numpy.testing import assert_allclose
import pytest

SCENES = sorted(schema.builtin_scenes())
FD_STEP_S = 1e-5


@pytest.fixture(params=SCENES)
def rig(request):
    return rig_for(schema.load(request.param))


def test_every_built_in_scene_builds_a_rig_with_the_protocol(rig):
    for attr in ('scene', 'name', 'joint_names', 'crank_joint', 'moment_point',
                 'capabilities', 'driving_series', 'outputs', 'drawing'):
        assert getattr(rig, attr) is not None, attr
    assert rig.crank_joint in rig.joint_names
    assert schema.kind_of(rig) is schema.kind_of(rig.scene)
    data = rig.at(cycle_angles(12), outputs=('shaking_wrench', 'driving_torque'))
    n, nj = 12, len(rig.joint_names)
    assert data.joint_position.shape == (n, nj) and data.joint_velocity.shape == (n, nj)
    assert data.force_N.shape == (n, 3) and data.moment_Nm.shape == (n, 3)
    # the driving effort under the series the rig names (a prismatic input's: a force)
    assert set(data.series) == {rig.driving_series} and rig.driving_series in SERIES
    assert data.series[rig.driving_series].shape == (n,)
    assert data.residual.shape == (n,) and data.near_singular.dtype == bool
    bodies = data.bodies
    assert bodies.names[0] == 'frame' and bodies.origin_m.shape[:2] == (n, len(bodies.names))
    rot = bodies.rotation
    assert_allclose(np.einsum('nbij,nbkj->nbik', rot, rot), np.broadcast_to(np.eye(3),
                    rot.shape), atol=1e-12)


def test_outputs_not_asked_for_are_not_computed(rig):
    """Leave out what a scene does not need: both kinds."""
    psi = cycle_angles(8)
    kin = rig.at(psi, outputs=('kinematics',))
    assert kin.force_N is None and kin.joint_effort is None and not kin.series
    wrench = rig.at(psi, outputs=('shaking_wrench',))
    assert wrench.force_N is not None and rig.driving_series not in wrench.series
    assert 'kinetic_energy' not in wrench.series and wrench.reactions is None
    energy = rig.at(psi, outputs=('kinematics', 'kinetic_energy'))
    assert set(energy.series) == {'kinetic_energy'} and energy.force_N is None


def test_planar_rig_data_is_the_core_evaluation():
    sc = schema.load('hoeken')
    rig = rig_for(sc)
    psi = cycle_angles(30)
    data = rig.at(psi, 3.0, -0.5, outputs=('bearing_reactions',))
    state, w = analysis.Rig(sc).evaluate(psi, ('bearing_reactions',), 3.0, -0.5)
    assert_allclose(data.force_N[:, 0] + 1j * data.force_N[:, 1], w.shaking_force, rtol=1e-13)
    assert_allclose(data.moment_Nm[:, 2], w.shaking_moment, rtol=1e-13)
    assert_allclose(data.series['driving_torque'], w.driving_torque, rtol=1e-12)
    for name, (force, moment) in data.reactions.items():
        assert_allclose(force[:, 0] + 1j * force[:, 1], w.reaction_force[name], rtol=1e-13)
        assert_allclose(moment[:, 2], w.reaction_moment[name], rtol=1e-13)
    assert_allclose(data.residual, state.residual)
    assert not data.near_singular.any()


@pytest.mark.parametrize('name', SCENES)
def test_drawing_and_poses_close_every_joint(name):
    """Both points of every joint meet in the frame: the drawing adapter's invariant."""
    rig = rig_for(schema.load(name))
    drawing, data = rig.drawing, rig.at(cycle_angles(24), outputs=('kinematics',))
    points = {b.name: b.points for b in drawing.bodies}
    bodies = data.bodies
    scale = max(np.max(np.abs(p)) for b in drawing.bodies for p in b.points.values())
    if drawing.dimension == 2 or hasattr(rig.scene, 'joints'):  # planar, spatial kinds
        for j in rig.scene.joints:
            if j.prismatic or getattr(j, 'joint_type', '') == 'cylindrical':
                continue
            ends = []
            for link, point in ((j.link_a, j.point_a), (j.link_b, j.point_b)):
                if link == schema.FRAME:
                    ends.append(np.broadcast_to(np.append(drawing.frame[point], 0.0)[:3],
                                                (24, 3)))
                else:
                    ends.append(bodies.world(link, points[link][point]))
            assert_allclose(ends[0], ends[1], rtol=0, atol=1e-12 * scale), (name, j.name)


def _kinetic_energy_by_differences(rig, psi, omega):
    """Return T from finite differences of the body poses in time (independent of the rigs)."""
    def poses(t):
        return rig.at(psi + omega * t, omega, outputs=('kinematics',)).bodies
    ahead, behind, now = poses(FD_STEP_S), poses(-FD_STEP_S), poses(0.0)
    total = np.zeros(psi.size)
    for body in rig.drawing.bodies:
        k = now.names.index(body.name)
        c_local = np.asarray(body.mass_centre_m, dtype=float)
        v = (ahead.world(k, c_local) - behind.world(k, c_local)) / (2 * FD_STEP_S)
        rdot = (ahead.rotation[:, k] - behind.rotation[:, k]) / (2 * FD_STEP_S)
        skew = rdot @ np.swapaxes(now.rotation[:, k], 1, 2)      # [omega]x in the frame
        w = np.stack([skew[:, 2, 1], skew[:, 0, 2], skew[:, 1, 0]], -1)
        mass, inertia = _mass_and_inertia(rig.scene, body.name, now.rotation[:, k])
        total += 0.5 * mass * np.sum(v * v, axis=1) + 0.5 * np.einsum('ni,nij,nj->n', w,
                                                                      inertia, w)
    return total


def _mass_and_inertia(sc, name, rotation):
    """Return a body's mass and its world inertia tensor about its mass centre, (n, 3, 3)."""
    lk = sc.link(name)
    if hasattr(lk, 'inertia_matrix'):   # a spatial link: its tensor about its mass centre
        local = np.array(lk.inertia_matrix())
    else:                               # planar: about z only
        local = np.diag([0.0, 0.0, lk.inertia_com_kg_m2])
    return lk.mass_kg, rotation @ local @ np.swapaxes(rotation, 1, 2)


@pytest.mark.parametrize('name', ['hoeken', 'slider_crank', 'carpet_scraper', 'rggr'])
def test_kinetic_energy_equals_finite_differences_of_the_poses(name):
    sc = schema.load(name)
    rig = rig_for(sc)
    omega = 2.0
    psi = cycle_angles(16) + 0.1
    t = rig.at(psi, omega, outputs=('kinematics', 'kinetic_energy')).series['kinetic_energy']
    reference = _kinetic_energy_by_differences(rig, psi, omega)
    assert_allclose(t, reference, rtol=1e-6, atol=1e-9 * np.max(reference))
    assert np.all(t > 0.0)


def test_kinetic_energy_rate_is_the_driving_power_without_gravity():
    """dT/dt = tau * omega at constant speed (no gravity in the built-in scenes)."""
    sc = schema.load('carpet_scraper')
    rig = rig_for(sc)
    omega, h = 3.0, 1e-4
    psi = cycle_angles(20)
    energy = [rig.at(psi + omega * dt, omega, outputs=('kinetic_energy',)).series[
        'kinetic_energy'] for dt in (-h, h)]
    torque = rig.at(psi, omega, outputs=('driving_torque',)).series['driving_torque']
    rate = (energy[1] - energy[0]) / (2 * h)
    assert_allclose(rate, torque * omega, rtol=0, atol=1e-6 * np.max(np.abs(torque * omega)))


def test_kinetic_energy_reaches_the_table_and_json_only_when_asked(tmp_path, capsys):
    data, _ = schema.load_data('hoeken')
    assert cli.main(['analyze', '--scene', 'hoeken', '--json']) == 0
    rows = {r['quantity'] for r in json.loads(capsys.readouterr().out)['rows']}
    assert 'kinetic energy T' not in rows
    data['outputs'] = ['shaking_wrench', 'kinetic_energy']
    path = tmp_path / 'hoeken_energy.yaml'
    path.write_text(schema.to_yaml(schema.from_dict(data)))
    assert cli.main(['analyze', '--scene', str(path), '--json']) == 0
    report = json.loads(capsys.readouterr().out)
    row = next(r for r in report['rows'] if r['quantity'] == 'kinetic energy T')
    assert row['unit'] == 'J' and row['kind'] == 'energy'
    rig = rig_for(schema.load('hoeken'))
    t = rig.at(cycle_angles(360, rig.scene.assembly_crank_angle_rad),
               outputs=('kinetic_energy',)).series['kinetic_energy']
    assert math.isclose(row['rms'], float(np.sqrt(np.mean(t * t))), rel_tol=1e-12)


def test_the_public_face_resolves_every_name():
    import mech_balance
    for name in mech_balance.__all__:
        assert getattr(mech_balance, name) is not None, name
    with pytest.raises(AttributeError, match='no attribute'):
        mech_balance.no_such_name  # noqa: B018 - the lookup itself is the test


def test_a_scene_differing_only_in_crank_speed_is_balanced_at_its_speed():
    # the compiled linkage is shared by geometry; its users pass their own scene's speed
    # (else balancing a scene whose speed changed, e.g. the node's crank_speed, used the first
    # scene's speed through the linear maps)
    import dataclasses
    from mech_balance import balance
    slow = schema.load('hoeken')
    fast = dataclasses.replace(slow, crank_speed_rad_s=3.0 * slow.crank_speed_rad_s)
    z_slow = balance(rig_for(slow), 'redistribution').report['objective']['z_original']
    z_fast = balance(rig_for(fast), 'redistribution').report['objective']['z_original']
    assert z_fast == pytest.approx(9.0 * z_slow, rel=1e-9)   # the wrench goes with speed^2
