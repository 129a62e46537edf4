"""The identification: checked data in, calibrated inertial parameters and their report out."""

from dataclasses import dataclass, field, replace
import math

from mech_balance import schema
from mech_balance.analysis.identify import checks
from mech_balance.analysis.identify.alignment import check_pose_and_time
from mech_balance.analysis.identify.confidence import predicted_rms, std_directions
from mech_balance.analysis.identify.consistency import Consistency, consistent
from mech_balance.analysis.identify.encoder import (
    CrankMotion, MAX_WINDOW_TURNS, segment_motions)
from mech_balance.analysis.identify.least_squares import (
    base_parameters, measurements, RANK_RTOL, reduce_samples, weighted_fit)
from mech_balance.analysis.identify.model import (
    CHANNEL_UNITS, CHANNELS, check_identifiable, IdentifyError, parameter_scales,
    TORQUE_CHANNEL)
from mech_balance.core.planar import dynamics
from mech_balance.schema.scene import INERTIA_ROUNDOFF
import numpy as np

MIN_TURNS = 1.0
"""A recording must turn the crank at least this many revolutions in its usable span."""
CONFOUND_RTOL = 1e-9
"""A bias channel this insensitive (relative) to the unseen directions is identifiable."""


@dataclass
class Identification:
    """Result of :func:`identify` (SI throughout)."""

    scene: object
    names: tuple
    theta_scene: np.ndarray
    theta: np.ndarray               # calibrated parameters
    covariance: np.ndarray          # (4 n, 4 n) of theta
    rank: int
    singular_values: np.ndarray     # scaled, weighted, bias-free regressor
    condition_number: float         # of the identifiable part
    combinations: list
    channels: tuple
    bias: np.ndarray                # per channel
    bias_std_error: np.ndarray
    bias_confounding: np.ndarray    # (channels, 4 n): b estimates b + G (theta - theta_scene)
    bias_identifiable: np.ndarray   # (channels,) bool
    noise_std: np.ndarray           # per channel, residual standard deviation after
    rms_before: np.ndarray          # per channel: measured - scene model (bias fitted)
    rms_after: np.ndarray           # per channel: measured - calibrated model
    samples: int
    motion: CrankMotion
    kinematic_residual: float
    kinematic_cond: float
    calibrated_links: list          # dicts per link
    problems: list                  # why the calibrated scene is not physical, if it is not
    consistency: Consistency = None
    theta_ls: np.ndarray = None     # the unconstrained least squares (minimum norm)
    prediction: object = None       # PredictedRms of the calibrated scene
    source: str = ''
    segments: list = None           # per encoder stretch: EncoderSegment (see identify)
    findings: list = field(default_factory=list)   # checks.Finding
    noise_floor: np.ndarray = None  # per channel: the recording's sample-to-sample noise

    @property
    def refusals(self):
        """Return the findings that refuse the calibration."""
        return checks.refusals(self.findings)

    def summary(self):
        """Return the one-line summary: rank, residual, consistency and the prediction."""
        rms = ', '.join(f'{c} {b:.4g} -> {a:.4g} {CHANNEL_UNITS[c]}'
                        for c, b, a in zip(self.channels, self.rms_before, self.rms_after))
        out = (f'identified scene {self.scene.name!r} from {self.samples} measurements: rank '
               f'{self.rank} of {len(self.names)}; residual RMS before -> after: {rms}')
        if self.prediction is not None:
            out += '; ' + self.prediction.describe()
        return out

    def identification_block(self, source=None):
        """Return the calibrated scene's ``identification`` section (the schema's mapping)."""
        pred = self.prediction.to_dict() if self.prediction is not None else {}
        return {'source': self.source if source is None else source,
                'parameters': list(self.names), 'theta': [float(v) for v in self.theta],
                'std_directions': std_directions(self.covariance, self.rank).tolist(),
                'predicted_rms': pred}

    @property
    def realizable(self):
        """Return True if every calibrated link has a positive mass and inertia."""
        return not self.problems

    def bias_target(self, bias_true, theta_true):
        """Return what :attr:`bias` estimates for a true bias and parameter vector."""
        return np.asarray(bias_true, dtype=float) + self.bias_confounding @ (
            np.asarray(theta_true, dtype=float) - self.theta)

    def calibrated_scene(self, source=None):
        """
        Return the scene with the calibrated link inertias and its ``identification``.

        Raises :class:`IdentifyError` when refused or naming the links no body can have.
        """
        if self.refusals:
            raise IdentifyError('refused, no calibrated scene: '
                                + ' | '.join(f.describe() for f in self.refusals))
        if self.problems:
            raise IdentifyError('calibrated parameters are physically unrealizable: '
                                + '; '.join(self.problems)
                                + '; expected a positive mass and centroidal inertia per link '
                                  '(record a longer or richer motion, or check the sensor)')
        links = []
        for lk, c in zip(self.scene.links, self.calibrated_links):
            links.append(replace(lk, mass_kg=c['mass_kg'], com_m=tuple(c['com_m']),
                                 inertia_com_kg_m2=c['inertia_com_kg_m2']))
        out = self.scene.with_links(links, name=f'{self.scene.name}_calibrated')
        return replace(out, identification=schema.identification_from_dict(
            schema.plain(self.identification_block(source)), [lk.name for lk in links]))

    def to_dict(self):
        """Return the report as a plain, JSON- and YAML-able dict."""
        unit = [CHANNEL_UNITS[c] for c in self.channels]
        return {
            'scene': self.scene.name, 'samples': int(self.samples),
            'parameters': list(self.names), 'rank': int(self.rank),
            'parameter_count': len(self.names),
            'condition_number': self.condition_number,
            'singular_values': [float(s) for s in self.singular_values],
            'rank_rtol': RANK_RTOL,
            'combinations': [c.to_dict() for c in self.combinations],
            'bias': {c: {'estimate': float(b), 'std_error': float(s), 'unit': u,
                         'identifiable': bool(ok)}
                     for c, b, s, u, ok in zip(self.channels, self.bias, self.bias_std_error,
                                               unit, self.bias_identifiable)},
            'residual_rms': {c: {'before': float(b), 'after': float(a), 'unit': u}
                             for c, b, a, u in zip(self.channels, self.rms_before,
                                                   self.rms_after, unit)},
            'theta_scene': [float(v) for v in self.theta_scene],
            'theta': [float(v) for v in self.theta],
            'theta_std_error': [float(v) for v in np.sqrt(np.maximum(
                np.diag(self.covariance), 0.0))],
            'calibrated_links': self.calibrated_links, 'realizable': self.realizable,
            'problems': list(self.problems), 'crank_motion': self.motion.to_dict(),
            'encoder_segments': [g.to_dict() for g in self.segments or ()],
            'consistency': None if self.consistency is None else self.consistency.to_dict(),
            'summary': self.summary(),
            'predicted_rms': None if self.prediction is None else self.prediction.to_dict(),
            'kinematic_residual': self.kinematic_residual,
            'kinematic_condition': self.kinematic_cond,
            'findings': [f.to_dict() for f in self.findings],
            'refused': bool(self.refusals),
            'noise_floor': None if self.noise_floor is None else
            {c: float(v) for c, v in zip(self.channels, self.noise_floor)}}


