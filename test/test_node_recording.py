"""
The node's recording beside a dead live view (issue 32 item 0).

A node with ``recording_path`` and a ``rerun_url`` where nothing listens, set in either order
(and both at start-up), at 100 Hz and 1 kHz: the recording is independent of the live view
and holds every sample the node queued for it, read back with rerun's own loader; the
probe's samples received after both parameters were answered are all in it.  Endpoints are
waited for, never slept on; no rate or time is asserted.
"""

import json
import os
import socket
import sys

from mech_balance.ros import node as rig_node
from mech_balance.viz import readback
import pytest

sys.path.insert(0, os.path.dirname(__file__))
import test_node as tn  # noqa: E402, I100

SAMPLES = 300
"""Samples the probe receives while both the file and the dead viewer are set."""
PER_SAMPLE = '/plots/shaking_force/original'
"""An entity of the recording with one row per recorded sample."""


def _dead_url():
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        port = s.getsockname()[1]
    return f'rerun+http://127.0.0.1:{port}/proxy'   # closed again: nothing listens


def _stats(log):
    line = [x for x in log.splitlines() if rig_node.STATS_TAG in x][-1]
    return json.loads(line.split(rig_node.STATS_TAG, 1)[1])


@pytest.mark.parametrize('rate', [100.0, 1000.0])
@pytest.mark.parametrize('order', ['start', 'path_first', 'url_first'])
def test_a_dead_viewer_never_costs_the_recording(context, tmp_path, rate, order):
    path, url = str(tmp_path / 'rig.rrd'), _dead_url()
    both = ('-p', f'recording_path:={path}', '-p', f'rerun_url:={url}')
    ns = tn._namespace(f'rec_{order}_{int(rate)}')
    rig = tn.RigProcess(ns, '-p', f'publish_rate:={rate}', *(both if order == 'start' else ()))
    probe = tn.Probe(context, ns)
    try:
        probe.wait_for_rig(rig)
        if order != 'start':
            sets = [('recording_path', path), ('rerun_url', url)]
            for name, value in sets if order == 'path_first' else sets[::-1]:
                assert probe.set_params(**{name: value})[0].successful
        probe.collect(SAMPLES, 'samples with the file and the dead viewer set')
        received = len(probe.joints)
    finally:
        probe.destroy()
        log = rig.stop()
    assert rig.proc.returncode == 0, log
    assert 'Traceback' not in log and 'severity' not in log, log
    assert 'the viewer is dead' in log, log
    assert 'recording thread stopped' not in log, log
    stats = _stats(log)['recording']
    assert stats['batches_dropped'] == 0 and stats['file'] == 'closed', log[-3000:]
    rows = readback.read_recording(path)[PER_SAMPLE].rows
    print(f'{order} at {rate:g} Hz: {rows} rows recorded, {stats["queued"]} queued, '
          f'{received} received by the probe')
    assert rows == stats['queued'] == stats['logged']
    assert rows >= received >= SAMPLES
    assert not [n for n in os.listdir(tmp_path) if 'partial' in n]
