"""
The URDF of the spanning tree, checked with an independent URDF library (yourdfpy).

Forward kinematics of the generated URDF at the joint positions of
:func:`mech_balance.ros.urdf.joint_positions` must put every joint point, both points of each
cut joint included, where the core puts them, over a full cycle; the inertials must carry
the scene's mass and mass centre.
"""

from dataclasses import dataclass, replace
import io
import math

from mech_balance import schema as scene
from mech_balance.analysis import cycle as analysis
from mech_balance.cli import main as cli
from mech_balance.conventions import cycle_angles
from mech_balance.core.rig import rig_for
from mech_balance.ros import params, urdf
import numpy as np
from numpy.testing import assert_allclose
import pytest

yourdfpy = pytest.importorskip('yourdfpy')

POINT_TOL_M = 1e-9
"""Acceptance: URDF forward kinematics against the core's joint points."""
MASS_REL_TOL = 1e-12
CENTRE_TOL_M = 1e-12
CYCLE_SAMPLES = 90
"""Crank angles per cycle for the forward-kinematics comparison (every 4 degrees)."""
CYCLE_START = 0.0123
"""Start of the compared cycle, rad: off the scenes' grids and assembly angles."""
FD_STEP = 1e-6
"""Crank-angle step of the central differences that check the velocities, rad."""
SCENES = sorted(scene.builtin_scenes())
PLANAR = [n for n in SCENES if scene.load(n).kind == 'planar']


def _robot(sc, frame_id=urdf.DEFAULT_FRAME_ID):
    text = urdf.urdf_xml(sc, frame_id=frame_id)
    robot = yourdfpy.URDF.load(io.StringIO(text), load_meshes=False,
                               build_collision_scene_graph=False)
    assert robot.validate()
    return robot


def _pins(robot):
    """Return ``{(link, point): xyz in the link frame}`` of the pin visuals."""
    out = {}
    for name, link in robot.link_map.items():
        for v in link.visuals:
            if v.name and v.name.startswith('pin_'):
                out[(name, v.name[4:])] = v.origin[:3, 3]
    return out


def _world(robot, link, root, local):
    t = robot.get_transform(link, root)
    return t[:3, :3] @ local + t[:3, 3]


def _angles():
    return CYCLE_START + cycle_angles(CYCLE_SAMPLES)


# ----------------------------------------------------------------------------- planar


@pytest.mark.parametrize('name', PLANAR)
def test_planar_fk_puts_every_joint_point_where_the_core_does(name):
    sc = scene.load(name)
    lk = analysis.linkage_for(sc)
    robot = _robot(sc)
    root = urdf.DEFAULT_FRAME_ID
    assert set(robot.link_map) == {root} | {link.name for link in sc.links}
    assert robot.actuated_joint_names == [tj.name for tj in lk.tree]
    pins = _pins(robot)
    ends = [(j.link_a, j.point_a) for j in sc.joints]
    ends += [(j.link_b, j.point_b) for j in sc.joints]
    urdf_link = {scene.FRAME: root}
    for link, point in ends:  # every joint point, both ends of every cut joint included
        assert (urdf_link.get(link, link), point) in pins, (link, point)
    state = lk.solve(_angles())
    names, pos, _ = urdf.joint_positions(lk, state)
    body = {n: i for i, n in enumerate(lk.body_names)}
    local_points = {scene.FRAME: sc.frame_points, **{k.name: k.points for k in sc.links}}
    worst = 0.0
    for k in range(state.size):
        robot.update_cfg(dict(zip(names, pos[k])))
        for link, point in set(ends):
            b = body[link]
            core = state.pose.origin[b, k] + state.pose.rot[b, k] * complex(
                *local_points[link][point])
            local = pins[(urdf_link.get(link, link), point)]
            got = _world(robot, urdf_link.get(link, link), root, local)
            err = np.abs(got - np.array([core.real, core.imag, local[2]])).max()
            worst = max(worst, err)
    print(f'{name}: worst joint-point mismatch over {state.size} angles {worst:.2e} m')
    assert worst < POINT_TOL_M


