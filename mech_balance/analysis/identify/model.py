"""The measurement model: channels, inertial parameters, and the regressor that links them."""

from dataclasses import dataclass
import math

from mech_balance.analysis import cycle as analysis
from mech_balance.core.planar import dynamics
from mech_balance.core.planar.rig import objective_units
import numpy as np

CHANNELS = ('force_x', 'force_y', 'moment_z')
"""Wrench channels of a planar rig (rig frame, about the crank pivot)."""
TORQUE_CHANNEL = 'torque'
"""Channel of the driving torque (from the encoder's effort), stacked when present."""
CHANNEL_UNITS = {'force_x': 'N', 'force_y': 'N', 'moment_z': 'N*m', 'torque': 'N*m'}
PARAMETERS = ('m', 'hx', 'hy', 'I_O')
"""Per link: m (kg), m c_x, m c_y (kg*m), I_O (kg*m^2), as
:func:`mech_balance.core.planar.dynamics.parameter_vector` orders them."""
PARAMETER_UNITS = ('kg', 'kg*m', 'kg*m', 'kg*m^2')

SPATIAL_NOT_YET = (
    'identification of a spatial rig (kind spatial) is not implemented yet: the '
    'encoder model, the base-parameter fit and the physically consistent calibration are '
    'written for planar links (4 parameters each: m, m c_x, m c_y, I_O); a spatial body has 10 '
    '(m, m c, the inertia tensor), and the pieces a spatial identification would stand on '
    "exist (the rigs' body kinematics and core/regressor.py, the six-component wrench as a "
    'linear map of them) but are not wired into identify yet')
"""Why ``identify`` refuses a spatial scene (printed in its error)."""


class IdentifyError(ValueError):
    """Identification input is missing, inconsistent or cannot determine the parameters."""


def check_identifiable(scene):
    """Raise IdentifyError (one line: capability, kind, why) unless ``scene`` can be identified."""
    from mech_balance.core.rig import CapabilityError, require
    try:
        require(scene, 'identification', 'identify')
    except CapabilityError as exc:
        raise IdentifyError(f'{exc} ({SPATIAL_NOT_YET})') from None


def parameter_names(scene):
    """Return the names ``m[link]``, ``hx[link]``, ``hy[link]``, ``I_O[link]`` in order."""
    return tuple(f'{p}[{lk.name}]' for lk in scene.links for p in PARAMETERS)


def parameter_scales(scene):
    """
    Return the ``(4 n,)`` scale of each parameter: per link m, m l, m l, m l^2 (scene).

    l = sqrt(I_O / m), the radius of gyration (seed 001 eq. 27); else the rig's units.
    """
    units = objective_units(scene)
    out = []
    for lk in scene.links:
        m = lk.mass_kg if lk.mass_kg > 0.0 else units.mass_kg
        i_o = lk.inertia_origin_kg_m2
        gyration = math.sqrt(i_o / m) if i_o > 0.0 else units.length_m
        out += [m, m * gyration, m * gyration, m * gyration * gyration]
    return np.array(out)


@dataclass
class Regressor:
    """
    The measured quantities as a linear function of the inertial parameters theta (SI).

    ``wrench`` ``(p, 3, 4 n)``: [f_x, f_y, n_z] about the crank pivot; ``torque`` or None.
    """

    wrench: np.ndarray
    torque: np.ndarray = None
    names: tuple = ()
    residual: float = 0.0   # worst loop-closure residual of the kinematic solution
    cond: float = 0.0       # worst Jacobian condition number

    def predict(self, theta):
        """Return the modelled (wrench (p, 3), torque (p,) or None) of a parameter vector."""
        w = self.wrench @ theta
        return w, None if self.torque is None else self.torque @ theta


def cross_z(a, b):
    """Return the z component of a x b for complex-coded planar vectors."""
    return (np.conjugate(a) * b).imag


def regressor(scene, psi_rad, speed_rad_s, accel_rad_s2, torque=False, rig=None):
    """Return the :class:`Regressor` of a planar scene at per-sample crank states."""
    check_identifiable(scene)
    rig = analysis.Rig(scene) if rig is None else rig
    # the kinematics is periodic in the crank angle: solve at the wrapped angle (the solver
    # loses the branch at large unwrapped angles on some scenes)
    psi = np.mod(np.asarray(psi_rad, dtype=float), 2.0 * math.pi)
    state = rig.linkage.solve(psi, np.asarray(speed_rad_s, dtype=float),
                              np.asarray(accel_rad_s2, dtype=float))
    n = len(scene.links)
    gravity = complex(*scene.gravity_m_s2)
    need = ('shaking_wrench', 'driving_torque') if torque else ('shaking_wrench',)
    wrench = np.empty((psi.size, 3, 4 * n))
    tau = np.empty((psi.size, 4 * n)) if torque else None
    for k in range(4 * n):
        unit = np.zeros(4 * n)
        unit[k] = 1.0
        w = dynamics.inverse_dynamics(rig.linkage, state, dynamics.inertia_from_vector(unit),
                                      gravity, need)
        wrench[:, 0, k] = w.shaking_force.real
        wrench[:, 1, k] = w.shaking_force.imag
        wrench[:, 2, k] = w.shaking_moment
        if torque:
            tau[:, k] = w.driving_torque
    if gravity:
        # the links' weight on the frame: m_i g at c_i; about the pivot
        # (c_i - O) x m_i g = (m_i (o_i - O) + R_i h_i) x g
        arm = state.pose.origin[1:] - rig.linkage.pivot          # (n, p)
        rot = state.pose.rot[1:]
        for i in range(n):
            k = 4 * i
            wrench[:, 0, k] += gravity.real
            wrench[:, 1, k] += gravity.imag
            wrench[:, 2, k] += cross_z(arm[i], gravity)
            wrench[:, 2, k + 1] += cross_z(rot[i], gravity)
            wrench[:, 2, k + 2] += cross_z(1j * rot[i], gravity)
    return Regressor(wrench, tau, parameter_names(scene), float(np.max(state.residual)),
                     float(np.max(state.cond)))
