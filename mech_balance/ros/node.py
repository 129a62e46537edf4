"""
The rig node: joint states and the shaking wrench on ROS 2 topics, a balancing service.

``ros2 run mech_balance rig_node`` (here: the ``rig_node`` console script or
``python -m mech_balance.node``) starts node ``rig``; every name is relative, so
``--ros-args -r __ns:=/cell3`` runs several rigs side by side.

Publications (both stamped with the time of the crank angle they belong to)
    ``joint_states`` (sensor_msgs/msg/JointState: the URDF's joints,
    :mod:`mech_balance.ros.description`) and ``shaking_wrench``
    (geometry_msgs/msg/WrenchStamped), values in :mod:`mech_balance.twin`; the URDF on
    ``robot_description`` (latched, while ``publish_robot_description``).
Subscription (follow mode)
    ``crank_joint_state`` (sensor_msgs/msg/JointState), the crank encoder.
Services (std_srvs/srv/Trigger)
    ``~/balance`` runs the balancing with the ``balance.*`` parameters and publishes the
    balanced design (the answer's ``message`` is the YAML of the result); ``~/reset``
    returns to the scene's original design (and from a calibrated scene to the scene).
The real rig (section "the twin against the real rig" below, :mod:`mech_balance.ros.sensor`)
    subscribes ``measured_wrench`` (geometry_msgs/msg/WrenchStamped, the force sensor),
    publishes ``wrench_residual`` (measured minus model, rig frame, moment point, the
    measurement's stamp) and ``/diagnostics`` (diagnostic_msgs/msg/DiagnosticArray, 1 Hz,
    :mod:`mech_balance.ros.diagnostics`); services ``~/tare`` (the sensor bias) and
    ``~/identify`` (calibrate the scene from the buffered data, publish it).
Every parameter is declared once in :data:`mech_balance.params.PARAMETERS`
(``config/rig_params.yaml`` is a working set).

The node holds no numerics: :mod:`mech_balance.twin` evaluates the core and runs the
publishing threads, :mod:`mech_balance.ros_conversions` fills the messages.
"""

import json
import os
import sys
import tempfile
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped
from mech_balance import atomic, balancing
from mech_balance import schema as scene_mod
from mech_balance.analysis import identify
from mech_balance.ros import conversions as conv, description
from mech_balance.ros import diagnostics, sensor
from mech_balance.ros import guard as guards
from mech_balance.ros import params, streaming as twin
from rcl_interfaces.msg import SetParametersResult
import rclpy
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import JointState
from std_msgs.msg import String
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
EXIT_FAILURE = 1
BALANCE_RESULT = '~/balance_result'
"""Transient-local std_msgs/String: the YAML of the last balancing run (late joiners get it)."""
MEASURED_WRENCH = 'measured_wrench'
WRENCH_RESIDUAL = 'wrench_residual'
DIAGNOSTICS = '/diagnostics'
MEASUREMENT_DEPTH = 1000
"""History of the measured_wrench subscription."""
SENSOR_PERIOD_S = 0.02
"""Period of the pairing of measurements with the model (one core call per period)."""
DIAGNOSTICS_PERIOD_S = 1.0
"""Period of /diagnostics (the ROS convention: 1 Hz)."""


