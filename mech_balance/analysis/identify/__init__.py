"""Identifying a planar rig's inertial parameters from encoder and force sensor (numpy)."""

from mech_balance.analysis.identify.alignment import FRAME_ANGLE_MAX_DEG, frame_check
from mech_balance.analysis.identify.checks import (
    Finding, FIT_RATIO_MAX, FIT_RATIO_WARN, interleaved, noise_floor)
from mech_balance.analysis.identify.confidence import (
    balance_confidence, format_balance_confidence, predicted_rms, PredictedRms,
    std_directions)
from mech_balance.analysis.identify.consistency import (
    CONFIDENCE_SE, Consistency, INERTIA_MARGIN_REL, LS_TIE_REL, MIN_MASS_REL)
from mech_balance.analysis.identify.encoder import (
    crank_motion, CrankMotion, encoder_segments, EncoderSegment, GAP_PERIODS, MIN_WINDOW)
from mech_balance.analysis.identify.estimate import (
    calibrated_links, Identification, identify)
from mech_balance.analysis.identify.least_squares import Combination, RANK_RTOL
from mech_balance.analysis.identify.model import (
    CHANNEL_UNITS, CHANNELS, check_identifiable, IdentifyError, parameter_names,
    parameter_scales, PARAMETERS, Regressor, regressor)
from mech_balance.analysis.identify.quantization import (
    estimate_quantization, QUANT_FRACTION_MIN, Quantization, unwrap_encoder)
from mech_balance.analysis.identify.report import calibrated_yaml, format_report

__all__ = [
    'identify', 'Identification', 'IdentifyError', 'check_identifiable', 'Combination',
    'Consistency', 'calibrated_links', 'PredictedRms', 'predicted_rms', 'std_directions',
    'format_report', 'calibrated_yaml', 'balance_confidence', 'format_balance_confidence',
    'CHANNELS', 'CHANNEL_UNITS', 'PARAMETERS', 'parameter_names', 'parameter_scales',
    'regressor', 'Regressor',
    'crank_motion', 'CrankMotion', 'encoder_segments', 'EncoderSegment',
    'estimate_quantization', 'Quantization', 'unwrap_encoder', 'GAP_PERIODS', 'MIN_WINDOW',
    'QUANT_FRACTION_MIN',
    'RANK_RTOL', 'CONFIDENCE_SE', 'INERTIA_MARGIN_REL', 'LS_TIE_REL', 'MIN_MASS_REL',
    'Finding', 'noise_floor', 'interleaved', 'frame_check', 'FIT_RATIO_MAX',
    'FIT_RATIO_WARN', 'FRAME_ANGLE_MAX_DEG',
]
