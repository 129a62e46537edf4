"""
The rig node's parameters, each declared once: type, default, description, bounds, check.

In the manner of generate_parameter_library: :data:`PARAMETERS` is the table the node
declares from and :func:`check` the validator of every update (its ``ValueError`` is the
refusal's reason); the ``balance.*`` ones come from
:data:`mech_balance.balancing.options.OPTIONS`.  No ROS import here.
"""

from dataclasses import dataclass
import math
import re

from mech_balance import identifiers, paths
from mech_balance.balancing import defaults as balancing_defaults
from mech_balance.balancing import options
from mech_balance.balancing.options import BOOL, DOUBLE, DOUBLE_ARRAY, INTEGER, LINK_OPTIONS, \
    LINK_PREFIX, parse_link_bounds, split_links, STRING
from mech_balance.ros import names, sensor
from mech_balance.ros.guard import show as _show

MODES = ('clock', 'follow')
MAX_SENSOR_OFFSET_M = 100.0
"""Largest |sensor.x|, |sensor.y|, |sensor.z| accepted, m."""
MAX_ANGLE_RAD = 2.0 * math.pi
"""Largest |sensor.roll|, |sensor.pitch|, |sensor.yaw| accepted, rad."""
MAX_FRACTION = 1000.0
"""Largest diagnostics threshold (residual RMS / measured RMS)."""
METHODS = ('redistribution', 'counterweights', 'analytic')
"""``balance.method``: :func:`mech_balance.balancing.balance`'s methods the node offers."""
MAX_CRANK_SPEED = 1000.0
"""Largest |crank_speed| accepted, rad/s (about 9500 rpm)."""
MIN_PUBLISH_RATE = 0.1
"""Slowest clock-mode publish rate, Hz."""
MAX_PUBLISH_RATE = 20000.0
"""Fastest clock-mode publish rate, Hz (see ``mech-balance bench`` for what is sustained)."""


@dataclass(frozen=True)
class Spec:
    """One parameter: name, ROS type, default, description, bounds, allowed values, check."""

    name: str
    value_type: str           # STRING, DOUBLE, INTEGER, BOOL or DOUBLE_ARRAY (the ROS type)
    default: object
    description: str
    bounds: tuple = None      # (low, high) inclusive, numbers only
    choices: tuple = None     # allowed values, strings only
    check: object = None      # callable(value) raising ValueError with the reason
    rule: str = ''            # what ``check`` accepts, for ``ros2 param describe``

    @property
    def constraints(self):
        """Return the constraint text shown by ``ros2 param describe``."""
        parts = []
        if self.bounds is not None:
            parts.append(f'{self.bounds[0]:g} <= value <= {self.bounds[1]:g}')
        if self.choices is not None:
            parts.append('one of: ' + ', '.join(self.choices))
        if self.rule:
            parts.append(self.rule)
        return '; '.join(parts)


def _scene(value):
    """Reject an empty scene name (the node then loads and assembles the scene)."""
    if not value:
        raise ValueError('scene: got an empty name, expected a built-in scene or a path')


def _joint_name(value):
    """Accept empty (the scene's crank joint) or a joint name (identifiers.check_name)."""
    if value != value.strip():
        raise ValueError(f'crank_joint: got {value!r}, expected a joint name without '
                         "surrounding spaces (or empty for the scene's crank joint)")
    identifiers.check_name(value, 'crank_joint', allow_empty=True)


def _link_pair(name, unit):
    def check(value):
        """Accept [] (the factors), [min] (no upper bound) or [min, max], 0 < min <= max."""
        if len(value) > 2 or (value and not value[0] > 0.0) or \
                (len(value) == 2 and not value[1] >= value[0]):
            raise ValueError(f'{name}: got {list(value)}, expected [] (the factors), [min] '
                             f'or [min, max] in {unit} with 0 < min <= max')
        if value:
            balancing_defaults.check_bound_pair(name, value[0],
                                                value[1] if len(value) == 2 else None, unit)
    return check


