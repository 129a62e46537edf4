"""The live recording of a running rig (the node's hook): to a file, to a viewer."""

import atexit
from collections import deque
import socket
import threading
import time
from urllib.parse import urlsplit

from mech_balance import atomic, conventions
from mech_balance.paths import check_viewer_url
from mech_balance.viz.drawing import concat_motions, live_motion, plan
from mech_balance.viz.streams import (
    application_id, check_output_path, log_motion, start_stream
)
import numpy as np
import rerun as rr


CLOSE_TIMEOUT_S = 5.0
"""How long :meth:`LiveRecorder.close` gives the viewer (the file is waited for, not timed)."""
LIVE_MAX_RATE_HZ = 30.0
"""The live view logs at most this many samples per second of the rig's clock."""
LIVE_FLUSH_HZ = 5.0
"""The live view's thread sends what it kept at most this often (per second of the rig's
clock): a send costs ~15 ms of Python whatever its size, which the publishing thread waits
for in slices of the node's switch interval."""
LIVE_QUEUE = 256
"""Batches waiting for the live view's thread; when full the oldest is dropped."""
LIVE_FLUSH_TIMEOUT_S = 2.0
"""The live view's thread waits this long for a flush to reach the viewer (else: dead)."""
LIVE_RETRY_S = 5.0
"""A dead viewer is tried again this often (its samples are dropped meanwhile)."""
LIVE_KNOCK_TIMEOUT_S = 1.0
"""How long the view's thread waits for a TCP connection to the viewer's port."""
LIVE_DEFAULT_PORT = 9876
"""The viewer's gRPC port when the url names none (rerun's default)."""


