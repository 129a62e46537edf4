"""
The rig node's balancing part: ``~/balance``, ``use_balanced`` and ``~/balance_result``.

One run of :func:`mech_balance.balancing.balance` at a time; the answer's text:
`docs/node.md#the-balance-answer`.
"""

import os
import tempfile
import threading
import weakref

from mech_balance import atomic, balancing
from mech_balance.balancing.result import STATUS
from mech_balance.ros import params
from rclpy.qos import DurabilityPolicy, QoSProfile
from std_msgs.msg import String
import yaml

BUSY = 'a balancing run is in progress'
WAIT_S = 600.0
"""Longest wait of a ``~/balance`` caller for the run in progress (then: call again)."""
BALANCE_RESULT = '~/balance_result'
"""Transient-local std_msgs/String: the YAML of the last balancing run (late joiners get it)."""


def balance_method(values, rig):
    """Return the method of ``balance.method`` for ``rig`` (default: the rig's own); ValueError."""
    chosen = values['balance.method']
    if chosen == params.BY_NAME['balance.method'].default and \
            balancing.METHODS[chosen] not in rig.capabilities:
        return balancing.method_for(rig)
    try:
        return balancing.method_for(rig, chosen)
    except ValueError as exc:
        raise ValueError(f'balance.method: got {chosen!r}, expected a method of this scene '
                         f'({exc})') from None


def result_path(fully_qualified_name):
    """
    Return the file the balancing result of node ``fully_qualified_name`` is written to.

    '/' written '__' (``/cell3/rig`` -> ``mech_balance_cell3__rig_balance.yaml``).
    """
    name = fully_qualified_name.strip('/').replace('/', '__')
    return os.path.join(tempfile.gettempdir(), f'mech_balance_{name}_balance.yaml')


def headline(design):
    """Return the first line of an answer (about 120 characters): summary, certified or not."""
    head = design.summary(certificate=False).rstrip(' ;:')
    verdict = 'certified' if design.success else STATUS[design.status]
    return f'{head}; {verdict}'


def answer_text(design, where, topic):
    """Return the text of a balancing result: three comment lines, then the YAML."""
    return (f'# {headline(design)}\n'
            f'# full result: {where} (std_msgs/String YAML; whole: ros2 topic echo --once '
            f'--full-length {topic})\n'
            f'# certificate {design.certificate_text}\n'
            + yaml.safe_dump(design.to_dict(), sort_keys=False))


def request_key(values):
    """Return what decides a balancing run besides the design: the ``balance.*`` values."""
    return tuple(sorted((k, repr(v)) for k, v in values.items() if k.startswith('balance.')))


class Balancer:
    """
    Balance the state's original design; publish and write the result.

    A caller asking the same as the last run (same original model object, same
    ``balance.*`` values) gets its answer; :meth:`original_of` names a model's design.
    """

    def __init__(self, node, state, guard):
        self._node = node
        self._state = state
        self._guard = guard
        self.lock = threading.Lock()
        self._last = None          # (original, request key, model, answer)
        self._origins = weakref.WeakKeyDictionary()   # balanced model -> its original
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.result_pub = node.create_publisher(String, BALANCE_RESULT, latched)

    @property
    def busy(self):
        """Return whether a balancing run is in progress."""
        return self.lock.locked()

    def balance(self, wait=False, still_wanted=None, timeout_s=WAIT_S):
        """
        Return ``(model or None, answer)``: a balancing run, or why there is none.

        While one runs: :data:`BUSY`, or with ``wait`` queue behind it (``timeout_s``).  Runs
        only if ``still_wanted()`` (when given), else answers ``(None, None)``.
        """
        if not self.lock.acquire(timeout=timeout_s) if wait else \
                not self.lock.acquire(blocking=False):
            return None, BUSY if not wait else (
                f'{BUSY} (waited {timeout_s:g} s); call again when it ends: '
                f'{self.result_pub.topic_name} announces its result')
        try:
            if still_wanted is not None and not still_wanted():
                return None, None
            with self._state.lock:
                original, values = self._state.original, dict(self._state.values)
            last = self._last
            if last is not None and last[0] is original and last[1] == request_key(values):
                return last[2], last[3]
            return self._run()
        except Exception as exc:  # noqa: BLE001 - any failure is answered, never fatal
            with self._state.lock:
                which = 'balanced' if self._state.balanced else 'original'
            return None, f'balancing failed: {exc}; still publishing the {which} design'
        finally:
            self.lock.release()

    def original_of(self, model):
        """Return the original design ``model`` (a returned balanced design) was computed for."""
        return self._origins.get(model)

    def _run(self):
        with self._state.lock:
            original, values = self._state.original, dict(self._state.values)
        method = balance_method(values, original.rig)
        design = balancing.balance(original.rig, method, **params.balance_options(values, method))
        model = original.with_design(design.scene)
        with self._state.lock:
            if self._state.original is not original:
                return None, ('the scene changed during the balancing run; still publishing '
                              "the new scene's original design; call again for it")
        answer = self.publish_result(design)
        self._last = (original, request_key(values), model, answer)
        self._origins[model] = original
        return model, answer

    def publish_result(self, design):
        """Publish a result on ``~/balance_result``, write it to a file; return the text."""
        path = result_path(self._node.get_fully_qualified_name())
        topic = self.result_pub.topic_name
        where = f'{path} and {topic}'
        text = answer_text(design, where, topic)
        try:
            atomic.write_text_atomic(path, text)
        except OSError as exc:
            where = f'{topic} ({path} not written: {exc.strerror})'
            text = answer_text(design, where, topic)
        self.result_pub.publish(String(data=text))
        return text

    def in_background(self, done):
        """
        Balance on a thread of its own (returned); then call ``done(model or None, answer)``.

        Waits for a run in progress, then runs only if the state has no balanced design yet.
        """
        with self._state.lock:
            original = self._state.original

        def still_wanted():
            with self._state.lock:
                return self._state.original is original and self._state.balanced is None

        @self._guard.skipping('use_balanced')
        def run():
            model, text = self.balance(wait=True, still_wanted=still_wanted)
            if model is None and text is None:
                return
            done(model, text)

        thread = threading.Thread(target=run, name='rig-balance', daemon=True)
        thread.start()
        return thread