class RigNode(Node):
    """Wire the twin of a scene to topics, the balancing services and the parameters."""

    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        self._lock = threading.RLock()
        self._balance_lock = threading.Lock()
        self._guard = guards.Guard(lambda text: self.get_logger().warning(text))
        self._values = {}
        for spec in params.PARAMETERS:
            self._declare(spec)
        self._original = self._build_model(self._values['scene'])
        self._declare_link_parameters(self._original)
        _check_link_options(self._values, self._original)
        self._zero_stamp_said = False
        params.check_together(self._values)
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
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self._result_pub = self.create_publisher(String, BALANCE_RESULT, latched)
        self._balance_srv = self.create_service(Trigger, '~/balance',
                                                self._refusing('~/balance', self._on_balance),
                                                callback_group=ReentrantCallbackGroup())
        self._reset_srv = self.create_service(Trigger, '~/reset',
                                              self._refusing('~/reset', self._on_reset))
        self._description = description.DescriptionPublisher(self)

        self._streamer = twin.Streamer(lambda: self.get_clock().now().nanoseconds,
                                       self._prepare, self._publish, self._warn, self._record,
                                       guard=self._guard)
        self._open_recorder()
        self._describe()
        self._init_real_rig()
        # say what the node publishes before it starts to (a signal right after the first
        # samples then finds nothing left to log to rosout)
        self._announce()
        self._apply_mode()
        self.add_pre_set_parameters_callback(self._coerce_parameters)
        self.add_on_set_parameters_callback(self._guard.refusing(
            'parameters', lambda exc, ps: SetParametersResult(
                successful=False, reason=guards.parameter_reason(ps, exc)))(
                    self._on_set_parameters))
        self.add_post_set_parameters_callback(
            self._guard.skipping('applying parameters')(self._on_parameters_set))
        if self._values['use_balanced']:
            self._balance_in_background()

    # ------------------------------------------------------------------ guard

    def _refusing(self, label, callback):
        """Guard a Trigger service: any exception is answered ``success=False`` (a reason)."""
        def refuse(exc, request, response):
            response.success, response.message = False, f'{label}: {guards.describe(exc)}'
            return response
        return self._guard.refusing(label, refuse)(callback)

    def _declare(self, spec):
        """Declare a parameter; store its checked value, of the declared type (ROS too)."""
        declared = self.declare_parameter(spec.name, spec.default if not
                                          spec.name.startswith(params.LINK_PREFIX) else None,
                                          conv.parameter_descriptor(spec))
        value = conv.parameter_value(declared)
        value = spec.default if value is None else params.coerced(spec.name, value)
        self._values[spec.name] = params.check(spec.name, value)
        typed = conv.ros_parameter(spec.name, self._values[spec.name])
        if declared.type_ != typed.type_:  # an integer for a double, an unset link option
            self.set_parameters([typed])

    def _declare_link_parameters(self, model):
        """Declare ``balance.links.<link>.*`` for the scene's links; drop the others'."""
        links = model.rig.scene.links if 'mass_redistribution' in model.rig.capabilities \
            else ()
        wanted = {spec.name: spec for spec in params.link_specs([lk.name for lk in links])}
        for name in [n for n in self._values if n.startswith(params.LINK_PREFIX)]:
            if name not in wanted:
                self.undeclare_parameter(name)
                self._values.pop(name, None)
        for name, spec in wanted.items():
            if name not in self._values:
                self._declare(spec)

    def _coerce_parameters(self, parameters):
        """Pre-set: an integer becomes the declared double (rclpy stores the declared type)."""
        out = []
        for p in parameters:
            try:
                value = conv.parameter_value(p)
                new = params.coerced(p.name, value)
                out.append(p if new is value else conv.ros_parameter(p.name, new))
            except Exception:  # noqa: BLE001 - the on-set callback names what is wrong
                out.append(p)
        return out

    # ------------------------------------------------------------------ wiring

    def _build_model(self, name):
        """Load, validate and assemble a scene (the scene loader's checks); ValueError."""
        try:
            return description.twin_for(scene_mod.load(name))  # URDF joints: description
        except OSError as exc:
            raise ValueError(f'scene: cannot read {name!r}: {exc.strerror}') from None
        except ValueError as exc:
            if str(exc).startswith('scene'):
                raise
            raise ValueError(f'scene {name!r}: {exc}') from None

    def _new_estimator(self, values):
        return twin.CrankEstimator(values['follow.window'], values['follow.max_speed'],
                                   values['follow.max_gap'],
                                   values['follow.use_encoder_velocity'],
                                   values['follow.resync_after'])

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
                JointState, ENCODER, self._guard.skipping(ENCODER)(self._on_encoder),
                QoSProfile(depth=ENCODER_DEPTH),
                callback_group=self._encoder_group,
                qos_overriding_options=QoSOverridingOptions.with_default_policies())

    def _switch_to(self, model):
        """Publish ``model`` (the original or a balanced design) from the next sample on."""
        with self._lock:
            self._published = model
            self._streamer.set_model(model)
        self._describe()

    def _describe(self):
        """Publish the URDF of the published design on robot_description (if enabled)."""
        self._description.show(self._values['publish_robot_description'], self._published,
                               self._values['frame_id'])

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
        self._model_watch.add(samples)
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
            self._encoder_input.reject('ignored in clock mode')
            return
        joint = self._values['crank_joint'] or self._original.crank_joint
        estimator = self._estimator
        try:
            stamp_ns, position, velocity = conv.crank_reading(msg, joint)
            if stamp_ns == 0:  # unset: `ros2 topic pub` sends stamp 0 (README: follow mode)
                stamp_ns = self.get_clock().now().nanoseconds
                if not self._zero_stamp_said:
                    self._zero_stamp_said = True
                    self.get_logger().info(f'{ENCODER}: a message with an unset (zero) stamp: '
                                           'such messages are stamped with their receive time')
            sample = estimator.update(stamp_ns, position, velocity)
        except ValueError as exc:
            self._skipped_inputs += 1
            self._encoder_input.reject(diagnostics.reason_of(exc))
            self._warn(f'{ENCODER}: skipped a message ({self._skipped_inputs} so far): {exc}')
            return
        if estimator.just_resynced:
            self.get_logger().warning(f'{ENCODER}: re-synchronized on the incoming stream at '
                                      f'{stamp_ns * 1e-9:.9f} s: {estimator.last_resync}')
        self._encoder_input.use()
        self._sensor_encoder(stamp_ns, position, None if sample is None else sample.turned_rad)
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
        candidate = dict(self._values)
        model = self._original
        for p in parameters:
            if params.spec_for(p.name) is None:
                continue  # use_sim_time, qos overrides: rclpy's own
            value = conv.parameter_value(p)
            if value is None and p.name.startswith(params.LINK_PREFIX):
                value = []  # declared unset: the factors
            value = candidate[p.name] = params.check(p.name, value)
            if p.name == 'scene' and value != self._values['scene']:
                model = self._build_model(value)
                self._pending_scene = (value, model)
        _check_link_options(candidate, model)
        _balance_method(candidate, model.rig)
        params.check_together(candidate)
        return SetParametersResult(successful=True)

    def _on_parameters_set(self, parameters):
        """Apply an accepted update."""
        changed = {p.name: params.check(p.name, conv.parameter_value(p))
                   for p in parameters if params.spec_for(p.name) is not None and
                   p.value is not None}
        with self._lock:
            self._values.update(changed)
            if 'scene' in changed and self._pending_scene is not None and \
                    self._pending_scene[0] == changed['scene']:
                self._original = self._pending_scene[1]
                self._balanced = None
                self._published = self._original
            self._pending_scene = None
            restart = {'scene', 'mode', 'crank_speed', 'publish_rate'} & set(changed) or \
                'use_sim_time' in {p.name for p in parameters}  # a new clock: start again
            if any(k.startswith('follow.') for k in changed):
                self._estimator = self._new_estimator(self._values)
        if 'scene' in changed:
            self._declare_link_parameters(self._original)
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
        if {'scene', 'frame_id', 'publish_robot_description'} & set(changed):
            self._describe()
        if 'scene' in changed or 'mode' in changed:
            self._announce()
        self._sensor_parameters_set(changed)

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
        note = self._uncalibrate()
        with self._lock:
            self._balanced = None
        self.set_parameters([Parameter('use_balanced', value=False)])
        response.success = True
        response.message = f'publishing the original design of scene ' \
                           f'{self._original.scene.name!r}{note}'
        return response

    def _run_balancing(self):
        """Return ``(model, answer)`` of the balanced design, or ``(None, reason)``."""
        with self._lock:
            original, values = self._original, dict(self._values)
        method = _balance_method(values, original.rig)
        design = balancing.balance(original.rig, method, **params.balance_options(values, method))
        model = original.with_design(design.scene)
        with self._lock:
            if self._original is not original:
                return None, ('the scene changed during the balancing run; still publishing '
                              "the new scene's original design")
        return model, self._publish_result(design)

    def _publish_result(self, design):
        """
        Publish a result on ``~/balance_result``, write it to a file; return the answer.

        The answer is YAML whose first line, a comment, is :meth:`Design.summary` (one line
        under 200 characters), the second where the full result is.
        """
        text = yaml.safe_dump(design.report, sort_keys=False)
        self._result_pub.publish(String(data=text))
        name = self.get_fully_qualified_name().strip('/').replace('/', '_')
        path = os.path.join(tempfile.gettempdir(), f'mech_balance_{name}_balance.yaml')
        try:
            atomic.write_text_atomic(path, text)
            where = f'{path} and {self._result_pub.topic_name}'
        except OSError as exc:
            where = f'{self._result_pub.topic_name} ({path} not written: {exc.strerror})'
        return f'# {design.summary()}\n# full result: {where} (std_msgs/String YAML)\n{text}'

    def _balance_in_background(self):
        """use_balanced is true but no design is known: balance, then publish the design."""
        @self._guard.skipping('use_balanced')
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

    # ------------------------------------------------------------------ the real rig
    # The twin against the real rig: measured_wrench paired with the published model
    # (mech_balance.ros.sensor), wrench_residual, ~/tare, ~/identify, /diagnostics
    # (mech_balance.ros.diagnostics).  self._sensor is guarded by self._sensor_lock.

    def _init_real_rig(self):
        """Create the sensor comparison, its topics, services and timers."""
        model = self._published
        self._sensor_lock = threading.Lock()
        self._sensor = sensor.Comparison(
            sensor.SensorPose(**params.sensor_pose_values(self._values)), model.moment_point_m,
            self._values['sensor.crank_window'], sensor.WeightModel.of(model.rig))
        self._sensor_model = model           # the model self._sensor compares with
        self._calibration = None             # (calibrated, the model it replaced, old bias)
        self._last_measurement_s = None      # time.monotonic() of the last measurement
        self._sensor_skips = 0
        self._encoder_input = diagnostics.InputCounter()
        self._model_watch = diagnostics.ModelWatch()
        self._rate_meter = diagnostics.RateMeter()
        self._skipped_reported = 0
        group = MutuallyExclusiveCallbackGroup()
        self._measured_sub = self.create_subscription(
            WrenchStamped, MEASURED_WRENCH,
            self._guard.skipping(MEASURED_WRENCH)(self._on_measured_wrench),
            QoSProfile(depth=MEASUREMENT_DEPTH), callback_group=group)
        self._residual_pub = self.create_publisher(WrenchStamped, WRENCH_RESIDUAL,
                                                   QoSProfile(depth=PUBLISH_DEPTH))
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, DIAGNOSTICS,
                                                      QoSProfile(depth=10))
        self._sensor_timer = self.create_timer(SENSOR_PERIOD_S,
                                               self._guard.skipping('sensor pairing')(
                                                   self._on_sensor_tick),
                                               callback_group=group)
        services = MutuallyExclusiveCallbackGroup()
        self._tare_srv = self.create_service(Trigger, '~/tare',
                                             self._refusing('~/tare', self._on_tare),
                                             callback_group=services)
        self._identify_srv = self.create_service(Trigger, '~/identify',
                                                 self._refusing('~/identify', self._on_identify),
                                                 callback_group=services)
        self._diagnostics_timer = self.create_timer(
            DIAGNOSTICS_PERIOD_S, self._guard.skipping(DIAGNOSTICS)(self._on_diagnostics),
            callback_group=MutuallyExclusiveCallbackGroup())
        self.get_logger().info(
            f'real rig: {self._measured_sub.topic_name} (geometry_msgs/msg/WrenchStamped, '
            f'sensor frame) -> {self._residual_pub.topic_name} (measured minus model, '
            f'{self._values["frame_id"]!r}, about {model.moment_point}); '
            f'{self._tare_srv.service_name}, {self._identify_srv.service_name}; '
            f'{DIAGNOSTICS} at {1.0 / DIAGNOSTICS_PERIOD_S:g} Hz')

    def _sensor_skip(self, what, exc):
        """Count and report a skipped sensor step (the node never dies from input)."""
        self._sensor_skips += 1
        self._warn(f'{what}: skipped ({self._sensor_skips} so far): '
                   f'{type(exc).__name__}: {exc}')

    def _sensor_encoder(self, stamp_ns, position_rad, turned_rad):
        """Follow mode: add an accepted encoder sample to the crank track."""
        with self._sensor_lock:
            self._sensor.encoder(stamp_ns, position_rad, turned_rad)

    def _on_measured_wrench(self, msg):
        """Accept one measurement; a bad one is counted by reason and skipped."""
        try:
            stamp_ns, force, torque = conv.wrench_reading(msg)
            with self._sensor_lock:
                self._sensor.measurement(stamp_ns, force, torque)
            self._last_measurement_s = time.monotonic()
        except Exception as exc:  # noqa: BLE001 - bad input is counted, never fatal
            with self._sensor_lock:
                self._sensor.rejected[diagnostics.reason_of(exc)] += 1
            self._warn(f'{MEASURED_WRENCH}: skipped a message: {exc}')

    def _on_sensor_tick(self):
        """Pair the measurements that can be paired; publish their residuals."""
        try:
            with self._sensor_lock:
                model = self._published
                if model is not self._sensor_model:
                    self._sensor.new_model(sensor.WeightModel.of(model.rig),
                                           model.moment_point_m)
                    self._sensor_model = model
                schedule = self._streamer.clock_schedule
                if self._values['mode'] == 'clock' and schedule is None:
                    return
                paired = self._sensor.process(model.evaluate, schedule)
            frame_id = self._values['frame_id']
            for stamp_ns, residual in zip(paired.stamps_ns, paired.residual):
                self._residual_pub.publish(conv.fill_wrench_values(
                    WrenchStamped(), int(stamp_ns), frame_id, residual))
        except Exception as exc:  # noqa: BLE001 - counted and reported, never fatal
            if self.context.ok():
                self._sensor_skip(WRENCH_RESIDUAL, exc)

    def _sensor_parameters_set(self, changed):
        """Apply accepted sensor.* parameters (a new pose forgets the bias and the data)."""
        if not any(k.startswith('sensor.') for k in changed):
            return
        pose = sensor.SensorPose(**params.sensor_pose_values(self._values))
        with self._sensor_lock:
            reposed = pose != self._sensor.pose
            self._sensor.configure(pose, self._values['sensor.crank_window'])
        if reposed:
            self.get_logger().info('sensor pose or convention changed: bias and buffered '
                                   'measurements forgotten (~/tare again)')

    def _on_tare(self, request, response):
        """Estimate the sensor bias from the last sensor.tare_seconds and use it."""
        try:
            with self._sensor_lock:
                estimate = self._sensor.tare(self._values['sensor.tare_seconds'])
        except Exception as exc:  # noqa: BLE001 - any failure is answered, never fatal
            response.success, response.message = False, f'tare failed: {exc}'
            return response
        response.success = True
        response.message = estimate.summary() + '\n' + yaml.safe_dump(
            scene_mod.plain(estimate.to_dict()), sort_keys=False)
        return response

    def _on_identify(self, request, response):
        """Identify the scene's inertial parameters from the buffered data; publish them."""
        try:
            with self._lock:
                base = self._original if self._calibration is None or \
                    self._original is not self._calibration[0] else self._calibration[1]
            with self._sensor_lock:
                schedule = self._streamer.clock_schedule
                data = self._sensor.identification_data(schedule)
            result = identify.identify(base.scene, *data[:4])
            summary = _identify_summary(result)
            report = {'summary': summary, **result.to_dict(),
                      'calibrated_scene': identify.calibrated_yaml(result, 'the rig node')
                      if result.realizable else None}
            text = yaml.safe_dump(scene_mod.plain(report), sort_keys=False)
            if not result.realizable:
                response.success = False
                response.message = f'{summary}; NOT physically realizable, still publishing ' \
                                   f'the current model\n{text}'
                return response
            calibrated = base.with_design(result.calibrated_scene())
        except Exception as exc:  # noqa: BLE001 - any failure is answered, never fatal
            response.success, response.message = False, f'identify failed: {exc}'
            return response
        with self._sensor_lock:
            old_bias = self._sensor.bias.copy()
            bias = old_bias.copy()
            bias[list(sensor.PLANAR)] = result.bias[:len(sensor.PLANAR)]
            self._sensor.bias = bias
        with self._lock:
            self._calibration = (calibrated, base, old_bias)
            self._original = calibrated
            self._balanced = None
        self.set_parameters([Parameter('use_balanced', value=False)])
        self._switch_to(calibrated)
        response.success, response.message = True, f'{summary}\n{text}'
        return response

    def _uncalibrate(self):
        """~/reset: from a calibrated scene back to the scene and the bias before it."""
        with self._lock:
            cal, self._calibration = self._calibration, None
            if cal is None or self._original is not cal[0]:
                return ''
            self._original = cal[1]
        with self._sensor_lock:
            self._sensor.bias = cal[2]
        return ' (calibration dropped)'

    def _on_diagnostics(self):
        """Publish the four statuses on /diagnostics."""
        try:
            now_ns = self.get_clock().now().nanoseconds
            self._diagnostics_pub.publish(conv.diagnostic_array(self._statuses(now_ns),
                                                                now_ns))
        except Exception as exc:  # noqa: BLE001 - counted and reported, never fatal
            if self.context.ok():
                self._sensor_skip(DIAGNOSTICS, exc)

    def _statuses(self, now_ns):
        """Return the publisher, encoder input, model and measured-wrench statuses."""
        name, hw, v = self.get_fully_qualified_name(), self._published.scene.name, self._values
        stats = self._streamer.stats
        skipped_new = max(stats.skipped - self._skipped_reported, 0)
        self._skipped_reported = stats.skipped
        clock = v['mode'] == 'clock'
        out = [diagnostics.publisher_status(
            f'{name}: publisher', hw, v['mode'], v['publish_rate'] if clock else None,
            self._rate_meter.rate(stats.count, now_ns), stats.count, stats.skipped,
            skipped_new)]
        used, rejected, new = self._encoder_input.snapshot()
        out.append(diagnostics.input_status(f'{name}: encoder input', hw, ENCODER, used,
                                            rejected, new))
        out.append(diagnostics.model_status(f'{name}: model', hw,
                                            *self._model_watch.snapshot()))
        last = self._last_measurement_s
        with self._sensor_lock:
            s = self._sensor
            rms = s.rms(v['sensor.residual_window'])
            out.append(diagnostics.measurement_status(
                f'{name}: measured wrench', hw, rms, sensor.COMPONENTS, sensor.UNITS,
                v['diagnostics.warn_fraction'], v['diagnostics.error_fraction'],
                s.received, s.used, dict(s.rejected),
                None if last is None else time.monotonic() - last, s.bias,
                self._sensor_model.scene.name))
        return out

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
        stats['caught'] = dict(self._guard.counts)
        return (f'published {stats["published"]} samples ({stats["skipped"]} ticks skipped, '
                f'{stats["withheld"]} non-finite withheld, {self._guard.total()} callback '
                'errors caught); '
                f'compute {stats["prepare_per_sample_s"] * 1e6:.1f} us per sample (core and '
                f'serialization, batched); publishing {stats["step_median_s"] * 1e6:.1f} us '
                f'median per sample; {STATS_TAG}{json.dumps(stats)}')


