"""
Recordings of a real rig: rosbag2 (MCAP or sqlite3) and CSV, read and written.

No ROS install is needed: rosbag2 files are read and written with the pure-Python
``rosbags`` library, messages converted with its typestore for ROS 2 Jazzy
(``rosbags.typesys.Stores.ROS2_JAZZY``).  A recording holds two streams:

* the crank encoder, ``sensor_msgs/msg/JointState`` (default topic
  :data:`ENCODER_TOPIC`): the position of one joint (rad), and its effort (the motor
  torque, N*m) when the message carries one;
* the force sensor, ``geometry_msgs/msg/WrenchStamped`` (default topic
  :data:`WRENCH_TOPIC`): force (N) and torque (N*m) in the rig frame about the crank pivot,
  the load the rig exerts on its frame (:mod:`mech_balance.conventions`).

Both streams are stamped by their messages' ``header.stamp`` (not the recording time);
times are returned in seconds from the earliest stamp of either stream (``t0_ns``).

CSV alternative (:func:`read_csv`, :func:`write_csv`): one row per sample, encoder and
sensor sampled together, a header line naming the columns (any order; ``#`` lines are
comments):

    ``t_s``                  stamp, s (increasing)
    ``crank_position_rad``   encoder angle of the crank joint, rad
    ``force_x_N``, ``force_y_N``, ``torque_z_Nm``       required
    ``force_z_N``, ``torque_x_Nm``, ``torque_y_Nm``     optional (0 when absent)
    ``crank_effort_Nm``      optional: the motor torque
"""

import csv
from dataclasses import dataclass
import math
import os
from pathlib import Path
import shutil
import tempfile

from mech_balance.ros.names import ENCODER_TOPIC, WRENCH_TOPIC
import numpy as np

JOINT_STATE = 'sensor_msgs/msg/JointState'
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

    @property
    def planar_wrench(self):
        """Return the ``(m, 3)`` planar wrench [f_x, f_y, n_z]."""
        return self.wrench[:, [0, 1, 5]]


def _typestore():
    from rosbags.typesys import get_typestore, Stores
    return get_typestore(Stores.ROS2_JAZZY)


def read(path, encoder_topic=ENCODER_TOPIC, wrench_topic=WRENCH_TOPIC, joint=None,
         progress=None, default_joint=None):
    """
    Return the :class:`Recording` of a rosbag2 directory (or its file) or a CSV file.

    Without ``joint`` the encoder's joint is ``default_joint`` (the scene's crank joint) if
    the JointState carries it, else its only joint.
    """
    p = Path(path)
    if not p.exists():
        raise RecordingError(f'--bag: got {str(path)!r}, which does not exist, expected a '
                             'rosbag2 directory or a .csv file')
    if p.suffix.lower() == '.csv':
        return read_csv(p, joint=joint or default_joint)
    return read_bag(p, encoder_topic, wrench_topic, joint, progress, default_joint)


def _bag_dir(p):
    """Return the rosbag2 directory of a path (a file inside it counts)."""
    if p.is_file() and (p.parent / 'metadata.yaml').exists():
        return p.parent
    if p.is_dir() and (p / 'metadata.yaml').exists():
        return p
    raise RecordingError(f'--bag: got {str(p)!r}, expected a rosbag2 directory (with '
                         'metadata.yaml) or a .csv file')


def _stamp_ns(header):
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def read_bag(path, encoder_topic=ENCODER_TOPIC, wrench_topic=WRENCH_TOPIC, joint=None,
             progress=None, default_joint=None):
    """
    Return the :class:`Recording` of a rosbag2 recording (MCAP or sqlite3 storage).

    ``joint``: the crank's name in the JointState (None: ``default_joint`` if the message
    carries it, else the only name it carries).
    ``progress(text)`` is called every :data:`PROGRESS_EVERY` messages.
    """
    from rosbags.rosbag2 import Reader
    from rosbags.rosbag2.errors import ReaderError
    bag = _bag_dir(Path(path))
    store = _typestore()
    try:
        reader = Reader(bag)
        reader.open()
    except (ReaderError, KeyError, ValueError) as exc:
        raise RecordingError(f'--bag: {str(bag)!r} is not a readable rosbag2 recording '
                             f'({exc})') from None
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
        conns = [c for c in reader.connections if c.topic in (encoder_topic, wrench_topic)]
        total = sum(c.msgcount for c in conns)
        enc_t, enc_pos, enc_eff, w_t, w = [], [], [], [], []
        frame_ids = set()
        names = None
        index = None
        for count, (conn, _, raw) in enumerate(reader.messages(connections=conns), 1):
            msg = store.deserialize_cdr(raw, conn.msgtype)
            if conn.topic == encoder_topic:
                if names != list(msg.name):
                    names = list(msg.name)
                    index = _joint_index(names, joint, encoder_topic, default_joint)
                if len(msg.position) <= index:
                    raise RecordingError(f'{encoder_topic}: a JointState without a position '
                                         f'for joint {names[index]!r}, expected one')
                enc_t.append(_stamp_ns(msg.header))
                enc_pos.append(float(msg.position[index]))
                enc_eff.append(float(msg.effort[index]) if len(msg.effort) > index
                               else math.nan)
            else:
                wr = msg.wrench
                w_t.append(_stamp_ns(msg.header))
                w.append((wr.force.x, wr.force.y, wr.force.z,
                          wr.torque.x, wr.torque.y, wr.torque.z))
                frame_ids.add(msg.header.frame_id)
            if progress is not None and count % PROGRESS_EVERY == 0:
                progress(f'  read {count} of {total} messages ({100.0 * count / total:.0f}%)')
    finally:
        reader.close()
    for option, topic, got in (('--encoder-topic', encoder_topic, enc_t),
                               ('--wrench-topic', wrench_topic, w_t)):
        if not got:
            raise RecordingError(f'{option}: topic {topic!r} has no messages in {bag}, '
                                 'expected the recorded samples')
    eff = np.array(enc_eff)
    return _recording(np.array(enc_t, dtype=np.int64), np.array(enc_pos),
                      None if np.isnan(eff).any() else eff, np.array(w_t, dtype=np.int64),
                      np.array(w, dtype=float).reshape(-1, 6), names[index],
                      ','.join(sorted(frame_ids)), str(bag))


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
    order = np.argsort(enc_ns, kind='stable')
    w_order = np.argsort(w_ns, kind='stable')
    t0 = int(min(enc_ns.min(), w_ns.min()))
    return Recording(encoder_t_s=(enc_ns[order] - t0) * 1e-9, position_rad=pos[order],
                     effort_Nm=None if eff is None else eff[order],
                     wrench_t_s=(w_ns[w_order] - t0) * 1e-9, wrench=wrench[w_order],
                     joint=joint, frame_id=frame_id, t0_ns=t0, source=source)


