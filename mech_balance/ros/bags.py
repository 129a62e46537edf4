"""
Recordings of a real rig: rosbag2 (MCAP or sqlite3) and CSV, read and written.

No ROS install is needed (``rosbags``).  The encoder's JointState and the sensor's
WrenchStamped, by their header stamps, in seconds from the earliest; the CSV columns
(:data:`CSV_REQUIRED`, :data:`CSV_OPTIONAL`): `docs/identification.md` (*Recording*).
"""

import csv
from dataclasses import dataclass
import math
import os
from pathlib import Path
import re
import shutil
import tempfile
import warnings

from mech_balance import atomic
from mech_balance.ros.names import DEFAULT_FRAME_ID, ENCODER_TOPIC, WRENCH_TOPIC
from mech_balance.rotations import matrix_rpy, quaternion_matrix
from mech_balance.schema.fields import MAX_ABS_VALUE
import numpy as np

JOINT_STATE = 'sensor_msgs/msg/JointState'
TF_MESSAGE = 'tf2_msgs/msg/TFMessage'
TF_STATIC_TOPIC = '/tf_static'
WRENCH_STAMPED = 'geometry_msgs/msg/WrenchStamped'
STORAGES = ('mcap', 'sqlite3')
"""rosbag2 storage plugins written and read (both Jazzy defaults)."""
BAG_VERSION = 9
"""rosbag2 metadata version written (Jazzy's)."""
PROGRESS_EVERY = 20000
"""Messages between two progress reports of a bag read."""
CSV_REQUIRED = ('t_s', 'crank_position_rad', 'force_x_N', 'force_y_N', 'torque_z_Nm')
CSV_OPTIONAL = ('force_z_N', 'torque_x_Nm', 'torque_y_Nm', 'crank_effort_Nm')
WRENCH_COLUMNS = ('force_x_N', 'force_y_N', 'force_z_N', 'torque_x_Nm', 'torque_y_Nm',
                  'torque_z_Nm')
"""Order of the six wrench components in :attr:`Recording.wrench`."""
MAX_SAMPLES = 2_000_000
"""Most samples per stream (33 min at 1 kHz; the arrays below about 160 MiB)."""
MAX_CSV_BYTES = 400 * 2 ** 20
"""Largest CSV file read (MAX_SAMPLES rows of nine full-precision numbers)."""
MAX_LINE_CHARS = 4096
"""Longest CSV line (a row of numbers is under 300 characters)."""
MAX_FIELD_CHARS = 64
"""Longest CSV field (a full-precision float is under 25 characters)."""
_LONG_FIELD = re.compile('[^,\n]{%d,}' % (MAX_FIELD_CHARS + 1))
_EMPTY_OR_SPLIT_FIELD = re.compile(r'(^|,)[ \t\r]*(,|$)|[^\s,][ \t]+[^\s,]', re.M)
"""An empty field, or two numbers in one field: left to the row-by-row parse, which names them."""
CSV_CHUNK_ROWS = 20000
"""CSV data lines parsed and checked at once (numpy), at most a few MiB of text."""
MAX_T_S = 9.2e9
"""Largest |t_s| in a CSV (int64 nanoseconds)."""


class RecordingError(ValueError):
    """A recording is missing, unreadable, or lacks a topic, joint or field."""


@dataclass
class Recording:
    """Encoder and force-sensor samples of a rig (SI, seconds from ``t0_ns``)."""

    encoder_t_s: np.ndarray        # (n,)
    position_rad: np.ndarray       # (n,)
    effort_Nm: np.ndarray          # (n,) or None
    wrench_t_s: np.ndarray         # (m,)
    wrench: np.ndarray             # (m, 6) force xyz N, torque xyz N*m
    joint: str
    frame_id: str
    t0_ns: int
    source: str
    sensor_tf: tuple = None        # (x, y, z, roll, pitch, yaw, parent, child) from /tf_static

    @property
    def planar_wrench(self):
        """Return the ``(m, 3)`` planar wrench [f_x, f_y, n_z]."""
        return self.wrench[:, [0, 1, 5]]