def calibrated_links(scene, theta):
    """Return (per-link dicts of mass, centre, inertias; problems) of a parameter vector."""
    links, problems = [], []
    for lk, (m, hx, hy, i_o) in zip(scene.links, np.asarray(theta).reshape(-1, 4)):
        entry = {'name': lk.name, 'mass_kg': float(m), 'inertia_origin_kg_m2': float(i_o)}
        if not m > 0.0:
            problems.append(f'links.{lk.name}.mass_kg = {m:.6g}, expected > 0')
            entry.update(com_m=[math.nan, math.nan], inertia_com_kg_m2=math.nan)
        else:
            i_c = i_o - (hx * hx + hy * hy) / m
            if i_c < -INERTIA_ROUNDOFF * abs(i_o):
                problems.append(f'links.{lk.name}.inertia_com_kg_m2 = {i_c:.6g} (from I_O = '
                                f'{i_o:.6g} and m c = ({hx:.6g}, {hy:.6g})), expected >= 0')
            else:
                i_c = max(i_c, 0.0)   # parallel-axis round-off
            entry.update(com_m=[float(hx / m), float(hy / m)], inertia_com_kg_m2=float(i_c))
        links.append(entry)
    return links, problems


def identify(scene, t_encoder, position_rad, t_wrench, wrench, effort=None, window=None,
             quantization_rad=None, counts_per_turn=None, check=True, encoder_unit='auto',
             max_residual_ratio=checks.FIT_RATIO_MAX):
    """
    Return the :class:`Identification` of a planar rig from encoder and wrench samples.

    ``t_encoder``, ``position_rad`` (s, rad); ``t_wrench``, ``wrench`` ``(samples, 3)``:
    [f_x, f_y, n_z] about the crank pivot (N, N*m); ``effort`` (N*m) or None.  ``encoder_unit``
    ``auto``, ``rad`` or ``deg``; a refused finding blocks the calibrated scene.
    """
    check_identifiable(scene)
    findings = []
    if check:
        t_encoder, position_rad, effort, findings = checks.check_data(
            t_encoder, position_rad, t_wrench, wrench, effort, encoder_unit)
    motion, stretches = segment_motions(t_encoder, position_rad, window, quantization_rad,
                                        counts_per_turn)
    theta0 = dynamics.parameter_vector(dynamics.Inertia.from_links(scene.links))
    scale = parameter_scales(scene)
    floor = None
    if check and checks.checkable(t_wrench, wrench) and np.ndim(wrench) == 2 and \
            np.shape(wrench)[1] == 3:
        floor = checks.noise_floor(wrench)
        if effort is not None:
            floor = np.append(floor, checks.noise_floor(effort))
        t_wrench, found = check_pose_and_time(scene, motion, t_wrench, wrench, floor,
                                              theta0, scale)
        findings += found
    if check:
        found = checks.encoder_smoothing(motion, MAX_WINDOW_TURNS)
        findings += [found] if found else []
    try:
        return _fit(scene, motion, stretches, t_encoder, t_wrench, wrench, effort, theta0,
                    scale, floor, findings, max_residual_ratio)
    except IdentifyError as exc:
        refused = checks.refusals(findings)
        if not refused:
            raise
        raise IdentifyError(' | '.join(f.describe() for f in refused)
                            + f' (and then: {exc})') from None


