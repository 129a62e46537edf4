"""
Bounded spatial inputs (issue 32): huge crank angles, the length scale, a design at round-off.

``assembly.crank_angle_deg`` of any magnitude the scene admits is the angle it denotes
(reduced exactly), so 1e12..1e18 deg either assembles there or is refused for the reason that
holds (the poses do not fit that angle); every figure of every spatial built-in scales
exactly with its lengths from 1e-12 to 1e3 m; and ``balance --output`` writes the design it
prints where the optimum puts a rod's transverse inertia at zero.
"""

import copy
import math

from mech_balance import schema
from mech_balance.balancing import spatial
from mech_balance.balancing.spatial import model as spatial_model
from mech_balance.core.rig import rig_for
from mech_balance.core.spatial import assembly
from mech_balance.core.spatial.kinematics import SpatialError
from mech_balance.schema.spatial import spatial_from_dict
import numpy as np
from numpy.testing import assert_allclose
import pytest

SPATIAL = ('rssr_skew', 'rssp_slider', 'spatial_two_loop', 'pssr_skew', 'rggr_spatial', 'rggr')
SCALES = (1e-12, 1e-9, 1e-6, 1e-3, 1e3)
"""Length factors of the scale-invariance test (the built-ins' own lengths are ~0.1 m)."""
SCALE_RTOL = 1e-9
"""Every figure, relative to its family's largest value (issue 32's acceptance)."""


def _data(name):
    data, _ = schema.load_data(name)
    return copy.deepcopy(data)


# ----------------------------------------------------------------------------- crank angle

@pytest.mark.parametrize('angle_deg', [1e12, 1e16, 1e18, -1e18])
def test_huge_crank_angle_is_the_angle_it_denotes(angle_deg):
    """The poses hold at 0 deg; 1e12 deg is 280 deg: refused there, for that reason."""
    data = _data('rssr_skew')
    data['assembly']['crank_angle_deg'] = angle_deg
    sc = spatial_from_dict(data)
    assert sc.assembly_crank_angle_deg == angle_deg          # kept as written
    reduced = math.fmod(angle_deg, 360.0) % 360.0
    assert math.degrees(sc.assembly_crank_angle_rad) % 360.0 == pytest.approx(reduced, abs=1e-9)
    with pytest.raises(SpatialError, match=rf'assembly: at crank angle {reduced:.4f} deg the '
                                           r'linkage does not close at the stated poses: '
                                           r'crank closed'):
        rig_for(sc, cache=False)


def test_huge_crank_angle_whole_turns_give_the_same_figures():
    """360 x 2^40 deg (exact) is 0 deg: the same cycle figures, bit for bit in the wrench."""
    base = rig_for(schema.load('rssr_skew'))
    data = _data('rssr_skew')
    data['assembly']['crank_angle_deg'] = 360.0 * 2.0 ** 40
    rig = rig_for(spatial_from_dict(data), cache=False)
    psi = np.linspace(0.0, 2.0 * np.pi, 36, endpoint=False)
    a, b = base.at(psi), rig.at(psi)
    assert_allclose(b.force_N, a.force_N, rtol=0, atol=1e-12 * np.max(np.abs(a.force_N)))
    assert_allclose(b.moment_Nm, a.moment_Nm, rtol=0, atol=1e-12 * np.max(np.abs(a.moment_Nm)))


# ----------------------------------------------------------------------------- length scale

def _scaled(data, s):
    """Return a spatial mapping with every length times ``s`` (inertias times s^2)."""
    data = copy.deepcopy(data)
    data['frame']['points'] = {k: [v * s for v in p] for k, p in data['frame']['points'].items()}
    for lk in data['links'].values():
        lk['points'] = {k: [v * s for v in p] for k, p in lk['points'].items()}
        lk['com_m'] = [v * s for v in lk.get('com_m', [0.0, 0.0, 0.0])]
        lk['inertia_com_kg_m2'] = [v * s * s for v in lk['inertia_com_kg_m2']]
    for pose in data.get('assembly', {}).get('poses', {}).values():
        pose['origin_m'] = [v * s for v in pose['origin_m']]
    data['moment_point_m'] = [v * s for v in data['moment_point_m']]
    if 'stroke_m' in data['crank']:
        data['crank']['stroke_m'] = [v * s for v in data['crank']['stroke_m']]
    data.pop('normalization', None)
    return data