def _typestore():
    from rosbags.typesys import get_typestore, Stores
    return get_typestore(Stores.ROS2_JAZZY)


def read(path, encoder_topic=ENCODER_TOPIC, wrench_topic=WRENCH_TOPIC, joint=None,
         progress=None, default_joint=None, rig_frame=DEFAULT_FRAME_ID, wrench_frame_id=None):
    """
    Return the :class:`Recording` of a rosbag2 directory (or its file) or a CSV file.

    Options: :func:`read_bag`.  Every bad recording raises one :class:`RecordingError`
    naming the file, the topic or column, the record or row and what was expected.
    """
    p = Path(path)
    if not p.exists():
        raise RecordingError(f'--bag: got {str(path)!r}, which does not exist, expected a '
                             'rosbag2 directory or a .csv file')
    if p.suffix.lower() == '.csv':
        return read_csv(p, joint=joint or default_joint)
    return read_bag(p, encoder_topic, wrench_topic, joint, progress, default_joint,
                    rig_frame, wrench_frame_id)


def _bag_dir(p):
    """Return the rosbag2 directory of a path (a file inside it counts)."""
    if p.is_file() and (p.parent / 'metadata.yaml').exists():
        return p.parent
    if p.is_dir() and (p / 'metadata.yaml').exists():
        return p
    raise RecordingError(f'--bag: got {str(p)!r}, expected a rosbag2 directory (with '
                         'metadata.yaml) or a .csv file')


def _stamp_ns(header, topic, k):
    sec, nsec = int(header.stamp.sec), int(header.stamp.nanosec)
    if not 0 <= nsec < 1_000_000_000:
        raise RecordingError(f'{topic}: message {k}: header.stamp.nanosec = {nsec}, expected '
                             '0 <= nanosec < 1e9')
    return sec * 1_000_000_000 + nsec


def _check_metadata(bag):
    """Parse metadata.yaml with the package's bounded reader before rosbags sees it."""
    from mech_balance.schema import safe_yaml
    label = f'--bag: {str(bag / "metadata.yaml")!r}'
    data = safe_yaml.load_file(bag / 'metadata.yaml', label, RecordingError)
    if not isinstance(data, dict) or not isinstance(data.get('rosbag2_bagfile_information'),
                                                    dict):
        raise RecordingError(f'{label}: expected a mapping with rosbag2_bagfile_information')


class _Growing:
    """Columns of float64 samples appended one row at a time, in doubling numpy buffers."""

    def __init__(self, width, what):
        self.rows = np.empty((1024, width))
        self.stamps = np.empty(1024, dtype=np.int64)
        self.n = 0
        self.what = what

    def _reserve(self, need):
        if need > MAX_SAMPLES:
            raise RecordingError(f'{self.what}: more than {MAX_SAMPLES} samples, expected '
                                 f'at most {MAX_SAMPLES} (a fixed limit, about '
                                 f'{MAX_SAMPLES * 80 // 2 ** 20} MiB)')
        if need > self.rows.shape[0]:
            grow = min(max(2 * self.rows.shape[0], need), MAX_SAMPLES)
            self.rows = np.resize(self.rows, (grow, self.rows.shape[1]))
            self.stamps = np.resize(self.stamps, grow)

    def add(self, stamp_ns, row):
        if self.n == self.rows.shape[0]:
            self._reserve(self.n + 1)
        self.rows[self.n] = row
        self.stamps[self.n] = stamp_ns
        self.n += 1

    def extend(self, stamps_ns, rows):
        need = self.n + len(stamps_ns)
        self._reserve(need)
        self.rows[self.n:need] = rows
        self.stamps[self.n:need] = stamps_ns
        self.n = need

    def arrays(self):
        return self.stamps[:self.n].copy(), self.rows[:self.n].copy()


def _check_values(values, what, names):
    """Refuse non-finite or implausible values, naming the record and the field."""
    bad = ~np.isfinite(values) | (np.abs(values) > MAX_ABS_VALUE)
    if bad.any():
        k, c = (int(v[0]) for v in np.nonzero(bad))
        raise RecordingError(f'{what} {k}: {names[c]} = {float(values[k, c])!r}, expected a '
                             f'finite value of magnitude at most {MAX_ABS_VALUE:g}')


