"""
Recordings a real rig produces when something is set up wrong or the storage is damaged.

Made from the synthetic rig (test/synthetic_rig.py: Hoeken, inertias perturbed by up to 20%,
4096-count encoder, 1 kHz, 1% sensor noise) and written as a real rig would write them:
rosbag2 MCAP, rosbag2 sqlite3 or CSV.  Each fault is a function of the clean streams;
:data:`FAULTS` names them (issue 32, item 5).
"""

from dataclasses import dataclass, replace
import math
import os
from pathlib import Path
import sys

from mech_balance import schema as scene_mod
from mech_balance.ros import bags
import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
import synthetic_rig as sr  # noqa: E402, I100

COUNTS = 4096
SPEED_RAD_S = 1.5 * math.pi
"""0.75 rev/s: an encoder stuck for 0.5 s misses 0.375 turn (less than half a turn: the
jump unwraps and went unnoticed)."""
SECONDS = 3.0
SEED = 61
LATE_NS = 50_000_000
"""The sensor 50 ms late."""
STUCK_S = (2.0, 2.5)
"""The encoder repeats its last position over this span (s from the start)."""
ENCODER_NOISE_RAD = 0.05
SECOND_ENCODER_OFFSET_RAD = 0.7
"""The second encoder's zero, relative to the first (its stamps 0.5 ms after the first's)."""
SECOND_SENSOR = ((0.1, 0.0, 0.0), (0.0, 0.0, 0.5 * math.pi))
"""The second sensor's pose in the rig frame (xyz m, rpy rad)."""


@dataclass
class Streams:
    """The two streams of a recording: stamps (int ns), values, and the wrench's frame_ids."""

    enc_ns: np.ndarray
    position: np.ndarray
    w_ns: np.ndarray
    wrench: np.ndarray          # (m, 3) or (m, 6)
    frame_ids: object = 'ft'    # one frame_id, or one per wrench message


def scenes():
    """Return (nominal, true) Hoeken scenes of the faults."""
    nominal = scene_mod.load('hoeken')
    return nominal, sr.perturbed(nominal, SEED)


def clean(seconds=SECONDS, seed=SEED):
    """Return the :class:`Streams` of a good recording of the true rig."""
    _, true = scenes()
    t_ns, pos, wrench, _ = sr.record_real(true, seconds, COUNTS, seed, w0=SPEED_RAD_S)
    return Streams(t_ns, pos, t_ns.copy(), wrench)


def degrees(s):
    """Return the streams with the encoder's positions in degrees, wrapping at 360."""
    return replace(s, position=np.degrees(s.position))


def negated(s):
    """Return the streams with the wrench negated: a sensor mounted upside down."""
    return replace(s, wrench=-s.wrench)


def swapped(s):
    """Return the wrench with its x and y exchanged."""
    return replace(s, wrench=s.wrench[:, [1, 0, 2]])


def late(s):
    """Return the sensor stamped 50 ms late."""
    return replace(s, w_ns=s.w_ns + LATE_NS)


def stuck(s):
    """Return the encoder stuck at one position for 0.5 s (it repeats its last message)."""
    t = (s.enc_ns - s.enc_ns[0]) * 1e-9
    k = np.flatnonzero((t >= STUCK_S[0]) & (t < STUCK_S[1]))
    pos = s.position.copy()
    pos[k] = pos[k[0] - 1]
    return replace(s, position=pos)


def encoder_noise(s):
    """Return 0.05 rad of white noise on the encoder (wrapped at 2 pi)."""
    rng = np.random.default_rng(SEED + 7)
    noisy = s.position + rng.normal(0.0, ENCODER_NOISE_RAD, s.position.size)
    return replace(s, position=np.mod(noisy, 2.0 * math.pi))