class LiveView:
    """
    The views of a running rig streamed to a viewer, throttled, on a thread of its own.

    :meth:`push` only queues (dropping the oldest beyond :data:`LIVE_QUEUE`); :meth:`close`
    waits at most ``timeout_s``; a dead viewer is retried every :data:`LIVE_RETRY_S`.
    """

    def __init__(self, url, scene, layout=None, balanced=None, balanced_source=None):
        self.url = url
        self.layout = layout
        self._queue = deque(maxlen=LIVE_QUEUE)
        self._cond = threading.Condition()
        self._stopped = False
        self._next_t = None
        self._t0 = None
        self._rec = None
        self._status = 'connecting'
        self._retry_at = 0.0
        self._thread = threading.Thread(
            target=self._run, args=(scene, balanced, balanced_source), name='rig-live-view',
            daemon=True)
        self._thread.start()

    @property
    def status(self):
        """Return ``'connecting'``, ``'connected'`` or ``'dead: <reason>'``."""
        return self._status

    def push(self, t, psi, data):
        """Queue a batch (the rig's clock in s, cumulative crank angles, original RigData)."""
        with self._cond:
            if self._stopped:
                return
            self._queue.append((t, psi, data))
            self._cond.notify()

    def _run(self, scene, balanced, balanced_source):
        try:
            while not self._knock():
                with self._cond:                # nobody listens: drop, wait, knock again
                    self._queue.clear()
                    if self._stopped:
                        return
                    self._cond.wait(LIVE_RETRY_S)
            if self.layout is None:
                samples = getattr(scene, 'samples', conventions.DEFAULT_SAMPLES)
                self.layout, _ = plan(scene, balanced, samples, balanced_source, live=True)
            self._rec = rr.RecordingStream(application_id(scene))
            self._rec.connect_grpc(self.url)
            start_stream(self._rec, scene, self.layout)
            self._flush(LIVE_FLUSH_TIMEOUT_S)
            self._loop()
        except Exception as exc:  # noqa: BLE001 - a dead viewer stops nothing but itself
            self._status = f'dead: {exc}'
        finally:
            self._disconnect()

    def _loop(self):
        pending = []        # (t, psi, data, keep) kept samples, not yet logged
        while True:
            with self._cond:
                if not self._queue and not self._stopped:
                    self._cond.wait(1.0 / LIVE_FLUSH_HZ)
                batches = list(self._queue)
                self._queue.clear()
                stopped = self._stopped
            for t, psi, data in batches:
                keep = self._keep(t)
                if keep.size:
                    pending.append((t[keep], psi[keep], data, keep))
            due = pending and (stopped or pending[-1][0][-1] - pending[0][0][0] >=
                               1.0 / LIVE_FLUSH_HZ)
            if self._status.startswith('dead'):
                pending = []            # nobody listens: drop, and knock now and then
                if not stopped and time.monotonic() >= self._retry_at:
                    self._flush(LIVE_FLUSH_TIMEOUT_S)
            elif due:
                self._log(pending)
                self._flush(LIVE_FLUSH_TIMEOUT_S)
                pending = []
            if stopped:
                return

    def _knock(self):
        """Return whether something accepts a connection at the viewer's port (else: dead)."""
        where = urlsplit(self.url.replace('rerun+', '', 1))
        try:
            with socket.create_connection((where.hostname, where.port or LIVE_DEFAULT_PORT),
                                          timeout=LIVE_KNOCK_TIMEOUT_S):
                return True
        except OSError as exc:
            self._status = (f'dead: nothing accepts a connection at {where.hostname}:'
                            f'{where.port or LIVE_DEFAULT_PORT} ({exc}); retried every '
                            f'{LIVE_RETRY_S:g} s')
            return False

    def _flush(self, timeout_s):
        """Flush to the viewer within ``timeout_s``; set :attr:`status` from the outcome."""
        try:
            self._rec.flush(timeout_sec=timeout_s)
        except Exception as exc:  # noqa: BLE001 - rerun raises RuntimeError; any is 'dead'
            self._status = f'dead: {exc} ({self.url})'
            self._retry_at = time.monotonic() + LIVE_RETRY_S
        else:
            self._status = 'connected'

    def _disconnect(self):
        if self._rec is not None:
            try:
                self._rec.disconnect()      # waits up to 5 s for a viewer that is not there
            except Exception:  # noqa: BLE001 - this thread ends anyway
                pass

    def _keep(self, t):
        """Return the indices of the samples kept by the throttle (rig's clock)."""
        if self._next_t is None:
            self._next_t, self._t0 = float(t[0]), float(t[0])
        keep = []
        for k, tk in enumerate(t):
            if tk >= self._next_t:
                keep.append(k)
                self._next_t = tk + 1.0 / LIVE_MAX_RATE_HZ
        return np.array(keep, dtype=np.int64)

    def _log(self, pending):
        """Send the kept samples of several batches as one batch (one send per entity)."""
        motion = concat_motions([live_motion(self.layout, psi, data, keep)
                                 for _, psi, data, keep in pending])
        t = np.concatenate([p[0] for p in pending])
        psi = np.concatenate([p[1] for p in pending])
        log_motion(self._rec, self.layout, motion, np.round(np.degrees(psi)).astype(np.int64),
                   t - self._t0)

    def close(self, timeout_s=CLOSE_TIMEOUT_S):
        """Ask the thread to send what is queued and disconnect; wait at most ``timeout_s``."""
        with self._cond:
            self._stopped = True
            self._cond.notify()
        self._thread.join(max(0.0, float(timeout_s)))


