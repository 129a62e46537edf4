"""
The rig node's publishing threads: clock-mode ticks on schedule, follow-mode samples.

numpy only (the node passes its clock and publishers in as callables).  Clock mode's
promise under overload: `docs/node.md` (*Parameters*).
"""

from collections import Counter, deque
import threading
import time

from mech_balance.ros.guard import Guard
from mech_balance.ros.streaming import batch_size, ClockSchedule, TWO_PI, withhold_nonfinite
import numpy as np

MAX_LAG_S = 0.5
"""Clock mode: a tick later than this is skipped (counted) instead of published late."""
CLOCK_JUMP_S = 5.0
"""Clock mode: a tick later than this is a jump of the clock (the schedule restarts)."""
STALL_SHARE = 0.5
"""Clock mode: a tick later than CLOCK_JUMP_S is a stall, not a jump, when this share of
the clock's advance since the last step also passed on the monotonic clock."""
NO_CLOCK_WARN_S = 3.0
"""Clock mode: a node clock reading 0 (no ``/clock`` yet) this long is reported."""
NO_CLOCK_REPEAT_S = 30.0
"""Interval between two reports of a clock that still reads 0."""
MAX_WAIT_S = 0.005
"""Longest single wait of the publishing thread (bounds its reaction to sim-time jumps)."""
MAX_FOLLOW_BATCH = 256
"""Follow mode: most encoder samples evaluated in one core call."""
MAX_PENDING = 10000
"""Follow mode: encoder samples waiting for evaluation before the oldest are dropped."""
STATS_WINDOW = 4096
"""Per-callback times kept for the median (the most recent ones)."""


class TickStats:
    """Wall time of the publishing step of each sample since the last mode, rate or speed."""

    def __init__(self):
        self.count = 0
        self.skipped = 0
        self.withheld = 0   # samples with a non-finite value, never published
        self.late_max_s = 0.0
        self.first_tick = None  # clock mode: the first tick index sent, the last one passed
        self.last_tick = None
        self.rebased = 0        # clock mode: schedules started again (a clock jump)
        self._times = deque(maxlen=STATS_WINDOW)
        self.batch_seconds = deque(maxlen=64)
        self.batch_sizes = deque(maxlen=64)

    def add(self, seconds):
        """Record one publishing step."""
        self.count += 1
        self._times.append(seconds)

    def summary(self):
        """Return the counts, publishing step percentiles and compute per sample (a dict)."""
        times = np.array(self._times) if self._times else np.zeros(1)
        per_tick = (sum(self.batch_seconds) / sum(self.batch_sizes)) if self.batch_sizes \
            else float('nan')
        return {'published': self.count, 'skipped': self.skipped, 'withheld': self.withheld,
                'step_median_s': float(np.median(times)),
                'step_p99_s': float(np.percentile(times, 99)),
                'late_max_s': self.late_max_s,
                'ticks_due': 0 if self.first_tick is None else
                self.last_tick - self.first_tick + 1, 'rebased': self.rebased,
                'prepare_per_sample_s': per_tick}


