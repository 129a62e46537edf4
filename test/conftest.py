"""
Test-session set-up: numpy's BLAS pool limited, and the suite's modules ordered for xdist.

The suite's process limits BLAS threads as :mod:`mech_balance.threads` does, so that a loaded
CI machine does not stall the small LAPACK calls of the tests that call the library directly.

``make test`` runs the suite on two workers (``pytest -n 2 --dist loadfile
--no-loadscope-reorder``; README "Tests"): every module goes whole to one worker, so a costly
module-scoped fixture (a recording of every scene, a node process, twenty random rigs) is
built once.  (``xdist_group`` marks would not help: pytest-xdist 3.8 writes the group into
``item._nodeid``, which pytest 9 no longer reads, so ``--dist loadgroup`` ignores them.)
The workers take the modules in collection order, which
:func:`pytest_collection_modifyitems` makes longest first (:data:`SLOW_MODULES`), so that
no long module starts last; a serial run keeps the files' order.

Every worker is its own process: the node tests' namespaces, probe names and log files carry
its pid (``test_node``), result files carry the namespace, and files go to pytest's
per-worker temporary directories.  Both workers share ``ROS_DOMAIN_ID`` when it is set (else
each takes one from its pid), which the namespaces make harmless.
"""

from mech_balance import threads
import pytest

threads.limit_blas_threads()

SLOW_MODULES = (
    'test_spatial.py', 'test_node_services.py', 'test_flake8.py', 'test_node_faults.py',
    'test_node_recording.py', 'test_node.py', 'test_twin_sensor.py', 'test_identify_real.py',
    'test_recording_layout.py', 'test_fuzz_verbs.py', 'test_conformance.py',
    'test_node_hardening.py', 'test_spatial_branch.py', 'test_fuzz_scenes.py',
    'test_cli_signals.py', 'test_examples.py', 'test_hardening.py', 'test_bad_input.py',
    'test_recording.py', 'test_spatial_bounds.py', 'test_forward_generic.py',
    'test_identify.py', 'test_identify_faults.py', 'test_accuracy.py', 'test_recording_fuzz.py',
    'test_cli.py', 'test_description.py', 'test_layers.py', 'test_clearance_design.py',
    'test_certificate.py', 'test_extreme.py', 'test_pep257.py', 'test_node_overload.py',
    'test_clearance_spatial.py', 'test_cli_snapshot.py', 'test_bench_mujoco.py',
    'test_node_follow.py', 'test_dyads.py', 'test_cycle_table.py', 'test_spatial_ranges.py',
    'test_threads.py', 'test_simulate.py', 'test_colcon_build.py',
)
"""
The longest modules, longest first: the others follow in file order.

Ranked by the CPU time each module costs, its own and its child processes' (the node, the
command line, flake8's workers), measured one group of modules at a time (a pytest plugin
summing ``time.process_time()`` and ``RUSAGE_CHILDREN`` per test phase, 2026-12-06 08:00-08:50
UTC, on the loaded 2-core machine, so ranked relatively), after the speed-ups of that round
(``test_clearance_spatial.py``'s exact tube distance, ``test_conformance.py``'s quickstart
in-process).  A module of node tests also waits (discovery, the node's ticks) while the
other worker computes: ranking it early lets that wait overlap.  A long module left out of
this list starts last and bounds the run: add a new module here by its measured time.
"""


def _rank(item):
    """Return the start rank of an item's module: the measured slow ones first."""
    module = item.path.name
    return SLOW_MODULES.index(module) if module in SLOW_MODULES else len(SLOW_MODULES)


def pytest_collection_modifyitems(config, items):
    """On an xdist worker, put the slow modules first (the order within a module is kept)."""
    if hasattr(config, 'workerinput'):
        items.sort(key=_rank)


@pytest.fixture(scope='module')
def context():
    """Return an rclpy context of the module's own on the node tests' domain (then shut down)."""
    import rclpy
    from test_node import DOMAIN_ID
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=DOMAIN_ID)
    yield ctx
    rclpy.try_shutdown(context=ctx)