@pytest.mark.parametrize('name', PLANAR)
def test_planar_inertials_carry_the_scene_mass_and_centre(name):
    sc = scene.load(name)
    lk = analysis.linkage_for(sc)
    robot = _robot(sc)
    root = urdf.DEFAULT_FRAME_ID
    masses = {n: link.inertial.mass for n, link in robot.link_map.items()
              if link.inertial is not None}
    total = sum(link.mass_kg for link in sc.links)
    assert set(masses) == {link.name for link in sc.links}
    assert_allclose(sum(masses.values()), total, rtol=MASS_REL_TOL)
    state = lk.solve(_angles())
    names, pos, _ = urdf.joint_positions(lk, state)
    body = {n: i for i, n in enumerate(lk.body_names)}
    worst = 0.0
    for k in range(0, state.size, 5):
        robot.update_cfg(dict(zip(names, pos[k])))
        centre = np.zeros(3)
        core = 0j
        for link in sc.links:
            inertial = robot.link_map[link.name].inertial
            t = robot.get_transform(link.name, root) @ inertial.origin
            centre += inertial.mass * t[:3, 3]
            b = body[link.name]
            core += link.mass_kg * (state.pose.origin[b, k]
                                    + state.pose.rot[b, k] * complex(*link.com_m))
            # the centroidal inertia about z, and a real body (triangle inequality)
            inertia = inertial.inertia
            assert_allclose(inertia[2, 2], link.inertia_com_kg_m2, rtol=1e-15)
            eig = np.linalg.eigvalsh(inertia)
            assert eig.min() >= -1e-18 and 2 * eig.max() <= eig.sum() * (1 + 1e-12)
        err = np.abs(centre / total - np.array([core.real / total, core.imag / total, 0.0]))
        worst = max(worst, err.max())
    print(f'{name}: total mass {sum(masses.values())!r} kg (scene {total!r}); worst mass '
          f'centre mismatch {worst:.2e} m')
    assert worst < CENTRE_TOL_M


@pytest.mark.parametrize('name', SCENES)
def test_positions_wrapped_within_limits_and_velocities_are_their_rates(name):
    sc = scene.load(name)
    model = urdf.tree_model(sc)
    psi = cycle_angles(720, CYCLE_START)
    if sc.kind == 'spatial':   # through the Rig protocol (the node's path)
        rig = rig_for(sc)

        def solve(p):
            return rig.at(p, outputs=('kinematics',))
    else:
        lk = analysis.linkage_for(sc)

        def solve(p):
            return lk.solve(p)
    names, pos, vel = urdf.joint_positions(model, solve(psi))
    assert names == model.names
    assert not np.any(np.signbit(pos) & (pos == 0.0))
    assert not np.any(np.signbit(vel) & (vel == 0.0))
    for j, spec in enumerate(model.joints):
        if spec.joint_type != 'prismatic':
            assert np.all(pos[:, j] > -math.pi) and np.all(pos[:, j] <= math.pi)
        if spec.joint_type == 'continuous':
            continue
        # within the limits, and the limits are the cycle's extremes (not a loose box)
        assert np.all(pos[:, j] >= spec.lower) and np.all(pos[:, j] <= spec.upper), spec.name
        span = spec.upper - spec.lower
        assert pos[:, j].min() - spec.lower < 1e-4 * span
        assert spec.upper - pos[:, j].max() < 1e-4 * span
    # velocities: d(position)/dt by central differences in the crank angle
    _, plus, _ = urdf.joint_positions(model, solve(psi + FD_STEP))
    _, minus, _ = urdf.joint_positions(model, solve(psi - FD_STEP))
    diff = plus - minus
    angular = np.array([s.joint_type != 'prismatic' for s in model.joints])
    diff[:, angular] = urdf.wrap_angle(diff[:, angular])
    rate = diff / (2.0 * FD_STEP) * sc.crank_speed_rad_s
    scale = np.abs(vel).max(axis=0)
    assert_allclose(vel, rate, rtol=0.0, atol=1e-6 * scale.max())


def test_planar_joint_names_are_those_of_joint_states():
    from mech_balance.ros import streaming as twin
    for name in PLANAR:
        sc = scene.load(name)
        model = urdf.tree_model(sc)
        assert set(model.names) <= set(twin.model_for(sc).joint_names)
        cuts = {c.name for c in analysis.linkage_for(sc).cuts}
        assert set(model.names) | cuts == {j.name for j in sc.joints}
        text = urdf.urdf_xml(sc)
        for c in cuts:
            assert f'{c}: revolute, closes' in text or f'{c}: prismatic, closes' in text


