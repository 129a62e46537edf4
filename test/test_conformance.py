"""
One contract, every kind: each public verb on every built-in and on generated scenes.

Issue 28: every verb takes a rig (or a scene) of any kind -- through the Python API, the
command line (subprocess, ``--json`` parsed) and the node (the scene switched at run time
through the parameter service, the per-link parameters listed) -- with no traceback
anywhere; where a kind lacks a capability the verb says which capability and which kind in
one line.  ``analyze --json`` and ``balance --json`` have one top-level shape for every
kind; ``balance`` returns one result type.  ``examples/quickstart.py`` (the five lines of
``mech_balance``'s docstring) runs unchanged on every built-in.
"""

import contextlib
import copy
import io
import json
import math
import os
from pathlib import Path
import runpy
import subprocess
import sys
import time

import mech_balance as mb
from mech_balance import schema
from mech_balance.analysis import cycle as analysis
from mech_balance.balancing import result as balance_result
from mech_balance.cli import main as cli_main
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

ROOT = Path(__file__).resolve().parent.parent
BUILTINS = tuple(schema.builtin_scenes())
SAMPLES = 24
"""Crank angles per revolution of the runs here (the figures are not the point)."""
CLI_TIMEOUT_S = 300
NODE_TIMEOUT_S = 60.0


def _load_data(name):
    data, _ = schema.load_data(schema.builtin_scenes()[name])
    return copy.deepcopy(data)


def _planar_variant():
    """Return Hoeken with a heavier rocker and no normalization: a planar scene no file holds."""
    data = _load_data('hoeken')
    data['name'] = 'hoeken_variant'
    data.pop('normalization', None)
    data['links']['rocker']['mass_kg'] = 1.25 * float(data['links']['rocker']['mass_kg'])
    return data


def _spatial_universal():
    """Return rssr_skew with a universal joint at the crank pin (a U in the tree)."""
    data = _load_data('rssr_skew')
    data['name'] = 'rssr_universal'
    data['links']['coupler']['inertia_com_kg_m2'] = [1e-6, 6.75e-4, 6.75e-4, 0.0, 0.0, 0.0]
    # the cross axis fixed in the coupler, normal to the crank's y axis and to the coupler's
    # line at the stated poses (the loader refuses an axis_b the poses contradict)
    pose = data['assembly']['poses']['coupler']
    rot = Rotation.from_euler('xyz', pose['rpy_deg'], degrees=True).as_matrix()
    cross = np.cross([0.0, 1.0, 0.0], rot[:, 0])
    axis_b = rot.T @ (cross / np.linalg.norm(cross))
    data['joints']['B'] = {'type': 'universal', 'a': 'crank.B', 'b': 'coupler.B',
                           'axis': [0.0, 1.0, 0.0], 'axis_b': [float(x) for x in axis_b]}
    return data


def _spatial_cylindrical():
    """Return the RSCR of test_spatial: a cylindrical joint in the tree, S, R (generated)."""
    from test_spatial import _rscr
    return schema.to_dict(_rscr(cut=False))


GENERATED = {'hoeken_variant': _planar_variant, 'rssr_universal': _spatial_universal,
             'rscr': _spatial_cylindrical}
"""Generated scenes: planar; spatial with U, C and S joints (the built-ins add P joints and a
prismatic input: rssp_slider, pssr_skew)."""
SCENES = BUILTINS + tuple(GENERATED)


@pytest.fixture(scope='module')
def scene_files(tmp_path_factory):
    """Return ``{name: path}``: every scene as a file the command line reads."""
    out = {name: str(schema.builtin_scenes()[name]) for name in BUILTINS}
    folder = tmp_path_factory.mktemp('scenes')
    for name, make in GENERATED.items():
        sc = schema.from_dict(make(), source=name)
        path = folder / f'{name}.yaml'
        path.write_text(schema.to_yaml(sc))
        out[name] = str(path)
    return out


def _scene(name, files):
    return schema.load(files[name])


