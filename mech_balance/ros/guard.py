"""
The one guard of every callback of the rig node: no input, of any kind, kills the node.

rclpy lets an exception raised in a callback escape ``rclpy.spin`` and end the process; a
thread that raises simply stops.  Every callback the node registers (parameter pre-, on- and
post-set callbacks, services, subscriptions, timers) and every loop of its threads therefore
runs under a :class:`Guard`:

* a callback that answers (a parameter update, a service) turns any exception into a
  *refusal with a reason*: :meth:`Guard.refusing` calls ``refuse(reason, *args)``, which
  builds the answer (``SetParametersResult(successful=False, reason=...)``,
  ``success=False, message=...``);
* a callback that answers nobody (a subscription, a timer, a thread's loop) turns it into a
  *logged, counted skip*: :meth:`Guard.skipping` counts it under the callback's label and
  warns at most once every :data:`WARN_INTERVAL_S` per label, with the count so far.

"Any exception" is every ``Exception``: ``RecursionError`` and ``MemoryError`` included (a
deeply nested or huge input), ``KeyboardInterrupt`` and ``SystemExit`` excluded (they are
how the process is asked to stop).  No ROS import: the publishing threads use it too.
"""

import functools
import threading
import time

WARN_INTERVAL_S = 2.0
"""Shortest interval between two warnings of one label (a storm of bad input logs little)."""
MAX_VALUE_CHARS = 80
"""Longest rendering of an offending value in a reason (a 5000-character value is cut)."""
MAX_REASON_CHARS = 600
"""Longest reason or warning text (the rest is cut, with the count of characters left)."""


def clip(text, limit=MAX_REASON_CHARS):
    """Return ``text`` cut to ``limit`` characters, saying how much was left off."""
    text = str(text)
    if len(text) <= limit:
        return text
    return f'{text[:limit]}... ({len(text) - limit} more characters)'


def show(value):
    """Return ``repr(value)`` cut to :data:`MAX_VALUE_CHARS` (for ``got <value>``)."""
    try:
        text = repr(value)
    except Exception:  # noqa: BLE001 - a value whose repr fails is still named
        text = f'<{type(value).__name__}>'
    return clip(text, MAX_VALUE_CHARS)


def describe(exc):
    """
    Return the reason of an exception: its message, or what it means and its type.

    A ``ValueError`` is the package's own error (its message names the field); any other
    exception is a defect or a resource limit, named by its type so that it can be found.
    """
    if isinstance(exc, RecursionError):
        return 'the value is nested too deeply to process (RecursionError)'
    if isinstance(exc, MemoryError):
        return 'the value is too large to process (MemoryError)'
    if isinstance(exc, ValueError):
        return clip(str(exc))
    return clip(f'{type(exc).__name__}: {exc}')


def parameter_reason(parameters, exc):
    """
    Return the reason of a refused parameter update, starting with a parameter's name.

    ``parameters``: the update (objects with ``name`` and ``value``).  A message that starts
    with one of their names is kept; otherwise it is given the node's form
    ``name: got <value>, expected ...`` for the first parameter of the update.
    """
    text = describe(exc)
    for p in parameters:
        if text.startswith((f'{p.name}:', f'{p.name}.', f'{p.name} ')):
            return text
    if not parameters:
        return text
    first = parameters[0]
    if isinstance(exc, ValueError):
        return clip(f'{first.name}: got {show(first.value)}, expected a value consistent with '
                    f'the other parameters ({text})')
    return clip(f'{first.name}: got {show(first.value)}, expected a value the node can '
                f'process ({text})')


class Guard:
    """
    Wrap callbacks so that an exception becomes a refusal or a counted, logged skip.

    ``warn(text)`` logs a warning (the node's logger).  ``counts`` holds the exceptions
    caught per label (``mech-balance`` statistics and tests read it).
    """

    def __init__(self, warn):
        self._warn = warn
        self._lock = threading.Lock()
        self.counts = {}
        self._last_warning = {}

    def caught(self, label, exc):
        """Count an exception of ``label`` and warn (rate-limited); return its reason."""
        reason = describe(exc)
        with self._lock:
            count = self.counts[label] = self.counts.get(label, 0) + 1
            now = time.monotonic()
            due = now - self._last_warning.get(label, -float('inf')) >= WARN_INTERVAL_S
            if due:
                self._last_warning[label] = now
        if due:
            try:
                self._warn(f'{label}: skipped ({count} so far): {reason}')
            except Exception:  # noqa: BLE001 - a failing logger (shutdown) must not raise
                pass
        return reason

    def refusing(self, label, refuse):
        """
        Return a decorator: an exception becomes ``refuse(exc, *args)``, counted.

        ``refuse`` builds the callback's answer from the exception and the callback's
        arguments (:func:`parameter_reason` for parameters, :func:`describe` for others).
        """
        def decorate(callback):
            @functools.wraps(callback)
            def guarded(*args):
                try:
                    return callback(*args)
                except Exception as exc:  # noqa: BLE001 - the point of the guard
                    with self._lock:
                        self.counts[label] = self.counts.get(label, 0) + 1
                    return refuse(exc, *args)
            return guarded
        return decorate

    def skipping(self, label, default=None):
        """Return a decorator: an exception is a counted, logged skip returning ``default``."""
        def decorate(callback):
            @functools.wraps(callback)
            def guarded(*args, **kwargs):
                try:
                    return callback(*args, **kwargs)
                except Exception as exc:  # noqa: BLE001 - the point of the guard
                    self.caught(label, exc)
                    return default
            return guarded
        return decorate

    def total(self):
        """Return the number of exceptions caught under every label."""
        with self._lock:
            return sum(self.counts.values())
