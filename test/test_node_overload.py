"""
Clock mode's promise under overload (issue 31 item 4): every tick published or counted.

Clock mode publishes tick k at its stamp; a publishing thread held up (the machine
overloaded) skips the ticks it can no longer publish on time and counts them (the stats
line, ``/diagnostics``' publisher status): it never catches up with a burst of stale
samples.  With the machine loaded by busy processes beside the node, the ticks of the
schedule from the first to the last are each published, withheld or counted as skipped.
Counts, never a rate or a time.
"""

import json
import multiprocessing
import os
import sys

from mech_balance.ros import node as rig_node

sys.path.insert(0, os.path.dirname(__file__))
import test_node as tn  # noqa: E402, I100

LOADERS = 3
"""Busy processes beside the node (the machine has 2 cores)."""


def _spin_forever():
    while True:
        pass


def test_every_tick_is_published_or_counted_on_a_loaded_machine(context):
    ns = tn._namespace('overload')
    rig = tn.RigProcess(ns, '-p', 'publish_rate:=1000.0')
    probe = tn.Probe(context, ns)
    loaders = [multiprocessing.Process(target=_spin_forever, daemon=True)
               for _ in range(LOADERS)]
    try:
        probe.wait_for_rig(rig)
        for p in loaders:
            p.start()
        probe.collect(2000, 'samples on the loaded machine')
    finally:
        for p in loaders:
            p.kill()
            p.join()
        probe.destroy()
        log = rig.stop()
    line = [x for x in log.splitlines() if rig_node.STATS_TAG in x][-1]
    stats = json.loads(line.split(rig_node.STATS_TAG, 1)[1])
    print(f'ticks due {stats["ticks_due"]}: published {stats["published"]}, skipped '
          f'{stats["skipped"]}, withheld {stats["withheld"]}, late max '
          f'{stats["late_max_s"]:.3f} s')
    assert stats['rebased'] == 0
    assert stats['ticks_due'] >= 2000
    assert stats['published'] + stats['skipped'] + stats['withheld'] == stats['ticks_due']
