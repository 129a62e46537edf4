"""
A synthetic real rig for the identification tests: made here, not by the code under test.

A built-in scene's link inertias are perturbed (seeded, up to 20%: masses, mass centres,
centroidal inertias); the TRUE scene is driven with a rippled crank speed
omega(t) = w0 (1 + ripple sin(2 pi f_r t)), f_r = 0.7 turns per second of the mean speed
(not locked to the crank angle).  The wrench the rig exerts on its frame is the core's
forward evaluation (``analysis.Rig(true).evaluate(psi, speed=..., accel=...)``) plus the
links' weight when the scene has gravity in its plane, computed here from the link poses;
the sensor adds white noise (1% of the peak shaking force and moment) and a constant bias;
the encoder quantizes the wrapped crank angle to 4096 counts per turn at 1 kHz.
"""

from dataclasses import dataclass, replace
import math

from mech_balance.analysis import cycle as analysis
from mech_balance.core.planar import dynamics
import numpy as np

COUNTS_PER_TURN = 4096
RATE_HZ = 1000.0
RIPPLE = 0.05
RIPPLE_TURNS = 0.7
NOISE_REL = 0.01
PERTURB_REL = 0.2


def perturbed(scene, seed, rel=PERTURB_REL, gravity=None):
    """Return ``scene`` with every link's mass, centre and centroidal inertia perturbed."""
    rng = np.random.default_rng(seed)
    links = []
    for lk in scene.links:
        c = np.array(lk.com_m)
        size = max(float(np.hypot(*c)), 1e-3)
        links.append(replace(
            lk, mass_kg=lk.mass_kg * (1.0 + rng.uniform(-rel, rel)),
            com_m=tuple(float(v) for v in c + rng.uniform(-rel, rel, 2) * size),
            inertia_com_kg_m2=lk.inertia_com_kg_m2 * (1.0 + rng.uniform(-rel, rel))))
    out = scene.with_links(links, name=f'{scene.name}_true')
    return out if gravity is None else replace(out, gravity_m_s2=tuple(gravity))


def theta_of(scene):
    """Return the (4 n,) inertial parameter vector of a scene."""
    return dynamics.parameter_vector(dynamics.Inertia.from_links(scene.links))


@dataclass
class RigData:
    """What the rig's encoder and sensor recorded, and the truth behind it."""

    t_ns: np.ndarray
    position_rad: np.ndarray     # quantized, wrapped to [0, 2 pi)
    wrench: np.ndarray           # (n, 3) measured f_x, f_y, n_z
    effort_Nm: np.ndarray        # measured motor torque or None
    psi: np.ndarray              # true crank state
    speed: np.ndarray
    accel: np.ndarray
    true_wrench: np.ndarray      # noise- and bias-free
    noise_std: np.ndarray        # per channel (f_x, f_y, n_z[, tau])
    bias: np.ndarray             # per channel
    theta_true: np.ndarray


def crank(t, w0, psi0=0.3):
    """Return the true crank angle, speed and acceleration at times ``t``."""
    wr = 2.0 * math.pi * RIPPLE_TURNS * abs(w0) / (2.0 * math.pi)
    speed = w0 * (1.0 + RIPPLE * np.sin(wr * t))
    accel = w0 * RIPPLE * wr * np.cos(wr * t)
    psi = psi0 + w0 * t + w0 * RIPPLE * (1.0 - np.cos(wr * t)) / wr
    return psi, speed, accel


def _add_weight(true, true_scene, rig, state):
    """Add the links' weight on the frame (at their mass centres, about the crank pivot)."""
    g = complex(*true_scene.gravity_m_s2)
    if g:
        for i, lk in enumerate(true_scene.links, 1):
            c = state.pose.origin[i] + state.pose.rot[i] * complex(*lk.com_m)
            weight = lk.mass_kg * g
            arm = c - rig.linkage.pivot
            true[:, 0] += weight.real
            true[:, 1] += weight.imag
            true[:, 2] += arm.real * weight.imag - arm.imag * weight.real