def _cli(*argv, ok=(0,), process=False):
    """
    Run ``mech-balance ARGV``; return (status, stdout, stderr).

    In this process (:func:`mech_balance.cli.main.main`, what the console script calls) unless
    ``process``: then in a fresh interpreter, as a user runs it.
    """
    if process:
        proc = subprocess.run([sys.executable, '-m', 'mech_balance.cli', *argv],
                              capture_output=True, text=True, timeout=CLI_TIMEOUT_S,
                              env=dict(os.environ, PYTHONPATH=str(ROOT)), cwd=str(ROOT))
        status, out, err = proc.returncode, proc.stdout, proc.stderr
    else:
        out_io, err_io = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(out_io), contextlib.redirect_stderr(err_io):
            try:
                status = cli_main.main(list(argv))
            except SystemExit as exc:   # argparse's usage errors
                status = exc.code
        status, out, err = status or 0, out_io.getvalue(), err_io.getvalue()
    assert 'Traceback' not in err + out, err
    assert status in ok, (argv, err)
    if status:   # a refusal is one line naming what is wrong
        assert len([ln for ln in err.splitlines() if 'error' in ln]) == 1, err
    return status, out, err


# ------------------------------------------------------------------------------ Python API


@pytest.mark.parametrize('name', SCENES)
def test_every_verb_through_the_python_api(name, scene_files, tmp_path):
    sc = _scene(name, scene_files)
    rig = mb.rig_for(sc)
    # run_cycle and summarize take a rig or a scene of any kind
    rows = mb.summarize(mb.run_cycle(rig, SAMPLES))
    again = mb.summarize(mb.run_cycle(sc, SAMPLES))
    assert [r.quantity for r in rows] == [r.quantity for r in again]
    assert rows and all(math.isfinite(r.rms) and r.unit for r in rows)
    force = next(r for r in rows if r.quantity.startswith('shaking force'))
    data = rig.at(analysis.cycle_angles(SAMPLES, sc.assembly_crank_angle_rad,
                                        links=len(sc.links)))
    np.testing.assert_allclose(force.rms, np.sqrt(np.mean(np.sum(data.force_N ** 2, -1))),
                               rtol=1e-12)
    # balance: one result type for every method and kind
    design = mb.balance(rig, samples=SAMPLES)
    _check_design(design, sc)
    # identify: runs, or says in one line which capability the kind lacks
    from mech_balance.analysis import identify
    if 'identification' in rig.capabilities:
        identify.check_identifiable(sc)
    else:
        with pytest.raises(ValueError, match=f"capability 'identification'.* kind "
                                             f'{schema.kind_of(sc).name}') as err:
            mb.identify(sc, np.arange(3.0), np.arange(3.0), np.arange(3.0), np.zeros((3, 6)))
        assert '\n' not in str(err.value)
    # record and urdf
    from mech_balance.ros import urdf
    from mech_balance.viz import recording
    summary = recording.record(tmp_path / 'x.rrd', sc, design.scene, samples=8)
    assert summary.size_bytes > 0
    assert '<robot' in urdf.urdf_xml(sc)
    # accuracy: the RMS study of any kind
    from mech_balance.bench import accuracy
    study = accuracy.run(scene_files[name], sections=('rms',))['rms']
    assert study['rows'][-1]['max_rel_error'] < 1e-6


def _check_design(design, sc):
    """Hold a balancing result to its documented fields (balancing/result.py)."""
    assert isinstance(design, mb.Design)
    assert isinstance(design.success, bool) and design.status in balance_result.STATUS
    assert design.success == (design.status == 0) and design.message
    assert design.lower_bound <= design.objective + 1e-9 * max(1.0, abs(design.objective))
    assert design.certified in (True, False)
    links = [lk.name for lk in design.scene.links]
    assert list(design.masses_kg) == links and list(design.mass_centres_m) == links
    assert all(len(c) == 3 for c in design.mass_centres_m.values())
    assert list(design.inertias_kg_m2) == links
    for lk in design.scene.links:
        assert design.masses_kg[lk.name] == lk.mass_kg
    out = design.to_dict()
    assert tuple(out) == balance_result.SCHEMA_KEYS
    assert out['kind'] == schema.kind_of(sc).name and out['normalized'] is False
    assert all(set(r) == {'quantity', 'unit', 'before', 'after', 'change_percent'}
               for r in out['table'])
    json.dumps(out)