def _identify_summary(result):
    """Return the one-line summary of an identification (the first line of ~/identify)."""
    rms = ', '.join(f'{c} {b:.4g} -> {a:.4g} {identify.CHANNEL_UNITS[c]}'
                    for c, b, a in zip(result.channels, result.rms_before, result.rms_after))
    return (f'identified scene {result.scene.name!r} from {result.samples} measurements: '
            f'rank {result.rank} of {len(result.names)}, condition number '
            f'{result.condition_number:.4g}; residual RMS before -> after: {rms}')


def _check_link_options(values, model):
    """Check the per-link balancing options against the links of a redistributable rig."""
    if 'mass_redistribution' in model.rig.capabilities:
        links = [lk.name for lk in model.scene.links]
        own = {f'{params.LINK_PREFIX}{link}.' for link in links}
        params.check_links({k: v for k, v in values.items() if not k.startswith(
            params.LINK_PREFIX) or k[:k.rindex('.') + 1] in own}, links)


def _balance_method(values, rig):
    """
    Return the balancing method of ``balance.method`` for ``rig``; ValueError if it has none.

    The default, redistribution, on a rig that cannot be redistributed (the RGGR) is the
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
        print(f'rig_node: error: {guards.clip(exc)}', file=sys.stderr)
        return EXIT_BAD_PARAMETER
    except Exception as exc:  # noqa: BLE001 - a defect is one line, not a traceback
        print(f'rig_node: error: {guards.describe(exc)}', file=sys.stderr)
        return EXIT_FAILURE
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