def two_encoders(s):
    """Return two encoders interleaved on one topic (the second's zero 0.7 rad off)."""
    second = np.mod(s.position + SECOND_ENCODER_OFFSET_RAD, 2.0 * math.pi)
    enc_ns = np.empty(2 * s.enc_ns.size, dtype=np.int64)
    enc_ns[0::2], enc_ns[1::2] = s.enc_ns, s.enc_ns + 500_000
    pos = np.empty(enc_ns.size)
    pos[0::2], pos[1::2] = s.position, second
    return replace(s, enc_ns=enc_ns, position=pos)


def two_sensors(s):
    """Return the wrench alternating between two sensors (the second mounted elsewhere)."""
    from mech_balance.core.rig import rig_for
    from mech_balance.ros import sensor
    nominal, _ = scenes()
    six = np.zeros((s.wrench.shape[0], 6))
    six[:, [0, 1, 5]] = s.wrench
    pose = sensor.SensorPose(*SECOND_SENSOR[0], *SECOND_SENSOR[1])
    f_b, n_b = pose.to_sensor(six, rig_for(nominal).moment_point_m)
    out = six.copy()
    out[1::2] = np.hstack([f_b, n_b])[1::2]
    ids = ['ft_a' if k % 2 == 0 else 'ft_b' for k in range(out.shape[0])]
    return replace(s, wrench=out, frame_ids=ids)


FAULTS = {
    'degrees': degrees, 'negated': negated, 'xy_swapped': swapped, 'late_50ms': late,
    'stuck': stuck, 'encoder_noise': encoder_noise, 'two_encoders': two_encoders,
    'two_sensors': two_sensors,
}
"""The misconfigurations of issue 32, item 5: name -> fault(clean streams)."""


def write(path, storage, s):
    """
    Write streams as a real rig would: a rosbag2 (mcap, sqlite3) or a CSV; return the path.

    A CSV row holds one encoder sample and one wrench sample: the wrench row k is the
    sensor's k-th sample wherever its stamp is (a late sensor is one whose rows carry
    samples taken before the row's time), and two interleaved encoders double the rows
    (the wrench repeated).
    """
    path = Path(path)
    if storage == 'csv':
        n = s.enc_ns.size
        wrench = s.wrench
        if wrench.shape[0] != n:
            wrench = np.repeat(wrench, n // wrench.shape[0], axis=0)
        if not np.array_equal(s.w_ns, s.enc_ns) and s.w_ns.size == n:
            # a late sensor: at row time t the sensor's newest sample is the one taken at
            # t - LATE (its stamp says t)
            shift = int(round(np.median(s.w_ns - s.enc_ns) / np.median(np.diff(s.enc_ns))))
            wrench = np.vstack([np.repeat(wrench[:1], shift, axis=0), wrench[:n - shift]])
        return bags.write_csv(path.with_suffix('.csv'), s.enc_ns * 1e-9, s.position, wrench)
    w_ns = None if np.array_equal(s.w_ns, s.enc_ns) else s.w_ns
    return bags.write_bag(path, storage, s.enc_ns, s.position, s.wrench, frame_id=s.frame_ids,
                          wrench_t_ns=w_ns)


BLOCK = 4096
"""A storage block: one of them zeroed."""


def zero_block(path, fraction=0.4):
    """Zero the 4 KiB block at ``fraction`` of a file (of a rosbag2's storage file)."""
    path = Path(path)
    if path.is_dir():
        path = next(p for p in path.iterdir() if p.suffix in ('.mcap', '.db3'))
    data = bytearray(path.read_bytes())
    start = int(len(data) * fraction) // BLOCK * BLOCK
    data[start:start + BLOCK] = bytes(BLOCK)
    path.write_bytes(bytes(data))
    return start


def stray_field(path, line=1000):
    """
    Append a stray number (`` 3.0``) to a CSV row's second field and leave its last empty.

    The row keeps as many commas as the header: read as whitespace-separated numbers every
    value after the stray one is one column to the right, the last one lost.
    """
    path = Path(path)
    lines = path.read_text().splitlines(keepends=True)
    fields = lines[line].rstrip('\n').split(',')
    fields[1] += ' 3.0'
    lines[line] = ','.join(fields[:-1] + ['']) + '\n'
    path.write_text(''.join(lines))
