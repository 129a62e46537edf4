"""
Identification of a planar rig's inertial parameters from its encoder and force sensor.

Pure functions on numpy arrays (numpy, scipy, clarabel): the ``identify`` command feeds them
the arrays of a recording (:mod:`mech_balance.ros.bags`), the rig node its buffered
samples.  The method, its derivation and the figures behind the constants are in
docs/identification.md (*How identify computes*).  The modules, in the order the data
passes through them:

* :mod:`~mech_balance.analysis.identify.checks`: the recording checked (unit, interleaved
  sources, a stuck or noisy encoder, the fit against the noise), :class:`Finding`;
* :mod:`~mech_balance.analysis.identify.alignment`: the sensor's frame and clock against the
  scene's model;
* :mod:`~mech_balance.analysis.identify.quantization`,
  :mod:`~mech_balance.analysis.identify.smoothing`,
  :mod:`~mech_balance.analysis.identify.encoder`: the encoder's step, the Savitzky-Golay
  smoothing, the crank's angle, speed and acceleration per stretch between gaps;
* :mod:`~mech_balance.analysis.identify.model`: channels, parameters, the regressor;
* :mod:`~mech_balance.analysis.identify.least_squares`: the weighted least squares, rank,
  base parameters;
* :mod:`~mech_balance.analysis.identify.consistency`: the physically consistent calibration;
* :mod:`~mech_balance.analysis.identify.confidence`: the predicted RMS and its standard
  errors, a balanced design's range;
* :mod:`~mech_balance.analysis.identify.estimate`: :func:`identify` and its
  :class:`Identification`;
* :mod:`~mech_balance.analysis.identify.report`: the printed report and the calibrated YAML.
"""

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
    # the identification and its result
    'identify', 'Identification', 'IdentifyError', 'check_identifiable', 'Combination',
    'Consistency', 'calibrated_links', 'PredictedRms', 'predicted_rms', 'std_directions',
    # the printed forms
    'format_report', 'calibrated_yaml', 'balance_confidence', 'format_balance_confidence',
    # the measurement model
    'CHANNELS', 'CHANNEL_UNITS', 'PARAMETERS', 'parameter_names', 'parameter_scales',
    'regressor', 'Regressor',
    # the encoder
    'crank_motion', 'CrankMotion', 'encoder_segments', 'EncoderSegment',
    'estimate_quantization', 'Quantization', 'unwrap_encoder', 'GAP_PERIODS', 'MIN_WINDOW',
    'QUANT_FRACTION_MIN',
    # the fit's and the consistency's thresholds
    'RANK_RTOL', 'CONFIDENCE_SE', 'INERTIA_MARGIN_REL', 'LS_TIE_REL', 'MIN_MASS_REL',
    # the checks
    'Finding', 'noise_floor', 'interleaved', 'frame_check', 'FIT_RATIO_MAX',
    'FIT_RATIO_WARN', 'FRAME_ANGLE_MAX_DEG',
]
