"""
The rig node's parameters, each declared once: type, default, description, bounds, check.

In the manner of generate_parameter_library: :data:`PARAMETERS` is the single table the
node declares from (:func:`mech_balance.ros.conversions.parameter_descriptor` turns a
:class:`Spec` into a ROS ``ParameterDescriptor``), ``config/rig_params.yaml`` documents a
working set and :func:`check` is the validator the node runs on every update (a
``ValueError`` naming the parameter, the value and what was expected becomes the ``reason``
of ``SetParametersResult(successful=False)``).  ``scene`` is validated by the scene loader
itself (:func:`mech_balance.schema.load`, then the twin traces the linkage's branch), the
balancing options by the same rules as :func:`mech_balance.balancing.optimize`.  No ROS
import here: the command line and the tests use this table too.
"""

from dataclasses import dataclass
import math
import re

from mech_balance import conventions, identifiers, paths
from mech_balance.balancing import defaults as balancing_defaults
from mech_balance.balancing import socp as balancing
from mech_balance.ros import sensor
from mech_balance.schema import safe_yaml

STRING, DOUBLE, INTEGER, BOOL, DOUBLE_ARRAY = 'string', 'double', 'integer', 'bool', \
    'double_array'
MODES = ('clock', 'follow')
MAX_SENSOR_OFFSET_M = 100.0
"""Largest |sensor.x|, |sensor.y|, |sensor.z| accepted, m."""
MAX_ANGLE_RAD = 2.0 * math.pi
"""Largest |sensor.roll|, |sensor.pitch|, |sensor.yaw| accepted, rad."""
MAX_FRACTION = 1000.0
"""Largest diagnostics threshold (residual RMS / measured RMS)."""
CASES = ('a', 'b')
METHODS = ('redistribution', 'counterweights', 'analytic')
"""``balance.method``: :func:`mech_balance.balancing.balance`'s methods the node offers (a
rig that cannot be redistributed, the closed-form ``rggr`` scene, is balanced by its own
method when the method is the default, redistribution; spatial scenes are redistributed)."""
LINK_PREFIX = 'balance.links.'
"""Per-link balancing options are ``balance.links.<link>.<option>``, declared from the scene."""
LINK_OPTIONS = {'mass_bounds': ('kg', 'balance.mass_bounds', 'link mass bounds'),
                'distance_bounds': ('m', 'balance.distance_bounds',
                                    'point-mass distance bounds')}
"""Per-link options: unit, the older text parameter they replace, what they bound."""
MAX_COUNTERWEIGHT_VALUE = 1e6
"""Largest counterweight density (kg/m^3), thickness (m) or factor accepted (a finite cap)."""
MAX_CRANK_SPEED = 1000.0
"""Largest |crank_speed| accepted, rad/s (about 9500 rpm)."""
MIN_PUBLISH_RATE = 0.1
"""Slowest clock-mode publish rate, Hz."""
MAX_PUBLISH_RATE = 20000.0
"""Fastest clock-mode publish rate, Hz (see ``mech-balance bench`` for what is sustained)."""
MAX_SAMPLES = conventions.MAX_SAMPLES
"""Most crank angles per revolution in a balancing run."""
MAX_WEIGHT = conventions.MAX_WEIGHT
"""Largest objective weight accepted."""
MAX_MARGIN = 0.999
"""Largest realizability margin (the balancing requires margin < 1)."""


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
    def kind(self):
        """Return the ROS type, as :attr:`value_type` (the name ``ros2 param`` shows)."""
        return self.value_type

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


# ------------------------------------------------------------------------------ checks


def _scene(value):
    """Reject an empty scene name (the node then loads and assembles the scene)."""
    if not value:
        raise ValueError('scene: got an empty name, expected a built-in scene or a path')


def _frame_id(value):
    """Accept a TF frame name (:func:`mech_balance.identifiers.check_frame_id`)."""
    identifiers.check_frame_id(value, 'frame_id')


def _joint_name(value):
    """Accept empty (the scene's crank joint) or a joint name (identifiers.check_name)."""
    if value != value.strip():
        raise ValueError(f'crank_joint: got {value!r}, expected a joint name without '
                         "surrounding spaces (or empty for the scene's crank joint)")
    identifiers.check_name(value, 'crank_joint', allow_empty=True)