class Streamer:
    """
    The publishing threads of the rig node (no ROS inside: callables are passed in).

    ``now_ns()``, ``prepare(samples, stamps_ns)`` (one payload per sample), ``publish(payload)``,
    ``warn(text)``, ``record(samples, turned_rad, stamps_ns)`` (optional); ``guard`` counts
    what the threads catch (an exception skips one step).  Clock mode: one thread publishes,
    a second prepares the next batch ahead; follow mode: samples queued by :meth:`push` are
    evaluated in batches.  A sample with a non-finite value is withheld, never published.
    """

    def __init__(self, now_ns, prepare, publish, warn, record=None, guard=None):
        self._now_ns = now_ns
        self._guard = guard if guard is not None else Guard(warn)
        self._zero_clock_since = None   # monotonic time since the clock reads 0
        self._zero_clock_warned = None
        self._prepare = prepare
        self._publish = publish
        self._warn = warn
        self._record = record
        self._cond = threading.Condition()
        self._generation = 0
        self._mode = None
        self._model = None
        self._schedule = None
        self._batches = deque()        # (k0, payloads), contiguous, ascending
        self._next_k = None
        self._pending = deque()        # CrankSample, follow mode
        self.follow_exact = False      # follow mode: the exact core, never the cycle table
        self._stopped = False
        self._refill = threading.Event()  # wakes the precompute thread (not every tick)
        self.stats = TickStats()
        self.published_total = 0        # since the start, across restarts
        self.unanswered = Counter()     # follow mode: samples queued, never published, why
        self._last_step = None          # (node clock ns, monotonic s) of the last clock step
        self._threads = [threading.Thread(target=self._run_publisher, name='rig-publish',
                                          daemon=True),
                         threading.Thread(target=self._run_precompute, name='rig-precompute',
                                          daemon=True)]
        for t in self._threads:
            t.start()

    def clock(self, model, speed_rad_s, period_ns, angle0_rad=0.0):
        """Publish ticks of ``model`` at ``speed_rad_s`` every ``period_ns``, continuing on."""
        with self._cond:
            now = self._now_ns()
            if self._mode == 'clock' and self._schedule is not None:
                schedule = self._schedule.rebased(now, float(speed_rad_s), int(period_ns))
            else:
                schedule = ClockSchedule(int(now), int(period_ns), float(angle0_rad),
                                         float(speed_rad_s))
            self._restart('clock', model, schedule)

    def follow(self, model):
        """Publish one sample of ``model`` per encoder sample pushed."""
        with self._cond:
            self._restart('follow', model, None)

    def set_model(self, model):
        """Publish another design (or re-prepare) from the next sample on, same schedule."""
        with self._cond:
            self._restart(self._mode, model, self._schedule, keep_pending=True)

    @property
    def clock_schedule(self):
        """Return the clock-mode :class:`ClockSchedule` in force, or None (follow mode)."""
        with self._cond:
            return self._schedule if self._mode == 'clock' else None

    def push(self, sample):
        """Queue a follow-mode :class:`CrankSample`; return False if the oldest was dropped."""
        with self._cond:
            dropped = len(self._pending) >= MAX_PENDING
            if dropped:
                self._pending.popleft()
                self.unanswered['queue full (the core fell behind)'] += 1
            self._pending.append(sample)
            self._cond.notify_all()
        return not dropped

    def stop(self, timeout=2.0):
        """Stop both threads (idempotent)."""
        with self._cond:
            self._stopped = True
            self._cond.notify_all()
        self._refill.set()
        for t in self._threads:
            if t is not threading.current_thread():
                t.join(timeout)

    def _restart(self, mode, model, schedule, keep_pending=False):
        self._last_step = None
        if not keep_pending:  # a new mode, rate or speed: statistics start again
            self.stats = TickStats()
        same_ticks = keep_pending and schedule is not None and schedule is self._schedule
        self._generation += 1
        self._mode, self._model, self._schedule = mode, model, schedule
        self._batches.clear()
        if not same_ticks:   # a design switch goes on from the next tick: none left out
            self._next_k = None
        if not keep_pending and self._pending:
            self.unanswered['discarded by a mode, rate or scene change'] += len(self._pending)
            self._pending.clear()
        self._cond.notify_all()

    def _evaluate_ticks(self, model, schedule, k0, count):
        """Return the payloads of ticks ``k0 ..``: the core on their exact angles, prepared."""
        t0 = time.perf_counter()
        turned = schedule.turned(k0, count)
        samples = model.evaluate(np.mod(turned, TWO_PI), schedule.speed_rad_s, 0.0)
        stamps = schedule.epoch_ns + np.arange(k0, k0 + count, dtype=np.int64) * \
            schedule.period_ns
        payloads = self._prepared(samples, stamps)
        self.stats.batch_seconds.append(time.perf_counter() - t0)
        self.stats.batch_sizes.append(count)
        if self._record is not None:
            self._record(samples, turned, stamps)
        return payloads

    def _evaluate_follow(self, model, batch):
        """Evaluate queued encoder samples; on a core error, one by one (skipping bad ones)."""
        t0 = time.perf_counter()
        evaluate = model.evaluate if self.follow_exact else \
            getattr(model, 'follow_evaluate', model.evaluate)
        try:
            _, angle, _, speed, accel = zip(*batch)   # the CrankSample fields, as columns
            groups = [(evaluate(angle, speed, accel), batch)]
        except ValueError:
            groups = []
            for s in batch:
                try:
                    groups.append((evaluate([s.angle_rad], [s.speed_rad_s],
                                            [s.accel_rad_s2]), [s]))
                except ValueError as exc:
                    with self._cond:
                        self.unanswered['refused by the core'] += 1
                    self._warn(f'crank_joint_state: skipped the sample at '
                               f'{s.stamp_ns * 1e-9:.9f} s: {exc}')
        out = []
        for samples, group in groups:
            stamp, _, turned, _, _ = zip(*group)
            stamps = np.array(stamp, dtype=np.int64)
            out.append(self._prepared(samples, stamps))
            if self._record is not None:
                self._record(samples, np.array(turned), stamps)
        self.stats.batch_seconds.append(time.perf_counter() - t0)
        self.stats.batch_sizes.append(len(batch))
        return [p for payloads in out for p in payloads]

    def _prepared(self, samples, stamps):
        """Prepare a batch; a sample with a non-finite value gets the payload None."""
        samples, ok = withhold_nonfinite(samples)
        payloads = list(self._prepare(samples, stamps))
        if not ok.all():
            for i in np.flatnonzero(~ok):
                payloads[i] = None
        return payloads

    def _send(self, payload):
        """Publish one payload, the last check first: None (non-finite) is withheld."""
        if payload is None:
            self.stats.withheld += 1
            self._warn(f'publishing: withheld a sample with a non-finite value '
                       f'({self.stats.withheld} so far); nothing non-finite is published')
            return
        t0 = time.perf_counter()
        self._publish(payload)
        self.stats.add(time.perf_counter() - t0)
        self.published_total += 1

    def _run_publisher(self):
        while True:
            with self._cond:
                if self._stopped:
                    return
                mode = self._mode
                if mode is None:
                    self._cond.wait(MAX_WAIT_S * 20)
                    continue
            try:
                if mode == 'clock':
                    self._clock_step()
                else:
                    self._follow_step()
            except Exception as exc:  # noqa: BLE001 - the node never dies on a sample
                self._guard.caught('publishing failed', exc)
                time.sleep(MAX_WAIT_S)

    def _clock_step(self):
        with self._cond:
            gen, model, schedule = self._generation, self._model, self._schedule
            now = self._now_ns()
            if now == 0:  # simulated time that has not started (no /clock yet)
                self._report_zero_clock()
                self._cond.wait(MAX_WAIT_S)
                return
            self._zero_clock_since = self._zero_clock_warned = None
            if schedule.epoch_ns == 0:  # the schedule was made before the clock started
                schedule = self._schedule = ClockSchedule(
                    now, schedule.period_ns, schedule.angle0_rad, schedule.speed_rad_s)
            k = self._next_k
            if k is None:
                k = schedule.first_index_at_or_after(now)
            due = schedule.time_ns(k)
            if due > now + schedule.period_ns + int(MAX_LAG_S * 1e9):
                self._rebase(schedule, now)   # the clock went back (a simulation restarted)
                return
            if due > now:
                self._next_k = k
                self._cond.wait(min((due - now) * 1e-9, MAX_WAIT_S))
                return
            late = (now - due) * 1e-9
            last, mono = self._last_step, time.monotonic()
            self._last_step = (now, mono)
            held = last is not None and mono - last[1] >= STALL_SHARE * (now - last[0]) * 1e-9
            if late > CLOCK_JUMP_S and held:  # this thread was held, the clock ran on
                skipped = self._skip(schedule, k, now)
                self._warn(f'clock mode: publishing was held up for {mono - last[1]:.3g} s '
                           f'(not a clock jump: the clock advanced as much): skipped '
                           f'{skipped} ticks')
                return
            if late > CLOCK_JUMP_S:  # use_sim_time switched, a simulation resumed
                self._rebase(schedule, now)
                self._warn(f'clock mode: the clock jumped forward by {late:.3g} s (use_sim_time '
                           'switched or a simulation resumed): publishing from now on, no '
                           'ticks counted as skipped')
                return
            if late > MAX_LAG_S:
                skipped = self._skip(schedule, k, now)
                self._warn(f'clock mode: skipped {skipped} ticks ({late:.3f} s late: the '
                           'clock jumped or the machine is overloaded)')
                return
            found = self._lookup(k)
        if found is None:  # not prepared yet (start, design change): evaluate it now
            payloads = self._evaluate_ticks(model, schedule, k, batch_size(schedule.period_ns))
            with self._cond:
                if gen != self._generation:
                    return
                self._batches.clear()
                self._batches.append((k, payloads))
                found = payloads[0]
        self._send(found)
        if self.stats.first_tick is None:
            self.stats.first_tick = k - self.stats.skipped   # skips before the first send
        self.stats.last_tick = k
        self.stats.late_max_s = max(self.stats.late_max_s, late)
        with self._cond:
            if gen == self._generation:
                self._next_k = k + 1
                if self._needs_refill():
                    self._refill.set()

    def _rebase(self, schedule, now):
        """Start the schedule again from ``now`` (lock held)."""
        self._schedule = schedule.rebased(now)
        self.stats.rebased += 1
        self._next_k = None
        self._batches.clear()
        self._generation += 1

    def _skip(self, schedule, k, now):
        """Skip from tick ``k`` to the first tick at ``now``; return the count (lock held)."""
        k_now = schedule.first_index_at_or_after(now)
        self.stats.skipped += k_now - k
        self._next_k = k_now
        self._batches.clear()
        return k_now - k

    def _report_zero_clock(self):
        """Say so when the clock has read 0 for NO_CLOCK_WARN_S (lock held)."""
        now = time.monotonic()
        if self._zero_clock_since is None:
            self._zero_clock_since = now
        waited = now - self._zero_clock_since
        last = self._zero_clock_warned
        if waited >= NO_CLOCK_WARN_S and (last is None or now - last >= NO_CLOCK_REPEAT_S):
            self._zero_clock_warned = now
            self._warn(f'clock mode: not publishing: the node clock has read 0 for {waited:.0f} '
                       's (use_sim_time is true and no /clock message has arrived; start the '
                       'simulation or set use_sim_time false)')

    def _needs_refill(self):
        """Return whether less than one batch lies ahead of the next tick (lock held)."""
        if not self._batches or self._next_k is None:
            return False
        k0, last = self._batches[-1]
        return k0 + len(last) - self._next_k < batch_size(self._schedule.period_ns)

    def _lookup(self, k):
        while self._batches:
            k0, payloads = self._batches[0]
            if k < k0:
                return None
            if k < k0 + len(payloads):
                return payloads[k - k0]
            self._batches.popleft()
        return None

    def _run_precompute(self):
        """Evaluate the next clock-mode batch whenever less than one batch lies ahead."""
        while not self._stopped:
            try:
                self._precompute_step()
            except Exception as exc:  # noqa: BLE001 - reported, the publisher retries
                self._guard.caught('clock mode: evaluating ticks', exc)
                time.sleep(MAX_WAIT_S * 20)

    def _precompute_step(self):
        """Evaluate one clock-mode batch if less than one batch lies ahead."""
        self._refill.wait(MAX_WAIT_S * 20)
        self._refill.clear()
        with self._cond:
            if self._stopped:
                return
            if self._mode != 'clock' or not self._needs_refill():
                return
            k0, last = self._batches[-1]
            gen, model, schedule = self._generation, self._model, self._schedule
            k0, count = k0 + len(last), batch_size(schedule.period_ns)
        payloads = self._evaluate_ticks(model, schedule, k0, count)
        with self._cond:
            if gen == self._generation and self._batches:
                k_last, last = self._batches[-1]
                if k_last + len(last) == k0:
                    self._batches.append((k0, payloads))

    def _follow_step(self):
        with self._cond:
            if not self._pending:
                self._cond.wait(MAX_WAIT_S * 20)
                return
            gen, model = self._generation, self._model
            batch = [self._pending.popleft()
                     for _ in range(min(len(self._pending), MAX_FOLLOW_BATCH))]
        payloads = self._evaluate_follow(model, batch)
        for i, payload in enumerate(payloads):
            with self._cond:
                if gen != self._generation or self._stopped:
                    self.unanswered['evaluated for a design switched away from'] += \
                        len(payloads) - i
                    return
            self._send(payload)