def _check_increasing(stamps_ns, what):
    """Refuse stamps that do not increase (never sorted silently)."""
    d = np.diff(stamps_ns)
    if (d <= 0).any():
        k = int(np.flatnonzero(d <= 0)[0]) + 1
        raise RecordingError(f'{what} {k}: stamp {stamps_ns[k] * 1e-9:.9f} s is not after '
                             f'the previous {stamps_ns[k - 1] * 1e-9:.9f} s, expected '
                             'increasing stamps (the recording is not sorted here)')


def read_bag(path, encoder_topic=ENCODER_TOPIC, wrench_topic=WRENCH_TOPIC, joint=None,
             progress=None, default_joint=None, rig_frame=DEFAULT_FRAME_ID,
             wrench_frame_id=None):
    """
    Return the :class:`Recording` of a rosbag2 recording (MCAP or sqlite3 storage).

    ``joint``: the crank's name in the JointState (None: ``default_joint`` if the message
    carries it, else its only name).  ``progress(text)`` is called every
    :data:`PROGRESS_EVERY` messages.  A recorded ``/tf_static`` gives
    :attr:`Recording.sensor_tf`.  Refused besides: fewer messages than the metadata counts,
    and several wrench ``frame_id`` s unless ``wrench_frame_id`` selects one.
    """
    bag = _bag_dir(Path(path))
    _check_metadata(bag)
    try:
        return _read_bag(bag, encoder_topic, wrench_topic, joint, progress, default_joint,
                         rig_frame, wrench_frame_id)
    except RecordingError:
        raise
    except Exception as exc:  # noqa: BLE001 - a corrupt file: any reader error is the file's
        raise RecordingError(f'--bag: {str(bag)!r} is not a readable rosbag2 recording '
                             f'({type(exc).__name__}: {str(exc)[:200]}), expected an intact '
                             'MCAP or sqlite3 bag') from None