def _weights(value):
    """Accept [w1, w2] >= 0, not both 0 (weights of the RMS shaking force and moment)."""
    if len(value) != 2 or not all(math.isfinite(v) and 0.0 <= v <= MAX_WEIGHT for v in value):
        raise ValueError(f'balance.weights: got {list(value)}, expected [w1, w2] with '
                         f'0 <= w1, w2 <= {MAX_WEIGHT:g} (Chaudhary & Saha '
                         'eq. 43; the upper bound is fixed)')
    if value[0] + value[1] == 0.0:
        raise ValueError('balance.weights: got [0, 0], expected at least one positive weight')


def _factors(name, ratio_range):
    def check(value):
        """Accept [low, high] factors of the original value, 0 < low <= high, in range."""
        if len(value) != 2 or not all(math.isfinite(v) for v in value) or \
                not 0.0 < value[0] <= value[1]:
            raise ValueError(f'{name}: got {list(value)}, expected [low, high] with '
                             '0 < low <= high (factors of the original link value)')
        for v in value:
            balancing_defaults.check_range(name, v, *ratio_range)
    return check


def _link_bounds(name, unit):
    def check(value):
        """Accept empty or a YAML mapping link: [min, max] in SI (max may be null)."""
        parse_link_bounds(name, value, unit)
    return check


def parse_link_bounds(name, text, unit):
    """
    Return ``{link: (min, max)}`` from a ``balance.*_bounds`` text, or None when empty.

    The text is a YAML mapping such as ``{crank: [0.3, 1.5], rocker: [5e-1, null]}`` in
    ``unit``, parsed as scenes are (:func:`mech_balance.safe_yaml.loads`: YAML 1.2 floats,
    ``1e-1`` is a number); link names are checked against the scene when the balancing
    runs.
    """
    if not text.strip():
        return None
    data = safe_yaml.loads(text, name)  # bounded: depth, size, aliases (a YamlError)
    if not isinstance(data, dict) or not data:
        raise ValueError(f'{name}: got {text!r}, expected a mapping link: [min, max] in {unit}')
    out = {}
    for link, pair in data.items():
        ok = isinstance(link, str) and isinstance(pair, (list, tuple)) and len(pair) == 2
        if ok:
            lo, hi = pair
            ok = all(v is None or (isinstance(v, (int, float)) and not isinstance(v, bool)
                                   and math.isfinite(v)) for v in (lo, hi))
            ok = ok and lo is not None and lo > 0.0 and (hi is None or hi >= lo)
        if not ok:
            raise ValueError(f'{name}.{link}: got {pair!r}, expected [min, max] in {unit} with '
                             '0 < min <= max (max may be null: no upper bound)')
        balancing_defaults.check_bound_pair(f'{name}.{link}', lo, hi, unit)
        out[link] = (float(lo), None if hi is None else float(hi))
    return out


def _link_list(value):
    """Accept empty or comma-separated link names, each once."""
    identifiers.check_name_list(value, 'balance.fixed_links')


def split_links(text):
    """Return the link names of a comma-separated ``balance.fixed_links`` text."""
    return [n.strip() for n in text.split(',')] if text.strip() else []


def _positive(name, option=None):
    def check(value):
        """Accept a number in the option's range (as ``mech-balance balance --counterweights``)."""
        if not 0.0 < value <= MAX_COUNTERWEIGHT_VALUE:
            raise ValueError(f'{name}: got {value!r}, expected a number > 0 and at most '
                             f'{MAX_COUNTERWEIGHT_VALUE:g}')
        if option is not None:
            balancing_defaults.check_counterweight_option(option, value, name)
    return check


def _ranged(name, option):
    """Return the check and rule of a counterweight option (balancing's documented range)."""
    lowest, highest = balancing_defaults.COUNTERWEIGHT_RANGES[option]
    return {'check': _positive(name, option), 'rule': f'in [{lowest:g}, {highest:g}]'}


def _counterweight_links(value):
    """Accept empty or comma-separated link names, each once (as ``--counterweights``)."""
    identifiers.check_name_list(value, 'balance.counterweight_links')


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


def link_specs(link_names):
    """Return the per-link :class:`Spec` of every link and option, in declaration order."""
    return [link_spec(link, option) for link in link_names for option in LINK_OPTIONS]


def spec_for(name):
    """Return the :class:`Spec` of a parameter name (per-link ones included), or None."""
    spec = BY_NAME.get(name)
    if spec is None and name.startswith(LINK_PREFIX):
        link, _, option = name[len(LINK_PREFIX):].rpartition('.')
        if link and option in LINK_OPTIONS:
            spec = link_spec(link, option)
    return spec


