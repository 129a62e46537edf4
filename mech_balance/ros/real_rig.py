"""
The rig node's real-rig part: the twin against a force sensor, ``~/tare``, ``~/identify``.

``measured_wrench`` in, paired with the published model (:mod:`mech_balance.ros.sensor`);
``wrench_residual`` and ``/diagnostics`` out.
"""

import threading
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped
from mech_balance import schema as scene_mod, threads
from mech_balance.analysis import identify as identification
from mech_balance.ros import conversions as conv, diagnostics, params, sensor
import numpy as np
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.qos import QoSProfile
import yaml

MEASURED_WRENCH = 'measured_wrench'
WRENCH_RESIDUAL = 'wrench_residual'
DIAGNOSTICS = '/diagnostics'
MEASUREMENT_DEPTH = 1000
"""History of the measured_wrench subscription."""
RESIDUAL_DEPTH = 100
"""History of the wrench_residual publisher."""
SENSOR_PERIOD_S = 0.02
"""Period of the pairing of measurements with the model (one core call per period)."""
DIAGNOSTICS_PERIOD_S = 1.0
"""Period of /diagnostics (the ROS convention: 1 Hz)."""


class RealRig:
    """
    The measured wrench against the published model (the node's state), and its services.

    ``extra_statuses(name, hardware_id)``: more statuses for ``/diagnostics``, or None.
    """

    def __init__(self, node, state, guard, warn, publisher, extra_statuses=None):
        self._node = node
        self._state = state
        self._warn = warn
        self._publisher = publisher
        self._extra_statuses = extra_statuses
        values, model = state.values, state.published
        self.lock = threading.Lock()
        self.comparison = sensor.Comparison(
            params.sensor_pose(values), model.moment_point_m,
            values['sensor.crank_window'], sensor.WeightModel.of(model.rig),
            resync_after=values['follow.resync_after'])
        self._model = model                 # the model self.comparison compares with
        self._last_measurement_s = None     # time.monotonic() of the last measurement
        self._skips = 0
        group = MutuallyExclusiveCallbackGroup()
        self.measured_sub = node.create_subscription(
            WrenchStamped, MEASURED_WRENCH,
            guard.skipping(MEASURED_WRENCH)(self.on_measured_wrench),
            QoSProfile(depth=MEASUREMENT_DEPTH), callback_group=group)
        self.residual_pub = node.create_publisher(WrenchStamped, WRENCH_RESIDUAL,
                                                  QoSProfile(depth=RESIDUAL_DEPTH))
        self.diagnostics_pub = node.create_publisher(DiagnosticArray, DIAGNOSTICS,
                                                     QoSProfile(depth=10))
        self._pairing_timer = node.create_timer(
            SENSOR_PERIOD_S, guard.skipping('sensor pairing')(self.on_pairing_tick),
            callback_group=group)
        self._diagnostics_timer = node.create_timer(
            DIAGNOSTICS_PERIOD_S, guard.skipping(DIAGNOSTICS)(self.on_diagnostics),
            callback_group=MutuallyExclusiveCallbackGroup())

    def _skip(self, what, exc):
        """Count and report a skipped sensor step (the node never dies from input)."""
        self._skips += 1
        self._warn(f'{what}: skipped ({self._skips} so far): {type(exc).__name__}: {exc}')

    def on_encoder(self, stamp_ns, position_rad, turned_rad, resynced=False):
        """Follow mode: add an accepted encoder sample to the crank track."""
        with self.lock:
            self.comparison.encoder(stamp_ns, position_rad, turned_rad, resynced=resynced)

    def on_measured_wrench(self, msg):
        """Accept one measurement; a bad one is counted by reason and skipped."""
        try:
            stamp_ns, force, torque = conv.wrench_reading(msg)
            with self.lock:
                self.comparison.measurement(stamp_ns, force, torque)
                resync = self.comparison.just_resynced
            self._last_measurement_s = time.monotonic()
            if resync:
                self._node.get_logger().warning(
                    f'{MEASURED_WRENCH}: re-synchronized on the incoming stream at '
                    f'{stamp_ns * 1e-9:.9f} s: {self.comparison.last_resync}')
        except Exception as exc:  # noqa: BLE001 - bad input is counted, never fatal
            with self.lock:
                self.comparison.rejected[diagnostics.reason_of(exc)] += 1
            self._warn(f'{MEASURED_WRENCH}: skipped a message: {exc}')

    def on_pairing_tick(self):
        """Pair the measurements that can be paired; publish their residuals."""
        try:
            with self.lock:
                model = self._state.published
                if model is not self._model:
                    self.comparison.new_model(sensor.WeightModel.of(model.rig),
                                              model.moment_point_m)
                    self._model = model
                schedule = self._publisher.streamer.clock_schedule
                if self._state.values['mode'] == 'clock' and schedule is None:
                    return
                paired = self.comparison.process(model.evaluate, schedule)
            frame_id = self._state.values['frame_id']
            finite = np.all(np.isfinite(paired.residual), axis=1)
            if not finite.all():  # the last check: nothing non-finite is published
                with self.lock:
                    self.comparison.rejected['non-finite residual'] += int(np.sum(~finite))
            for stamp_ns, residual in zip(paired.stamps_ns[finite], paired.residual[finite]):
                self.residual_pub.publish(conv.fill_wrench_values(
                    WrenchStamped(), int(stamp_ns), frame_id, residual))
        except Exception as exc:  # noqa: BLE001 - counted and reported, never fatal
            if self._node.context.ok():
                self._skip(WRENCH_RESIDUAL, exc)

    def parameters_set(self, changed):
        """Apply accepted sensor.* parameters (a new pose forgets the bias and the data)."""
        values = self._state.values
        if 'follow.resync_after' in changed:
            with self.lock:
                self.comparison.resync_after = max(1, int(values['follow.resync_after']))
        if not any(k.startswith('sensor.') for k in changed):
            return
        pose = params.sensor_pose(values)
        with self.lock:
            reposed = pose != self.comparison.pose
            self.comparison.configure(pose, values['sensor.crank_window'])
        if reposed:
            self._node.get_logger().info('sensor pose or convention changed: bias and buffered '
                                         'measurements forgotten (~/tare again)')

    def tare(self):
        """Return ``(success, message)``: the bias from the last sensor.tare_seconds, used."""
        try:
            with self.lock:
                estimate = self.comparison.tare(self._state.values['sensor.tare_seconds'])
        except Exception as exc:  # noqa: BLE001 - any failure is answered, never fatal
            return False, f'tare failed: {exc}'
        return True, estimate.summary() + '\n' + yaml.safe_dump(
            scene_mod.plain(estimate.to_dict()), sort_keys=False)

    def identify(self, base):
        """
        Identify ``base``'s inertial parameters (and the bias, then used) from the buffered data.

        Return ``(success, message, calibrated model or None, bias before)``.
        """
        try:
            with self.lock:
                schedule = self._publisher.streamer.clock_schedule
                data = self.comparison.identification_data(schedule)
            result = identification.identify(base.scene, *data[:4])
            rms = ', '.join(f'{c} {b:.4g} -> {a:.4g} {identification.CHANNEL_UNITS[c]}' for c, b, a
                            in zip(result.channels, result.rms_before, result.rms_after))
            summary = (f'identified scene {result.scene.name!r} from {result.samples} '
                       f'measurements: rank {result.rank} of {len(result.names)}, condition '
                       f'number {result.condition_number:.4g}; residual RMS before -> after: '
                       f'{rms}')
            report = {'summary': summary, **result.to_dict(),
                      'calibrated_scene': identification.calibrated_yaml(result, 'the rig node')
                      if result.realizable else None}
            text = yaml.safe_dump(scene_mod.plain(report), sort_keys=False)
            if not result.realizable:
                return False, (f'{summary}; NOT physically realizable, still publishing the '
                               f'current model\n{text}'), None, None
            calibrated = base.with_design(result.calibrated_scene())
        except Exception as exc:  # noqa: BLE001 - any failure is answered, never fatal
            return False, f'identify failed: {exc}', None, None
        finally:
            threads.release_memory()    # its working memory back to the system
        with self.lock:
            old_bias = self.comparison.bias.copy()
            bias = old_bias.copy()
            bias[list(sensor.PLANAR)] = result.bias[:len(sensor.PLANAR)]
            self.comparison.bias = bias
        return True, f'{summary}\n{text}', calibrated, old_bias

    def restore_bias(self, bias):
        """Use ``bias`` again (``~/reset`` from a calibrated scene)."""
        with self.lock:
            self.comparison.bias = bias

    def on_diagnostics(self):
        """Publish the statuses on /diagnostics."""
        try:
            now_ns = self._node.get_clock().now().nanoseconds
            self.diagnostics_pub.publish(conv.diagnostic_array(self.statuses(now_ns), now_ns))
        except Exception as exc:  # noqa: BLE001 - counted and reported, never fatal
            if self._node.context.ok():
                self._skip(DIAGNOSTICS, exc)

    def statuses(self, now_ns):
        """Return the publisher's statuses, the measured-wrench status and any extra ones."""
        name = self._node.get_fully_qualified_name()
        hw, values = self._state.published.scene.name, self._state.values
        out = self._publisher.statuses(name, hw, now_ns)
        last = self._last_measurement_s
        with self.lock:
            s = self.comparison
            rms = s.rms(values['sensor.residual_window'])
            out.append(diagnostics.measurement_status(
                f'{name}: measured wrench', hw, rms, sensor.COMPONENTS, sensor.UNITS,
                values['diagnostics.warn_fraction'], values['diagnostics.error_fraction'],
                s.received, s.used, dict(s.rejected),
                None if last is None else time.monotonic() - last, s.bias,
                self._model.scene.name, s.resyncs))
        if self._extra_statuses is not None:
            out.extend(self._extra_statuses(name, hw))
        return out