def write_bag(path, storage, t_ns, position_rad, wrench, effort_Nm=None, joint='O1',
              encoder_topic=ENCODER_TOPIC, wrench_topic=WRENCH_TOPIC, frame_id='rig',
              extra_joints=()):
    """
    Write encoder and wrench samples as a rosbag2 recording (``storage`` mcap or sqlite3).

    ``t_ns`` (int nanoseconds) stamps both streams; ``wrench`` is ``(n, 6)`` or ``(n, 3)``
    planar [f_x, f_y, n_z]; ``extra_joints`` are more joint names in the JointState (at
    position 0), to exercise the joint selection.  Written atomically: into a temporary
    directory beside ``path``, then renamed; ``path`` must not exist.
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
    tmp_dir = Path(tempfile.mkdtemp(dir=path.parent, prefix=f'.{path.name}.'))
    try:
        out = tmp_dir / path.name
        names = [joint, *extra_joints]
        zeros = [0.0] * len(extra_joints)
        empty = np.zeros(0)
        with Writer(out, version=BAG_VERSION, storage_plugin=plugin) as writer:
            c_enc = writer.add_connection(encoder_topic, JOINT_STATE, typestore=store)
            c_w = writer.add_connection(wrench_topic, WRENCH_STAMPED, typestore=store)
            for k, stamp in enumerate(t_ns):
                sec, nsec = divmod(int(stamp), 1_000_000_000)
                hdr = header_t(stamp=time_t(sec=sec, nanosec=nsec), frame_id=frame_id)
                eff = empty if effort_Nm is None else \
                    np.array([float(effort_Nm[k]), *zeros])
                js = joint_t(header=hdr, name=names,
                             position=np.array([float(position_rad[k]), *zeros]),
                             velocity=empty, effort=eff)
                f, m = wrench[k, :3], wrench[k, 3:]
                ws = wrench_t(header=hdr, wrench=wr_t(force=vec_t(x=f[0], y=f[1], z=f[2]),
                                                      torque=vec_t(x=m[0], y=m[1], z=m[2])))
                writer.write(c_enc, int(stamp), store.serialize_cdr(js, JOINT_STATE))
                writer.write(c_w, int(stamp), store.serialize_cdr(ws, WRENCH_STAMPED))
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
    """Write samples as the CSV of this module's docstring (atomically)."""
    wrench = _six(np.asarray(wrench, dtype=float))
    cols = ['t_s', 'crank_position_rad', *WRENCH_COLUMNS]
    data = [np.asarray(t_s, dtype=float), np.asarray(position_rad, dtype=float),
            *wrench.T]
    if effort_Nm is not None:
        cols.append('crank_effort_Nm')
        data.append(np.asarray(effort_Nm, dtype=float))
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f'.{path.name}.', suffix='.tmp')
    try:
        with os.fdopen(fd, 'w', newline='') as fh:
            w = csv.writer(fh)
            w.writerow(cols)
            w.writerows(zip(*(map(repr, map(float, col)) for col in data)))
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def read_csv(path, joint=None):
    """Return the :class:`Recording` of a CSV file (columns: this module's docstring)."""
    path = Path(path)
    with open(path, newline='') as fh:
        rows = [r for r in csv.reader(fh) if r and not r[0].lstrip().startswith('#')]
    if not rows:
        raise RecordingError(f'--bag: {str(path)!r} is empty, expected a header line with '
                             + ', '.join(CSV_REQUIRED))
    head = [h.strip() for h in rows[0]]
    missing = [c for c in CSV_REQUIRED if c not in head]
    if missing:
        raise RecordingError(f'--bag: {str(path)!r} has no column {", ".join(missing)}; '
                             f'expected the columns {", ".join(CSV_REQUIRED)}')
    try:
        values = np.array([[float(v) for v in r] for r in rows[1:]], dtype=float)
    except ValueError as exc:
        raise RecordingError(f'--bag: {str(path)!r}: {exc}, expected numbers') from None
    if values.ndim != 2 or values.shape[0] == 0 or values.shape[1] != len(head):
        raise RecordingError(f'--bag: {str(path)!r}: expected rows of {len(head)} numbers')
    col = {h: values[:, i] for i, h in enumerate(head)}
    n = values.shape[0]
    wrench = np.column_stack([col.get(c, np.zeros(n)) for c in WRENCH_COLUMNS])
    t_ns = np.round(col['t_s'] * 1e9).astype(np.int64)
    return _recording(t_ns, col['crank_position_rad'], col.get('crank_effort_Nm'), t_ns,
                      wrench, joint or 'crank', '', str(path))
