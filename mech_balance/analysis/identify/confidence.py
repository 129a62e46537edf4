"""What the calibration's uncertainty means for the RMS shaking force and moment."""

from dataclasses import dataclass
import math

from mech_balance.analysis.linear_maps import linear_maps
from mech_balance.core.planar import dynamics
from mech_balance.core.planar.rig import objective_units
import numpy as np


@dataclass
class PredictedRms:
    """RMS shaking force (N) and moment (N*m) of a parameter vector, with standard errors."""

    force_N: float
    force_std_error_N: float
    moment_Nm: float
    moment_std_error_Nm: float
    speed_rad_s: float
    samples: int

    def describe(self):
        """Return the prediction in words."""
        return (f'predicted RMS shaking force {self.force_N:.6g} +- '
                f'{self.force_std_error_N:.2g} N, moment {self.moment_Nm:.6g} +- '
                f'{self.moment_std_error_Nm:.2g} N*m (calibrated scene at '
                f'{self.speed_rad_s:.6g} rad/s, {self.samples} crank angles; standard errors '
                "from the combinations' covariance)")

    def to_dict(self):
        """Return the prediction as the scene's ``identification.predicted_rms`` mapping."""
        return {'shaking_force_N': {'value': self.force_N,
                                    'std_error': self.force_std_error_N},
                'shaking_moment_Nm': {'value': self.moment_Nm,
                                      'std_error': self.moment_std_error_Nm}}


def rms_maps(scene):
    """Return (force map, moment map) in SI: RMS = ||map @ theta|| (theta SI)."""
    units = objective_units(scene)
    maps = linear_maps(scene, units=units)
    m, ln, om = units.mass_kg, units.length_m, units.omega_rad_s
    scale = np.tile([m, m * ln, m * ln, m * ln * ln], len(scene.links))
    force_unit, moment_unit = m * ln * om ** 2, m * ln * ln * om ** 2
    return maps.force * force_unit / scale, maps.moment * moment_unit / scale


def predicted_rms(scene, theta, covariance):
    """Return the :class:`PredictedRms` of parameters ``theta`` (SI) on ``scene``'s geometry."""
    theta = np.asarray(theta, dtype=float)
    out = []
    for r in rms_maps(scene):
        v = r @ theta
        value = float(np.linalg.norm(v))
        g = r.T @ v / value if value > 0.0 else np.zeros_like(theta)
        out += [value, float(math.sqrt(max(g @ covariance @ g, 0.0)))]
    return PredictedRms(*out, abs(scene.crank_speed_rad_s), int(scene.samples))


def std_directions(covariance, rank):
    """Return the ``(rank, n)`` factor D with D^T D = Cov (symmetric eigen-decomposition)."""
    w, v = np.linalg.eigh(0.5 * (covariance + covariance.T))
    keep = np.argsort(w)[::-1][:rank]
    return (v[:, keep] * np.sqrt(np.maximum(w[keep], 0.0))).T


def balance_confidence(scene, balanced_scene):
    """Return how a balanced design's RMS shaking force and moment vary within +-1 SE, or None."""
    block = getattr(scene, 'identification', None)
    if block is None:
        return None
    theta_b = dynamics.parameter_vector(dynamics.Inertia.from_links(balanced_scene.links))
    d = np.array(block['std_directions'], dtype=float).reshape(-1, theta_b.size)
    out = {}
    for name, r in zip(('shaking_force_N', 'shaking_moment_Nm'), rms_maps(balanced_scene)):
        value = float(np.linalg.norm(r @ theta_b))
        spread = float(np.linalg.norm(r @ d.T, 2)) if d.size else 0.0
        out[name] = {'value': value, 'low': max(value - spread, 0.0), 'high': value + spread}
    return out


def format_balance_confidence(conf):
    """Return the line ``mech-balance balance`` prints for :func:`balance_confidence`."""
    f, n = conf['shaking_force_N'], conf['shaking_moment_Nm']
    return (f"identification confidence (+-1 SE of the calibrated inertias): the optimum's RMS "
            f"shaking force {f['value']:.6g} N lies within [{f['low']:.6g}, {f['high']:.6g}] "
            f"N, moment {n['value']:.6g} N*m within [{n['low']:.6g}, {n['high']:.6g}] N*m")
