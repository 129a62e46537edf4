"""
The rig node's balancing part: ``~/balance``, ``use_balanced`` and ``~/balance_result``.

:class:`Balancer` runs :func:`mech_balance.balancing.balance` with the ``balance.*``
parameters on the state's original design, one run at a time (callers of the same request
share its answer), publishes the result's YAML on ``~/balance_result`` (transient local:
late joiners get it) and writes it to a file named by the node's namespace and name.
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
"""Longest wait of a ``~/balance`` caller for the run in progress before it is told to call
again (runs are bounded by the solvers; this only bounds a caller's wait)."""
BALANCE_RESULT = '~/balance_result'
"""Transient-local std_msgs/String: the YAML of the last balancing run (late joiners get it)."""


def balance_method(values, rig):
    """
    Return the balancing method of ``balance.method`` for ``rig``; ValueError if it has none.

    The default, redistribution, on a rig that cannot be redistributed (a spatial rig) is the
    rig's own method (:func:`mech_balance.balancing.method_for`).
    """
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

    The namespace is part of the name, '/' written '__' (``/cell3/rig`` ->
    ``mech_balance_cell3__rig_balance.yaml``; ROS names never repeat '_', so no two nodes
    share a file): rigs in different namespaces never overwrite each other's result.
    """
    name = fully_qualified_name.strip('/').replace('/', '__')
    return os.path.join(tempfile.gettempdir(), f'mech_balance_{name}_balance.yaml')


def headline(design):
    """
    Return the first line of an answer: scene, method, RMS before -> after, certified or not.

    :meth:`Design.summary` without its certificate, then ``certified`` or the status in
    words: short enough (about 120 characters) for ``ros2 topic echo``'s 128-character cut.
    """
    head = design.summary(certificate=False).rstrip(' ;:')
    verdict = 'certified' if design.success else STATUS[design.status]
    return f'{head}; {verdict}'


def answer_text(design, where, topic):
    """
    Return the text of a balancing result: three comment lines, then the YAML.

    ``# <headline>``, ``# full result: <where> ...`` (how to read it whole), ``# <the
    certificate in words>``, then :meth:`Design.to_dict` as block YAML (one key a line).
    """
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

    The last answer is kept with the design it was computed for (the original model object,
    its content included) and the ``balance.*`` values: a caller asking the same again --
    while the run is in progress (it waits for it) or after -- gets that answer, not a run
    of its own and not :data:`BUSY`.  :attr:`last_original` names the design a returned
    model belongs to.
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

        One run at a time: while one runs, the answer is :data:`BUSY`, unless ``wait``: then
        the call queues behind the running one (at most ``timeout_s``, then it is told to
        call again) and, once it may start, answers the result of the run it waited for if
        that was the same request (same design, same options), else runs -- only if
        ``still_wanted()`` (when given) is true, else answers ``(None, None)``.  The model
        returned belongs to :meth:`original_of`.
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
        """
        Publish a result on ``~/balance_result``, write it to a file; return the answer.

        The answer, the topic's message and the file carry the same text
        (:func:`answer_text`): three comment lines a person reads first -- the summary, where
        the full result is, the certificate -- then the YAML of :meth:`Design.to_dict` in SI,
        what ``mech-balance balance --json`` prints (the comments leave it YAML).
        """
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

        A run already in progress (a ``~/balance`` call, or the background run of a scene
        switched away from) is waited for; this one then starts only if the state still
        has no balanced design of the same original design (the run waited for may have
        published it), so a scene switch during a run is balanced in its turn.
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
