"""
Calibrate a rig's twin from a recording: encoder and force sensor in a rosbag2 bag.

::

    python examples/identify.py [DIR]      # writes DIR/rig_bag (default: a temporary dir)

A real rig records its crank encoder (``sensor_msgs/msg/JointState``) and the force sensor
under its frame (``geometry_msgs/msg/WrenchStamped``).  Here the "real" rig is Hoeken's
four-bar with heavier links than its scene says, run with a rippled crank speed, its
encoder quantized to 4096 counts per turn and its sensor noisy and biased; the bag is
written as the rig would record it, read back, and the scene's inertial parameters are
identified from it (docs/identification.md).
"""

from dataclasses import replace
import sys
import tempfile

import mech_balance as mb
from mech_balance.ros import bags
import numpy as np

scene = mb.load_scene('hoeken')
true = scene.with_links([replace(link, mass_kg=link.mass_kg * factor)
                         for link, factor in zip(scene.links, (1.2, 0.9, 1.1))],
                        name='hoeken_as_built')

# 12 s at 500 Hz, crank speed 1 rad/s +- 5 %
rng = np.random.default_rng(1)
t = np.arange(6000) / 500.0
w0, ripple, wr = scene.crank_speed_rad_s, 0.05, 2.0
psi = w0 * t + w0 * ripple * (1.0 - np.cos(wr * t)) / wr
speed = w0 * (1.0 + ripple * np.sin(wr * t))
accel = w0 * ripple * wr * np.cos(wr * t)
data = mb.rig_for(true).at(psi, speed=speed, accel=accel, outputs=('shaking_wrench',))
wrench = np.column_stack([data.force_N[:, :2], data.moment_Nm[:, 2]])
peak = np.abs(wrench).max(axis=0)
wrench += 0.05 * peak + 0.01 * peak * rng.standard_normal(wrench.shape)
counts = 2.0 * np.pi / 4096
encoder = np.mod(np.round(psi / counts) * counts, 2.0 * np.pi)
t_ns = 1_700_000_000_000_000_000 + np.round(t * 1e9).astype(np.int64)

path = f'{sys.argv[1] if len(sys.argv) > 1 else tempfile.mkdtemp()}/rig_bag'
bags.write_bag(path, 'mcap', t_ns, encoder, wrench, joint='O1', frame_id='rig_frame')
print(f'wrote {path}: {len(t)} encoder and {len(t)} wrench messages')

rec = bags.read(path)
result = mb.identify(scene, rec.encoder_t_s, rec.position_rad, rec.wrench_t_s,
                     rec.planar_wrench, rec.effort_Nm)
print(result.summary())
print(f'rank {result.rank} of {len(result.names)}, condition {result.condition_number:.4g}')
for channel, before, after in zip(result.channels, result.rms_before, result.rms_after):
    print(f'residual {channel}: {before:.6g} -> {after:.6g}')
calibrated = result.calibrated_scene()
rms = {}
for name, sc in (('scene', scene), ('true', true), ('calibrated', calibrated)):
    rows = {row.quantity: row.rms for row in mb.summarize(mb.run_cycle(sc))}
    rms[name] = rows['shaking force |f_sh|'], rows['shaking moment n_sh']
pred = result.prediction
print(f'RMS shaking force: scene {rms["scene"][0]:.6g} N, true {rms["true"][0]:.6g} N, '
      f'calibrated {rms["calibrated"][0]:.6g} N (predicted {pred.force_N:.6g} +- '
      f'{pred.force_std_error_N:.2g} N)')
print(f'RMS shaking moment: scene {rms["scene"][1]:.6g} N m, true {rms["true"][1]:.6g} N m, '
      f'calibrated {rms["calibrated"][1]:.6g} N m (predicted {pred.moment_Nm:.6g} +- '
      f'{pred.moment_std_error_Nm:.2g} N m)')
for link, link_true, link_cal in zip(scene.links, true.links, calibrated.links):
    print(f'link {link.name}: mass scene {link.mass_kg:.6g} kg, true {link_true.mass_kg:.6g} '
          f'kg, calibrated {link_cal.mass_kg:.6g} kg')