# ----------------------------------------------------------------------------- RGGR (spatial)


@pytest.fixture(scope='module')
def rggr_designs():
    """Return the RGGR (kind spatial) and its seed-002 design (weights folded in)."""
    from mech_balance.balancing import weights
    sc = scene.load('rggr')
    return {False: sc, True: weights.balance_weights(rig_for(sc)).balanced_scene}


@pytest.mark.parametrize('with_weights', [False, True])
def test_rggr_inertials_carry_mass_centre_and_the_pivot_inertia(rggr_designs, with_weights):
    """The links' mass, centre and I_ww, I_wu, I_vw about the pivot (seed 002's J)."""
    sc = rggr_designs[with_weights]
    robot = _robot(sc)
    root = urdf.DEFAULT_FRAME_ID
    rig = rig_for(sc)
    total = sum(lk.mass_kg for lk in sc.links)
    masses = {n: link.inertial.mass for n, link in robot.link_map.items()
              if link.inertial is not None}
    assert_allclose(sum(masses.values()), total, rtol=MASS_REL_TOL)
    data = rig.at(_angles(), outputs=('kinematics',))
    names, pos, _ = urdf.rig_joint_positions(sc, data)
    poses = data.bodies
    core = sum(lk.mass_kg * poses.world(lk.name, lk.com_m) for lk in sc.links) / total
    worst = worst_pivot = 0.0
    for k in range(pos.shape[0]):
        robot.update_cfg(dict(zip(names, pos[k])))
        centre = np.zeros(3)
        for name, mass in masses.items():
            t = robot.get_transform(name, root) @ robot.link_map[name].inertial.origin
            centre += mass * t[:3, 3]
        worst = max(worst, np.abs(centre / total - core[k]).max())
        for name in ('crank', 'output'):   # the inertia about the pivot, in frame axes
            t = robot.get_transform(name, root) @ robot.link_map[name].inertial.origin
            lk = sc.link(name)
            rot = poses.rotation[k, poses.names.index(name)]
            mine = t[:3, :3] @ robot.link_map[name].inertial.inertia @ t[:3, :3].T
            theirs = rot @ np.array(lk.inertia_matrix()) @ rot.T
            worst_pivot = max(worst_pivot, np.abs(mine - theirs).max())
    print(f'rggr (weights {with_weights}): worst mass centre mismatch {worst:.2e} m, '
          f'inertia {worst_pivot:.2e} kg m^2')
    assert worst < CENTRE_TOL_M
    assert worst_pivot < 1e-15


def test_rggr_output_limits_are_its_swing():
    sc = scene.load('rggr')
    model = urdf.tree_model(sc)
    types = {j.name: j.joint_type for j in model.joints}
    assert types['crank'] == 'continuous' and types['output'] == 'revolute'
    data = rig_for(sc).at(cycle_angles(36000), outputs=('kinematics',))
    names, pos, _ = urdf.rig_joint_positions(sc, data)
    phi3 = pos[:, names.index('output')]
    out = next(j for j in model.joints if j.name == 'output')
    assert abs(out.lower - phi3.min()) < 1e-8 and abs(out.upper - phi3.max()) < 1e-8


# ----------------------------------------------------------------------------- conventions


def test_angle_limits_move_a_swing_through_pi_to_its_middle():
    offset, lo, hi = urdf.angle_limits(2.5, 3.8)
    assert_allclose(offset, urdf.wrap_angle(3.15))
    assert_allclose([lo, hi], [-0.65 - urdf.LIMIT_MARGIN, 0.65 + urdf.LIMIT_MARGIN])
    # a swing that fits in (-pi, pi] after whole turns keeps the natural zero
    offset, lo, hi = urdf.angle_limits(1.0 + 2 * math.pi, 2.0 + 2 * math.pi)
    assert offset == 0.0
    assert_allclose([lo, hi], [1.0 - urdf.LIMIT_MARGIN, 2.0 + urdf.LIMIT_MARGIN])