def test_a_verb_a_kind_cannot_do_says_so_in_one_line():
    sc = schema.load('rssr_skew')
    from mech_balance.core.rig import CapabilityError, require
    with pytest.raises(CapabilityError, match=r'^accuracy: needs the capability '
                                              r"'accuracy_study', which scene 'rssr_skew' "
                                              r'of kind spatial lacks; expected a scene of '
                                              r'kind planar$'):
        require(mb.rig_for(sc), 'accuracy_study', 'accuracy')
    require(sc, 'body_kinematics', 'balance')   # has it: no error


# ------------------------------------------------------------------------------ CLI


ANALYZE_KEYS = analysis.ANALYSIS_KEYS


@pytest.mark.parametrize('name', SCENES)
def test_every_verb_through_the_command_line(name, scene_files, tmp_path):
    sc = _scene(name, scene_files)
    path = scene_files[name]
    # in this process (the same argv and exits as the console script); a fresh process for
    # the first verb of one built-in per kind, as a user's shell runs it
    _, out, _ = _cli('analyze', '--scene', path, '--samples', str(SAMPLES), '--json',
                     process=name in ('hoeken', 'rssr_skew'))
    report = json.loads(out)
    assert tuple(report) == ANALYZE_KEYS and report['kind'] == schema.kind_of(sc).name
    assert report['normalized'] is False and report['rows']
    assert all(set(r) == {'quantity', 'unit', 'rms', 'max_abs', 'kind'} for r in report['rows'])
    status, out, _ = _cli('balance', '--scene', path, '--samples', str(SAMPLES), '--json',
                          ok=(0, 2))
    result = json.loads(out)
    assert tuple(result) == balance_result.SCHEMA_KEYS
    assert status == (0 if result['certified'] else 2)
    assert [lk['name'] for lk in result['links']] == [lk.name for lk in sc.links]
    _, out, _ = _cli('urdf', '--scene', path)
    assert '<robot' in out
    _, out, _ = _cli('record', '--scene', path, '--samples', '8', '--out',
                     str(tmp_path / 'x.rrd'))
    assert (tmp_path / 'x.rrd').stat().st_size > 0
    _, out, _ = _cli('accuracy', '--scene', path, '--sections', 'rms', '--json')
    assert json.loads(out)['rms']['rows']
    status, _, err = _cli('identify', '--scene', path, '--bag', str(tmp_path / 'none.csv'),
                          ok=(2,))
    if 'identification' not in mb.rig_for(sc).capabilities:
        assert "capability 'identification'" in err and schema.kind_of(sc).name in err


def test_analyze_and_balance_units_si_by_default():
    """SI unless --normalized; --si stays accepted and is the default."""
    rows = {}
    for flags in ((), ('--si',), ('--normalized',)):
        _, out, _ = _cli('balance', '--scene', 'hoeken', '--samples', str(SAMPLES), '--json',
                         *flags)
        rows[flags] = json.loads(out)['table']
    assert rows[()] == rows[('--si',)]
    assert {r['unit'] for r in rows[()]} <= {'N', 'N*m'}
    assert {r['unit'] for r in rows[('--normalized',)]} <= {'m1*a1*w^2', 'm1*a1^2*w^2'}
    _cli('balance', '--scene', 'hoeken', '--si', '--normalized', ok=(2,))


# ------------------------------------------------------------------------------ example