def _read_bag(bag, encoder_topic, wrench_topic, joint, progress, default_joint, rig_frame,
              wrench_frame_id=None):
    from rosbags.rosbag2 import Reader
    store = _typestore()
    reader = Reader(bag)
    reader.open()
    try:
        topics = {c.topic: c.msgtype for c in reader.connections}
        for option, topic, msgtype in (('--encoder-topic', encoder_topic, JOINT_STATE),
                                       ('--wrench-topic', wrench_topic, WRENCH_STAMPED)):
            if topic not in topics:
                have = ', '.join(f'{t} ({m})' for t, m in sorted(topics.items())) or 'none'
                raise RecordingError(f'{option}: got {topic!r}, not in the recording {bag}; '
                                     f'its topics: {have}')
            if topics[topic] != msgtype:
                raise RecordingError(f'{option}: topic {topic!r} carries {topics[topic]}, '
                                     f'expected {msgtype}')
        wanted = (encoder_topic, wrench_topic, TF_STATIC_TOPIC)
        conns = [c for c in reader.connections if c.topic in wanted
                 and (c.topic != TF_STATIC_TOPIC or c.msgtype == TF_MESSAGE)]
        total = max(sum(c.msgcount for c in conns), 1)
        enc = _Growing(2, f'{encoder_topic}: message')
        wr = _Growing(6, f'{wrench_topic}: message')
        frame_ids = {}
        names, index, with_effort = None, None, None
        tf = []
        counts = {encoder_topic: 0, wrench_topic: 0, TF_STATIC_TOPIC: 0}
        messages = reader.messages(connections=conns)
        count = 0
        while True:
            try:
                item = next(messages)
            except StopIteration:
                break
            except Exception as exc:  # noqa: BLE001 - truncated or corrupt storage
                raise RecordingError(
                    f'--bag: {str(bag)!r}: unreadable after {count} messages '
                    f'({type(exc).__name__}: {str(exc)[:200]}), expected an intact recording '
                    '(truncated or corrupt?)') from None
            conn, _, raw = item
            count += 1
            k = counts[conn.topic]
            counts[conn.topic] += 1
            try:
                msg = store.deserialize_cdr(raw, conn.msgtype)
            except Exception as exc:  # noqa: BLE001 - any undecodable payload
                raise RecordingError(
                    f'--bag: {str(bag)!r}: topic {conn.topic} message {k}: undecodable '
                    f'{conn.msgtype} payload ({type(exc).__name__}: {str(exc)[:120]}), '
                    'expected a CDR-serialized message') from None
            if conn.topic == TF_STATIC_TOPIC:
                tf.extend(msg.transforms)
            elif conn.topic == encoder_topic:
                if names != list(msg.name):
                    names = list(msg.name)
                    index = _joint_index(names, joint, encoder_topic, default_joint)
                if len(msg.position) <= index:
                    raise RecordingError(f'{encoder_topic}: message {k}: no position for '
                                         f'joint {names[index]!r}, expected one')
                has = len(msg.effort) > index
                if with_effort is None:
                    with_effort = has
                elif has != with_effort:
                    raise RecordingError(f'{encoder_topic}: message {k}: effort '
                                         + ('given' if has else 'missing')
                                         + ' for the crank, expected it in every message or '
                                           'in none')
                enc.add(_stamp_ns(msg.header, encoder_topic, k),
                        (float(msg.position[index]),
                         float(msg.effort[index]) if has else 0.0))
            else:
                frame = msg.header.frame_id
                frame_ids[frame] = frame_ids.get(frame, 0) + 1
                if wrench_frame_id is None or frame == wrench_frame_id:
                    w = msg.wrench
                    wr.add(_stamp_ns(msg.header, wrench_topic, k),
                           (w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y,
                            w.torque.z))
            if progress is not None and count % PROGRESS_EVERY == 0:
                progress(f'  read {count} of {total} messages ({100.0 * count / total:.0f}%)')
    finally:
        reader.close()
    _check_counts(bag, conns, counts)
    frame_ids = _check_frame_ids(wrench_topic, frame_ids, wrench_frame_id)
    for option, topic, got in (('--encoder-topic', encoder_topic, enc.n),
                               ('--wrench-topic', wrench_topic, wr.n)):
        if not got:
            raise RecordingError(f'{option}: topic {topic!r} has no messages in {bag}, '
                                 'expected the recorded samples')
    enc_t, enc_v = enc.arrays()
    w_t, w_v = wr.arrays()
    _check_values(enc_v[:, :1 + bool(with_effort)], f'{encoder_topic}: message',
                  ('position', 'effort'))
    _check_values(w_v, f'{wrench_topic}: message',
                  ('force.x', 'force.y', 'force.z', 'torque.x', 'torque.y', 'torque.z'))
    _check_increasing(enc_t, f'{encoder_topic}: message')
    _check_increasing(w_t, f'{wrench_topic}: message')
    frame_id = ','.join(sorted(frame_ids))
    rec = _recording(enc_t, enc_v[:, 0], enc_v[:, 1] if with_effort else None, w_t, w_v,
                     names[index], frame_id, str(bag))
    rec.sensor_tf = _sensor_tf(tf, rig_frame, frame_ids)
    return rec


def _check_counts(bag, conns, counts):
    """Refuse a topic with fewer messages read than the bag's metadata counts."""
    for topic, got in counts.items():
        expected = sum(c.msgcount for c in conns if c.topic == topic)
        if got < expected:
            raise RecordingError(
                f"--bag: {str(bag)!r}: topic {topic}: {got} messages read, the bag's "
                f'metadata counts {expected} ({expected - got} missing, '
                f'{100.0 * (expected - got) / expected:.0f}%), expected all of them: the '
                'storage is damaged (a lost or zeroed block reads without an error); record '
                'again, or `ros2 bag reindex` the bag to accept what is readable')


def _check_frame_ids(topic, frame_ids, wanted):
    """Return the wrench's frame_ids (one), refusing several unless one is selected."""
    have = ', '.join(f'{f!r} ({n} messages)' for f, n in sorted(frame_ids.items()))
    if wanted is not None:
        if wanted not in frame_ids:
            raise RecordingError(f'--wrench-frame-id: got {wanted!r}, not among the frame_ids '
                                 f'of {topic}: {have or "none"}')
        return {wanted}
    if len(frame_ids) > 1:
        raise RecordingError(f'{topic}: messages of {len(frame_ids)} frame_ids: {have}, '
                             'expected one sensor (two sensors publishing on one topic?); '
                             '--wrench-frame-id FRAME uses the messages of one')
    return set(frame_ids)