def _samples(value):
    """Accept 0 (the scene's samples) or an integer >= 4."""
    if 0 < value < 4:
        raise ValueError(f"balance.samples: got {value}, expected 0 (the scene's) or an "
                         'integer >= 4')


def check_links(values, link_names):
    """
    Raise ValueError if a ``balance.*`` option names a link the scene does not have.

    ``values`` holds checked parameter values; ``link_names`` are the scene's moving links.
    """
    named = {'balance.fixed_links': split_links(values['balance.fixed_links']),
             'balance.counterweight_links': split_links(values['balance.counterweight_links'])}
    for key, unit in (('balance.mass_bounds', 'kg'), ('balance.distance_bounds', 'm')):
        named[key] = list(parse_link_bounds(key, values[key], unit) or ())
    for key, value in values.items():
        if key.startswith(LINK_PREFIX) and value:
            link, _, option = key[len(LINK_PREFIX):].rpartition('.')
            named[key] = [link]
            older = LINK_OPTIONS[option][1]
            if link in named[older]:
                raise ValueError(f'{key}: got {list(value)}, expected no second bound for link '
                                 f'{link!r} ({older} gives one; clear one of them)')
    for key, names in named.items():
        for name in names:
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


def _viewer_url(value):
    """Accept empty (no live view) or a rerun viewer's gRPC address."""
    if value:
        paths.check_viewer_url(value, 'rerun_url')


# ------------------------------------------------------------------------------ table