def link_spec(link, option):
    """Return the :class:`Spec` of ``balance.links.<link>.<option>`` (LINK_OPTIONS)."""
    unit, older, what = LINK_OPTIONS[option]
    name = f'{LINK_PREFIX}{link}.{option}'
    return Spec(name, DOUBLE_ARRAY, [],
                f'Link {link!r}: {what} [min, max] in {unit} overriding the factors; [min]: no '
                f'upper bound; []: the factors (typed form of {older}, which it may not '
                'contradict).', check=_link_pair(name, unit),
                rule=f'[], [min] or [min, max] in {unit}, 0 < min <= max')


def spec_for(name):
    """Return the :class:`Spec` of a parameter name (per-link ones included), or None."""
    spec = BY_NAME.get(name)
    if spec is None and name.startswith(LINK_PREFIX):
        link, _, option = name[len(LINK_PREFIX):].rpartition('.')
        if link and option in LINK_OPTIONS:
            spec = link_spec(link, option)
    return spec


def named_links(values):
    """Return ``{option: [link names]}`` of the ``balance.*`` options that name links."""
    named = {key: split_links(values[key])
             for key in ('balance.fixed_links', 'balance.counterweight_links')}
    for key, unit in (('balance.mass_bounds', 'kg'), ('balance.distance_bounds', 'm')):
        named[key] = list(parse_link_bounds(key, values[key], unit) or ())
    return named


def check_links(values, link_names):
    """Raise ValueError if a ``balance.*`` option names a link not in ``link_names``."""
    named = named_links(values)
    for key, value in values.items():
        if key.startswith(LINK_PREFIX) and value:
            link, _, option = key[len(LINK_PREFIX):].rpartition('.')
            named[key] = [link]
            older = LINK_OPTIONS[option][1]
            if link in named[older]:
                raise ValueError(f'{key}: got {list(value)}, expected no second bound for link '
                                 f'{link!r} ({older} gives one; clear one of them)')
    for key, found in named.items():
        for name in found:
            if name not in link_names:
                raise ValueError(f'{key}: got link {name!r}, expected links of the scene '
                                 f'({", ".join(link_names)})')
    if link_names and set(named['balance.fixed_links']) >= set(link_names):
        raise ValueError(f'balance.fixed_links: got every link ({", ".join(link_names)}), '
                         'expected at least one link free to balance')


def _path(value):
    """Accept empty (no recording) or a writable .rrd file in an existing directory."""
    if value.endswith(('/', '\\')) or value.endswith(('/.', '/..')):
        raise ValueError(f'recording_path: got {value!r}, a directory, expected a file name '
                         f"ending in .rrd (e.g. {value.rstrip('/')}/rig.rrd)")
    if value:
        paths.check_output_path(value, 'recording_path', ('.rrd',), create_dir=False)


def _balance_specs():
    """Return the ``balance.*`` specs: :data:`mech_balance.balancing.options.OPTIONS`."""
    out = []
    for opt in options.OPTIONS:
        if opt.param is None:
            continue
        check = None if opt.check is None else (lambda value, o=opt: o.check(o.param, value))
        out.append(Spec(opt.param, opt.value_type, options.param_default(opt), opt.description,
                        bounds=opt.bounds, choices=opt.choices, check=check, rule=opt.rule))
        if opt.param == 'balance.samples':
            out.append(METHOD_SPEC)
    return out


METHOD_SPEC = Spec(
    'balance.method', STRING, 'redistribution',
    'redistribution: the certified optimal mass redistribution (Chaudhary & Saha); '
    'counterweights: add-only discs on balance.counterweight_links (certified); '
    'analytic: complete force balance in closed form (slider-crank: Sinatra & Angeles, '
    'four-bar: Chaudhary & Saha eq. 48). A spatial scene that lists balancing_weights '
    '(rggr) is balanced by its own method (weights, Hedaya) with the default; other '
    'spatial scenes are redistributed.', choices=METHODS)
"""``balance.method``: the node's own (the command line chooses by its flags)."""