def record(true_scene, duration_s, w0, seed, effort=False, t0_ns=1_700_000_000_000_000_000):
    """Return the :class:`RigData` of ``duration_s`` seconds of the true rig at 1 kHz."""
    rng = np.random.default_rng(seed + 1000)
    n = int(round(duration_s * RATE_HZ))
    k = np.arange(n)
    t_ns = t0_ns + (k * (1e9 / RATE_HZ)).round().astype(np.int64)
    t = k / RATE_HZ
    psi, speed, accel = crank(t, w0)
    rig = analysis.Rig(true_scene)
    outputs = ('driving_torque',) if effort else ('shaking_wrench',)
    # the kinematics is periodic in psi; the solver is given the wrapped angle (it loses the
    # branch of slider_crank beyond ~40 unwrapped turns)
    state, w = rig.evaluate(np.mod(psi, 2.0 * math.pi), outputs=outputs, speed=speed,
                            accel=accel)
    true = np.column_stack([w.shaking_force.real, w.shaking_force.imag, w.shaking_moment])
    peak_f = np.max(np.abs(w.shaking_force))
    peak_n = np.max(np.abs(w.shaking_moment))
    _add_weight(true, true_scene, rig, state)
    std = np.array([NOISE_REL * peak_f, NOISE_REL * peak_f, NOISE_REL * peak_n])
    bias = np.array([0.3, -0.2, 0.25]) * std * 10.0
    wrench = true + bias + rng.normal(size=true.shape) * std
    tau = None
    if effort:
        peak_t = np.max(np.abs(w.driving_torque))
        std = np.append(std, NOISE_REL * peak_t)
        bias = np.append(bias, 0.05 * peak_t)
        tau = w.driving_torque + bias[3] + rng.normal(size=n) * std[3]
    q = 2.0 * math.pi / COUNTS_PER_TURN
    counts = np.mod(np.round(psi / q), COUNTS_PER_TURN)
    return RigData(t_ns, counts * q, wrench, tau, psi, speed, accel, true, std, bias,
                   theta_of(true_scene))


def encoder_positions(psi, counts, mode='round', dtype=np.float64, modulus=2.0 * math.pi,
                      offset_rad=0.0):
    """
    Return what an encoder of ``counts`` per turn publishes for true angles ``psi``.

    ``mode`` ``round`` (round of psi N / 2 pi) or ``floor`` (a half-count offset), the count
    times 2 pi / N, wrapped with a floating-point modulo at ``modulus``, cast to ``dtype``.
    """
    q = 2.0 * math.pi / counts
    c = np.round(psi * counts / (2.0 * math.pi)) if mode == 'round' else \
        np.floor(psi * counts / (2.0 * math.pi))
    return np.mod(c * q + offset_rad, modulus).astype(dtype)


def true_rms(scene):
    """Return the true RMS shaking force (N) and moment (N*m) by the core's cycle analysis."""
    rig = analysis.Rig(scene.with_outputs(('shaking_wrench',)))
    rows = {r.quantity: r.rms for r in analysis.summarize(analysis.run_cycle(rig), False)}
    return rows['shaking force |f_sh|'], rows['shaking moment n_sh']


def record_real(true_scene, duration_s, counts, seed, mode='round', dtype=np.float64,
                noise_rel=NOISE_REL, w0=None, t0_ns=1_700_000_000_123_456_789,
                rate_hz=RATE_HZ, jitter_s=0.0, direction=1.0, modulus=2.0 * math.pi):
    """
    Return ``(t_ns, positions, wrench (n, 3), psi)`` of a recording made as a real rig would.

    The encoder of :func:`encoder_positions`; the stamps at ``rate_hz`` from a real epoch
    ``t0_ns``, with uniform jitter of +- ``jitter_s``; the wrench the core's forward
    evaluation of the true scene (weight included when it has gravity in its plane), plus a
    bias and white noise of ``noise_rel`` of the peak force and moment.
    """
    rng = np.random.default_rng(seed)
    n = int(round(duration_s * rate_hz))
    t = np.arange(n) / rate_hz
    if jitter_s:
        t = t + rng.uniform(-jitter_s, jitter_s, n)
    w0 = direction * abs(true_scene.crank_speed_rad_s if w0 is None else w0)
    psi, speed, accel = crank(t, w0)
    rig = analysis.Rig(true_scene)
    state, w = rig.evaluate(np.mod(psi, 2.0 * math.pi), outputs=('shaking_wrench',),
                            speed=speed, accel=accel)
    true = np.column_stack([w.shaking_force.real, w.shaking_force.imag, w.shaking_moment])
    _add_weight(true, true_scene, rig, state)
    peak = np.array([np.max(np.abs(w.shaking_force))] * 2 + [np.max(np.abs(w.shaking_moment))])
    wrench = true + np.array([0.3, -0.2, 0.25]) * peak * 0.05 + \
        rng.normal(size=true.shape) * noise_rel * peak
    t_ns = t0_ns + np.round(t * 1e9).astype(np.int64)
    return t_ns, encoder_positions(psi, counts, mode, dtype, modulus), wrench, psi