def _figures(data):
    """Return ``{family: (power of the length, [arrays])}`` of a cycle of 36 angles."""
    sc = spatial_from_dict(data)
    rig = rig_for(sc, cache=False)
    psi = sc.assembly_crank_angle_rad + np.linspace(0.0, 2.0 * np.pi, 36, endpoint=False)
    outputs = ('kinematics', 'shaking_wrench', 'driving_torque', 'bearing_reactions',
               'kinetic_energy')
    d = rig.at(psi, speed=7.0, accel=3.0, outputs=outputs)
    slides = np.array(rig.joint_prismatic)
    effort = 1 if rig.driving_series == 'driving_force' else 2
    return {'force': (1, [d.force_N] + [f for f, _ in d.reactions.values()]),
            'moment': (2, [d.moment_Nm] + [m for _, m in d.reactions.values()]),
            'effort': (effort, [d.joint_effort[:, rig.crank_index]]),
            'energy': (2, [d.series['kinetic_energy']]),
            'angles': (0, [d.joint_position[:, ~slides], d.joint_velocity[:, ~slides]]),
            'slides': (1, [d.joint_position[:, slides], d.joint_velocity[:, slides]]),
            'origins': (1, [d.bodies.origin_m]), 'rotations': (0, [d.bodies.rotation])}


@pytest.mark.parametrize('name', SPATIAL)
def test_every_figure_scales_with_the_lengths(name):
    """
    Lengths x s (1e-12 to 1e3), inertias x s^2: every figure x s^p to 1e-9 of its family.

    Forces and slides go as s, moments, torques and energies as s^2, angles not at all;
    each array is compared relative to the largest value of its family (a spherical joint's
    reaction moment is zero up to round-off).
    """
    data = _data(name)
    base = _figures(_scaled(data, 1.0))
    for s in SCALES:
        got = _figures(_scaled(data, s))
        for family, (power, arrays) in base.items():
            scale = max([float(np.max(np.abs(a))) for a in arrays if a.size] + [0.0])
            for ref, new in zip(arrays, got[family][1]):
                if not ref.size:
                    continue
                err = float(np.max(np.abs(new / s ** power - ref)))
                assert err <= SCALE_RTOL * scale, (name, s, family, err / scale)


UNIT_POWER = {'N': 1, 'N*m': 2, 'm': 1, 'm/s': 1, 'rad': 0, 'rad/s': 0, 'J': 2, 'W': 2}
"""The power of the length scale each unit of ``analyze``'s rows goes with."""


def _analyze_rows(data, tmp_path):
    """Return ``analyze --json``'s rows of the scene ``data`` (run as the command line)."""
    import contextlib
    import io
    import json
    import yaml
    from mech_balance.cli import main as cli
    path = tmp_path / 'scaled.yaml'
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding='utf-8')
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert cli.main(['analyze', '--json', '--scene', str(path)]) == 0
    return json.loads(out.getvalue())['rows']


@pytest.mark.parametrize('name', SPATIAL)
def test_every_printed_figure_scales_with_the_lengths(name, tmp_path):
    """
    ``mech-balance analyze``'s every RMS and peak, lengths x 1e-12..1e3: x s^p to 1e-9.

    Each figure relative to the largest of its unit (the command line's own path: loader,
    rig, summary), at the scene's 36 angles.
    """
    data = _data(name)
    data['samples'] = 36
    base = _analyze_rows(_scaled(data, 1.0), tmp_path)
    for s in SCALES:
        rows = _analyze_rows(_scaled(data, s), tmp_path)
        assert [r['quantity'] for r in rows] == [r['quantity'] for r in base]
        for unit in {r['unit'] for r in base}:
            power = UNIT_POWER[unit]
            pairs = [(r, q) for r, q in zip(base, rows) if r['unit'] == unit]
            scale = max(max(r['rms'], r['max_abs']) for r, _ in pairs)
            for r, q in pairs:
                for key in ('rms', 'max_abs'):
                    err = abs(q[key] / s ** power - r[key])
                    assert err <= SCALE_RTOL * scale, (name, s, r['quantity'], key,
                                                       err / scale)


