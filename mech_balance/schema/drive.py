"""The ``drive:`` section of a scene: motor, speed controller, joint damping, initial state."""

from dataclasses import dataclass, field
import functools

from mech_balance.schema import fields


VOLTAGE_FRACTION_MAX = 10.0
"""Largest |voltage fraction| accepted (over-voltage beyond 10x rated is a typo)."""


class DriveError(ValueError):
    """A ``drive`` field is missing, has the wrong type or an impossible value."""


@dataclass(frozen=True)
class Motor:
    """DC motor on its torque-speed line (SI)."""

    stall_torque_Nm: float
    no_load_speed_rad_s: float
    rotor_inertia_kg_m2: float = 0.0
    gear_ratio: float = 1.0
    electrical_time_constant_s: float = 0.0
    voltage_fraction: float = 1.0


@dataclass(frozen=True)
class SpeedController:
    """PI crank-speed controller acting on the motor voltage fraction."""

    kp_per_rad_s: float
    ki_per_rad: float
    setpoint_rad_s: float = None
    voltage_limit: float = 1.0


@dataclass(frozen=True)
class Drive:
    """Motor, speed controller, damping, input (crank) flywheel inertia and initial state (SI)."""

    motor: Motor = None
    speed_controller: SpeedController = None
    joint_damping: dict = field(default_factory=dict)
    initial_speed_rad_s: float = None
    initial_crank_angle_deg: float = None
    input_inertia_kg_m2: float = 0.0


_DRIVE_KEYS = {'motor', 'speed_controller', 'joint_damping', 'initial_speed_rad_s',
               'initial_crank_angle_deg', 'input_inertia_kg_m2'}
_MOTOR_KEYS = {'stall_torque_Nm', 'no_load_speed_rad_s', 'rotor_inertia_kg_m2', 'gear_ratio',
               'electrical_time_constant_s', 'voltage_fraction'}
_PI_KEYS = {'kp_per_rad_s', 'ki_per_rad', 'setpoint_rad_s', 'voltage_limit'}


def drive_from_dict(data, scene=None, joint_names=None):
    """
    Return the validated :class:`Drive` of a scene's ``drive`` mapping (raises DriveError).

    ``joint_damping`` keys are checked against ``joint_names``, else the joints of ``scene``.
    """
    if data is None:
        return Drive()
    if isinstance(data, Drive):
        data_drive = data
    else:
        data = _mapping(data, 'drive')
        _known(data, _DRIVE_KEYS, 'drive')
        motor = None
        if data.get('motor') is not None:
            m = _mapping(data['motor'], 'drive.motor')
            _known(m, _MOTOR_KEYS, 'drive.motor')
            motor = Motor(
                stall_torque_Nm=_field(m, 'drive.motor', 'stall_torque_Nm', _positive),
                no_load_speed_rad_s=_field(m, 'drive.motor', 'no_load_speed_rad_s', _positive),
                rotor_inertia_kg_m2=_field(m, 'drive.motor', 'rotor_inertia_kg_m2', _nonneg, 0.0),
                gear_ratio=_field(m, 'drive.motor', 'gear_ratio', _positive, 1.0),
                electrical_time_constant_s=_field(m, 'drive.motor', 'electrical_time_constant_s',
                                                  _nonneg, 0.0),
                voltage_fraction=_field(m, 'drive.motor', 'voltage_fraction', _number, 1.0))
            if abs(motor.voltage_fraction) > VOLTAGE_FRACTION_MAX:
                raise DriveError(
                    f'drive.motor.voltage_fraction: got {motor.voltage_fraction!r}, expected '
                    f'a fraction of the rated voltage with magnitude <= '
                    f'{VOLTAGE_FRACTION_MAX:g}')
        pi = None
        if data.get('speed_controller') is not None:
            if motor is None:
                raise DriveError('drive.speed_controller: got a speed controller without a '
                                 'motor, expected drive.motor as well')
            c = _mapping(data['speed_controller'], 'drive.speed_controller')
            _known(c, _PI_KEYS, 'drive.speed_controller')
            where = 'drive.speed_controller'
            pi = SpeedController(
                kp_per_rad_s=_field(c, where, 'kp_per_rad_s', _nonneg),
                ki_per_rad=_field(c, where, 'ki_per_rad', _nonneg),
                setpoint_rad_s=_field(c, where, 'setpoint_rad_s', _number, None),
                voltage_limit=_field(c, where, 'voltage_limit', _positive, 1.0))
            if pi.voltage_limit > VOLTAGE_FRACTION_MAX:
                raise DriveError(
                    f'drive.speed_controller.voltage_limit: got {pi.voltage_limit!r}, '
                    f'expected a fraction of the rated voltage <= {VOLTAGE_FRACTION_MAX:g}')
        damping = {}
        for name, value in _mapping(data.get('joint_damping') or {},
                                    'drive.joint_damping').items():
            damping[name] = _nonneg(value, f'drive.joint_damping.{name}')
        data_drive = Drive(
            motor=motor, speed_controller=pi, joint_damping=damping,
            initial_speed_rad_s=_field(data, 'drive', 'initial_speed_rad_s', _number, None),
            initial_crank_angle_deg=_field(data, 'drive', 'initial_crank_angle_deg', _number,
                                           None),
            input_inertia_kg_m2=_field(data, 'drive', 'input_inertia_kg_m2', _nonneg, 0.0))
    if joint_names is None and scene is not None:
        joint_names = [j.name for j in scene.joints]
    if joint_names is not None:
        for name in data_drive.joint_damping:
            if name not in joint_names:
                raise DriveError(
                    f'drive.joint_damping.{name}: no such joint, expected one of '
                    f'{", ".join(joint_names)}')
    return data_drive


# the scene loader's field checks, raising DriveError (a ValueError) instead of SceneError
_mapping = functools.partial(fields.mapping, error=DriveError)
_known = functools.partial(fields.known_keys, error=DriveError)
_require = functools.partial(fields.require, error=DriveError)
_number = functools.partial(fields.number, error=DriveError)
_positive = functools.partial(fields.positive, error=DriveError)
_nonneg = functools.partial(fields.nonneg, error=DriveError)
_REQUIRED = object()


def _field(spec, where, key, check, default=_REQUIRED):
    """Return ``spec[key]`` (required, or ``default``; None stays None) checked, named."""
    value = _require(spec, key, where) if default is _REQUIRED else spec.get(key, default)
    return None if value is None and default is None else check(value, f'{where}.{key}')