def _joint_index(names, joint, topic, default_joint=None):
    if joint is None:
        if default_joint in names:
            return names.index(default_joint)
        if len(names) == 1:
            return 0
        raise RecordingError(f'--joint: not given, and {topic} carries the joints '
                             f'{", ".join(names) or "(none)"}; expected --joint NAME')
    if joint not in names:
        raise RecordingError(f'--joint: got {joint!r}, not among the joints of {topic}: '
                             f'{", ".join(names) or "(none)"}')
    return names.index(joint)


def _recording(enc_ns, pos, eff, w_ns, wrench, joint, frame_id, source):
    """Return the :class:`Recording` of checked (increasing) stamps, from the earliest."""
    t0 = int(min(enc_ns.min(), w_ns.min()))
    return Recording(encoder_t_s=(enc_ns - t0) * 1e-9, position_rad=pos,
                     effort_Nm=eff, wrench_t_s=(w_ns - t0) * 1e-9, wrench=wrench,
                     joint=joint, frame_id=frame_id, t0_ns=t0, source=source)


def _quat_rpy(x, y, z, w):
    """Return (roll, pitch, yaw) of a unit quaternion (R = Rz(yaw) Ry(pitch) Rx(roll))."""
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if not (math.isfinite(norm) and norm > 0.5):
        raise RecordingError(f'{TF_STATIC_TOPIC}: rotation ({x}, {y}, {z}, {w}), expected a '
                             'unit quaternion')
    return tuple(float(v) for v in matrix_rpy(quaternion_matrix((x, y, z, w))))


def _sensor_tf(transforms, rig_frame, frame_ids):
    """Return ``(x, y, z, roll, pitch, yaw, parent, child)`` of rig -> wrench frame, or None."""
    if len(frame_ids) != 1:
        return None
    child = next(iter(frame_ids))
    if not child or child == rig_frame:
        return None
    for tr in transforms:
        if tr.header.frame_id == rig_frame and tr.child_frame_id == child:
            t, r = tr.transform.translation, tr.transform.rotation
            xyz = (float(t.x), float(t.y), float(t.z))
            if not all(math.isfinite(v) and abs(v) <= MAX_ABS_VALUE for v in xyz):
                raise RecordingError(f'{TF_STATIC_TOPIC}: {rig_frame} -> {child} translation '
                                     f'{xyz}, expected finite metres')
            return (*xyz, *_quat_rpy(float(r.x), float(r.y), float(r.z), float(r.w)),
                    rig_frame, child)
    return None


