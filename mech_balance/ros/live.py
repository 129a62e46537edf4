"""
The rig node's recording part: ``recording_path`` (a file) and ``rerun_url`` (a viewer).

Never holds the caller: a thread of its own probes the viewer, opens, logs and closes, each
with a bounded wait (`docs/node.md`, *A dead viewer holds nothing*).
"""

from collections import deque
import socket
import sys
import threading
import time
from urllib.parse import urlsplit

from mech_balance.ros import diagnostics

QUEUE_BATCHES = 1024
"""Batches waiting for the recording thread before the oldest are dropped (counted)."""
PROBE_TIMEOUT_S = 1.0
"""Longest wait for a viewer's address to accept a TCP connection."""
RETRY_S = 5.0
"""A viewer found dead is tried again after this long."""
CLOSE_TIMEOUT_S = 5.0
"""Longest wait for a viewer's stream to close (rerun itself waits 5 s for a dead one)."""
FILE_CLOSE_TIMEOUT_S = 120.0
"""Longest wait for the file to be written whole and closed (longer: a stuck disk)."""
IDLE_WAIT_S = 0.05
"""Longest sleep of the recording thread between two looks at its queue."""
OFF, CONNECTING, CONNECTED, DEAD = 'off', 'connecting', 'connected', 'dead'


def viewer_address(url):
    """Return ``(host, port)`` of a viewer URL ``rerun+http://HOST:PORT/proxy``."""
    parts = urlsplit(url.replace('rerun+', '', 1).replace('rerun://', 'http://', 1))
    return parts.hostname or '127.0.0.1', parts.port or 9876


def probe_viewer(url, timeout_s=PROBE_TIMEOUT_S):
    """Return None if something accepts a TCP connection at the viewer's address, else why."""
    host, port = viewer_address(url)
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            return None
    except OSError as exc:
        return f'nothing answers at {host}:{port} ({exc.strerror or exc})'


class _Target:
    """One recorder (the file, or the viewer) and its state, owned by the recording thread."""

    def __init__(self, is_viewer, where):
        self.is_viewer, self.where = is_viewer, where
        self.recorder = None
        self.status = CONNECTING
        self.retry_at = 0.0

    def state(self):
        own = getattr(self.recorder, 'status', None)
        return own if isinstance(own, str) else self.status


