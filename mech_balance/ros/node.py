"""
The rig node: joint states and the shaking wrench on ROS 2 topics, a balancing service.

``ros2 run mech_balance rig_node`` starts node ``rig``.  It holds no numerics: it declares
the parameters and wires the parts to its topics and services (`docs/node.md`).
"""

from collections import deque
import json
import sys
import threading
import time
import warnings

from mech_balance import threads
from mech_balance.ros import description, guard as guards, live
from mech_balance.ros import parameters as node_params, params, publisher as pub, real_rig
from mech_balance.ros.balance_service import Balancer, BUSY
from mech_balance.ros.names import NODE_NAME
from mech_balance.ros.rig_state import RigState
from rcl_interfaces.msg import SetParametersResult
import rclpy
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile
from rclpy.service import Service
from std_srvs.srv import Trigger

EXECUTOR_THREADS = 4
"""Threads serving parameters, services and the inputs (a balancing run holds one)."""
SERVICE_DEPTH = 1000
"""Request and answer history of every service: a burst of calls is queued, never lost."""
ANSWER_GAP_S = 0.01
"""Shortest pause between two answers while more are waiting (why: `docs/node.md`, *Every
service call is answered*)."""
ANSWER_GAP_PER_CLIENT_S = 0.002
"""The pause per client of the service, when that is longer than :data:`ANSWER_GAP_S`."""
ANSWER_TRIES = 100
"""Sends of one answer whose client is not matched yet (:data:`NOT_SENT`) before giving up."""
ANSWER_ECHOES = 2
"""Sends again of an answer of a burst, once the waiting answers are out (harmless: a client
drops an answer whose request it no longer waits for)."""
ANSWER_BURST_S = 1.0
"""Two answers sent closer than this (s) make a burst, whose answers are echoed."""
NOT_SENT = (RuntimeWarning, SystemError)
"""What a send whose answer was dropped raises, once the warning is an error (``main``)."""
SWITCH_INTERVAL_S = 1e-4
"""Python's thread switch interval in the node (the default, 5 ms, would delay kHz ticks)."""
WARN_THROTTLE_S = 2.0
"""Shortest interval between two warnings about the same kind of bad input."""
STATS_TAG = 'stats '
"""Precedes the JSON of the publishing statistics in the node's last log line."""
EXIT_BAD_PARAMETER = 2
EXIT_FAILURE = 1
RESTARTING = frozenset({'scene', 'mode', 'crank_speed', 'publish_rate'})
"""Parameters after which publishing starts again (a new schedule or model)."""