_BOUNDS_RULE = ("empty or the quoted YAML '{link: [min, max]}', 0 < min <= max, max may be "
                'null')


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
    Spec('frame_id', STRING, 'rig_frame',
         'Frame of the shaking wrench (header.frame_id of shaking_wrench).', check=_frame_id,
         rule="letters, digits, '_' and '/', not starting with '/' or a digit"),
    Spec('publish_robot_description', BOOL, True,
         'Publish the URDF of the published design on robot_description (std_msgs/String, '
         'transient local, as robot_state_publisher does), again when the scene, the design '
         'or frame_id changes; false when robot_state_publisher publishes it (the launch '
         'file).'),
    Spec('crank_joint', STRING, '',
         "Follow mode: the crank's name in the encoder's JointState; empty: the scene's "
         'crank joint (RGGR: crank).', check=_joint_name, rule='no surrounding spaces'),
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
    Spec('follow.resync_after', INTEGER, 10,
         'Follow mode: after this many encoder messages in a row rejected for their stamp '
         '(not after the last accepted) or their step (a jump), the node re-synchronizes on '
         'the incoming stream (one message stamped far in the future cannot lock it out).',
         bounds=(1, 100000)),
    Spec('follow.exact', BOOL, False,
         'Follow mode: evaluate the core exactly at every encoder sample; false (default) '
         "uses the design's cycle table, verified against the core when it is built (its "
         'accuracy is logged and on /diagnostics; where it cannot be trusted the core is '
         'evaluated per sample anyway).'),
    Spec('balance.weights', DOUBLE_ARRAY, list(balancing.DEFAULT_WEIGHTS),
         'Weights [w1, w2] of the RMS shaking force and moment in the balancing objective '
         '(Chaudhary & Saha eq. 43; mech-balance balance --weights).', check=_weights,
         rule='two numbers >= 0, not both 0'),
    Spec('balance.case', STRING, 'a',
         'a: point masses of any sign; b: non-negative point masses (counterweights).',
         choices=CASES),
    Spec('balance.realizable', BOOL, True,
         'Require every balanced link to be a realizable body (centroidal inertia >= '
         'balance.margin x I_O); false is --no-realizable.'),
    Spec('balance.margin', DOUBLE, balancing.CENTROIDAL_MARGIN,
         'Realizability margin: centroidal inertia >= margin x inertia about the link '
         'origin.', bounds=(0.0, MAX_MARGIN)),
    Spec('balance.paper_constraints', BOOL, False,
         "Solve exactly Chaudhary & Saha eqs. 50/53 (the paper's bounds, no realizability); other "
         'bound options must keep their defaults.'),
    Spec('balance.mass_factors', DOUBLE_ARRAY, list(balancing.PAPER_MASS_FACTORS),
         'Link mass bounds [low, high] as factors of the original link mass (eq. 50b).',
         check=_factors('balance.mass_factors', balancing_defaults.BOUND_RATIO_RANGE),
         rule='[low, high], 0 < low <= high, each in [1e-06, 1e+06]'),
    Spec('balance.distance_factors', DOUBLE_ARRAY, list(balancing.PAPER_DISTANCE_FACTORS),
         'Point-mass distance bounds [low, high] as factors of the original '
         'l = sqrt(I_O/m) (eq. 50c).',
         check=_factors('balance.distance_factors', balancing_defaults.DISTANCE_RATIO_RANGE),
         rule='[low, high], 0 < low <= high, each in [0.01, 100]'),
    Spec('balance.mass_bounds', STRING, '',
         'Per-link mass bounds in kg overriding the factors, YAML text, quoted on the command '
         'line: ros2 param set /rig balance.mass_bounds "\'{crank: [0.3, 1.6]}\'" (the older '
         'form of the typed balance.links.crank.mass_bounds "[0.3, 1.6]").',
         check=_link_bounds('balance.mass_bounds', 'kg'), rule=_BOUNDS_RULE),
    Spec('balance.distance_bounds', STRING, '',
         'Per-link point-mass distance bounds in m overriding the factors, YAML text, quoted '
         'on the command line: "\'{crank: [0.02, null]}\'" (the older form of the typed '
         'balance.links.crank.distance_bounds "[0.02]").',
         check=_link_bounds('balance.distance_bounds', 'm'),
         rule=_BOUNDS_RULE),
    Spec('balance.torque_weight', DOUBLE, 0.0,
         'Extra weight on the RMS normalized driving torque.', bounds=(0.0, MAX_WEIGHT)),
    Spec('balance.reaction_weight', DOUBLE, 0.0,
         'Extra weight on the sum of the RMS normalized bearing forces.',
         bounds=(0.0, MAX_WEIGHT)),
    Spec('balance.max_added_mass', DOUBLE, -1.0,
         'Cap on the total added mass, kg (over the original total); negative: no cap.',
         bounds=(-1.0, 1e6)),
    Spec('balance.fixed_links', STRING, '',
         'Comma-separated links kept as they are (e.g. "crank,rocker"); empty: none.',
         check=_link_list, rule='links of the scene'),
    Spec('balance.samples', INTEGER, 0,
         "Crank angles per revolution in the balancing objective; 0: the scene's samples "
         '(RGGR: 360).', bounds=(0, MAX_SAMPLES), check=_samples,
         rule='0 or >= 4'),
    Spec('balance.method', STRING, 'redistribution',
         'redistribution: the certified optimal mass redistribution (Chaudhary & Saha); '
         'counterweights: add-only discs on balance.counterweight_links (certified); '
         'analytic: complete force balance in closed form (slider-crank: Sinatra & Angeles, '
         'four-bar: Chaudhary & Saha eq. 48). A scene that cannot be redistributed (the '
         'closed-form rggr scene) is balanced by its own method (weights) with the default; '
         'spatial scenes, rggr_spatial included, are redistributed.', choices=METHODS),
    Spec('balance.counterweight_links', STRING, '',
         'Counterweights: comma-separated links that each gain one disc (e.g. '
         '"crank,rocker"); needed by balance.method counterweights.',
         check=_counterweight_links, rule='links of the scene, each once'),
    Spec('balance.density', DOUBLE, balancing_defaults.DEFAULT_DENSITY_KG_M3,
         'Counterweights: disc material density, kg/m^3 (steel).',
         **_ranged('balance.density', 'density_kg_m3')),
    Spec('balance.max_thickness', DOUBLE, balancing_defaults.DEFAULT_MAX_THICKNESS_M,
         'Counterweights: thickest disc, m.',
         **_ranged('balance.max_thickness', 'max_thickness_m')),
    Spec('balance.max_radius_factor', DOUBLE, balancing_defaults.DEFAULT_MAX_RADIUS_FACTOR,
         "Counterweights: disc centre at most this factor times the distance from the link's "
         'origin to its farthest joint point.',
         **_ranged('balance.max_radius_factor', 'max_radius_factor')),
    Spec('balance.max_mass_factor', DOUBLE, balancing_defaults.DEFAULT_MAX_MASS_FACTOR,
         "Counterweights: disc mass at most this factor times the link's own mass.",
         **_ranged('balance.max_mass_factor', 'max_mass_factor')),
    Spec('balance.max_gyration_factor', DOUBLE,
         balancing_defaults.DEFAULT_MAX_GYRATION_FACTOR,
         "Counterweights: the disc's radius of gyration about the link origin at most this "
         "factor times the link's joint reach.",
         **_ranged('balance.max_gyration_factor', 'max_gyration_factor')),
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
         check=_viewer_url, rule='empty or rerun[+http|+https]://HOST[:PORT]/proxy'),
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
    """
    Return ``value`` of parameter ``name`` checked (lists for arrays); raise ValueError.

    The reason names the parameter, the value and what was expected.
    """
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
    """
    Raise ValueError if checked parameter values disagree with each other.

    ``diagnostics.warn_fraction`` must not exceed ``diagnostics.error_fraction``.
    """
    warn, error = values['diagnostics.warn_fraction'], values['diagnostics.error_fraction']
    if warn > error:
        raise ValueError(f'diagnostics.warn_fraction: got {warn:g} above '
                         f'diagnostics.error_fraction = {error:g}, expected warn <= error')