class Recording:
    """
    The node's recording and live view, run on a thread of their own.

    ``log(level, text)`` logs; ``make(path, url, scene, balanced)`` returns a recorder.
    """

    def __init__(self, log, make):
        self._log = log
        self._make = make
        self._cond = threading.Condition()
        self._queue = deque(maxlen=QUEUE_BATCHES)
        self._wanted = None        # (generation, path, url, scene, balanced) to open
        self._generation = 0
        self._opened = 0           # the generation opened by the thread
        self._context = (None, None)
        self._targets = []
        self._stopped = False
        self.dropped = 0
        self.logged = 0
        self.queued = 0            # samples pushed for the recording now asked for
        self.died = None           # why the recording thread stopped on an error, if it did
        self._thread = threading.Thread(target=self._run_guarded, name='rig-recording',
                                        daemon=True)
        self._thread.start()

    def start(self, path, url, scene, balanced=None):
        """
        Record ``scene`` (against ``balanced``) to ``path`` and/or ``url``; returns at once.

        The batches queued for the same scene and design stay queued.
        """
        with self._cond:
            same = self._wanted is not None and self._wanted[3] is scene and \
                self._wanted[4] is balanced
            same_file = same and self._wanted[1] == (path or None)
            self._generation += 1
            self._wanted = (self._generation, path or None, url or None, scene, balanced)
            if not same:
                self._queue.clear()
            if not same_file:   # the same file goes on (only the viewer changed): its count too
                self.queued = sum(len(batch[0]) for batch in self._queue)
            self._cond.notify_all()

    @property
    def active(self):
        """Return whether a file or a viewer is asked for."""
        with self._cond:
            return self._wanted is not None and (self._wanted[1] or self._wanted[2])

    def push(self, samples, turned_rad, stamps_ns, original=True):
        """Queue an evaluated batch (never blocks; the oldest dropped when full; not closing)."""
        with self._cond:
            if self._stopped or not self.active:
                return
            if len(self._queue) == self._queue.maxlen:
                self.dropped += 1
            self.queued += len(stamps_ns)
            self._queue.append((stamps_ns * 1e-9, turned_rad, samples if original else None))
            self._cond.notify_all()

    @property
    def status(self):
        """Return the viewer's state: 'off', 'connecting', 'connected' or 'dead: <reason>'."""
        with self._cond:
            wanted, targets = self._wanted, list(self._targets)
        if wanted is None or not wanted[2]:
            return OFF
        for t in targets:
            if t.is_viewer:
                return t.state()
        return CONNECTING

    def file_status(self):
        """Return the file's state: 'off', 'recording', 'opening', 'closed' or 'dead: <why>'."""
        with self._cond:
            wanted, targets = self._wanted, list(self._targets)
        if self.died is not None:
            return f'{DEAD}: the recording thread stopped: {self.died}'
        if wanted is None or not wanted[1]:
            return OFF
        if self._stopped and not self._thread.is_alive():
            return 'closed'
        for t in targets:
            if not t.is_viewer:
                return 'recording' if t.status == CONNECTED else t.status
        return 'opening'

    def diagnostic_statuses(self, name, hardware_id):
        """Return the ``recording`` and ``live view`` statuses that apply (a list)."""
        out = []
        state = self.file_status()
        if state != OFF:
            path = self._wanted[1] if self._wanted else ''
            level = diagnostics.ERROR if state.startswith(DEAD) else diagnostics.OK
            out.append(diagnostics.Status(
                f'{name}: recording', level, f'recording_path {path}: {state}', hardware_id,
                [('path', str(path)), ('status', state), ('samples queued', str(self.queued)),
                 ('samples logged', str(self.logged)),
                 ('batches dropped', str(self.dropped))]))
        live_view = self.diagnostic_status(name, hardware_id)
        if live_view is not None:
            out.append(live_view)
        return out

    def diagnostic_status(self, name, hardware_id):
        """Return the ``live view`` :class:`~mech_balance.ros.diagnostics.Status`, or None."""
        status = self.status
        if status == OFF:
            return None
        url = self._wanted[2] if self._wanted else ''
        level = diagnostics.OK if status == CONNECTED else \
            diagnostics.WARN if status == CONNECTING else diagnostics.ERROR
        return diagnostics.Status(f'{name}: live view', level, f'rerun_url {url}: {status}',
                                  hardware_id, [('url', str(url)), ('status', status),
                                                ('batches dropped', str(self.dropped))])

    def close(self, timeout_s=None):
        """Log the queued batches, write the file, stop the thread; wait at most ``timeout_s``."""
        with self._cond:
            self._stopped = True
            self._cond.notify_all()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout_s)

    def _say(self, level, text):
        """Log through the node; if even that fails, to stderr (never raises)."""
        try:
            self._log(level, text)
        except Exception as exc:  # noqa: BLE001 - the log itself failed: the console
            print(f'rig_node: recording: {text} (and logging failed: {exc})',
                  file=sys.stderr, flush=True)

    def _run_guarded(self):
        """Run the thread; if it stops on an error, say so (log, /diagnostics)."""
        try:
            self._run()
        except BaseException as exc:  # noqa: BLE001 - reported, and the rig goes on
            self.died = f'{type(exc).__name__}: {exc}'
            self._say('error', f'recording: the recording thread stopped: {self.died}; '
                      'nothing more is recorded (the rig goes on publishing)')

    def _run(self):
        while True:
            try:
                self._retry_dead()
            except Exception as exc:  # noqa: BLE001 - the recording never stops the rig
                self._say('warning', f'recording: {type(exc).__name__}: {exc}')
            with self._cond:
                wanted = self._wanted
                if wanted is not None and wanted[0] == self._opened:
                    wanted = None
                if wanted is None and not self._queue and not self._stopped:
                    self._cond.wait(IDLE_WAIT_S)
                    continue  # look again: what woke the thread is read afresh
                if wanted is not None:
                    self._opened = wanted[0]
                batches = list(self._queue)
                self._queue.clear()
                stopped = self._stopped
            try:
                if wanted is not None:
                    self._reopen(*wanted[1:])
                for batch in batches:
                    self._log_batch(batch)
            except Exception as exc:  # noqa: BLE001 - the recording never stops the rig
                self._say('warning', f'recording: {type(exc).__name__}: {exc}')
            if stopped:
                self._close_all()
                return

    def _reopen(self, path, url, scene, balanced):
        # a file of the same scene and design goes on as it is (only the viewer changed):
        # closed and opened again, it would be replaced by one without its first samples
        kept = [t for t in self._targets if not t.is_viewer and t.where == path and
                t.recorder is not None and self._context[0] is scene and
                self._context[1] is balanced]
        for t in self._targets:
            if t not in kept:
                self._close_one(t)
        if not kept:
            self.logged = 0
        targets = list(kept)
        if path and not kept:
            targets.append(_Target(False, path))
        if url:
            targets.append(_Target(True, url))
        with self._cond:
            self._targets = targets
            self._context = (scene, balanced)
        for t in targets:
            if t not in kept:
                self._connect(t)
        said = [f'{"streaming the views to" if t.is_viewer else "recording to"} {t.where}'
                for t in targets if t.recorder is not None and t not in kept]
        if said:
            self._say('info', ' and '.join(said))

    def _connect(self, target):
        scene, balanced = self._context
        if target.is_viewer:
            why = probe_viewer(target.where)
            if why is not None:
                self._mark_dead(target, why)
                return
        path, url = (None, target.where) if target.is_viewer else (target.where, None)
        try:
            target.recorder = self._make(path, url, scene, balanced)
            target.status = CONNECTED
        except (ValueError, OSError) as exc:  # checked when set; the disk may change
            if not target.is_viewer:
                self._say('error', f'not recording: {exc}')
                self._file_dead(target, exc)
            else:
                self._mark_dead(target, str(exc))

    def _file_dead(self, target, exc):
        """Mark the file dead for good (it is not tried again)."""
        target.status = f'{DEAD}: {exc}'
        target.retry_at = float('inf')

    def _mark_dead(self, target, why):
        first = not target.status.startswith(DEAD)
        target.status = f'{DEAD}: {why}'
        target.recorder = None
        target.retry_at = time.monotonic() + RETRY_S
        if first:
            self._say('error', f'rerun_url {target.where}: the viewer is dead: {why}; '
                      f'publishing goes on, trying again every {RETRY_S:g} s')

    def _retry_dead(self):
        now = time.monotonic()
        for t in list(self._targets):
            if t.is_viewer and t.recorder is None and now >= t.retry_at:
                self._connect(t)
                if t.recorder is not None:
                    self._say('info', f'rerun_url {t.where}: connected')

    def _log_batch(self, batch):
        t_s, turned, data = batch
        counted = self._targets[0] if self._targets else None   # the file if any, else the view
        for t in self._targets:
            if t.recorder is None:
                continue
            try:
                log = getattr(t.recorder, 'log_sample', None) or t.recorder.push
                taken = log(t_s, turned, data=data)
                if t is counted:    # what the recorder says it took (a count), else the batch
                    self.logged += taken if isinstance(taken, int) else len(t_s)
            except Exception as exc:  # noqa: BLE001 - a full disk must not stop the rig
                if not t.is_viewer:
                    self._say('warning', f'recording_path: stopped recording: {exc}')
                    self._close_one(t)
                    self._file_dead(t, exc)
                else:
                    self._close_one(t)
                    self._mark_dead(t, str(exc))

    def _close_one(self, target):
        rec, target.recorder = target.recorder, None
        if rec is None:
            return
        done = threading.Event()

        def close():
            try:
                try:
                    rec.close(CLOSE_TIMEOUT_S)
                except TypeError:  # a recorder whose close takes no timeout
                    rec.close()
            except Exception as exc:  # noqa: BLE001 - reported, never fatal
                self._say('warning', f'recording: closing {target.where}: {exc}')
            finally:
                done.set()
        worker = threading.Thread(target=close, name='rig-recording-close', daemon=True)
        worker.start()
        limit = CLOSE_TIMEOUT_S if target.is_viewer else FILE_CLOSE_TIMEOUT_S
        if not done.wait(limit):
            self._say('warning', f'recording: {target.where} did not close within '
                      f'{limit:g} s; left behind')

    def _close_all(self):
        for t in self._targets:
            self._close_one(t)
        self._targets = []