class RigNode(Node):
    """Wire the twin of a scene to topics, the balancing services and the parameters."""

    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        self._guard = guards.Guard(lambda text: self.get_logger().warning(text))
        self._params = node_params.NodeParameters(self)
        values = self._params.declare_all()
        original = node_params.build_model(values['scene'])
        self._params.declare_link_parameters(original)
        node_params.check_link_options(values, original)
        params.check_together(values)
        self._state = state = RigState(values, original)

        self._recording = live.Recording(self._log, make=_viz_recorder)
        self._publisher = pub.Publisher(self, state, self._guard, self._warn, self._record,
                                        on_encoder=self._on_encoder_sample)
        self._rig = real_rig.RealRig(self, state, self._guard, self._warn, self._publisher,
                                     extra_statuses=self._recording.diagnostic_statuses)
        self._balancer = Balancer(self, state, self._guard)
        self._description = description.DescriptionPublisher(self)
        self._identify_busy = False
        qos = QoSProfile(depth=SERVICE_DEPTH)
        either = ReentrantCallbackGroup()  # each refuses with "busy" what it cannot run now
        self._answers = _PacedAnswers(self, self._guard)
        # ~/balance callers queue (one executor thread at most waits for a run; the others
        # serve parameters and the other services) and share the result of the same request
        self._triggers = {name: self._answers.pace(self.create_service(
            Trigger, name, self._refusing(name, callback), qos_profile=qos,
            callback_group=group)) for name, callback, group in (
                ('~/balance', self._on_balance, MutuallyExclusiveCallbackGroup()),
                ('~/reset', self._on_reset, either),
                ('~/tare', self._on_tare, MutuallyExclusiveCallbackGroup()),
                ('~/identify', self._on_identify, either))}

        self._open_recording(publishing=False)
        self._describe()
        # say what the node publishes before it starts to (a signal right after the first
        # samples then finds nothing left to log to rosout)
        self._announce()
        self._publisher.apply_mode()
        threading.Thread(target=self._guard.skipping('warm-up')(_import_solvers),
                         name='rig-warm-up', daemon=True).start()
        self.add_pre_set_parameters_callback(self._params.coerce)
        self.add_on_set_parameters_callback(self._guard.refusing(
            'parameters', lambda exc, ps: SetParametersResult(
                successful=False, reason=guards.parameter_reason(ps, exc)))(
                    lambda ps: self._params.check(ps, self._state.original)))
        self.add_post_set_parameters_callback(
            self._guard.skipping('applying parameters')(self._on_parameters_set))
        if values['use_balanced']:
            self._balance_in_background()

    def _refusing(self, label, callback):
        """Guard a Trigger service: any exception is answered ``success=False`` (a reason)."""
        def refuse(exc, request, response):
            response.success, response.message = False, f'{label}: {guards.describe(exc)}'
            return response
        return self._guard.refusing(label, refuse)(callback)

    def _warn(self, text):
        self.get_logger().warning(text, throttle_duration_sec=WARN_THROTTLE_S)

    def _log(self, level, text):
        """Log ``text`` at ``level`` ('info', 'warning', 'error'), one call site per level."""
        logger = self.get_logger()
        if level == 'error':
            logger.error(text)
        elif level == 'warning':
            logger.warning(text)
        else:
            logger.info(text)

    def _service_name(self, name):
        return self._triggers[name].service_name

    def _record(self, samples, turned_rad, stamps_ns):
        """Queue a batch for the recording (the original's data when it is published)."""
        state = self._state
        self._recording.push(samples, turned_rad, stamps_ns,
                             original=state.published is state.original)

    def _on_encoder_sample(self, stamp_ns, position_rad, turned_rad, resynced):
        """Pass an accepted encoder sample from the publisher to the real rig."""
        self._rig.on_encoder(stamp_ns, position_rad, turned_rad, resynced)

    def _open_recording(self, publishing=True):
        """(Re)open the recording (``publishing``: not at start-up): original against balanced."""
        state = self._state
        with state.lock:
            balanced = None if state.balanced is None else state.balanced.scene
            self._recording.start(state.values['recording_path'], state.values['rerun_url'],
                                  state.original.scene, balanced)
            if publishing and self._recording.active:
                # the ticks evaluated ahead went to the recording's old targets, or nowhere:
                # evaluated again, every sample published from now on reaches the new ones (a
                # sample of the window may be recorded twice, never left out)
                self._publisher.set_model(state.published)

    def _switch_to(self, model):
        """Publish ``model`` from the next sample on if it is the scene's; return whether."""
        with self._state.lock:
            if model is not self._state.original and model is not self._state.balanced:
                return False
            self._state.published = model
            self._publisher.set_model(model)
        self._describe()
        return True

    def _describe(self):
        """Publish the URDF of the published design on robot_description (if enabled)."""
        v = self._state.values
        self._description.show(v['publish_robot_description'], self._state.published,
                               v['frame_id'])

    def _announce(self):
        model, v = self._state.published, self._state.values
        sc, me = model.scene, self.get_fully_qualified_name()
        effort = 'position, velocity, effort' if model.has_effort else \
            'position, velocity (no effort: the scene computes no driving torque)'
        encoder = self._publisher.encoder_topic
        how = (f'clock mode: crank at {self._state.crank_speed():g} rad/s, '
               f'{v["publish_rate"]:g} Hz' if v['mode'] == 'clock' else
               f'follow mode: one sample per message on {encoder}')
        rig = self._rig
        for line in (
                f'scene {sc.name!r} ({model.kind}, from {sc.source}), {how}',
                f'publishing {self._publisher.joint_pub.topic_name} (sensor_msgs/msg/'
                f'JointState): joints {", ".join(model.joint_names)}; {effort}',
                f'publishing {self._publisher.wrench_pub.topic_name} (geometry_msgs/msg/'
                'WrenchStamped): force and moment the rig exerts on its frame, frame_id '
                f'{v["frame_id"]!r}, about {model.moment_point}',
                f'balance: ros2 service call {self._service_name("~/balance")} std_srvs/srv/'
                f'Trigger  (options: e.g. ros2 param set {me} balance.weights "[0.5, 0.5]")',
                f'reset:   ros2 service call {self._service_name("~/reset")} '
                'std_srvs/srv/Trigger',
                f'follow a real rig: ros2 param set {me} mode follow (crank encoder '
                f'JointState on {encoder})',
                f'real rig: {rig.measured_sub.topic_name} (geometry_msgs/msg/WrenchStamped, '
                f'sensor frame) -> {rig.residual_pub.topic_name} (measured minus model, '
                f'{v["frame_id"]!r}, about {model.moment_point}); '
                f'{self._service_name("~/tare")}, {self._service_name("~/identify")}; '
                f'{real_rig.DIAGNOSTICS} at {1.0 / real_rig.DIAGNOSTICS_PERIOD_S:g} Hz'):
            self.get_logger().info(line)

    def _on_parameters_set(self, parameters):
        """Apply an accepted update: tell each part what changed."""
        changed = self._params.accepted(parameters)
        state = self._state
        with state.lock:
            state.values.update(changed)
            model = self._params.take_scene(changed['scene']) if 'scene' in changed else None
            if model is not None:
                state.original = state.published = model
                state.balanced = state.calibration = None
            restart = RESTARTING & set(changed) or \
                'use_sim_time' in {p.name for p in parameters}  # a new clock: start again
            if any(k.startswith('follow.') for k in changed):
                self._publisher.renew_estimator()
        # publishing first: a new scene's first sample needs only its model (built by the
        # on-set check); its parameters, URDF and announcement follow, the follow-mode cycle
        # table and the recording are built on threads of their own (docs/node.md)
        if restart:
            self._publisher.apply_mode()
        elif 'frame_id' in changed:
            self._publisher.set_model(state.published)  # prepared messages carry the old one
        if 'scene' in changed:
            self._params.clear_refuted(changed['scene'])  # first: the links' checks see it
            self._params.declare_link_parameters(state.original)
        if 'use_balanced' in changed or 'scene' in changed:
            wanted = state.wanted_design()
            if wanted is not None:
                self._switch_to(wanted)
            else:
                self._balance_in_background()
        if {'scene', 'recording_path', 'rerun_url'} & set(changed):
            self._open_recording()
        if {'scene', 'frame_id', 'publish_robot_description'} & set(changed):
            self._describe()
        if 'scene' in changed or 'mode' in changed:
            self._announce()
        self._rig.parameters_set(changed)

    def _on_balance(self, request, response):
        """Balance with the current options, publish the design, answer its YAML."""
        model, response.message = self._balancer.balance(wait=True)
        response.success = model is not None
        if model is not None and not self._use_balanced(model,
                                                        self._balancer.original_of(model)):
            response.success = False
            response.message = ('the scene changed during the balancing run; its design is '
                                'not published; call again to balance the new scene\n'
                                f'{response.message}')
        return response

    def _use_balanced(self, model, original):
        """Make ``model``, computed for ``original``, the balanced design; False if stale."""
        with self._state.lock:
            if original is None or self._state.original is not original:
                return False
            self._state.balanced = model
        self._open_recording()  # the recording shows the original against the new design
        if self._state.values['use_balanced']:
            self._switch_to(model)  # set again: no parameter event, the design is new
        else:
            self.set_parameters([Parameter('use_balanced', value=True)])
        return True

    def _balance_in_background(self):
        """use_balanced is true but no design is known: balance, then publish the design."""
        original = self._state.original

        def done(model, text):
            with self._state.lock:
                stale = self._state.original is not original
            if stale:   # the scene changed meanwhile: its own run publishes its design
                self.get_logger().info(f'use_balanced: the design of {original.scene.name!r} '
                                       'is not published (the scene has changed)')
                return
            if model is None:
                self.get_logger().error(f'use_balanced: {text}; publishing the original')
                self.set_parameters([Parameter('use_balanced', value=False)])
                return
            with self._state.lock:
                if self._state.original is not original:
                    return
                self._state.balanced = model
                wanted = self._state.values['use_balanced']
            self._open_recording()
            if wanted and self._switch_to(model):
                self.get_logger().info('use_balanced: publishing the balanced design')

        self.get_logger().info(f'use_balanced: balancing scene '
                               f'{self._state.original.scene.name!r} with the balance.* '
                               'parameters ...')
        self._balancer.in_background(done)

    def _on_reset(self, request, response):
        """Return to the scene's original design (from a calibrated scene: to the scene)."""
        if self._balancer.busy:
            response.success = False
            response.message = (f'{BUSY}; call ~/reset again when it ends '
                                f'({self._balancer.result_pub.topic_name} announces it)')
            return response
        state, note = self._state, ''
        with state.lock:
            cal, state.calibration = state.calibration, None
            if cal is not None and state.original is cal[0]:
                state.original = cal[1]
                self._rig.restore_bias(cal[2])
                note = ' (calibration dropped)'
            state.balanced = None
        self.set_parameters([Parameter('use_balanced', value=False)])
        response.success = True
        response.message = f'publishing the original design of scene ' \
                           f'{state.original.scene.name!r}{note}'
        return response

    def _on_tare(self, request, response):
        """Estimate the sensor bias from the last sensor.tare_seconds and use it."""
        response.success, response.message = self._rig.tare()
        return response

    def _on_identify(self, request, response):
        """Identify the scene's inertial parameters from the buffered data; publish them."""
        state = self._state
        with state.lock:
            if self._identify_busy:
                response.success, response.message = False, 'an identification is in progress'
                return response
            self._identify_busy = True
            cal = state.calibration
            base = state.original if cal is None or state.original is not cal[0] else cal[1]
        try:
            ok, response.message, calibrated, old_bias = self._rig.identify(base)
        finally:
            with state.lock:
                self._identify_busy = False
        response.success = ok
        if ok:
            with state.lock:
                state.calibration = (calibrated, base, old_bias)
                state.original, state.balanced = calibrated, None
            self.set_parameters([Parameter('use_balanced', value=False)])
            self._switch_to(calibrated)
        return response

    def destroy_node(self, signalled=False):
        """
        Stop the publishing threads, close the recording, destroy the node, log the stats.

        ``signalled`` (Ctrl-C, SIGTERM): logged after the node is gone, to the console only.
        """
        self._publisher.stop()
        self._recording.close()
        logger, line = self.get_logger(), self._stats_line()
        if self.context.ok() and not signalled:
            logger.info(line)
            return super().destroy_node()
        destroyed = super().destroy_node()
        logger.info(line)
        return destroyed

    def _stats_line(self):
        """Return the publishing statistics: a summary, then :data:`STATS_TAG` and JSON."""
        stats = self._publisher.streamer.stats.summary()
        counts = dict(self._guard.counts)
        stats['caught'] = counts
        stats['published_total'] = self._publisher.streamer.published_total
        follow = stats['follow'] = self._publisher.follow_counts()
        unanswered = sum(follow['unanswered'].values())
        said_follow = '' if not follow['received'] else (
            f'follow mode: {follow["received"]} encoder samples received, {unanswered} not '
            'answered (' + (', '.join(f'{k}: {v}' for k, v in follow['unanswered'].items())
                            or 'none') + '); ')
        stats['answers'] = {'sent': self._answers.sent, 'retried': self._answers.retried,
                            'echoed': self._answers.echoed}
        rec = self._recording
        stats['recording'] = {'file': rec.file_status(), 'queued': rec.queued,
                              'logged': rec.logged, 'batches_dropped': rec.dropped}
        refused_parameters = counts.get('parameters', 0)
        refused_calls = sum(v for k, v in counts.items() if k in self._triggers)
        errors = self._guard.total() - refused_parameters - refused_calls
        return (f'published {stats["published_total"]} samples in all, '
                f'{stats["published"]} since publishing last (re)started (a mode, rate, '
                f'speed or scene change; {stats["skipped"]} ticks skipped, '
                f'{stats["withheld"]} non-finite withheld since then); '
                f'{refused_parameters} parameter updates refused, {refused_calls} service '
                f'calls answered with an error, {errors} other exceptions caught in callbacks '
                f'and threads; {said_follow}'
                f'compute {stats["prepare_per_sample_s"] * 1e6:.1f} us per sample (core and '
                f'serialization, batched); publishing {stats["step_median_s"] * 1e6:.1f} us '
                f'median per sample; {STATS_TAG}{json.dumps(stats)}')


