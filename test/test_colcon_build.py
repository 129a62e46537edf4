"""
Build the package with colcon into a temporary workspace and check what it installs.

Everything colcon writes (build, install and log bases, its own configuration home) lives
under pytest's tmp_path, so the repository never gets build/, install/ or log/.
"""

import os
from pathlib import Path
import shutil
import subprocess
import sys

import pytest

PACKAGE_NAME = 'mech_balance'
PACKAGE_ROOT = Path(__file__).resolve().parent.parent
CONSOLE_SCRIPTS = ('mech-balance', 'rig_node')
COLCON_TIMEOUT_S = 300
WORKSPACE_DIRS = ('build', 'install', 'log')


def _colcon_executable():
    """
    Return the colcon of the running interpreter's environment, else the one on PATH.

    Returns None when colcon is not installed.
    """
    beside_python = Path(sys.executable).parent / 'colcon'
    if beside_python.is_file():
        return str(beside_python)
    return shutil.which('colcon')


@pytest.mark.colcon
def test_colcon_build(tmp_path):
    colcon = _colcon_executable()
    if colcon is None:
        pytest.skip('colcon is not installed (it is pinned in requirements.txt)')
    dirs_before = {name for name in WORKSPACE_DIRS if (PACKAGE_ROOT / name).exists()}
    build_base = tmp_path / 'build'
    install_base = tmp_path / 'install'
    env = dict(os.environ)
    # Keep a developer's ~/.colcon defaults and mixins out of the build.
    env['COLCON_HOME'] = str(tmp_path / 'colcon_home')
    command = [
        colcon,
        '--log-base', str(tmp_path / 'log'),
        'build',
        '--base-paths', str(PACKAGE_ROOT),
        '--packages-select', PACKAGE_NAME,
        '--build-base', str(build_base),
        '--install-base', str(install_base),
        '--executor', 'sequential',
        '--event-handlers', 'console_cohesion+', 'desktop_notification-',
        'status-', 'terminal_title-',
    ]
    result = subprocess.run(
        command, cwd=tmp_path, env=env, stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        timeout=COLCON_TIMEOUT_S, check=False)
    assert result.returncode == 0, \
        'colcon build failed (exit %d):\n%s' % (result.returncode, result.stdout)
    assert 'Summary: 1 package finished' in result.stdout, result.stdout

    prefix = install_base / PACKAGE_NAME
    share = prefix / 'share' / PACKAGE_NAME
    assert (share / 'package.xml').is_file()
    marker = prefix / 'share' / 'ament_index' / 'resource_index' / 'packages' / PACKAGE_NAME
    assert marker.is_file()
    for config in sorted((PACKAGE_ROOT / 'config').glob('*.yaml')):
        assert (share / 'config' / config.name).is_file(), config.name
    for script in CONSOLE_SCRIPTS:
        path = prefix / 'lib' / PACKAGE_NAME / script
        assert path.is_file(), path
        assert os.access(path, os.X_OK), path
    installed_init = list(prefix.glob('lib/python3*/site-packages/%s/__init__.py' % PACKAGE_NAME))
    assert len(installed_init) == 1, installed_init

    dirs_after = {name for name in WORKSPACE_DIRS if (PACKAGE_ROOT / name).exists()}
    assert dirs_after == dirs_before, 'colcon wrote into the repository'
