"""
The one guard of every callback of the rig node: no input, of any kind, kills the node.

Any ``Exception`` (``RecursionError`` and ``MemoryError`` included) becomes a refusal with
a reason (:meth:`Guard.refusing`) or a counted, rate-limited warning (:meth:`Guard.skipping`).
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
    """Return the reason of an exception: a ValueError's message, else named by its type."""
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

    Else in the node's form ``name: got <value>, expected ...`` for the first parameter.
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
    """Wrap callbacks: an exception becomes a refusal or a counted skip (``counts``, by label)."""

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
        """Return a decorator: an exception becomes the answer ``refuse(exc, *args)``, counted."""
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