class _PacedAnswers:
    """Send the services' answers from a thread of their own, paced (:meth:`pace`)."""

    def __init__(self, node, guard):
        self._node = node
        self._guard = guard
        self._cond = threading.Condition()
        self._queue = deque()
        self._echoes = deque()    # (service, response, header, echoes left) of a burst
        self.sent = 0
        self.retried = 0
        self.echoed = 0
        self._last = None         # (time, answer, echoed) of the last answer sent
        threading.Thread(target=self._run, name='rig-answers', daemon=True).start()

    def pace(self, service):
        """Route ``service``'s answers through the queue; return the service."""
        def send_response(response, header):
            with self._cond:
                self._queue.append((service, response, header, 0))
                self._cond.notify()
        service.send_response = send_response
        return service

    def _next(self):
        """Return the next send ``(service, response, header, tries, echoes left, echo?)``."""
        with self._cond:
            while not (self._queue or self._echoes):
                self._cond.wait()
            if self._queue:   # answers first; the answers of a burst are echoed afterwards
                service, response, header, tries = self._queue.popleft()
                return service, response, header, tries, 0, False
            service, response, header, left = self._echoes.popleft()
            return service, response, header, 0, left, True

    def _burst(self, answer):
        """Echo ``answer``, and the one before it, when they went out within a burst."""
        now = time.monotonic()
        echoed = self._last is not None and now - self._last[0] <= ANSWER_BURST_S
        if echoed:
            if not self._last[2]:
                self._echoes.append(self._last[1] + (ANSWER_ECHOES,))
            self._echoes.append(answer + (ANSWER_ECHOES,))
        self._last = (now, answer, echoed)

    def _run(self):
        while True:
            service, response, header, tries, echoes, echo = self._next()
            try:
                Service.send_response(service, response, header)
                with self._cond:
                    if echo:
                        self.echoed += 1
                        if echoes > 1:
                            self._echoes.append((service, response, header, echoes - 1))
                    else:
                        self.sent += 1
                        self._burst((service, response, header))
            except NOT_SENT as exc:  # the client's reader not matched yet: again, later
                if echo:   # its client has its answer and is gone
                    pass
                elif tries + 1 >= ANSWER_TRIES:
                    self._guard.caught('answering a service call', exc)
                else:
                    self.retried += 1
                    with self._cond:
                        self._queue.append((service, response, header, tries + 1))
            except Exception as exc:  # noqa: BLE001 - a destroyed service: counted, go on
                self._guard.caught('answering a service call', exc)
            with self._cond:
                more = bool(self._queue) or bool(self._echoes)
            if more:
                try:
                    clients = self._node.count_clients(service.service_name)
                except Exception:  # noqa: BLE001 - shutting down: the shortest pause
                    clients = 0
                time.sleep(max(ANSWER_GAP_S, ANSWER_GAP_PER_CLIENT_S * clients))


