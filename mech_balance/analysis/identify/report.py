"""The identification as text: the report ``mech-balance identify`` prints, the YAML."""

import math

from mech_balance import schema
from mech_balance.analysis.identify.encoder import GAP_PERIODS
from mech_balance.analysis.identify.least_squares import RANK_RTOL
from mech_balance.analysis.identify.model import CHANNEL_UNITS


def calibrated_yaml(result, source=''):
    """Return the calibrated scene as YAML text (:func:`mech_balance.schema.to_yaml`)."""
    sc = result.calibrated_scene(source)
    head = [f'# written by mech-balance identify from scene {result.scene.name}'
            + (f' and {source}' if source else ''),
            f'# rank {result.rank} of {len(result.names)} parameters, condition number '
            f'{result.condition_number:.4g}; residual RMS before -> after:']
    for c, b, a in zip(result.channels, result.rms_before, result.rms_after):
        head.append(f'#   {c}: {b:.6g} -> {a:.6g} {CHANNEL_UNITS[c]}')
    return '\n'.join(head) + '\n' + schema.to_yaml(sc)


def _segment_lines(segments):
    """Return the report's lines on the encoder's stretches (none for one stretch)."""
    if not segments or len(segments) == 1:
        return []
    used = [g for g in segments if g.used]
    lines = [f'  encoder gaps (> {GAP_PERIODS:g} periods): {len(segments)} stretches, '
             f'{len(used)} used ({sum(g.wrench_samples for g in used)} wrench samples); '
             'the wrench samples inside a gap are not used']
    lines += [f'    skipped {g.start_s:.3f}..{g.end_s:.3f} s: {g.reason}'
              for g in segments if not g.used]
    return lines


def _motion_lines(result):
    """Return the report's lines on the crank motion and the kinematics."""
    m = result.motion
    std = m.predicted_std
    return [
        f'crank motion: Savitzky-Golay order {m.order} over {m.window} samples '
        f'({m.window_s * 1e3:.1f} ms) at {1.0 / m.period_s:.6g} Hz'
        + (' (resampled to a uniform grid)' if m.resampled else ''),
        f'  {m.quantization.describe()}; mean speed {m.mean_speed_rad_s:.6g} rad/s',
        f'  window: {m.window_reason}',
        *_segment_lines(result.segments),
        f"  predicted noise: angle {std['angle_rad']:.2e} rad, speed "
        f"{std['speed_rad_s']:.2e} rad/s, acceleration {std['accel_rad_s2']:.2e} rad/s^2; "
        f"gain error at 1x/2x rotation: accel {m.gain_error['accel_1x']:+.1e}/"
        f"{m.gain_error['accel_2x']:+.1e}",
        f'kinematics: worst loop-closure residual {result.kinematic_residual:.2e}, worst '
        f'Jacobian condition {result.kinematic_cond:.4g}']


def format_report(result):
    """Return the identification report (an :class:`Identification`) as text."""
    lines = [
        f'scene: {result.scene.name} ({result.scene.source}); {result.samples} wrench samples, '
        f'channels {", ".join(result.channels)}',
        *_motion_lines(result),
        f'rank {result.rank} of {len(result.names)} inertial parameters (singular values > '
        f'{RANK_RTOL:g} x largest), condition number {result.condition_number:.4g}',
        '', 'identifiable combinations (base parameters; estimate +- standard error, scene):']
    for c in result.combinations:
        lines.append(f'  {c.text}')
        lines.append(f'      = {c.estimate:.6g} +- {c.std_error:.2g} {c.unit} '
                     f'(scene {c.scene_value:.6g})')
    lines += ['', 'sensor bias:']
    for i, ch in enumerate(result.channels):
        note = '' if result.bias_identifiable[i] else \
            '  (confounded with the static weight: given the non-identifiable parameters at ' \
            "the scene's values)"
        lines.append(f'  {ch:<10} {result.bias[i]:+.6g} +- {result.bias_std_error[i]:.2g} '
                     f'{CHANNEL_UNITS[ch]}{note}')
    lines += ['', f"{'residual RMS':<14}{'unit':>6}{'before':>14}{'after':>14}{'ratio':>9}",
              '-' * 57]
    for ch, b, a in zip(result.channels, result.rms_before, result.rms_after):
        ratio = a / b if b > 0 else math.nan
        lines.append(f'{ch:<14}{CHANNEL_UNITS[ch]:>6}{b:>14.6g}{a:>14.6g}{ratio:>9.3f}')
    lines.append('(before: the scene with a fitted bias; after: the calibrated scene)')
    lines += ['', 'calibrated links ('
              + (result.consistency.describe() if result.consistency else '') + '):']
    for c in result.calibrated_links:
        lines.append(f"  {c['name']:<10} mass {c['mass_kg']:.6g} kg, centre ({c['com_m'][0]:.6g},"
                     f" {c['com_m'][1]:.6g}) m, I_C {c['inertia_com_kg_m2']:.6g} kg*m^2, I_O "
                     f"{c['inertia_origin_kg_m2']:.6g} kg*m^2")
    if result.problems:
        lines.append('NOT physically realizable: ' + '; '.join(result.problems))
    if result.prediction is not None:
        lines += ['', result.prediction.describe()]
    if result.noise_floor is not None:
        lines += ['', 'noise floor (sample-to-sample) against the residual after: ' + ', '.join(
            f'{c} {f:.3g} / {a:.3g} {CHANNEL_UNITS[c]}'
            for c, f, a in zip(result.channels, result.noise_floor, result.rms_after))]
    if result.findings:
        lines += ['', 'findings (the recording and the fit checked):']
        lines += [f'  {f.describe()}' for f in result.findings]
    return '\n'.join(lines)
