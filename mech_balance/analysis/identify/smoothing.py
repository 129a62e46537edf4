"""Savitzky-Golay smoothing of the encoder angle: weights, their accuracy, the angle noise."""

import math

import numpy as np

SG_ORDER = 6
"""Order of the Savitzky-Golay polynomial fitted to the unwrapped encoder angle."""
FIT_NOISE_WINDOW = 31
"""Samples of the smooth fit whose residual measures the angle noise (order SG_ORDER)."""


def oaconvolve(*args, **kwargs):
    """Return :func:`scipy.signal.oaconvolve` (imported on first use: it costs 0.6 s)."""
    from scipy.signal import oaconvolve as convolve
    return convolve(*args, **kwargs)


def savgol_weights(window, order, period_s):
    """Return ``(3, window)`` Savitzky-Golay weights of value, slope, curvature at the centre."""
    half = (window - 1) // 2
    x = np.arange(-half, half + 1) / half
    vander = np.vander(x, order + 1, increasing=True)
    pinv = np.linalg.pinv(vander)                  # (order + 1, window)
    scale = half * period_s
    return np.stack([pinv[0], pinv[1] / scale, 2.0 * pinv[2] / scale ** 2])


def window_accuracy(window, order, period_s, angle_noise_rad, turn_hz):
    """
    Return (predicted std dict, gain error dict) of a Savitzky-Golay window.

    Std from white angle noise ``angle_noise_rad``; gain errors at 1x and 2x ``turn_hz``.
    """
    half = (window - 1) // 2
    k = np.arange(-half, half + 1)
    weights = savgol_weights(window, order, period_s)
    std = {'angle_rad': angle_noise_rad * float(np.linalg.norm(weights[0])),
           'speed_rad_s': angle_noise_rad * float(np.linalg.norm(weights[1])),
           'accel_rad_s2': angle_noise_rad * float(np.linalg.norm(weights[2]))}
    gain = {}
    for mult in (1, 2):
        omega = 2.0 * math.pi * turn_hz * mult
        phase = np.exp(1j * omega * k * period_s)
        for d, name in ((1, 'speed'), (2, 'accel')):
            g = abs(np.sum(weights[d] * phase)) / omega ** d if omega > 0.0 else 1.0
            gain[f'{name}_{mult}x'] = float(g - 1.0)
    return std, gain


def fit_noise(t_s, psi_rad, order=SG_ORDER):
    """Return the standard deviation of the angle noise about a smooth fit (rad)."""
    psi = np.asarray(psi_rad, dtype=float)
    window = min(FIT_NOISE_WINDOW, (psi.size - 1) | 1) | 1
    if window < order + 2:
        return 0.0
    period = float(np.median(np.diff(t_s)))
    value_weights = savgol_weights(window, order, period)[0]
    smooth = oaconvolve(psi - psi[0], value_weights[::-1], mode='valid') + psi[0]
    half = (window - 1) // 2
    res = psi[half:psi.size - half] - smooth
    h = float(value_weights[half])
    return float(np.sqrt(np.mean(res ** 2) / max(1.0 - h, 1e-12)))