def _viz_recorder(path, url, scene, balanced):
    """Return the viz recorder of a file (``path``) or a viewer (``url``): the recording hook."""
    from mech_balance.viz import recording
    return recording.LiveRecorder(path, scene, balanced, field='recording_path', url=url)


def _import_solvers():
    """Import the balancing and identification solvers (about 0.8 s) in a warm-up thread."""
    import importlib
    for name in ('mech_balance.balancing.redistribution',
                 'mech_balance.balancing.counterweights', 'mech_balance.balancing.certificate',
                 'mech_balance.analysis.identify', 'scipy.signal'):
        importlib.import_module(name)


def main(args=None):
    """Run the rig node until shutdown; return the exit status (0 after Ctrl-C, SIGTERM)."""
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    # an answer rclpy could not send (a client's reader not matched yet) raises: sent again
    warnings.filterwarnings('error', message='failed to send response', category=RuntimeWarning)
    threads.return_large_blocks()  # a long-running node: big temporaries back at free
    try:
        threads.limit_blas_threads()
    except ValueError as exc:      # names MECH_BALANCE_BLAS_THREADS and its value
        print(f'rig_node: error: {exc}', file=sys.stderr)
        return 2
    rclpy.init(args=args)
    node = None
    status = 0
    signalled = False
    try:
        node = RigNode()
        rclpy.spin(node, executor=MultiThreadedExecutor(num_threads=EXECUTOR_THREADS))
    except (KeyboardInterrupt, ExternalShutdownException):
        signalled = True
    except (ValueError, ParameterException) as exc:
        print(f'rig_node: error: {guards.clip(exc)}', file=sys.stderr)
        status = EXIT_BAD_PARAMETER
    except Exception as exc:  # noqa: BLE001 - a defect is one line, not a traceback
        if node is None or rclpy.ok():
            print(f'rig_node: error: {guards.describe(exc)}', file=sys.stderr)
            status = EXIT_FAILURE
    finally:
        if node is not None:
            try:
                node.destroy_node(signalled=signalled or not rclpy.ok())
            except Exception as exc:  # noqa: BLE001 - after a shutdown: one line, exit 0
                print(f'rig_node: while stopping: {guards.describe(exc)}', file=sys.stderr)
        rclpy.try_shutdown()
    return status


if __name__ == '__main__':
    sys.exit(main())
