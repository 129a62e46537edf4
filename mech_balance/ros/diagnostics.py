"""
The rig node's ``/diagnostics`` statuses, as plain data (no ROS: conversions fills messages).

``<node>: publisher``, ``encoder input``, ``model`` and ``measured wrench``, each with the
scene as ``hardware_id``; what each reports and its thresholds:
`docs/identification.md#the-twin-against-the-real-rig` (*Diagnostics and thresholds*).
"""

from collections import Counter
from dataclasses import dataclass, field
import math
import threading

from mech_balance.ros.sensor import MODEL_FLOOR
import numpy as np

OK, WARN, ERROR, STALE = 0, 1, 2, 3
"""diagnostic_msgs/DiagnosticStatus levels."""
LEVEL_NAMES = {OK: 'OK', WARN: 'WARN', ERROR: 'ERROR', STALE: 'STALE'}
RATE_WARN_FRACTION = 0.9
"""Clock mode: an achieved rate below this fraction of publish_rate is a WARN."""
RESIDUAL_ERROR = 1e-7
"""A loop-closure residual above this (relative) is an ERROR: the sample is off the linkage."""
STALE_AFTER_S = 5.0
"""The measured-wrench status is STALE when no measurement arrived for this long."""


@dataclass
class Status:
    """One diagnostic status: name, level, message, hardware id, key-value pairs."""

    name: str
    level: int
    message: str
    hardware_id: str = ''
    values: list = field(default_factory=list)   # [(key, text)]


NOT_MEASURED = 'n/a'
"""The text of a figure that has no finite value (yet): no topic carries nan or inf."""


def _fmt(value):
    if isinstance(value, float):
        return f'{value:.6g}' if math.isfinite(value) else NOT_MEASURED
    return str(value)


def reason_of(exc):
    """Return why a message was rejected: the field its ValueError names, or the error type."""
    if not isinstance(exc, ValueError):
        return f'internal error: {type(exc).__name__}'
    text = str(exc)
    if 'needs a crank speed' in text:
        return 'position jump'
    head = text.split(':', 1)[0].strip()
    return head.split(' ', 1)[0] if head else 'invalid'


class InputCounter:
    """Messages used and rejected by reason (thread-safe)."""

    def __init__(self):
        self._lock = threading.Lock()
        self.used = 0
        self.rejected = Counter()
        self._reported_rejected = 0

    def use(self):
        """Count a used message."""
        with self._lock:
            self.used += 1

    def reject(self, reason):
        """Count a rejected message."""
        with self._lock:
            self.rejected[reason] += 1

    def snapshot(self):
        """Return ``(used, {reason: count}, rejected since the last snapshot)``."""
        with self._lock:
            total = sum(self.rejected.values())
            new = total - self._reported_rejected
            self._reported_rejected = total
            return self.used, dict(self.rejected), new


class ModelWatch:
    """The worst solver diagnostics of the evaluated samples since the last snapshot."""

    def __init__(self):
        self._lock = threading.Lock()
        self._reset()

    def _reset(self):
        self.samples = 0
        self.residual = 0.0
        self.condition = 0.0
        self.near_singular = 0

    def add(self, data):
        """Take the ``residual``, ``condition`` and ``near_singular`` of a RigData batch."""
        res, cond = _worst(data.residual), _worst(data.condition)
        near = 0 if data.near_singular is None else int(np.count_nonzero(data.near_singular))
        with self._lock:
            self.samples += len(data)
            if res is not None:
                self.residual = max(self.residual, res)
            if cond is not None:
                self.condition = max(self.condition, cond)
            self.near_singular += near

    def snapshot(self):
        """Return ``(samples, worst residual, worst condition, near-singular)`` and restart."""
        with self._lock:
            out = (self.samples, self.residual, self.condition, self.near_singular)
            self._reset()
        return out


def _worst(values):
    """Return the largest of ``values`` as a float, or None (None or empty)."""
    if values is None:
        return None
    values = np.asarray(values)
    return float(values.max()) if values.size else None


class RateMeter:
    """Achieved rate from a growing count read at intervals (node clock, ns)."""

    def __init__(self):
        self._last = None     # (count, now_ns)

    def rate(self, count, now_ns):
        """Return the count per second since the previous call (None on the first)."""
        last, self._last = self._last, (count, now_ns)
        if last is None or now_ns <= last[1] or count < last[0]:
            return None
        return (count - last[0]) / ((now_ns - last[1]) * 1e-9)


def publisher_status(name, hardware_id, mode, configured_hz, achieved_hz, published,
                     skipped, skipped_new):
    """Return the publisher :class:`Status` (``configured_hz`` None: one per encoder sample)."""
    level, notes = OK, []
    if skipped_new:
        level = WARN
        notes.append(f'{skipped_new} ticks skipped in the last period')
    measured = achieved_hz is not None and math.isfinite(achieved_hz)
    if configured_hz is not None and measured and \
            achieved_hz < RATE_WARN_FRACTION * configured_hz:
        level = WARN
        notes.append(f'below {RATE_WARN_FRACTION:g} x the configured rate')
    how = f'{configured_hz:g} Hz configured' if configured_hz is not None else \
        'one sample per encoder message'
    achieved = f'{achieved_hz:.1f} Hz achieved' if measured else \
        'achieved rate not measured yet (first period)'
    message = f'{mode} mode, {how}, {achieved}' + (f' ({"; ".join(notes)})' if notes else '')
    return Status(name, level, message, hardware_id, [
        ('mode', mode),
        ('configured rate Hz', 'encoder' if configured_hz is None else _fmt(configured_hz)),
        ('achieved rate Hz', _fmt(float(achieved_hz)) if measured else NOT_MEASURED),
        ('published', _fmt(published)),
        ('skipped ticks', _fmt(skipped))])


