"""The rig node's publisher part: ``joint_states`` and ``shaking_wrench``, clock or follow mode."""

from collections import Counter, deque
import threading

from geometry_msgs.msg import WrenchStamped
from mech_balance.ros import conversions as conv, diagnostics
from mech_balance.ros import streamer, streaming
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.qos import QoSProfile
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import JointState

JOINT_STATES = 'joint_states'
SHAKING_WRENCH = 'shaking_wrench'
ENCODER = 'crank_joint_state'
PUBLISH_DEPTH = 100
"""History of both publishers (absorbs a subscriber's jitter at kHz rates)."""
ENCODER_DEPTH = 1000
"""History of the encoder subscription (1 s at 1 kHz; a lost sample is counted by its gap)."""
GAP_FACTOR = 1.5
"""A step of the encoder stamps longer than this many typical steps counts missing samples."""
GAP_WINDOW = 64
"""Recent encoder steps whose median is the typical step."""


def new_estimator(values):
    """Return the follow-mode :class:`~mech_balance.ros.streaming.CrankEstimator` of values."""
    return streaming.CrankEstimator(values['follow.window'], values['follow.max_speed'],
                                    values['follow.max_gap'],
                                    values['follow.use_encoder_velocity'],
                                    values['follow.resync_after'])


class Publisher:
    """
    Publish the state's design on ``joint_states`` and ``shaking_wrench``.

    ``record(samples, turned_rad, stamps_ns)`` receives every evaluated batch,
    ``on_encoder(stamp_ns, position_rad, turned_rad, resynced)`` every accepted encoder sample.
    """

    def __init__(self, node, state, guard, warn, record=None, on_encoder=None):
        self._node = node
        self._state = state
        self._guard = guard
        self._warn = warn
        self._on_encoder_sample = on_encoder
        self._serializer = None        # conv.SampleSerializer of the published names, frame
        self._zero_stamp_said = False
        self.skipped_inputs = 0
        self.received = 0                  # encoder messages received in follow mode
        self.unanswered = Counter()        # of them (or missing): never published, why
        self._last_stamp = None
        self._steps = deque(maxlen=GAP_WINDOW)
        self.encoder_input = diagnostics.InputCounter()
        self.model_watch = diagnostics.ModelWatch()
        self.rate_meter = diagnostics.RateMeter()
        self._skipped_reported = 0
        self.estimator = new_estimator(state.values)
        qos = QoSProfile(depth=PUBLISH_DEPTH)
        overrides = QoSOverridingOptions.with_default_policies()
        self.joint_pub = node.create_publisher(JointState, JOINT_STATES, qos,
                                               qos_overriding_options=overrides)
        self.wrench_pub = node.create_publisher(WrenchStamped, SHAKING_WRENCH, qos,
                                                qos_overriding_options=overrides)
        self._encoder_sub = None
        self._encoder_group = MutuallyExclusiveCallbackGroup()
        self.streamer = streamer.Streamer(lambda: node.get_clock().now().nanoseconds,
                                          self._prepare, self._publish, warn, record,
                                          guard=guard)

    @property
    def encoder_topic(self):
        """Return the resolved name of the encoder topic."""
        ns = self._node.get_namespace().rstrip('/')
        return f'{ns}/{ENCODER}'

    def apply_mode(self):
        """Start publishing in the current mode; subscribe the encoder when first following."""
        values, model = self._state.values, self._state.published
        if values['mode'] == 'clock':
            # the encoder subscription stays (destroyed from a parameter callback it races
            # with the executor's other threads: InvalidHandle); clock mode ignores it
            period_ns = max(1, round(1e9 / values['publish_rate']))
            self.streamer.clock(model, self._state.crank_speed(), period_ns)
            return
        self.renew_estimator()  # and the cycle table
        self.streamer.follow(model)
        if self._encoder_sub is None:
            guarded = self._guard.skipping(ENCODER)(self.on_encoder)
            # two required arguments: rclpy then passes the message info (its reception stamp)
            self._encoder_sub = self._node.create_subscription(
                JointState, ENCODER, lambda msg, info: guarded(msg, info),
                QoSProfile(depth=ENCODER_DEPTH), callback_group=self._encoder_group,
                qos_overriding_options=QoSOverridingOptions.with_default_policies())

    def set_model(self, model):
        """Publish ``model`` from the next sample on (also: re-prepare for a new frame_id)."""
        self.streamer.set_model(model)
        if self._state.values['mode'] == 'follow':
            self._build_table(model)

    def renew_estimator(self):
        """Start the follow-mode estimator again (new ``follow.*`` parameters)."""
        values = self._state.values
        self.estimator = new_estimator(values)
        self.streamer.follow_exact = values['follow.exact']
        if values['mode'] == 'follow':
            self._build_table(self._state.published)

    def _build_table(self, model):
        """Build ``model``'s cycle table in a thread of its own (follow mode), then log it."""
        if self._state.values['follow.exact'] or not hasattr(model, 'cycle_table'):
            return

        def build():
            try:
                model.cycle_table()
                if self._node.context.ok():
                    self._node.get_logger().info(
                        f'follow mode, scene {model.scene.name!r}: {model.table_status}')
            except Exception as exc:  # noqa: BLE001 - the exact core is used instead
                self._guard.caught('follow mode: building the cycle table', exc)
        threading.Thread(target=build, name='rig-cycle-table', daemon=True).start()

    def follow_evaluation(self):
        """Return what follow mode evaluates per sample (for the model status)."""
        values, model = self._state.values, self._state.published
        if values['mode'] != 'follow':
            return 'clock mode: the exact core at the tick angles'
        if values['follow.exact']:
            return 'exact core per sample (follow.exact)'
        status = getattr(model, 'table_status', None)
        return status or 'exact core per sample (the cycle table is being built)'

    def stop(self):
        """Stop the publishing threads."""
        self.streamer.stop()

    def _prepare(self, samples, stamps_ns):
        """Serialize a batch of samples (the streamer's evaluating threads)."""
        self.model_watch.add(samples)
        key = (samples.joint_names, samples.joint_effort is not None,
               self._state.values['frame_id'])
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
            self.joint_pub.publish(payload[0])
            self.wrench_pub.publish(payload[1])
        except Exception:
            if self._node.context.ok():
                raise
            # Ctrl-C or SIGTERM: rclpy shut the context down before destroy_node stops
            # this thread; the sample is dropped without a warning (rosout is gone too)

    def on_encoder(self, msg, info=None):
        """Turn one encoder message (``info``: rclpy's message info) into a sample to publish."""
        values = self._state.values
        if values['mode'] != 'follow':  # subscribed by an earlier follow mode
            self.encoder_input.reject('ignored in clock mode')
            return
        joint = values['crank_joint'] or self._state.original.crank_joint
        estimator = self.estimator
        self.received += 1
        try:
            stamp_ns, position, velocity = conv.crank_reading(msg, joint)
            if stamp_ns == 0:  # unset: `ros2 topic pub` sends stamp 0 (docs/node.md: follow mode)
                stamp_ns = self._receive_time(info)
                if not self._zero_stamp_said:
                    self._zero_stamp_said = True
                    self._node.get_logger().info(
                        f'{ENCODER}: a message with an unset (zero) stamp: such messages are '
                        'stamped with their receive time')
            sample = estimator.update(stamp_ns, position, velocity)
        except ValueError as exc:
            self.skipped_inputs += 1
            self.unanswered['rejected (bad input, see the encoder input status)'] += 1
            self.encoder_input.reject(diagnostics.reason_of(exc))
            self._warn(f'{ENCODER}: skipped a message ({self.skipped_inputs} so far): {exc}')
            return
        if estimator.just_resynced:
            self.encoder_input.reject('re-synchronized')
            self._node.get_logger().warning(
                f'{ENCODER}: re-synchronized on the incoming stream at {stamp_ns * 1e-9:.9f} '
                f's: {estimator.last_resync}')
        self.encoder_input.use()
        self._count_gap(stamp_ns)
        if sample is None:
            self.unanswered['priming or re-synchronizing the estimator'] += 1
        if self._on_encoder_sample is not None:
            self._on_encoder_sample(stamp_ns, position,
                                    None if sample is None else sample.turned_rad,
                                    estimator.just_resynced)
        if sample is not None and not self.streamer.push(sample):
            self._warn(f'{ENCODER}: the core is behind the encoder; dropped the oldest sample')

    def _count_gap(self, stamp_ns):
        """Count the samples missing before ``stamp_ns`` (a gap of the encoder's stamps)."""
        last, self._last_stamp = self._last_stamp, stamp_ns
        if last is None or stamp_ns <= last:
            return
        step = stamp_ns - last
        if len(self._steps) >= 8:
            typical = sorted(self._steps)[len(self._steps) // 2]
            if step > GAP_FACTOR * typical:
                self.unanswered['missing (gaps in the encoder stamps)'] += \
                    max(int(round(step / typical)) - 1, 0)
                return   # a gap is not a step of the encoder
        self._steps.append(step)

    def follow_counts(self):
        """Return ``{'received': n, 'unanswered': {why: n}}`` of follow mode (since start)."""
        both = Counter(self.unanswered)
        with self.streamer._cond:
            both.update(self.streamer.unanswered)
        both['non-finite, withheld'] = self.streamer.stats.withheld
        return {'received': self.received, 'unanswered': {k: v for k, v in both.items() if v}}

    def _receive_time(self, info):
        """
        Return the time of an encoder message whose stamp is unset, ns on the node's clock.

        The middleware's source (else received) stamp, so a burst keeps its spacing; with
        simulated time or no message info, the node's clock now (`docs/node.md#follow-mode`).
        """
        clock = self._node.get_clock()
        if isinstance(info, dict) and not getattr(clock, 'ros_time_is_active', False):
            for key in ('source_timestamp', 'received_timestamp'):
                stamp = info.get(key)
                if isinstance(stamp, int) and stamp > 0:
                    return stamp
        return clock.now().nanoseconds

    def statuses(self, name, hardware_id, now_ns):
        """Return the ``publisher``, ``encoder input`` and ``model`` diagnostic statuses."""
        values = self._state.values
        stats = self.streamer.stats
        skipped_new = max(stats.skipped - self._skipped_reported, 0)
        self._skipped_reported = stats.skipped
        clock = values['mode'] == 'clock'
        used, rejected, new = self.encoder_input.snapshot()
        encoder = diagnostics.input_status(f'{name}: encoder input', hardware_id, ENCODER, used,
                                           rejected, new)
        counts = self.follow_counts()
        encoder.values += [('received (follow mode)', str(counts['received']))] + \
            [(f'not answered: {k}', str(v)) for k, v in sorted(counts['unanswered'].items())]
        return [diagnostics.publisher_status(
                    f'{name}: publisher', hardware_id, values['mode'],
                    values['publish_rate'] if clock else None,
                    self.rate_meter.rate(stats.count, now_ns), stats.count, stats.skipped,
                    skipped_new),
                encoder,
                diagnostics.model_status(f'{name}: model', hardware_id,
                                         *self.model_watch.snapshot(),
                                         evaluation=self.follow_evaluation())]