class LiveRecorder:
    """
    Record a running rig sample by sample (used by the rig node): to a file and/or a viewer.

    ``path``: an ``.rrd`` file (errors name ``field``) or None, replaced only by a complete
    recording at :meth:`close`; ``url``: a viewer's ``rerun+http://HOST:PORT/proxy`` or None
    (throttled to :data:`LIVE_MAX_RATE_HZ`, never blocking the caller).
    """

    def __init__(self, path, scene, balanced=None, balanced_source=None, *, field='path',
                 url=None, url_field='rerun_url'):
        self.path = None if path is None else check_output_path(path, field)
        self.url = None if url is None else check_viewer_url(url, url_field)
        if self.path is None and self.url is None:
            raise ValueError(f'{field}, {url_field}: got neither, expected a file or a viewer')
        self.scene = scene
        samples = getattr(scene, 'samples', conventions.DEFAULT_SAMPLES)
        self._layout = None
        if self.path is not None:       # a viewer alone is laid out on its own thread
            self._layout, _ = plan(scene, balanced, samples, balanced_source, live=True)
        self._lock = threading.Lock()
        self._logging = threading.local()   # set before the lock is taken: see close()
        self._closed = False
        self._close_requested = False
        self.samples_logged = 0
        self._t0 = None
        self._rec = self._partial = self._view = None
        if self.path is not None:     # .NAME.partial-XXXXXXXX until close() renames it
            self._partial = atomic.partial_path(self.path)
            try:
                self._rec = rr.RecordingStream(application_id(scene))
                self._rec.save(str(self._partial))
                start_stream(self._rec, scene, self._layout)
            except BaseException:
                atomic.discard(self._partial)
                raise
        if self.url is not None:
            self._view = LiveView(self.url, scene, self._layout, balanced, balanced_source)
        atexit.register(self.close)

    @property
    def layout(self):
        """Return the recording's layout, or None while a viewer alone is being laid out."""
        return self._layout if self._layout is not None or self._view is None else \
            self._view.layout

    @property
    def status(self):
        """Return ``'off'`` (no viewer), ``'connecting'``, ``'connected'`` or ``'dead: ...'``."""
        return 'off' if self._view is None else self._view.status

    @property
    def closed(self):
        """Return whether the recording has been closed."""
        return self._closed

    def log_sample(self, time_s, crank_angle_rad, data=None):
        """
        Append one sample (scalars) or a batch ``(p,)`` of samples; return the count taken.

        ``crank_angle_rad``: cumulative; ``time_s``: the rig's clock; ``data``: the original's
        :class:`~mech_balance.core.rig.RigData` at those angles, or None.  After :meth:`close`: 0.
        """
        t = np.atleast_1d(np.asarray(time_s, dtype=float)).ravel()
        psi = np.atleast_1d(np.asarray(crank_angle_rad, dtype=float)).ravel()
        if t.shape != psi.shape or t.size == 0:
            raise ValueError(f'time_s: got shape {t.shape}, expected the shape of '
                             f'crank_angle_rad {psi.shape} (one time per angle, >= 1)')
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(psi))):
            raise ValueError('time_s, crank_angle_rad: got non-finite values, expected finite')
        if data is not None and len(data) != psi.size:
            raise ValueError(f'data: got {len(data)} angles, expected {psi.size}')
        if self._closed or self._close_requested:
            return 0
        if self._view is not None:
            self._view.push(t, psi, data)
        if self._rec is None:
            return psi.size
        motion = live_motion(self.layout, psi, data)
        degrees = np.round(np.degrees(psi)).astype(np.int64)
        self._logging.active = True
        try:
            with self._lock:        # held by a close at most: the file's flush, then closed
                if self._closed:
                    return 0
                if self._t0 is None:
                    self._t0 = float(t[0])
                log_motion(self._rec, self.layout, motion, degrees, t - self._t0)
                self.samples_logged += psi.size
        finally:
            self._logging.active = False
        if self._close_requested:
            self.close()
        return psi.size

    def close(self, timeout_s=CLOSE_TIMEOUT_S):
        """
        Flush and close the file and the viewer stream (idempotent; signal-safe).

        The viewer gets at most ``timeout_s``; the file is flushed and renamed over the target.
        """
        if self._closed:
            return
        deadline = time.monotonic() + max(0.0, float(timeout_s))
        self._close_requested = True
        if getattr(self._logging, 'active', False):
            return  # interrupted a log call on this thread: it closes the file when done
        self._lock.acquire()        # a log call on another thread: waited for, then closed
        try:
            if not self._closed:
                self._closed = True
                try:
                    if self._view is not None:
                        # a viewer that answers gets what is left of the time; else none
                        live = self._view.status == 'connected'
                        self._view.close(max(0.0, deadline - time.monotonic()) if live else 0.0)
                finally:
                    atexit.unregister(self.close)
                    if self._rec is not None:
                        try:
                            self._rec.flush()       # blocks until the file has every row
                        finally:
                            self._rec.disconnect()
                        # complete: replace the target (a failed flush leaves the .partial)
                        atomic.commit(self._partial, self.path)
        finally:
            self._lock.release()

    def __enter__(self):
        """Return the recorder (``with LiveRecorder(...) as rec:``)."""
        return self

    def __exit__(self, *exc):
        """Close the file."""
        self.close()