def _by_reason(rejected):
    """Return the text and the key-value pairs of ``{reason: count}``, by reason."""
    pairs = sorted(rejected.items())
    return ', '.join(f'{k} {v}' for k, v in pairs), [(f'rejected: {k}', _fmt(v)) for k, v in pairs]


def input_status(name, hardware_id, topic, used, rejected, rejected_new):
    """Return the :class:`Status` of an input topic: used and rejected by reason."""
    total = sum(rejected.values())
    detail, by_reason = _by_reason(rejected)
    message = f'{topic}: {used} used, {total} rejected' + (f' ({detail})' if detail else '')
    return Status(name, WARN if rejected_new else OK, message, hardware_id,
                  [('used', _fmt(used)), ('rejected', _fmt(total))] + by_reason)


def model_status(name, hardware_id, samples, residual, condition, near_singular,
                 evaluation=None):
    """Return the model :class:`Status` of a :class:`ModelWatch` snapshot (and ``evaluation``)."""
    extra = [] if evaluation is None else [('evaluation', str(evaluation))]
    if samples == 0:
        return Status(name, OK, 'no samples evaluated in the last period', hardware_id,
                      [('samples', '0')] + extra)
    level = ERROR if residual > RESIDUAL_ERROR else WARN if near_singular else OK
    message = (f'{samples} samples: worst Newton residual {residual:.2e}, worst condition '
               f'number {condition:.4g}' + (f', {near_singular} near-singular'
                                            if near_singular else ''))
    return Status(name, level, message, hardware_id, [
        ('samples', _fmt(samples)), ('worst residual', _fmt(residual)),
        ('worst condition number', _fmt(condition)),
        ('near singular', 'true' if near_singular else 'false'),
        ('near-singular samples', _fmt(near_singular))] + extra)


def measurement_status(name, hardware_id, rms, components, units, warn_fraction,
                       error_fraction, received, used, rejected, age_s, bias, model_name,
                       resyncs=0):
    """
    Return the measured-wrench :class:`Status`.

    ``rms``: :meth:`Comparison.rms`'s dict (or None); ``age_s``: since the last measurement
    (None: never).  Components the model or the measurement leave at 0 are not judged.
    """
    values = [('received', _fmt(received)), ('paired', _fmt(used)),
              ('rejected', _fmt(sum(rejected.values()))),
              ('re-synchronizations', _fmt(resyncs))]
    detail, by_reason = _by_reason(rejected)
    values += by_reason + [('model', model_name), ('warn fraction', _fmt(warn_fraction)),
                           ('error fraction', _fmt(error_fraction))]
    values += [(f'bias {c} {u}', _fmt(float(b))) for c, u, b in zip(components, units, bias)]
    if age_s is None:
        return Status(name, OK, 'no measured_wrench received (no sensor connected)',
                      hardware_id, values)
    if rms is None:
        return Status(name, WARN, f'{received} measurements received, none paired with the '
                      'model yet' + (f' (rejected: {detail})' if detail else '') +
                      (f'; {resyncs} re-synchronizations on the incoming stamps'
                       if resyncs else ''), hardware_id, values)
    measured = rms['measured']
    modelled = (rms['model'] > MODEL_FLOOR) & (measured > 0.0) & np.isfinite(measured) & \
        np.isfinite(rms['residual'])
    fraction = np.zeros(measured.shape)
    fraction[modelled] = rms['residual'][modelled] / measured[modelled]
    per = np.where(~modelled, -1, np.where(fraction > error_fraction, ERROR,
                                           np.where(fraction > warn_fraction, WARN, OK)))
    level = int(max(per.max(), OK))
    judged = [f'{c} {f:.3g}' for c, f, m in zip(components, fraction, modelled) if m]
    message = ('residual RMS / measured RMS: ' + ', '.join(judged) if judged else
               'the model predicts no load: nothing to compare') + \
        f' (over {rms["samples"]} samples; warn > {warn_fraction:g}, error > ' \
        f'{error_fraction:g})'
    if resyncs:
        message += f'; {resyncs} re-synchronizations on the incoming stamps'
    if age_s > STALE_AFTER_S:
        level = STALE
        message = f'no measurement for {age_s:.1f} s; last: {message}'
    values += [('samples', _fmt(rms['samples'])),
               ('window oldest stamp s', f'{rms["oldest_ns"] * 1e-9:.9f}'),
               ('window newest stamp s', f'{rms["newest_ns"] * 1e-9:.9f}')]
    for c, u, r, m, f, lv in zip(components, units, rms['residual'], measured, fraction, per):
        values += [(f'{c} residual RMS {u}', _fmt(float(r))),
                   (f'{c} measured RMS {u}', _fmt(float(m))),
                   (f'{c} fraction', _fmt(float(f)) if lv >= 0 else 'not modelled'),
                   (f'{c} level', LEVEL_NAMES[int(lv)] if lv >= 0 else 'not judged')]
    return Status(name, level, message, hardware_id, values)