def write_bag(path, storage, t_ns, position_rad, wrench, effort_Nm=None, joint='O1',
              encoder_topic=ENCODER_TOPIC, wrench_topic=WRENCH_TOPIC, frame_id='rig',
              extra_joints=(), tf_static=None, wrench_t_ns=None):
    """
    Write encoder and wrench samples as a rosbag2 recording (``storage`` mcap or sqlite3).

    ``t_ns`` (int ns) stamps the encoder's messages, and the wrench's unless ``wrench_t_ns``
    is given; ``wrench`` is ``(m, 6)`` or ``(m, 3)`` [f_x, f_y, n_z]; ``frame_id`` one, or
    one per wrench message; ``extra_joints`` more JointState names (at 0); ``tf_static``
    ``(parent, (x, y, z), (qx, qy, qz, qw))`` adds the pose of ``frame_id`` in ``parent``.
    Written atomically; ``path`` must not exist.
    """
    from rosbags.rosbag2 import StoragePlugin, Writer
    if storage not in STORAGES:
        raise RecordingError(f'storage: got {storage!r}, expected one of {", ".join(STORAGES)}')
    path = Path(path)
    if path.exists():
        raise RecordingError(f'path: got {str(path)!r}, which exists, expected a new path')
    t_ns = np.asarray(t_ns, dtype=np.int64)
    wrench = _six(np.asarray(wrench, dtype=float))
    store = _typestore()
    types = store.types
    header_t, time_t = types['std_msgs/msg/Header'], types['builtin_interfaces/msg/Time']
    joint_t, wrench_t = types[JOINT_STATE], types[WRENCH_STAMPED]
    vec_t, wr_t = types['geometry_msgs/msg/Vector3'], types['geometry_msgs/msg/Wrench']
    plugin = StoragePlugin.MCAP if storage == 'mcap' else StoragePlugin.SQLITE3

    def header(stamp_ns, frame):
        sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
        return header_t(stamp=time_t(sec=sec, nanosec=nsec), frame_id=frame)

    tmp_dir = Path(tempfile.mkdtemp(dir=path.parent, prefix=f'.{path.name}.'))
    try:
        out = tmp_dir / path.name
        names = [joint, *extra_joints]
        zeros = [0.0] * len(extra_joints)
        empty = np.zeros(0)
        with Writer(out, version=BAG_VERSION, storage_plugin=plugin) as writer:
            c_enc = writer.add_connection(encoder_topic, JOINT_STATE, typestore=store)
            c_w = writer.add_connection(wrench_topic, WRENCH_STAMPED, typestore=store)
            if tf_static is not None:
                parent, xyz, quat = tf_static
                tr = types['geometry_msgs/msg/TransformStamped'](
                    header=header(t_ns[0], parent),
                    child_frame_id=frame_id, transform=types['geometry_msgs/msg/Transform'](
                        translation=vec_t(x=xyz[0], y=xyz[1], z=xyz[2]),
                        rotation=types['geometry_msgs/msg/Quaternion'](
                            x=quat[0], y=quat[1], z=quat[2], w=quat[3])))
                c_tf = writer.add_connection(TF_STATIC_TOPIC, TF_MESSAGE, typestore=store)
                writer.write(c_tf, int(t_ns[0]), store.serialize_cdr(
                    types[TF_MESSAGE](transforms=[tr]), TF_MESSAGE))
            w_ns = t_ns if wrench_t_ns is None else np.asarray(wrench_t_ns, dtype=np.int64)
            frames = [frame_id] * len(w_ns) if isinstance(frame_id, str) else list(frame_id)
            # (stamp, stream, index): encoder before wrench at equal stamps, as before
            order = sorted([(int(s), 0, k) for k, s in enumerate(t_ns)]
                           + [(int(s), 1, k) for k, s in enumerate(w_ns)])
            for stamp, stream, k in order:
                if stream == 0:
                    hdr = header(stamp, frames[0] if frames else '')
                    eff = empty if effort_Nm is None else \
                        np.array([float(effort_Nm[k]), *zeros])
                    js = joint_t(header=hdr, name=names,
                                 position=np.array([float(position_rad[k]), *zeros]),
                                 velocity=empty, effort=eff)
                    writer.write(c_enc, stamp, store.serialize_cdr(js, JOINT_STATE))
                    continue
                hdr = header(stamp, frames[k])
                f, m = wrench[k, :3], wrench[k, 3:]
                ws = wrench_t(header=hdr, wrench=wr_t(force=vec_t(x=f[0], y=f[1], z=f[2]),
                                                      torque=vec_t(x=m[0], y=m[1], z=m[2])))
                writer.write(c_w, stamp, store.serialize_cdr(ws, WRENCH_STAMPED))
        os.replace(out, path)
    finally:
        shutil.rmtree(tmp_dir, ignore_errors=True)
    return path


def _six(wrench):
    if wrench.ndim == 2 and wrench.shape[1] == 3:
        out = np.zeros((wrench.shape[0], 6))
        out[:, [0, 1, 5]] = wrench
        return out
    if wrench.ndim == 2 and wrench.shape[1] == 6:
        return wrench
    raise RecordingError(f'wrench: got shape {wrench.shape}, expected (n, 3) or (n, 6)')


