"""
The scripts of ``examples/`` run as a user runs them, and print what the library computes.

Each runs as a subprocess (``python examples/x.py``); its printed figures are read back and
compared with the library's own answer at the figures' printed precision
(``examples/quickstart.py`` is run on every built-in by ``test_conformance``).
"""

from dataclasses import replace
import os
from pathlib import Path
import re
import subprocess
import sys

import mech_balance as mb
from mech_balance.ros import bags
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
NUMBER = r'[-+]?(?:\d+\.?\d*|\.\d+)(?:e[-+]?\d+)?'
PRINTED_6 = 5.1e-6
"""Relative rounding of a figure printed with six significant digits (``:.6g``)."""
PRINTED_2 = 5.1e-2
"""Relative rounding of a figure printed with two significant digits (``:.2g``)."""
PRINTED_9 = 5.1e-9
"""Relative rounding of a figure printed with nine significant digits (``:.9g``)."""
ROUNDOFF = 1e-9
"""Components below this fraction of their quantity's scale are round-off: the script's
process and this one may differ there (their BLAS threads differ)."""
STEEL = 7850.0
"""The counterweights' default density, kg/m^3 (README "Balancing defaults")."""


def run(name, *args, env=None):
    """Run ``examples/<name>.py`` and return its standard output (it must exit 0)."""
    env = dict(os.environ if env is None else env, PYTHONPATH=str(ROOT))
    proc = subprocess.run([sys.executable, str(ROOT / 'examples' / f'{name}.py'), *args],
                          capture_output=True, text=True, timeout=240, env=env, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return proc.stdout


def numbers(line):
    """Return the numbers of a line after its label (the text up to the first colon)."""
    return np.array([float(x) for x in re.findall(NUMBER, line.split(':', 1)[1])])


def lines(text, prefix):
    """Return the stripped lines of ``text`` that start with ``prefix``."""
    return [x.strip() for x in text.splitlines() if x.strip().startswith(prefix)]


def close(printed, exact, digits_rel, scale=None):
    """Assert printed figures equal the exact ones to print precision (round-off aside)."""
    exact = np.atleast_1d(np.asarray(exact, dtype=float))
    scale = np.max(np.abs(exact)) if scale is None else scale
    np.testing.assert_allclose(printed, exact, rtol=digits_rel, atol=ROUNDOFF * scale)


@pytest.mark.parametrize('name', ['hoeken', 'pssr_skew'])
def test_evaluate_prints_the_rig_at_four_crank_angles(name):
    out = run('evaluate', name)
    scene = mb.load_scene(name)
    data = mb.rig_for(scene).at(
        np.radians([0.0, 90.0, 180.0, 270.0]), speed=scene.crank_speed_rad_s, accel=0.0,
        outputs=('kinematics', 'shaking_wrench', 'driving_torque', 'bearing_reactions'))
    effort = 'driving_force' if name == 'pssr_skew' else 'driving_torque'
    assert len(lines(out, 'crank ')) == 4
    close([numbers(x) for x in lines(out, 'joint positions')], data.joint_position, PRINTED_6)
    close([numbers(x)[0] for x in lines(out, effort)], data.series[effort], PRINTED_6)
    for joint, (force, _) in data.reactions.items():
        close([numbers(x) for x in lines(out, f'bearing {joint} force')], force, PRINTED_6)
    close([numbers(x) for x in lines(out, 'shaking force')], data.force_N, PRINTED_6)
    close([numbers(x) for x in lines(out, 'shaking moment')], data.moment_Nm, PRINTED_6)


def test_balance_prints_the_certified_design_and_its_certificate():
    out = run('balance')
    design = mb.balance(mb.load_scene('hoeken'))
    gap = design.objective - design.lower_bound
    objective = numbers(lines(out, 'objective:')[0])[0]
    lower = numbers(lines(out, 'lower bound:')[0])[0]
    # the script's solve and this one agree within the certificate's gap (their accuracy)
    assert abs(objective - design.objective) <= gap + PRINTED_9 * design.objective
    assert abs(lower - design.lower_bound) <= gap + PRINTED_9 * design.objective
    assert lower <= objective and design.certified
    assert lines(out, 'certified:')[0].startswith('certified: True, status 0')
    for link, mass in design.masses_kg.items():
        close(numbers(lines(out, f'link {link}:')[0])[0], mass, PRINTED_6)
    for row in design.table_in():
        close(numbers(lines(out, row['quantity'] + ':')[0]), [row['before'], row['after']],
              PRINTED_6)


def test_counterweights_prints_collision_free_discs_and_the_price_of_clearance():
    out = run('counterweights')
    blocks = out.split('every disc above:')
    for text, side in zip(blocks, ('auto', 'above')):
        design = mb.balance(mb.load_scene('hoeken'), 'counterweights', links=('crank', 'rocker'),
                            disc_side=side)
        clear = design.report['clearance_design']
        line = lines(text, 'collision-free: least clearance')[0]
        least, margin = numbers(line)[:2]
        close(least, clear['least_clearance_m'], PRINTED_6)
        assert least >= margin == clear['margin_m']
        price = lines(text, 'price of clearance:')[0]
        objective, lower, paid = numbers(price)
        close([objective, lower], [clear['objective'], clear['lower_bound']], PRINTED_9)
        close(paid, clear['price_of_clearance'], 5e-3)   # printed with 3 digits
        for link, discs in design.report['counterweights'].items():
            disc = numbers(lines(text, f'{link} disc:')[0])
            # a steel disc of the printed size weighs the printed mass
            close(disc[0], STEEL * np.pi * disc[1] ** 2 * disc[2], 3 * PRINTED_6)
            if side == 'auto':   # the convex optimum (the local search's moves are not unique)
                close(disc, [discs[0]['mass_kg'], discs[0]['radius_m'],
                             discs[0]['thickness_m'], *discs[0]['centre_m']], PRINTED_6)
    # the discs forced to one side move in the plane: clearance has a price there
    assert numbers(lines(blocks[1], 'price of clearance:')[0])[2] > \
        numbers(lines(blocks[0], 'price of clearance:')[0])[2]


def test_identify_from_a_bag_recovers_the_rig_as_built(tmp_path):
    out = run('identify', str(tmp_path))
    rec = bags.read(tmp_path / 'rig_bag')
    assert len(rec.encoder_t_s) == len(rec.wrench_t_s) == 6000
    scene = mb.load_scene('hoeken')
    result = mb.identify(scene, rec.encoder_t_s, rec.position_rad, rec.wrench_t_s,
                         rec.planar_wrench, rec.effort_Nm)
    assert f'rank {result.rank} of {len(result.names)}' in out
    for channel, before, after in zip(result.channels, result.rms_before, result.rms_after):
        close(numbers(lines(out, f'residual {channel}:')[0]), [before, after], PRINTED_6)
    calibrated = result.calibrated_scene()
    for link in calibrated.links:
        close(numbers(lines(out, f'link {link.name}:')[0])[2], link.mass_kg, PRINTED_6)
    force = numbers(lines(out, 'RMS shaking force:')[0])
    moment = numbers(lines(out, 'RMS shaking moment:')[0])
    pred = result.prediction
    close(force[[2, 3]], [pred.force_N] * 2, PRINTED_6)
    close(moment[[2, 3]], [pred.moment_Nm] * 2, PRINTED_6)
    close([force[4], moment[4]], [pred.force_std_error_N, pred.moment_std_error_Nm],
          PRINTED_2, scale=0.0)
    true = mb.summarize(mb.run_cycle(scene.with_links(
        [replace(lk, mass_kg=lk.mass_kg * f) for lk, f in zip(scene.links, (1.2, 0.9, 1.1))])))
    true = {row.quantity: row.rms for row in true}
    close([force[1], moment[1]], [true['shaking force |f_sh|'], true['shaking moment n_sh']],
          PRINTED_6, scale=0.0)
    # the calibrated twin predicts the rig as built, not the scene, within 4 standard errors
    assert abs(force[2] - force[1]) <= 4 * force[4] < abs(force[0] - force[1])
    assert abs(moment[2] - moment[1]) <= 4 * moment[4] < abs(moment[0] - moment[1])


def test_follow_encoder_receives_the_core_at_every_encoder_sample():
    from test_node import DOMAIN_ID
    env = dict(os.environ, ROS_DOMAIN_ID=str(DOMAIN_ID),
               ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    out = run('follow_encoder', env=env)
    assert 'hoeken: 40 of 40 encoder messages answered' in out
    stamps = lines(out, 'stamp ')
    forces = lines(out, 'shaking force')
    assert len(stamps) == len(forces) == 4
    rig = mb.rig_for(mb.load_scene('hoeken'))
    for head, wrench in zip(stamps, forces):
        crank, speed = [float(x) for x in re.findall(
            rf'crank ({NUMBER}) rad at ({NUMBER}) rad/s', head)[0]]
        data = rig.at([crank], speed=speed, accel=0.0)
        joints = [float(x) for x in re.findall(NUMBER, head.split('joints', 1)[1])]
        close([joints], data.joint_position, PRINTED_6)
        printed = numbers(wrench)
        close(printed[:3], data.force_N[0], PRINTED_9)
        close(printed[3:], data.moment_Nm[0], PRINTED_9)
