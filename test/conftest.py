"""
Test-session set-up: numpy's BLAS pool limited, and the suite spread over xdist workers.

The suite's process limits BLAS threads as :mod:`mech_balance.threads` does, so that a loaded
CI machine does not stall the small LAPACK calls of the tests that call the library directly.

``make test`` runs the suite on two workers (``pytest -n 2 --dist loadgroup
--no-loadscope-reorder``; README "Tests").  :func:`pytest_collection_modifyitems` decides
what each worker is sent:

* the tests of a module that share a costly module-scoped fixture (a recording of every
  scene, a node process, twenty random rigs) form one group, so the fixture is built once,
  on one worker; a test marked ``xdist_group`` keeps its own group;
* the other tests go one by one, after the groups, and fill the workers' idle ends;
* the groups start longest first (:data:`SLOW_MODULES`, measured), so that no long module
  starts last.

A serial run (no ``-n``) is left in collection order.  Every worker is its own process:
the node tests' namespaces, probe names and log files carry its pid (``test_node``), and
files go to pytest's per-worker temporary directories.
"""

from mech_balance import threads
import pytest

threads.limit_blas_threads()

SLOW_MODULES = (
    'test_node.py',
    'test_node_faults.py',
    'test_node_hardening.py',
    'test_recording_layout.py',
    'test_spatial.py',
    'test_twin_sensor.py',
    'test_identify.py',
    'test_description.py',
    'test_colcon_build.py',
)
"""Modules in order of their share of a serial run (``--durations``), longest first."""

SHARED_SCOPES = ('module', 'class', 'package', 'session')
"""Fixture scopes that a module's tests share: such a module is sent to one worker."""


def _shares_a_fixture(item):
    """Return True if ``item`` uses a fixture of the tests' own (not pytest's) wider than it."""
    info = getattr(item, '_fixtureinfo', None)
    if info is None:
        return False
    for defs in info.name2fixturedefs.values():
        for fixturedef in defs:
            if fixturedef.scope in SHARED_SCOPES and fixturedef.baseid:
                return True
    return False


def _rank(module):
    """Return the start rank of a module's group: the measured slow ones first."""
    return SLOW_MODULES.index(module) if module in SLOW_MODULES else len(SLOW_MODULES)


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """Group and order the tests for ``--dist loadgroup`` (workers only; see the module)."""
    if not getattr(config.option, 'loadgroup', False):
        return
    shared = {item.path.name for item in items if _shares_a_fixture(item)}
    grouped, single = [], []
    for item in items:
        module = item.path.name
        if item.get_closest_marker('xdist_group') is not None:
            grouped.append(item)
        elif module in shared or module in SLOW_MODULES:
            item.add_marker(pytest.mark.xdist_group(module))
            grouped.append(item)
        else:
            single.append(item)
    grouped.sort(key=lambda item: _rank(item.path.name))     # stable: order within kept
    items[:] = grouped + single
