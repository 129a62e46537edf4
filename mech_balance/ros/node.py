"""
The rig node: joint states and the shaking wrench on ROS 2 topics, a balancing service.

``ros2 run mech_balance rig_node`` (here: the ``rig_node`` console script or
``python -m mech_balance.node``) starts node ``rig``; every name is relative, so
``--ros-args -r __ns:=/cell3`` runs several rigs side by side.

Publications (both stamped with the time of the crank angle they belong to)
    ``joint_states`` (sensor_msgs/msg/JointState) and ``shaking_wrench``
    (geometry_msgs/msg/WrenchStamped), values in :mod:`mech_balance.twin`.
Subscription (follow mode)
    ``crank_joint_state`` (sensor_msgs/msg/JointState), the crank encoder.
Services (std_srvs/srv/Trigger)
    ``~/balance`` runs the balancing with the ``balance.*`` parameters and publishes the
    balanced design (the answer's ``message`` is the YAML of the result); ``~/reset``
    returns to the scene's original design.
Every parameter is declared once in :data:`mech_balance.params.PARAMETERS`
(``config/rig_params.yaml`` is a working set).

The node holds no numerics: :mod:`mech_balance.twin` evaluates the core and runs the
publishing threads, :mod:`mech_balance.ros_conversions` fills the messages.
"""

import json
import sys
import threading

from geometry_msgs.msg import WrenchStamped
from mech_balance import balancing
from mech_balance import schema as scene_mod
from mech_balance.ros import conversions as conv
from mech_balance.ros import params, streaming as twin
from rcl_interfaces.msg import SetParametersResult
import rclpy
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger
import yaml

NODE_NAME = 'rig'
JOINT_STATES = 'joint_states'
SHAKING_WRENCH = 'shaking_wrench'
ENCODER = 'crank_joint_state'
PUBLISH_DEPTH = 100
"""History of both publishers (absorbs a subscriber's jitter at kHz rates)."""
ENCODER_DEPTH = 100
"""History of the encoder subscription."""
EXECUTOR_THREADS = 4
"""Threads serving parameters, services and the encoder (a balancing run holds one)."""
SWITCH_INTERVAL_S = 1e-4
"""Python's thread switch interval in the node process: bounds how long a core evaluation
in one thread delays the publishing thread (the default, 5 ms, would delay kHz ticks)."""
WARN_THROTTLE_S = 2.0
"""Shortest interval between two warnings about the same kind of bad input."""
BUSY = 'a balancing run is in progress'
STATS_TAG = 'stats '
"""Precedes the JSON of the publishing statistics in the node's last log line."""
EXIT_BAD_PARAMETER = 2