def _samples(stretches, t_encoder, t_wrench, wrench, effort):
    """Return the wrench samples of the used stretches with their crank states, and turns."""
    parts, turns, span = [], 0.0, 0.0
    for fitted, segment in stretches:
        if fitted is None:
            continue
        t_k, meas_k = measurements(wrench, effort, t_wrench, t_encoder, fitted)
        segment.wrench_samples = int(t_k.size)
        if t_k.size:
            parts.append((t_k, meas_k) + tuple(fitted.at(t_k)))
            turns += abs(parts[-1][2][-1] - parts[-1][2][0]) / (2.0 * math.pi)
            span += t_k[-1] - t_k[0]
    return parts, turns, span


def _fit(scene, motion, stretches, t_encoder, t_wrench, wrench, effort, theta0, scale, floor,
         findings, max_residual_ratio):
    """Return the :class:`Identification` of :func:`identify` once the data is checked."""
    parts, turns, span = _samples(stretches, t_encoder, t_wrench, wrench, effort)
    channels = CHANNELS + ((TORQUE_CHANNEL,) if effort is not None else ())
    nc = len(channels)
    if sum(part[0].size for part in parts) < 2:
        raise IdentifyError(f'wrench: {sum(part[0].size for part in parts)} samples inside the '
                            f'encoder span {motion.t_s[0]:.3f}..{motion.t_s[-1]:.3f} s, '
                            'expected the sensor and the encoder to record the same time')
    _, meas, psi, speed, accel = (np.concatenate([part[i] for part in parts])
                                  for i in range(5))
    if turns < MIN_TURNS:
        raise IdentifyError(f'recording: the crank turns {turns:.3g} revolutions in the usable '
                            f'span of {span:.3g} s, expected at least {MIN_TURNS:g}'
                            ' (a longer recording)')
    reduction = reduce_samples(scene, psi, speed, accel, meas, effort is not None, theta0, scale)
    p, nparam = reduction.samples, theta0.size
    if p * nc <= nparam + nc:
        raise IdentifyError(f'recording: {p} samples, expected more than {nparam + nc} '
                            'measurements for the parameters and the bias')
    fit = weighted_fit(reduction, nparam, nc)
    rank, sv, v1, sigma = fit.rank, fit.singular_values, fit.row_space, fit.sigma
    cov_u = fit.s2 * (v1 / sv[:rank] ** 2) @ v1.T
    theta_ls = theta0 + scale * fit.du
    cov = cov_u * np.outer(scale, scale)
    se_u = np.sqrt(fit.s2) / sv[:rank]
    u_cal, consistency = consistent(scene, theta0, scale, v1, sv[:rank], fit.du,
                                    float(np.sum(fit.res_sq / sigma ** 2)), se_u)
    theta = theta0 + scale * u_cal
    res_sq = np.array([float(np.sum((f @ np.append(-u_cal, 1.0)) ** 2))
                       for f in reduction.factors])
    bias = reduction.r0_mean - reduction.ys_mean @ u_cal
    # Cov(b): sigma_c^2 / p from the mean, plus the slope's through the mean regressor row
    cov_b = fit.s2 * np.diag(sigma ** 2 / p) + reduction.ys_mean @ cov_u @ reduction.ys_mean.T
    unseen = fit.vt[rank:].T
    confound_u = reduction.ys_mean @ unseen @ unseen.T     # (c, n) per unit of u
    identifiable_b = np.linalg.norm(confound_u, axis=1) <= CONFOUND_RTOL * reduction.size
    confound = np.where(identifiable_b[:, None], 0.0, confound_u / scale)
    rms_after = np.sqrt(res_sq / p)
    combos = base_parameters(fit.vt[:rank], scale, reduction.names, theta_ls, theta0, cov, theta)
    links, problems = calibrated_links(scene, theta)
    if floor is not None:
        findings += checks.judge_fit(channels, rms_after, floor, motion,
                                     [CHANNEL_UNITS[c] for c in channels], max_residual_ratio)
    return Identification(
        scene=scene, names=reduction.names, theta_scene=theta0, theta=theta, covariance=cov,
        rank=rank, singular_values=sv,
        condition_number=float(sv[0] / sv[rank - 1]), combinations=combos,
        channels=channels, bias=bias, bias_std_error=np.sqrt(np.diag(cov_b)),
        bias_confounding=confound, bias_identifiable=identifiable_b, noise_std=sigma,
        rms_before=reduction.rms_before, rms_after=rms_after, samples=p, motion=motion,
        kinematic_residual=reduction.residual, kinematic_cond=reduction.cond,
        calibrated_links=links, problems=problems, consistency=consistency, theta_ls=theta_ls,
        prediction=None if problems else predicted_rms(scene, theta, cov),
        segments=[segment for _, segment in stretches], findings=findings,
        noise_floor=floor)
