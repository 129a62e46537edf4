"""
The one home of the project's conventions: units, the shaking wrench and the RMS.

Units
    SI everywhere inside: m, kg, s, rad, N, N*m, kg*m^2.  The papers' normalized quantities
    (by the original crank mass m_1, crank length a_1 and crank speed omega) are a view
    computed by :func:`normalize_force` and :func:`normalize_moment`, never stored.

Shaking wrench (seed 001 eq. 39)
    The wrench that the moving links exert on the frame, reduced to the crank pivot O and
    expressed in the frame's (world) axes, *minus* the static external loads (gravity) that
    the frame also carries:

        f_sh = -sum_i m_i * a_ci            = -dp/dt
        n_sh = -sum_i (I_ci*alpha_i + (c_i - O) x m_i*a_ci) = -dH_O/dt

    It includes the motor's reaction torque (the motor stator is fixed to the frame), so
    with no external loads it equals the sum of the bearing loads on the frame plus the
    motor reaction (seed 001 eq. 41/47).  Planar rigs: force (x, y), moment z.  Spatial
    rigs: force and moment 3-vectors.

RMS over a cycle
    The true root mean square over p equally spaced crank angles of one revolution,
    ``sqrt((1/p) * sum f_k^2)`` where f_k is the magnitude (Euclidean norm) of the vector
    quantity at angle k.  Seed 001 eq. 42 prints ``(1/p) sqrt(sum f^2)``; its tables were
    computed with the true RMS (checked against Table 4), so that is the one used here.
"""

import numpy as np

DEFAULT_SAMPLES = 360
"""Crank angles per revolution when a caller does not say (one per degree)."""


def cycle_angles(samples, start_rad=0.0):
    """
    Return ``samples`` equally spaced crank angles of one revolution, in rad.

    The end point is excluded, so that each angle carries the same weight in the RMS.
    """
    samples = int(samples)
    if samples < 1:
        raise ValueError(f'samples: got {samples}, expected an integer >= 1')
    return start_rad + 2.0 * np.pi * np.arange(samples) / samples


def rms(values, axis=0):
    """
    Return the RMS over a cycle (this module's docstring): sqrt(mean(|v|^2)).

    ``values`` is ``(p,)`` for a scalar series or ``(p, k)`` for a vector series, whose
    magnitude is taken over the last axis.  The mean runs over ``axis`` (the samples).
    """
    v = np.asarray(values, dtype=float)
    if v.ndim == 0:
        raise ValueError('values: got a scalar, expected a series over crank angles')
    sq = v * v if v.ndim == 1 else np.sum(v * v, axis=-1)
    return np.sqrt(np.mean(sq, axis=axis))


def normalize_force(force_N, mass_kg, length_m, omega_rad_s):
    """Return a force in units of m_1 * a_1 * omega^2 (seed 001, section 3.4)."""
    return np.asarray(force_N, dtype=float) / (mass_kg * length_m * omega_rad_s ** 2)


def normalize_moment(moment_Nm, mass_kg, length_m, omega_rad_s):
    """Return a moment or torque in units of m_1 * a_1^2 * omega^2 (seed 001, section 3.4)."""
    return np.asarray(moment_Nm, dtype=float) / (mass_kg * length_m ** 2 * omega_rad_s ** 2)