def test_wrap_angle_range_and_signed_zero():
    x = np.array([-0.0, math.pi, -math.pi, 3 * math.pi, -1e-20, 7.0, -7.0])
    w = urdf.wrap_angle(x)
    assert np.all(w > -math.pi) and np.all(w <= math.pi)
    assert not np.any(np.signbit(w) & (w == 0.0))
    assert_allclose(np.exp(1j * w), np.exp(1j * x), atol=1e-15)


def test_a_rocker_through_pi_gets_an_offset_and_stays_continuous():
    # Hoeken turned by 1.2 rad about the crank pivot: the rocker then swings through pi
    sc = scene.load('hoeken')
    turn = 1.2
    rot = complex(math.cos(turn), math.sin(turn))
    frame = {k: ((rot * complex(*p)).real, (rot * complex(*p)).imag)
             for k, p in sc.frame_points.items()}
    mirrored = replace(sc, name='hoeken_turned', frame_points=frame,
                       assembly_crank_angle_rad=sc.assembly_crank_angle_rad + turn,
                       assembly_link_angles_rad={k: v + turn for k, v in
                                                 sc.assembly_link_angles_rad.items()})
    lk = analysis.linkage_for(mirrored)
    model = urdf.tree_model(lk)
    rocker = next(j for j in model.joints if j.name == 'O3')
    q = lk.solve(cycle_angles(720)).q[[tj.name for tj in lk.tree].index('O3')]
    crosses = np.any(np.abs(urdf.wrap_angle(q) - math.pi) < 0.3)
    assert crosses, 'the test geometry must swing through pi'
    assert rocker.offset != 0.0 and rocker.rpy[2] == rocker.offset
    _, pos, _ = urdf.joint_positions(lk, lk.solve(cycle_angles(720)))
    j = model.names.index('O3')
    assert np.all(pos[:, j] >= rocker.lower) and np.all(pos[:, j] <= rocker.upper)
    assert np.abs(np.diff(pos[:, j])).max() < 0.1   # no jump at the wrap point
    robot = _robot(mirrored)
    robot.update_cfg(dict(zip(model.names, pos[5])))
    t = robot.get_transform('rocker', urdf.DEFAULT_FRAME_ID)
    phi = lk.solve(cycle_angles(720)[5:6]).pose.phi[lk.body_names.index('rocker'), 0]
    assert_allclose(t[:2, 0], [math.cos(phi), math.sin(phi)], atol=1e-12)


@dataclass(frozen=True)
class _Disc:
    mass_kg: float
    centre_m: tuple
    radius_m: float
    thickness_m: float


def _with_discs(link, discs):
    """Return ``link`` carrying ``discs`` in its totals (scene.add_counterweights if any)."""
    if hasattr(scene, 'add_counterweights') and hasattr(scene, 'Counterweight'):
        real = [scene.Counterweight(d.mass_kg, d.centre_m, d.radius_m, d.thickness_m,
                                    d.mass_kg / (math.pi * d.radius_m ** 2 * d.thickness_m))
                for d in discs]
        return scene.add_counterweights(link, real)

    @dataclass(frozen=True)
    class LinkWithDiscs(scene.Link):
        counterweights: tuple = ()
        own: tuple = None

    own = (link.mass_kg, tuple(link.com_m), link.inertia_com_kg_m2)
    m = link.mass_kg + sum(d.mass_kg for d in discs)
    hx = link.mass_kg * link.com_m[0] + sum(d.mass_kg * d.centre_m[0] for d in discs)
    hy = link.mass_kg * link.com_m[1] + sum(d.mass_kg * d.centre_m[1] for d in discs)
    i_o = link.inertia_origin_kg_m2 + sum(
        0.5 * d.mass_kg * d.radius_m ** 2 + d.mass_kg * (d.centre_m[0] ** 2 + d.centre_m[1] ** 2)
        for d in discs)
    com = (hx / m, hy / m)
    return LinkWithDiscs(link.name, link.points, m, com, i_o - m * (com[0] ** 2 + com[1] ** 2),
                         tuple(discs), own)


