"""SIGINT and SIGTERM during a write: no ``.partial`` file left, the status says what happened."""

import os
from pathlib import Path
import signal
import subprocess
import sys
import time

from mech_balance import atomic
import pytest

ROOT = Path(__file__).resolve().parents[1]
POLL_S = 0.0005
TIMEOUT_S = 120


def _record(out):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.Popen(
        [sys.executable, '-m', 'mech_balance.cli', 'record', '--scene', 'hoeken',
         '--samples', '3600', '--cycles', '10', '--out', str(out)],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _signal_when(proc, ready, signum):
    """Send ``signum`` as soon as ``ready()`` holds; return whether it was sent."""
    deadline = time.monotonic() + TIMEOUT_S
    while proc.poll() is None and time.monotonic() < deadline:
        if ready():
            proc.send_signal(signum)
            return True
        time.sleep(POLL_S)
    return False


@pytest.mark.parametrize('signum', [signal.SIGTERM, signal.SIGINT])
def test_signal_during_the_write_removes_the_partial_file(tmp_path, signum):
    """Signalled with its .partial file on disk, the verb removes it and exits 128 + signal."""
    out = tmp_path / 'big.rrd'
    proc = _record(out)
    sent = _signal_when(
        proc, lambda: any(atomic.PARTIAL_MARK in n for n in os.listdir(tmp_path)), signum)
    _, err = proc.communicate(timeout=TIMEOUT_S)
    assert sent, f'the .partial file never appeared: {err}'
    left = sorted(os.listdir(tmp_path))
    if left == ['big.rrd']:   # the signal came after the rename: the file is complete
        assert proc.returncode == 0, err
        return
    assert left == [], f'files left: {left}; {err}'
    assert proc.returncode == 128 + signum, err
    name = signal.Signals(signum).name
    assert f'interrupted ({name}); not written, its partial file removed: {out}' in err
    assert 'Traceback' not in err


@pytest.mark.parametrize('signum', [signal.SIGTERM, signal.SIGINT])
def test_signal_after_the_write_keeps_the_file_and_exits_0(tmp_path, signum):
    """Signalled once its file is renamed into place, the verb keeps it and exits 0."""
    out = tmp_path / 'big.rrd'
    proc = _record(out)
    sent = _signal_when(proc, out.exists, signum)
    _, err = proc.communicate(timeout=TIMEOUT_S)
    assert sent or proc.returncode == 0, err
    assert sorted(os.listdir(tmp_path)) == ['big.rrd']
    assert proc.returncode == 0, err
    assert 'Traceback' not in err and 'Exception ignored' not in err, err
    if 'interrupted' in err:
        assert f'written completely: {out}' in err


def test_the_list_of_pending_files_is_emptied(tmp_path):
    """discard_pending removes what was not committed; the log says what was written."""
    mark = atomic.write_count()
    tmp = atomic.partial_path(tmp_path / 'a.txt')
    kept = atomic.partial_path(tmp_path / 'b.txt')
    atomic.commit(kept, tmp_path / 'b.txt')
    assert atomic.target_of(tmp) == tmp_path / 'a.txt'
    assert atomic.discard_pending() == [tmp]
    assert sorted(os.listdir(tmp_path)) == ['b.txt']
    assert atomic.written_since(mark) == [tmp_path / 'b.txt']
    assert atomic.discarded_since(mark) == [tmp_path / 'a.txt']