@pytest.mark.parametrize('name', BUILTINS)
def test_quickstart_runs_unchanged_on_every_built_in(name, monkeypatch):
    """
    Run ``examples/quickstart.py`` unchanged on a built-in: it prints a mass per link.

    In a fresh interpreter for one built-in per kind, as a user runs it (as
    ``test_every_verb_through_the_command_line`` does); the others run the same file as
    ``__main__`` in this process (its argv set), without a second of imports each.
    """
    script = ROOT / 'examples' / 'quickstart.py'
    if name in ('hoeken', 'rssr_skew'):
        proc = subprocess.run([sys.executable, str(script), name],
                              capture_output=True, text=True, timeout=CLI_TIMEOUT_S,
                              env=dict(os.environ, PYTHONPATH=str(ROOT)))
        assert proc.returncode == 0 and 'Traceback' not in proc.stderr, proc.stderr
        printed = proc.stdout
    else:
        monkeypatch.setattr(sys, 'argv', [str(script), name])
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            runpy.run_path(str(script), run_name='__main__')
        printed = out.getvalue()
    masses = eval(printed, {})   # noqa: S307 - the dict of link masses it prints
    assert list(masses) == [lk.name for lk in schema.load(name).links]
    assert all(m > 0.0 for m in masses.values())


def test_quickstart_is_the_docstring_script():
    lines = [ln.strip() for ln in mb.__doc__.splitlines()]
    code = [ln.split('#')[0].strip() for ln in
            (ROOT / 'examples' / 'quickstart.py').read_text().splitlines()
            if ln.startswith(('sc =', 'rig =', 'data =', 'design =', 'print('))]
    assert len(code) == 5
    for line in code[1:]:
        assert any(doc.startswith(line) for doc in lines), line


# ------------------------------------------------------------------------------ node


def _domain_id():
    """Return ROS_DOMAIN_ID if set, else a domain from the pid outside 21-28 (the helpers')."""
    if os.environ.get('ROS_DOMAIN_ID', '').isdigit():
        return int(os.environ['ROS_DOMAIN_ID'])
    d = 1 + os.getpid() % 92
    return d + 8 if d >= 21 else d


def test_node_switches_to_every_built_in_and_lists_per_link_parameters():
    rclpy = pytest.importorskip('rclpy')
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient
    from mech_balance import balancing
    domain = _domain_id()
    ns = f'/conf{os.getpid()}'
    env = dict(os.environ, PYTHONPATH=str(ROOT), ROS_DOMAIN_ID=str(domain),
               ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST', PYTHONUNBUFFERED='1')
    log = open(Path(os.environ.get('TMPDIR', '/tmp')) / f'conformance_{os.getpid()}.log',
               'w+')
    proc = subprocess.Popen([sys.executable, '-m', 'mech_balance.ros.node', '--ros-args',
                             '-r', f'__ns:={ns}', '-p', 'publish_rate:=10.0'],
                            env=env, stdout=log, stderr=subprocess.STDOUT, cwd=str(ROOT))
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain)
    node = rclpy.create_node(f'conformance_{os.getpid()}', namespace=ns, context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    client = AsyncParameterClient(node, f'{ns}/rig')

    def wait(future, what):
        deadline = time.monotonic() + NODE_TIMEOUT_S
        while not future.done():
            assert proc.poll() is None, _read(log)
            assert time.monotonic() < deadline, f'timed out waiting for {what}'
            executor.spin_once(timeout_sec=0.05)
        return future.result()

    try:
        deadline = time.monotonic() + NODE_TIMEOUT_S
        while not client.services_are_ready():
            assert proc.poll() is None, _read(log)
            assert time.monotonic() < deadline, 'the rig node was not discovered'
            executor.spin_once(timeout_sec=0.05)
        for name in BUILTINS:
            result = wait(client.set_parameters([Parameter('scene', value=name)]),
                          f'scene {name}')
            assert result.results[0].successful, (name, result.results[0].reason)
            listed = wait(client.list_parameters(prefixes=['balance.links'], depth=0),
                          'the parameter list').result.names
            sc = schema.load(name)
            rig = mb.rig_for(sc)
            expected = {f'balance.links.{lk.name}.{option}' for lk in sc.links
                        for option in balancing.link_options(rig)}
            assert expected and set(listed) == expected, name
    finally:
        executor.remove_node(node)
        node.destroy_node()
        executor.shutdown()
        rclpy.try_shutdown(context=ctx)
        proc.terminate()
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=15)
        text = _read(log)
        log.close()
    assert 'Traceback' not in text, text


def _read(log):
    log.flush()
    log.seek(0)
    return log.read()