def write_csv(path, t_s, position_rad, wrench, effort_Nm=None):
    """Write samples as the CSV :func:`read_csv` reads (atomically)."""
    wrench = _six(np.asarray(wrench, dtype=float))
    cols = ['t_s', 'crank_position_rad', *WRENCH_COLUMNS]
    data = [np.asarray(t_s, dtype=float), np.asarray(position_rad, dtype=float),
            *wrench.T]
    if effort_Nm is not None:
        cols.append('crank_effort_Nm')
        data.append(np.asarray(effort_Nm, dtype=float))
    path = Path(path)
    with atomic.atomic_path(path) as tmp, open(tmp, 'w', newline='') as fh:
        w = csv.writer(fh)
        w.writerow(cols)
        w.writerows(zip(*(map(repr, map(float, col)) for col in data)))
    return path


def _csv_lines(fh, label):
    """Yield ``(line number, text)`` of a CSV file, each line bounded by MAX_LINE_CHARS."""
    number = 0
    while True:
        number += 1
        try:
            line = fh.readline(MAX_LINE_CHARS + 1)
        except UnicodeDecodeError as exc:
            raise RecordingError(f'{label}: line {number}: byte {exc.object[exc.start]:#04x} '
                                 'is not UTF-8, expected a text file of numbers') from None
        if not line:
            return
        if len(line) > MAX_LINE_CHARS and not line.endswith('\n'):
            raise RecordingError(f'{label}: line {number}: longer than {MAX_LINE_CHARS} '
                                 'characters, expected a row of numbers (a fixed limit)')
        if '\x00' in line:
            raise RecordingError(f'{label}: line {number}: a NUL byte, expected a text file '
                                 'of numbers (a binary file?)')
        yield number, line


def read_csv(path, joint=None):
    """Return the :class:`Recording` of a CSV file; a bad field raises naming line and column."""
    path = Path(path)
    label = f'--bag: {str(path)!r}'
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise RecordingError(f'{label}: cannot be read ({exc.strerror})') from None
    if not path.is_file():
        raise RecordingError(f'{label}: not a regular file, expected a .csv file')
    if size > MAX_CSV_BYTES:
        raise RecordingError(f'{label}: {size} bytes, expected at most {MAX_CSV_BYTES} '
                             f'(a fixed limit: {MAX_SAMPLES} rows)')
    try:
        fh = open(path, newline='', encoding='utf-8-sig', errors='strict')
    except OSError as exc:
        raise RecordingError(f'{label}: cannot be read ({exc.strerror})') from None
    with fh:
        head, store = None, None
        chunk = []
        for number, line in _csv_lines(fh, label):
            if not line.strip() or line.lstrip().startswith('#'):
                continue
            if head is None:
                head, store = _csv_header(_csv_split([line], [number], label)[0], label,
                                          number)
                continue
            chunk.append((number, line))
            if len(chunk) == CSV_CHUNK_ROWS:
                _csv_chunk(chunk, head, label, store)
                chunk = []
        if chunk:
            _csv_chunk(chunk, head, label, store)
    if head is None:
        raise RecordingError(f'{label}: is empty, expected a header line with '
                             + ', '.join(CSV_REQUIRED))
    if not store.n:
        raise RecordingError(f'{label}: a header and no rows, expected samples')
    t_ns, values = store.arrays()
    col = {h: values[:, i] for i, h in enumerate(head[1:])}
    n = values.shape[0]
    wrench = np.column_stack([col.get(c, np.zeros(n)) for c in WRENCH_COLUMNS])
    return _recording(t_ns, col['crank_position_rad'], col.get('crank_effort_Nm'), t_ns,
                      wrench, joint or 'crank', '', str(path))


def _csv_split(lines, numbers, label):
    """Return the fields of CSV lines (the csv module), naming the line of a csv error."""
    try:
        return list(csv.reader(lines))
    except csv.Error:
        for number, line in zip(numbers, lines):
            try:
                next(csv.reader([line]))
            except csv.Error as exc:
                raise RecordingError(f'{label}: line {number}: {exc}, expected '
                                     'comma-separated numbers') from None
        raise