PARAMETERS = (
    Spec('scene', STRING, 'hoeken',
         'Built-in scene name (`mech-balance scenes`) or path to a scene YAML file. A new '
         'value is loaded and assembled before it is accepted; the rig then restarts from '
         "the scene's original design.", check=_scene,
         rule='loads with the scene loader and assembles over a full crank turn'),
    Spec('mode', STRING, 'clock',
         'clock: the node turns the crank at crank_speed and publishes at publish_rate. '
         "follow: it publishes one sample per message of a real rig's crank encoder on "
         "crank_joint_state, stamped with the encoder's stamp.", choices=MODES),
    Spec('crank_speed', DOUBLE, 0.0,
         "Clock mode: crank speed in rad/s (negative turns backwards); 0 takes the scene's "
         'crank.speed_rad_s.', bounds=(-MAX_CRANK_SPEED, MAX_CRANK_SPEED)),
    Spec('publish_rate', DOUBLE, 100.0,
         'Clock mode: samples per second on joint_states and shaking_wrench, Hz.',
         bounds=(MIN_PUBLISH_RATE, MAX_PUBLISH_RATE)),
    Spec('frame_id', STRING, names.DEFAULT_FRAME_ID,
         'Frame of the shaking wrench (header.frame_id of shaking_wrench).',
         check=lambda value: identifiers.check_frame_id(value, 'frame_id'),
         rule="letters, digits, '_' and '/', not starting with '/' or a digit"),
    Spec('publish_robot_description', BOOL, True,
         'Publish the URDF of the published design on robot_description (std_msgs/String, '
         'transient local, as robot_state_publisher does), again when the scene, the design '
         'or frame_id changes; false when robot_state_publisher publishes it (the launch '
         'file).'),
    Spec('crank_joint', STRING, '',
         "Follow mode: the crank's name in the encoder's JointState; empty: the scene's "
         'crank joint.', check=_joint_name, rule='no surrounding spaces'),
    Spec('follow.window', INTEGER, 7,
         'Follow mode: encoder samples in the least-squares fit that estimates the crank '
         'speed and acceleration.', bounds=(2, 1000)),
    Spec('follow.use_encoder_velocity', BOOL, True,
         "Follow mode: use the encoder's velocity when it sends one; false estimates it "
         'from the positions (for a noisy velocity).'),
    Spec('follow.max_speed', DOUBLE, 200.0,
         'Follow mode: fastest crank the rig can have, rad/s; an encoder step that needs a '
         'faster crank is a jump the linkage cannot make and is skipped.',
         bounds=(1e-3, 1e5)),
    Spec('follow.max_gap', DOUBLE, 0.5,
         'Follow mode: a longer gap between encoder stamps, s, restarts the estimator.',
         bounds=(1e-6, 3600.0)),
    Spec('follow.resync_after', INTEGER, sensor.RESYNC_AFTER,
         'Follow mode: after this many encoder messages in a row rejected for their stamp '
         '(not after the last accepted) or their step (a jump), the node re-synchronizes on '
         'the incoming stream (one message stamped far in the future cannot lock it out).',
         bounds=(1, 100000)),
    Spec('follow.exact', BOOL, False,
         'Follow mode: evaluate the core exactly at every encoder sample; false (default) '
         "uses the design's cycle table, verified against the core when it is built (its "
         'accuracy is logged and on /diagnostics; where it cannot be trusted the core is '
         'evaluated per sample anyway).'),
    *_balance_specs(),
    Spec('use_balanced', BOOL, False,
         'Publish the balanced rig instead of the original; true runs the balancing with '
         'the balance.* options if no design is known for them (~/balance sets it, '
         '~/reset clears it).'),
    Spec('recording_path', STRING, '',
         'Write a rerun recording (.rrd) of the published samples; empty: none.',
         check=_path, rule="empty or a writable file ending in '.rrd' in an existing "
         'directory (none is created)'),
    Spec('rerun_url', STRING, '',
         "Stream the recording's views live to a running rerun viewer at this gRPC address "
         '(`rerun` prints it when it starts, e.g. rerun+http://127.0.0.1:9876/proxy), at most '
         '30 samples per second on a thread of its own; empty: none.',
         check=lambda value: paths.check_viewer_url(value, 'rerun_url') if value else None,
         rule='empty or rerun[+http|+https]://HOST[:PORT]/proxy'),
    # the twin against the real rig (mech_balance.ros.sensor, README)
    *(Spec(f'sensor.{axis}', DOUBLE, 0.0,
           f'Origin of the force sensor in frame_id (the rig frame), {axis} in m; the '
           'measured torque is about this point.',
           bounds=(-MAX_SENSOR_OFFSET_M, MAX_SENSOR_OFFSET_M)) for axis in 'xyz'),
    *(Spec(f'sensor.{angle}', DOUBLE, 0.0,
           f'Orientation of the force sensor in frame_id, {angle} in rad (ROS fixed axes: '
           'R = Rz(yaw) Ry(pitch) Rx(roll) maps the sensor axes to the rig axes).',
           bounds=(-MAX_ANGLE_RAD, MAX_ANGLE_RAD)) for angle in ('roll', 'pitch', 'yaw')),
    Spec('sensor.convention', STRING, sensor.CONVENTIONS[0],
         'load_on_sensor: measured_wrench is the load the rig exerts on the sensor (a rig '
         'at rest on it pushes down, the sign of shaking_wrench); reaction: the wrench the '
         'sensor exerts on the rig (pushes up), negated before the comparison.',
         choices=sensor.CONVENTIONS),
    Spec('sensor.residual_window', DOUBLE, 2.0,
         'Span of the running RMS of residual and measurement, s (by measurement stamps).',
         bounds=(0.01, 600.0)),
    Spec('sensor.crank_window', DOUBLE, 0.1,
         'Follow mode: span of the centred least-squares quadratic through the encoder '
         'angles that gives the crank state at a measurement stamp, s (longer: less '
         'quantization noise, more smoothing of speed variations; the residual lags by '
         'half of it).', bounds=(1e-3, 10.0)),
    Spec('sensor.tare_seconds', DOUBLE, 2.0,
         '~/tare estimates the sensor bias from the paired measurements of the last this '
         'many seconds.', bounds=(1e-3, 600.0)),
    Spec('diagnostics.warn_fraction', DOUBLE, 0.1,
         '/diagnostics: the measured-wrench status is WARN when the residual RMS of a '
         'component exceeds this fraction of its measured RMS.', bounds=(0.0, MAX_FRACTION)),
    Spec('diagnostics.error_fraction', DOUBLE, 0.3,
         '/diagnostics: ERROR above this fraction (>= diagnostics.warn_fraction).',
         bounds=(0.0, MAX_FRACTION)),
)
"""Every parameter of the rig node, in declaration order."""