def sensor_pose_values(values):
    """Return the keyword arguments of :class:`mech_balance.ros.sensor.SensorPose`."""
    out = {k: values[f'sensor.{k}'] for k in ('x', 'y', 'z', 'roll', 'pitch', 'yaw')}
    out['convention'] = values['sensor.convention']
    return out


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


def _show(value):
    text = repr(value)
    return text if len(text) <= 80 else f'{text[:80]}... ({len(text)} characters)'


NUMBER = re.compile(r'\s*[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?\s*')
"""A decimal number as text (``1e9``, which YAML 1.1 and so ros2cli read as a string)."""


def coerced(name, value):
    """
    Return ``value`` converted to the declared type of ``name`` where that loses nothing.

    An integer (or a list of integers, or an empty list of any type) becomes the double
    (list) a ``DOUBLE`` (``DOUBLE_ARRAY``) parameter is declared with, and so does a
    number written as text (:data:`NUMBER`: ``'1e9'``, then checked as any double); anything
    else is
    returned as it is (the check then names what is wrong).  The node applies it before
    rclpy stores a value, so that the stored type stays the declared one.
    """
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


def balance_options(values, method='redistribution'):
    """
    Return the options of :func:`mech_balance.balancing.balance` for ``values``.

    ``values`` maps parameter names to checked values (at least the ``balance.*`` ones);
    the same call as ``mech-balance balance`` with the matching options.  ``method`` is the
    balancing method (:func:`mech_balance.balancing.method_for`): the RGGR's ``weights``
    and ``analytic`` take the sample count only, ``counterweights`` the ``balance.*``
    counterweight options; the per-link ``balance.links.<link>.*_bounds`` join the text
    ``balance.*_bounds`` (a link in both is refused by :func:`check_links`).
    """
    if method == 'weights':
        return {'samples': values['balance.samples'] or None}
    if method == 'analytic':
        return {'samples': values['balance.samples'] or None}
    if method == 'counterweights':
        return {'links': tuple(split_links(values['balance.counterweight_links'])),
                'weights': tuple(values['balance.weights']),
                'density_kg_m3': values['balance.density'],
                'max_thickness_m': values['balance.max_thickness'],
                'max_radius_factor': values['balance.max_radius_factor'],
                'max_mass_factor': values['balance.max_mass_factor'],
                'max_gyration_factor': values['balance.max_gyration_factor'],
                'torque_weight': values['balance.torque_weight'],
                'reaction_weight': values['balance.reaction_weight'],
                'samples': values['balance.samples'] or None}
    bounds = {}
    for key, unit in (('mass_bounds', 'kg'), ('distance_bounds', 'm')):
        merged = dict(parse_link_bounds(f'balance.{key}', values[f'balance.{key}'], unit) or {})
        for name, value in values.items():
            if name.startswith(LINK_PREFIX) and name.endswith(f'.{key}') and value:
                link = name[len(LINK_PREFIX):-len(key) - 1]
                merged[link] = (float(value[0]), float(value[1]) if len(value) == 2 else None)
        bounds[key] = merged or None
    cap = values['balance.max_added_mass']
    return {'weights': tuple(values['balance.weights']), 'case': values['balance.case'],
            'realizable': values['balance.realizable'],
            'paper_constraints': values['balance.paper_constraints'],
            'mass_bounds': bounds['mass_bounds'],
            'distance_bounds': bounds['distance_bounds'],
            'samples': values['balance.samples'] or None,
            'torque_weight': values['balance.torque_weight'],
            'reaction_weight': values['balance.reaction_weight'],
            'max_added_mass_kg': None if cap < 0.0 else cap,
            'fixed_links': tuple(split_links(values['balance.fixed_links'])),
            'mass_factors': tuple(values['balance.mass_factors']),
            'distance_factors': tuple(values['balance.distance_factors']),
            'centroidal_margin': values['balance.margin']}