def _csv_chunk(chunk, head, label, store):
    """Parse and check CSV data lines into ``store``: numpy at once, row by row to refuse."""
    numbers = [n for n, _ in chunk]
    lines = [ln for _, ln in chunk]
    text = ''.join(lines)
    values = None
    if not _LONG_FIELD.search(text) and '"' not in text and \
            not _EMPTY_OR_SPLIT_FIELD.search(text) and \
            all(ln.count(',') == len(head) - 1 for ln in lines):
        with warnings.catch_warnings():
            warnings.simplefilter('error')
            try:
                flat = np.fromstring(text.replace(',', ' '), sep=' ')
            except (ValueError, DeprecationWarning):
                flat = None
        if flat is not None and flat.size == len(lines) * len(head):
            values = flat.reshape(len(lines), len(head))[:, head.index]
    if values is not None:
        limits = np.where(np.array(head) == 't_s', MAX_T_S, MAX_ABS_VALUE)
        if not (~np.isfinite(values) | (np.abs(values) > limits)).any():
            stamps = np.round(values[:, 0] * 1e9).astype(np.int64)
            if np.all(stamps[1:] > stamps[:-1]) and \
                    (not store.n or stamps[0] > store.stamps[store.n - 1]):
                store.extend(stamps, values[:, 1:])
                return
    # quoted, ragged or refused: row by row (naming the line and column of a bad field)
    previous = store.stamps[store.n - 1] if store.n else None
    for number, row in zip(numbers, _csv_split(lines, numbers, label)):
        stamp, row_values = _csv_row(row, number, head, label, previous)  # raises
        store.add(stamp, row_values)
        previous = stamp


def _csv_row(row, number, head, label, previous):
    """Return ``(stamp ns, values)`` of one CSV row, or raise naming its line and column."""
    if len(row) != len(head):
        raise RecordingError(f'{label}: line {number}: {len(row)} fields, expected '
                             f"{len(head)} (the header's columns)")
    values = []
    for name, v in zip(head, (row[i] for i in head.index)):
        if len(v) > MAX_FIELD_CHARS:
            raise RecordingError(f'{label}: line {number}, column {name}: a field of '
                                 f'{len(v)} characters, expected a number of at most '
                                 f'{MAX_FIELD_CHARS} (a fixed limit)')
        try:
            x = float(v)
        except ValueError:
            raise RecordingError(f'{label}: line {number}, column {name}: got '
                                 f'{v.strip()[:40]!r}, expected a number') from None
        limit = MAX_T_S if name == 't_s' else MAX_ABS_VALUE
        if not (math.isfinite(x) and abs(x) <= limit):
            raise RecordingError(f'{label}: line {number}, column {name}: got {x!r}, '
                                 f'expected a finite number of magnitude at most {limit:g}')
        values.append(x)
    stamp = int(round(values[0] * 1e9))
    if previous is not None and stamp <= previous:
        raise RecordingError(f'{label}: line {number}, column t_s: {values[0]!r} is not after '
                             f"the previous row's {int(previous) * 1e-9!r}, expected increasing "
                             'times (rows are not sorted here)')
    return stamp, values[1:]


def _csv_header(row, label, number):
    """Return (the columns with t_s first, the sample store) of a header row."""
    head = [h.strip() for h in row]
    known = CSV_REQUIRED + CSV_OPTIONAL
    seen = set()
    for h in head:
        if h in seen:
            raise RecordingError(f'{label}: line {number}: column {h!r} given twice, expected '
                                 'each column once')
        seen.add(h)
        if h not in known:
            raise RecordingError(f'{label}: line {number}: unknown column {h[:40]!r}, '
                                 f'expected columns of {", ".join(known)}')
    missing = [c for c in CSV_REQUIRED if c not in head]
    if missing:
        raise RecordingError(f'{label}: has no column {", ".join(missing)}; expected the '
                             f'columns {", ".join(CSV_REQUIRED)}')
    order = ['t_s'] + [h for h in head if h != 't_s']
    return _Reordered(head, order), _Growing(len(order) - 1, f'{label}: row')


class _Reordered(list):
    """The header's columns in t_s-first order, mapping each row to that order."""

    def __init__(self, head, order):
        super().__init__(order)
        self.index = [head.index(c) for c in order]