BY_NAME = {spec.name: spec for spec in PARAMETERS}


def check(name, value):
    """Return ``value`` of parameter ``name`` checked (lists for arrays); raise ValueError."""
    spec = spec_for(name)
    if spec is None:
        raise ValueError(f'{name}: unknown parameter, expected one of '
                         f'{", ".join(BY_NAME)} or {LINK_PREFIX}<link>.<'
                         f'{"|".join(LINK_OPTIONS)}>')
    value = _typed(spec, value)
    if spec.bounds is not None and not spec.bounds[0] <= value <= spec.bounds[1]:
        raise ValueError(f'{name}: got {value!r}, expected {spec.bounds[0]:g} <= value <= '
                         f'{spec.bounds[1]:g}')
    if spec.choices is not None and value not in spec.choices:
        raise ValueError(f'{name}: got {value!r}, expected one of {", ".join(spec.choices)}')
    if spec.check is not None:
        spec.check(value)
    return value


def check_together(values):
    """Raise ValueError if ``diagnostics.warn_fraction`` exceeds ``error_fraction``."""
    warn, error = values['diagnostics.warn_fraction'], values['diagnostics.error_fraction']
    if warn > error:
        raise ValueError(f'diagnostics.warn_fraction: got {warn:g} above '
                         f'diagnostics.error_fraction = {error:g}, expected warn <= error')


def sensor_pose(values):
    """Return the :class:`mech_balance.ros.sensor.SensorPose` of the ``sensor.*`` values."""
    return sensor.SensorPose(**{k: values[f'sensor.{k}'] for k in (
        'x', 'y', 'z', 'roll', 'pitch', 'yaw', 'convention')})