class RigNode(Node):
    """Wire the twin of a scene to topics, the balancing services and the parameters."""

    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        self._lock = threading.RLock()
        self._balance_lock = threading.Lock()
        self._values = {}
        for spec in params.PARAMETERS:
            declared = self.declare_parameter(spec.name, spec.default,
                                              conv.parameter_descriptor(spec))
            self._values[spec.name] = params.check(spec.name, conv.parameter_value(declared))
        self._original = self._build_model(self._values['scene'])
        _check_link_options(self._values, self._original)
        self._balanced = None          # the design published while use_balanced is true
        self._published = self._original
        self._pending_scene = None     # (name, model) checked by the on-set callback
        self._estimator = self._new_estimator(self._values)
        self._skipped_inputs = 0
        self._recorder = None
        self._recorder_lock = threading.Lock()
        self._serializer = None        # conv.SampleSerializer of the published names, frame

        qos = QoSProfile(depth=PUBLISH_DEPTH)
        overrides = QoSOverridingOptions.with_default_policies()
        self._joint_pub = self.create_publisher(JointState, JOINT_STATES, qos,
                                                qos_overriding_options=overrides)
        self._wrench_pub = self.create_publisher(WrenchStamped, SHAKING_WRENCH, qos,
                                                 qos_overriding_options=overrides)
        self._encoder_sub = None
        self._encoder_group = MutuallyExclusiveCallbackGroup()
        self._balance_srv = self.create_service(Trigger, '~/balance', self._on_balance,
                                                callback_group=ReentrantCallbackGroup())
        self._reset_srv = self.create_service(Trigger, '~/reset', self._on_reset)

        self._streamer = twin.Streamer(lambda: self.get_clock().now().nanoseconds,
                                       self._prepare, self._publish, self._warn, self._record)
        self._open_recorder()
        # say what the node publishes before it starts to (a signal right after the first
        # samples then finds nothing left to log to rosout)
        self._announce()
        self._apply_mode()
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.add_post_set_parameters_callback(self._on_parameters_set)
        if self._values['use_balanced']:
            self._balance_in_background()

    # ------------------------------------------------------------------ wiring

    def _build_model(self, name):
        """Load, validate and assemble a scene (the scene loader's checks); ValueError."""
        try:
            return twin.model_for(scene_mod.load(name))
        except OSError as exc:
            raise ValueError(f'scene: cannot read {name!r}: {exc.strerror}') from None
        except ValueError as exc:
            if str(exc).startswith('scene'):
                raise
            raise ValueError(f'scene {name!r}: {exc}') from None

    def _new_estimator(self, values):
        return twin.CrankEstimator(values['follow.window'], values['follow.max_speed'],
                                   values['follow.max_gap'],
                                   values['follow.use_encoder_velocity'])

    def _crank_speed(self):
        speed = self._values['crank_speed']
        return speed if speed != 0.0 else self._original.scene.crank_speed_rad_s

    def _apply_mode(self):
        """Start publishing in the current mode; subscribe the encoder when first following."""
        model = self._published
        if self._values['mode'] == 'clock':
            # The encoder subscription, once made, stays: destroying it from this parameter
            # callback races with the MultiThreadedExecutor's other threads, which may be
            # adding it to their wait sets (rclpy raises InvalidHandle there and the node
            # dies).  In clock mode _on_encoder ignores what arrives.
            period_ns = max(1, round(1e9 / self._values['publish_rate']))
            self._streamer.clock(model, self._crank_speed(), period_ns)
            return
        self._estimator = self._new_estimator(self._values)
        self._streamer.follow(model)
        if self._encoder_sub is None:
            self._encoder_sub = self.create_subscription(
                JointState, ENCODER, self._on_encoder, QoSProfile(depth=ENCODER_DEPTH),
                callback_group=self._encoder_group,
                qos_overriding_options=QoSOverridingOptions.with_default_policies())

    def _switch_to(self, model):
        """Publish ``model`` (the original or a balanced design) from the next sample on."""
        with self._lock:
            self._published = model
            self._streamer.set_model(model)

    def _announce(self):
        model, v = self._published, self._values
        sc = model.scene
        effort = 'position, velocity, effort' if model.has_effort else \
            'position, velocity (no effort: the scene computes no driving torque)'
        how = (f'clock mode: crank at {self._crank_speed():g} rad/s, '
               f'{v["publish_rate"]:g} Hz' if v['mode'] == 'clock' else
               f'follow mode: one sample per message on {self._encoder_topic()}')
        balance = self._balance_srv.service_name
        lines = [
            f'scene {sc.name!r} ({model.kind}, from {sc.source}), {how}',
            f'publishing {self._joint_pub.topic_name} (sensor_msgs/msg/JointState): joints '
            f'{", ".join(model.joint_names)}; {effort}',
            f'publishing {self._wrench_pub.topic_name} (geometry_msgs/msg/WrenchStamped): '
            f'force and moment the rig exerts on its frame, frame_id {v["frame_id"]!r}, '
            f'about {model.moment_point}',
            f'balance: ros2 service call {balance} std_srvs/srv/Trigger  (options: e.g. '
            f'ros2 param set {self.get_fully_qualified_name()} balance.weights "[0.5, 0.5]")',
            f'reset:   ros2 service call {self._reset_srv.service_name} std_srvs/srv/Trigger',
            f'follow a real rig: ros2 param set {self.get_fully_qualified_name()} mode follow '
            f'(crank encoder JointState on {self._encoder_topic()})',
        ]
        for line in lines:
            self.get_logger().info(line)

    def _encoder_topic(self):
        ns = self.get_namespace().rstrip('/')
        return f'{ns}/{ENCODER}'

    def _warn(self, text):
        self.get_logger().warning(text, throttle_duration_sec=WARN_THROTTLE_S)

    # ------------------------------------------------------------------ publishing

    def _prepare(self, samples, stamps_ns):
        """Serialize a batch of samples (the streamer's evaluating threads)."""
        key = (samples.joint_names, samples.joint_effort is not None, self._values['frame_id'])
        serializer = self._serializer
        if serializer is None or (serializer.joint_names, serializer.has_effort,
                                  serializer.frame_id) != key:
            serializer = self._serializer = conv.SampleSerializer(*key)
            if not serializer.fast:
                self._warn('publishing: serializing message by message (the fast path does '
                           'not match this middleware)')
        return serializer.serialize(samples, stamps_ns)

    def _publish(self, payload):
        """Publish one prepared sample on both topics (the streamer's publishing thread)."""
        try:
            self._joint_pub.publish(payload[0])
            self._wrench_pub.publish(payload[1])
        except Exception:
            if self.context.ok():
                raise
            # Ctrl-C or SIGTERM: rclpy shut the context down before destroy_node stops
            # this thread; the sample is dropped without a warning (rosout is gone too)

    def _on_encoder(self, msg):
        """Turn one encoder message into a sample to publish; skip bad input with a warning."""
        if self._values['mode'] != 'follow':  # subscribed by an earlier follow mode
            return
        joint = self._values['crank_joint'] or self._original.crank_joint
        try:
            stamp_ns, position, velocity = conv.crank_reading(msg, joint)
            sample = self._estimator.update(stamp_ns, position, velocity)
        except ValueError as exc:
            self._skipped_inputs += 1
            self._warn(f'{ENCODER}: skipped a message ({self._skipped_inputs} so far): {exc}')
            return
        if sample is not None and not self._streamer.push(sample):
            self._warn(f'{ENCODER}: the core is behind the encoder; dropped the oldest sample')

    # ------------------------------------------------------------------ recording

    def _record(self, samples, turned_rad, stamps_ns):
        with self._recorder_lock:
            recorder = self._recorder
            if recorder is None:
                return
            try:
                original = samples if self._published is self._original else None
                recorder.log_sample(stamps_ns * 1e-9, turned_rad, data=original)
            except Exception as exc:  # noqa: BLE001 - a full disk must not stop the rig
                self._warn(f'recording_path: stopped recording: {exc}')
                recorder.close()
                self._recorder = None

    def _open_recorder(self):
        """
        (Re)open the recording: the original against the balanced design, if one is known.

        Reopened (the file starts again) when the scene, the path or the balanced design
        changes; ``~/reset`` keeps it going (the original is in it).
        """
        path, url = self._values['recording_path'], self._values['rerun_url']
        with self._recorder_lock:
            if self._recorder is not None:
                self._recorder.close()
                self._recorder = None
            if not path and not url:
                return
            from mech_balance.viz import recording
            balanced = None if self._balanced is None else self._balanced.scene
            try:
                self._recorder = recording.LiveRecorder(path or None, self._original.scene,
                                                        balanced, field='recording_path',
                                                        url=url or None)
            except (ValueError, OSError) as exc:  # checked when set; the disk may change
                self.get_logger().error(f'not recording: {exc}')
                return
            self.get_logger().info(' and '.join(
                ([f'recording to {path}'] if path else []) +
                ([f'streaming the views to {url}'] if url else [])))

    # ------------------------------------------------------------------ parameters

    def _on_set_parameters(self, parameters):
        """Check an update with the same code as the scene loader; reject with a reason."""
        try:
            candidate = dict(self._values)
            model = self._original
            for p in parameters:
                if p.name not in params.BY_NAME:
                    continue  # use_sim_time, qos overrides: rclpy's own
                value = candidate[p.name] = params.check(p.name, conv.parameter_value(p))
                if p.name == 'scene' and value != self._values['scene']:
                    model = self._build_model(value)
                    self._pending_scene = (value, model)
            _check_link_options(candidate, model)
        except ValueError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _on_parameters_set(self, parameters):
        """Apply an accepted update."""
        changed = {p.name: params.check(p.name, conv.parameter_value(p))
                   for p in parameters if p.name in params.BY_NAME}
        with self._lock:
            self._values.update(changed)
            if 'scene' in changed and self._pending_scene is not None and \
                    self._pending_scene[0] == changed['scene']:
                self._original = self._pending_scene[1]
                self._balanced = None
                self._published = self._original
            self._pending_scene = None
            restart = {'scene', 'mode', 'crank_speed', 'publish_rate'} & set(changed)
            if any(k.startswith('follow.') for k in changed):
                self._estimator = self._new_estimator(self._values)
        if restart:
            self._apply_mode()
        elif 'frame_id' in changed:
            self._streamer.set_model(self._published)  # prepared messages carry the old one
        if 'use_balanced' in changed or 'scene' in changed:
            if not self._values['use_balanced']:
                self._switch_to(self._original)
            elif self._balanced is not None:
                self._switch_to(self._balanced)
            else:
                self._balance_in_background()
        if {'scene', 'recording_path', 'rerun_url'} & set(changed):
            self._open_recorder()
        if 'scene' in changed or 'mode' in changed:
            self._announce()

    # ------------------------------------------------------------------ services

    def _on_balance(self, request, response):
        """Balance with the current options, publish the design, answer its YAML."""
        if not self._balance_lock.acquire(blocking=False):
            response.success, response.message = False, BUSY
            return response
        try:
            model, text = self._run_balancing()
        except Exception as exc:  # noqa: BLE001 - any failure is answered, never fatal
            response.success = False
            response.message = (f'balancing failed: {exc}; still publishing the '
                                f'{"balanced" if self._balanced else "original"} design')
            return response
        finally:
            self._balance_lock.release()
        if model is None:
            response.success, response.message = False, text
            return response
        with self._lock:
            self._balanced = model
        self._open_recorder()  # the recording shows the original against the new design
        self.set_parameters([Parameter('use_balanced', value=True)])
        response.success, response.message = True, text
        return response

    def _on_reset(self, request, response):
        """Return to the scene's original design."""
        if self._balance_lock.locked():
            response.success, response.message = False, BUSY
            return response
        with self._lock:
            self._balanced = None
        self.set_parameters([Parameter('use_balanced', value=False)])
        response.success = True
        response.message = f'publishing the original design of scene ' \
                           f'{self._original.scene.name!r}'
        return response

    def _run_balancing(self):
        """Return ``(model, YAML)`` of the balanced design, or ``(None, reason)``."""
        with self._lock:
            original, values = self._original, dict(self._values)
        method = balancing.method_for(original.rig)
        design = balancing.balance(original.rig, method, **params.balance_options(values, method))
        report = design.report
        model = original.with_design(design.scene)
        with self._lock:
            if self._original is not original:
                return None, ('the scene changed during the balancing run; still publishing '
                              "the new scene's original design")
        return model, yaml.safe_dump(report, sort_keys=False)

    def _balance_in_background(self):
        """use_balanced is true but no design is known: balance, then publish the design."""
        def run():
            if not self._balance_lock.acquire(blocking=False):
                return  # the running ~/balance call publishes its design
            try:
                model, text = self._run_balancing()
            except Exception as exc:  # noqa: BLE001 - reported, the original stays
                model, text = None, f'balancing failed: {exc}'
            finally:
                self._balance_lock.release()
            if model is None:
                self.get_logger().error(f'use_balanced: {text}; publishing the original')
                self.set_parameters([Parameter('use_balanced', value=False)])
                return
            with self._lock:
                self._balanced = model
                wanted = self._values['use_balanced']
            self._open_recorder()
            if wanted:
                self._switch_to(model)
                self.get_logger().info('use_balanced: publishing the balanced design')

        self.get_logger().info('use_balanced: balancing with the balance.* parameters ...')
        threading.Thread(target=run, name='rig-balance', daemon=True).start()

    # ------------------------------------------------------------------ shutdown

    def destroy_node(self):
        """
        Stop the publishing threads, close the recording, destroy the node, log the stats.

        After Ctrl-C or SIGTERM rclpy has already shut the context down, so the node's
        rosout publisher is invalid: the statistics are then logged once the node (and its
        rosout registration) is gone, to the console only, instead of failing to reach
        rosout ("Failed to publish log message to rosout").
        """
        self._streamer.stop()
        with self._recorder_lock:
            if self._recorder is not None:
                self._recorder.close()
                self._recorder = None
        logger, line = self.get_logger(), self._stats_line()
        if self.context.ok():
            logger.info(line)
            return super().destroy_node()
        destroyed = super().destroy_node()
        logger.info(line)
        return destroyed

    def _stats_line(self):
        """Return the publishing statistics: a summary, then :data:`STATS_TAG` and JSON."""
        stats = self._streamer.stats.summary()
        return (f'published {stats["published"]} samples ({stats["skipped"]} ticks skipped); '
                f'compute {stats["prepare_per_sample_s"] * 1e6:.1f} us per sample (core and '
                f'serialization, batched); publishing {stats["step_median_s"] * 1e6:.1f} us '
                f'median per sample; {STATS_TAG}{json.dumps(stats)}')


def _check_link_options(values, model):
    """Check the per-link balancing options against the links of a redistributable rig."""
    if 'mass_redistribution' in model.rig.capabilities:
        params.check_links(values, [lk.name for lk in model.scene.links])


def main(args=None):
    """Run the rig node until shutdown; return the exit status."""
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    rclpy.init(args=args)
    node = None
    try:
        node = RigNode()
        rclpy.spin(node, executor=MultiThreadedExecutor(num_threads=EXECUTOR_THREADS))
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (ValueError, ParameterException) as exc:
        print(f'rig_node: error: {exc}', file=sys.stderr)
        return EXIT_BAD_PARAMETER
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