def test_counterweights_are_drawn_and_in_the_inertials():
    sc = scene.load('hoeken')
    discs = [_Disc(0.2, (-0.012, 0.003), 0.01, 0.008), _Disc(0.1, (-0.01, -0.006), 0.007, 0.01)]
    links = [_with_discs(lk, discs) if lk.name == 'crank' else lk for lk in sc.links]
    heavy = sc.with_links(links)
    robot = _robot(heavy)
    crank = robot.link_map['crank']
    drawn = [v for v in crank.visuals if v.name.startswith('counterweight_')]
    assert len(drawn) == 2
    assert_allclose(drawn[0].geometry.cylinder.radius, 0.01)
    total = heavy.link('crank')
    assert_allclose(crank.inertial.mass, total.mass_kg, rtol=1e-15)
    assert_allclose(crank.inertial.origin[:2, 3], total.com_m, atol=1e-15)
    inertia = crank.inertial.inertia
    assert_allclose(inertia[2, 2], total.inertia_com_kg_m2, rtol=1e-15)
    eig = np.linalg.eigvalsh(inertia)
    assert eig.min() > 0 and 2 * eig.max() <= eig.sum() * (1 + 1e-12)
    assert inertia[0, 0] != inertia[1, 1]   # the discs are not a symmetric plate
    # the cut joint and the positions do not change with the inertia
    assert urdf.tree_model(heavy).names == urdf.tree_model(sc).names


# ----------------------------------------------------------------------------- bad input


def test_bad_input_names_the_field():
    sc = scene.load('hoeken')
    lk = analysis.linkage_for(sc)
    with pytest.raises(urdf.UrdfError, match='frame_id: got .crank.'):
        urdf.urdf_xml(sc, frame_id='crank')
    with pytest.raises(urdf.UrdfError, match='frame_id: got'):
        urdf.urdf_xml(sc, frame_id='')
    with pytest.raises(urdf.UrdfError, match='without rates'):
        urdf.joint_positions(lk, lk.solve([0.1], need_rates=False))
    with pytest.raises(urdf.UrdfError, match='expected a planar or spatial scene'):
        urdf.tree_model(42)


def test_default_frame_id_is_the_nodes():
    spec = next(s for s in params.PARAMETERS if s.name == 'frame_id')
    assert spec.default == urdf.DEFAULT_FRAME_ID


# ----------------------------------------------------------------------------- command line


def test_cli_writes_atomically_and_prints_without_out(tmp_path, capsys):
    out = tmp_path / 'hoeken.urdf'
    assert cli.main(['urdf', '--scene', 'hoeken', '--out', str(out)]) == 0
    assert 'wrote' in capsys.readouterr().out
    text = out.read_text()
    assert text == urdf.urdf_xml(scene.load('hoeken'))
    assert [p.name for p in tmp_path.iterdir()] == ['hoeken.urdf']  # no temp file left
    assert cli.main(['urdf', '--scene', 'rggr', '--frame-id', 'base']) == 0
    printed = capsys.readouterr().out
    assert printed == urdf.urdf_xml(scene.load('rggr'), frame_id='base')
    assert '<link name="base"' in printed


def test_cli_design_takes_the_inertias_of_the_same_geometry(tmp_path, capsys):
    sc = scene.load('hoeken')
    from mech_balance.balancing import redistribution
    heavier = [replace(lk, mass_kg=2 * lk.mass_kg, inertia_com_kg_m2=2 * lk.inertia_com_kg_m2)
               for lk in sc.links]
    path = tmp_path / 'heavy.yaml'
    path.write_text(redistribution.scene_to_yaml(sc.with_links(heavier, name='heavy')))
    assert cli.main(['urdf', '--scene', 'hoeken', '--design', str(path)]) == 0
    robot = yourdfpy.URDF.load(io.StringIO(capsys.readouterr().out), load_meshes=False,
                               build_collision_scene_graph=False)
    assert_allclose(robot.link_map['crank'].inertial.mass, 2 * sc.link('crank').mass_kg)
    assert cli.main(['urdf', '--scene', 'hoeken', '--design', 'slider_crank']) == 2
    assert '--design: scene' in capsys.readouterr().err
    assert cli.main(['urdf', '--scene', 'hoeken', '--out', str(tmp_path / 'x.txt')]) == 2
    assert 'ending in .urdf' in capsys.readouterr().err
