"""The live recording of a running rig (the node's hook): to a file, to a viewer."""

import atexit
from collections import deque
import threading

from mech_balance import atomic, conventions
from mech_balance.viz.drawing import concat_motions, live_motion, plan
from mech_balance.viz.streams import (
    application_id, check_output_path, check_viewer_url, log_motion, start_stream
)
import numpy as np
import rerun as rr


CLOSE_TIMEOUT_S = 5.0
"""How long :meth:`LiveRecorder.close` waits for a logging call on another thread."""
LIVE_MAX_RATE_HZ = 30.0
"""The live view logs at most this many samples per second of the rig's clock."""
LIVE_FLUSH_HZ = 5.0
"""The live view's thread sends what it kept at most this often (per second of the rig's
clock): a send costs ~15 ms of Python whatever its size, which the publishing thread waits
for in slices of the node's switch interval."""
LIVE_QUEUE = 256
"""Batches waiting for the live view's thread; when full the oldest is dropped."""


class LiveView:
    """
    The views of a running rig streamed to a viewer, throttled, on a thread of its own.

    :meth:`push` only queues a batch (the oldest is dropped when :data:`LIVE_QUEUE` are
    waiting) and returns; the thread keeps at most one sample per 1 / :data:`LIVE_MAX_RATE_HZ`
    seconds of the rig's clock, evaluates the other design and logs.  A viewer that is slow
    or gone never holds up the caller.
    """

    def __init__(self, url, scene, layout):
        self.url = url
        self.layout = layout
        self.samples_logged = 0
        self._queue = deque(maxlen=LIVE_QUEUE)
        self._cond = threading.Condition()
        self._stopped = False
        self._next_t = None
        self._t0 = None
        self._rec = rr.RecordingStream(application_id(scene))
        self._rec.connect_grpc(url)
        start_stream(self._rec, scene, layout)
        self._thread = threading.Thread(target=self._run, name='rig-live-view', daemon=True)
        self._thread.start()

    def push(self, t, psi, data):
        """Queue a batch (the rig's clock in s, cumulative crank angles, original RigData)."""
        with self._cond:
            if self._stopped:
                return
            self._queue.append((t, psi, data))
            self._cond.notify()

    def _run(self):
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
            if due:
                try:
                    self._log(pending)
                except Exception:  # noqa: BLE001 - a viewer that went away stops nothing
                    pass
                pending = []
            if stopped:
                return

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
        self.samples_logged += t.size

    def close(self):
        """Send what is queued and disconnect (idempotent)."""
        with self._cond:
            if self._stopped:
                return
            self._stopped = True
            self._cond.notify()
        self._thread.join(CLOSE_TIMEOUT_S)
        try:
            self._rec.flush(timeout_sec=CLOSE_TIMEOUT_S)
        finally:
            self._rec.disconnect()


class LiveRecorder:
    """
    Record a running rig sample by sample (used by the rig node): to a file and/or a viewer.

    ``LiveRecorder(path, scene, balanced=None)`` opens ``path`` (``.rrd``, checked by
    :func:`check_output_path`, whose errors name ``field``; None for no file) and, with
    ``url`` (a running viewer's ``rerun+http://HOST:PORT/proxy``), streams the same views to
    it, throttled to :data:`LIVE_MAX_RATE_HZ` on a thread of its own.  Both are laid out
    from one reference turn (``scene.samples`` angles).  :meth:`log_sample` appends samples
    (the file gets every one); :meth:`close` (also run at interpreter exit) flushes and
    closes, is idempotent and safe to call from a signal handler or another thread.  Until
    then the file's samples go to ``.NAME.partial-XXXXXXXX`` next to ``path``
    (:mod:`mech_balance.atomic`); :meth:`close` renames it over ``path``, so an existing
    recording is replaced only by a complete one.
    """

    def __init__(self, path, scene, balanced=None, balanced_source=None, *, field='path',
                 url=None, url_field='rerun_url'):
        self.path = None if path is None else check_output_path(path, field)
        self.url = None if url is None else check_viewer_url(url, url_field)
        if self.path is None and self.url is None:
            raise ValueError(f'{field}, {url_field}: got neither, expected a file or a viewer')
        self.scene = scene
        samples = getattr(scene, 'samples', conventions.DEFAULT_SAMPLES)
        self.layout, _ = plan(scene, balanced, samples, balanced_source, live=True)
        self._lock = threading.Lock()
        self._owner = None
        self._closed = False
        self._close_requested = False
        self.samples_logged = 0
        self._t0 = None
        self._rec = self._partial = self._view = None
        if self.path is not None:
            # visibly partial (.NAME.partial-XXXXXXXX) until close() renames it over the path
            self._partial = atomic.partial_path(self.path)
            try:
                self._rec = rr.RecordingStream(application_id(scene))
                self._rec.save(str(self._partial))
                start_stream(self._rec, scene, self.layout)
            except BaseException:
                atomic.discard(self._partial)
                raise
        if self.url is not None:
            self._view = LiveView(self.url, scene, self.layout)
        atexit.register(self.close)

    @property
    def closed(self):
        """Return whether the recording has been closed."""
        return self._closed

    @property
    def view_samples_logged(self):
        """Return how many samples the live view has sent (after throttling)."""
        return 0 if self._view is None else self._view.samples_logged

    def log_sample(self, time_s, crank_angle_rad, state=None, wrenches=None,
                   balanced_wrenches=None, data=None):
        """
        Append one sample (scalars) or a batch ``(p,)`` of samples; return the count taken.

        ``crank_angle_rad`` is the cumulative crank angle (the ``crank_angle`` timeline shows
        it rounded to whole degrees), ``time_s`` the rig's clock in seconds (the ``time``
        timeline counts from the first sample logged).  ``data`` is the original design's
        :class:`~mech_balance.core.rig.RigData` at those angles if the caller has it (the
        node does), saving its evaluation; everything missing is evaluated here through the
        rig.  ``state``, ``wrenches`` and ``balanced_wrenches`` (a planar core's own
        results) are accepted for older callers and not read: the rig's data is.  After
        :meth:`close` nothing is logged and 0 is returned.
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
        if state is not None and getattr(state, 'size', psi.size) != psi.size:
            raise ValueError(f'state: got {state.size} angles, expected {psi.size}')
        if self._closed or self._close_requested:
            return 0
        if self._view is not None:
            self._view.push(t, psi, data)
        if self._rec is None:
            return psi.size
        motion = live_motion(self.layout, psi, data)
        degrees = np.round(np.degrees(psi)).astype(np.int64)
        if not self._lock.acquire(timeout=CLOSE_TIMEOUT_S):
            return 0
        self._owner = threading.get_ident()
        try:
            if self._closed:
                return 0
            if self._t0 is None:
                self._t0 = float(t[0])
            log_motion(self._rec, self.layout, motion, degrees, t - self._t0)
            self.samples_logged += psi.size
        finally:
            self._owner = None
            self._lock.release()
        if self._close_requested:
            self.close()
        return psi.size

    def close(self):
        """Flush and close the file and the viewer stream (idempotent; signal-safe)."""
        if self._closed:
            return
        self._close_requested = True
        if self._owner == threading.get_ident():
            return  # interrupted a log call on this thread: it closes the file when done
        if not self._lock.acquire(timeout=CLOSE_TIMEOUT_S):
            return
        try:
            if not self._closed:
                self._closed = True
                try:
                    if self._view is not None:
                        self._view.close()
                finally:
                    atexit.unregister(self.close)
                    if self._rec is not None:
                        try:
                            self._rec.flush(timeout_sec=CLOSE_TIMEOUT_S)
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