# ----------------------------------------------------------------------------- round-off design

def _restated(name, delta_deg):
    """Return ``name`` assembled ``delta_deg`` further on, its poses restated there."""
    sc = schema.load(name)
    rig = rig_for(sc)
    data = _data(name)
    bodies = rig.at([sc.assembly_crank_angle_rad + math.radians(delta_deg)],
                    outputs=('kinematics',)).bodies
    data['assembly']['crank_angle_deg'] = sc.assembly_crank_angle_deg + delta_deg
    for n in data['assembly']['poses']:
        k = bodies.names.index(n)
        data['assembly']['poses'][n] = {
            'origin_m': [float(v) for v in bodies.origin_m[0, k]],
            'rpy_deg': assembly.rpy_deg(bodies.rotation[0, k])}
    return data


@pytest.mark.parametrize('delta_deg', [45.0, 90.0, 180.0])
def test_balanced_design_at_round_off_is_written_and_reproduced(tmp_path, delta_deg):
    """
    rggr_spatial assembled at another crank angle: the design is written, as printed.

    Its optimum puts the coupler rod's transverse inertia at zero, which came out of the
    parameters a few 1e-15 kg m^2 below it and was refused on writing (exit 2).
    """
    rig = rig_for(spatial_from_dict(_restated('rggr_spatial', delta_deg)), cache=False)
    result = spatial.redistribute(rig, samples=72)
    inertia = np.array(result.balanced_scene.link('coupler').inertia_matrix())
    assert np.min(np.linalg.eigvalsh(inertia)) >= 0.0
    path = tmp_path / 'balanced.yaml'
    reloaded = spatial.write_scene(result, path)
    assert reloaded.link('coupler').inertia_com_kg_m2 == \
        result.balanced_scene.link('coupler').inertia_com_kg_m2


def test_round_off_clip_leaves_a_design_that_is_no_body():
    """Only round-off is clipped: -1e-15 of m reach^2 goes, -1e-6 stays (the loader names it)."""
    clip = spatial_model.clip_roundoff
    tiny = np.diag([0.0, -1e-15, -1e-15])
    assert np.array_equal(clip(tiny, 1.0), np.zeros((3, 3)))
    bad = np.diag([1.0, -1e-6, 1.0])
    assert np.array_equal(clip(bad, 1.0), bad)
    fine = np.diag([1.0, 2.0, 2.5])
    assert np.array_equal(clip(fine, 1.0), fine)


@pytest.mark.parametrize('name', SPATIAL[:5])
def test_the_balanced_optimum_scales_with_the_lengths(name):
    """
    The certified redistribution, lengths x 1e-12..1e3: the same optimum in the rig's units.

    The objective z is dimensionless (units from the rig's own mass, length and speed), so
    the optimum z* of every scaled rig is the same number; each solve brackets it by its
    certified lower bound and its design's z (the core's evaluation).  The brackets must
    overlap: every z of one scale at least every lower bound of another, to round-off.  The
    original's figures (z before balancing) scale exactly, to 1e-9.
    """
    from mech_balance import balance
    data = _data(name)
    runs = []
    for s in (1.0,) + SCALES:
        sc = spatial_from_dict(dict(_scaled(data, s), samples=36))
        design = balance(rig_for(sc, cache=False), 'redistribution')
        runs.append((s, design.report['objective'], design.result.certificate.lower_bound))
    z0 = runs[0][1]['z_original']
    for s, objective, lower in runs:
        assert objective['z_original'] == pytest.approx(z0, rel=SCALE_RTOL), s
        for _, other, _ in runs:   # z* lies in every bracket: lower <= z* <= z
            assert lower <= other['z'] * (1.0 + SCALE_RTOL) + 1e-12, (name, s, lower, other)