def _typed(spec, value):
    expected = {STRING: 'text', DOUBLE: 'a floating-point number', INTEGER: 'an integer',
                BOOL: 'true or false', DOUBLE_ARRAY: 'a list of numbers'}[spec.value_type]
    # ROS types 100 as an integer and 100.0 as a double: an integer is accepted (and
    # converted) where a double is declared, as `ros2 param set /rig publish_rate 100` sends
    ok = {STRING: lambda v: isinstance(v, str),
          DOUBLE: _is_number,
          INTEGER: lambda v: isinstance(v, int) and not isinstance(v, bool),
          BOOL: lambda v: isinstance(v, bool),
          DOUBLE_ARRAY: lambda v: not isinstance(v, (str, bytes)) and hasattr(v, '__len__')
          and len(v) <= MAX_ARRAY and all(_is_number(x) for x in v)}
    if not ok[spec.value_type](value):
        raise ValueError(f'{spec.name}: got {_show(value)}, expected {expected}')
    if spec.value_type == DOUBLE:
        value = _finite(spec.name, value)
    if spec.value_type == DOUBLE_ARRAY:
        value = [_finite(spec.name, x, value) for x in value]
    return value


MAX_ARRAY = 64
"""Longest array parameter accepted (the longest declared takes two numbers)."""


def _is_number(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _finite(name, x, whole=None):
    try:
        v = float(x)
    except OverflowError:  # an integer beyond the doubles
        v = math.inf
    if not math.isfinite(v):
        if whole is None:
            raise ValueError(f'{name}: got {_show(x)}, expected a finite number')
        raise ValueError(f'{name}: got {_show(list(whole))}, expected finite numbers')
    return v


NUMBER = re.compile(r'\s*[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?\s*')
"""A decimal number as text (``1e9``, which YAML 1.1 and so ros2cli read as a string)."""


def coerced(name, value):
    """Return ``value`` as the declared type of ``name`` where that loses nothing, else as is."""
    spec = spec_for(name)
    if spec is None:
        return value
    if spec.value_type == DOUBLE and isinstance(value, str) and NUMBER.fullmatch(value):
        return float(value)  # `ros2 param set /rig publish_rate 1e9`: YAML 1.1 sends text
    if spec.value_type == DOUBLE and _is_number(value) and isinstance(value, int):
        try:
            return float(value)
        except OverflowError:
            return value
    if spec.value_type == DOUBLE_ARRAY and isinstance(value, (list, tuple)) and \
            (not value or all(_is_number(x) for x in value)):
        try:
            return [float(x) for x in value]
        except OverflowError:
            return value
    return value


def defaults():
    """Return ``{name: default}`` of every parameter."""
    return {spec.name: spec.default for spec in PARAMETERS}


def frame_id_from_params_file(path):
    """
    Return the rig node's ``frame_id`` in a ROS params file (the URDF's root link name).

    Sections whose last name is ``*``, ``**`` or the node's apply in file order; default
    :data:`mech_balance.ros.names.DEFAULT_FRAME_ID`.
    """
    from pathlib import Path
    from mech_balance.schema.scene import parse_yaml
    try:
        data = parse_yaml(Path(path).read_text())
    except OSError as exc:
        raise ValueError(f'params_file: got {str(path)!r}, cannot read it '
                         f'({exc.strerror}); expected a ROS params file') from None
    if not isinstance(data, dict):
        raise ValueError(f'params_file: got {str(path)!r}, expected a mapping of node names '
                         'to ros__parameters')
    frame_id = names.DEFAULT_FRAME_ID
    for key, section in data.items():
        if str(key).rstrip('/').split('/')[-1] not in ('*', '**', names.NODE_NAME):
            continue
        values = section.get('ros__parameters', {}) if isinstance(section, dict) else {}
        if isinstance(values, dict) and 'frame_id' in values:
            frame_id = values['frame_id']
    if not isinstance(frame_id, str) or not frame_id:
        raise ValueError(f'params_file: frame_id: got {frame_id!r} in {str(path)!r}, expected '
                         'a frame name')
    return frame_id


def balance_options(values, method='redistribution'):
    """Return the options of :func:`mech_balance.balancing.balance` for checked ``values``."""
    return options.from_params(values, method)
