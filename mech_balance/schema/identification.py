"""
The ``identification:`` section of a calibrated scene: what the data said, and how sure.

Optional; the fields: docs/scenes.md#the-identification-section.  ``std_directions`` D
factors the parameters' covariance, Cov(theta) = D^T D.
"""

import math

from mech_balance.schema import fields

PREDICTED = ('shaking_force_N', 'shaking_moment_Nm')
"""The predicted RMS values the section records."""


class IdentificationError(fields.SceneError):
    """An ``identification`` field is missing, has the wrong shape or a bad value."""


def _floats(value, where, length=None):
    if not isinstance(value, list) or (length is not None and len(value) != length):
        raise IdentificationError(f'{where}: got {value!r:.80}, expected a list of '
                                  + (f'{length} ' if length is not None else '') + 'numbers')
    out = []
    for i, v in enumerate(value):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                or abs(v) > fields.MAX_ABS_VALUE:
            raise IdentificationError(f'{where}[{i}]: got {v!r}, expected a finite number of '
                                      f'magnitude at most {fields.MAX_ABS_VALUE:g}')
        out.append(float(v))
    return out


def identification_from_dict(value, links):
    """Return the validated ``identification`` mapping; raises :class:`IdentificationError`."""
    if not isinstance(value, dict):
        raise IdentificationError(f'identification: got {type(value).__name__}, expected a '
                                  'mapping')
    fields.known_keys(value, {'source', 'parameters', 'theta', 'std_directions',
                              'predicted_rms'}, 'identification', error=IdentificationError)
    n = 4 * len(links)
    names = value.get('parameters')
    expected = [f'{p}[{lk}]' for lk in links for p in ('m', 'hx', 'hy', 'I_O')]
    if names != expected:
        raise IdentificationError(f'identification.parameters: got {names!r:.80}, expected '
                                  f'{expected!r:.80} (4 per moving link, in order)')
    theta = _floats(value.get('theta'), 'identification.theta', n)
    rows = value.get('std_directions')
    if not isinstance(rows, list) or len(rows) > n:
        raise IdentificationError(f'identification.std_directions: got {rows!r:.80}, expected '
                                  f'a list of at most {n} rows')
    directions = [_floats(r, f'identification.std_directions[{i}]', n)
                  for i, r in enumerate(rows)]
    source = value.get('source', '')
    if not isinstance(source, str):
        raise IdentificationError(f'identification.source: got {source!r}, expected text')
    predicted = value.get('predicted_rms', {})
    if not isinstance(predicted, dict) or set(predicted) - set(PREDICTED):
        raise IdentificationError(f'identification.predicted_rms: got {predicted!r:.80}, '
                                  f'expected a mapping of {", ".join(PREDICTED)}')
    pred = {}
    for k, v in predicted.items():
        if not isinstance(v, dict) or set(v) != {'value', 'std_error'}:
            raise IdentificationError(f'identification.predicted_rms.{k}: got {v!r:.80}, '
                                      'expected {value: number, std_error: number}')
        got = _floats([v['value'], v['std_error']], f'identification.predicted_rms.{k}')
        pred[k] = {'value': got[0], 'std_error': got[1]}
    return {'source': source, 'parameters': list(expected), 'theta': theta,
            'std_directions': directions, 'predicted_rms': pred}


def identification_to_dict(block):
    """Return the ``identification`` mapping that :func:`identification_from_dict` reads."""
    return {'source': block['source'], 'parameters': list(block['parameters']),
            'theta': [float(v) for v in block['theta']],
            'std_directions': [[float(v) for v in r] for r in block['std_directions']],
            'predicted_rms': {k: {'value': float(v['value']),
                                  'std_error': float(v['std_error'])}
                              for k, v in block['predicted_rms'].items()}}
