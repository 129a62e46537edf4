"""Screen-space tests of the label placement, vectorized over samples ``p`` and places ``c``."""

import numpy as np

LABEL_CHUNK = 4
"""Candidate places of a label tested at once by the costly tests (:func:`first_passing`)."""


def segments_hit_boxes(segments, boxes):
    """
    Return ``(p, c)``: whether any segment ``(p, m, 2, 2)`` crosses box ``(p, c, 4)``.

    Liang-Barsky clipping; ``fmin``/``fmax`` skip the 0 * inf of an axis-parallel segment.
    """
    if segments.shape[1] == 0:
        return np.zeros(boxes.shape[:2], dtype=bool)
    a = segments[:, None, :, 0, :]                                  # (p, 1, m, 2)
    with np.errstate(divide='ignore', invalid='ignore'):
        inv = 1.0 / (segments[:, None, :, 1, :] - a)
        ta = (boxes[:, :, None, 0:2] - a) * inv                     # (p, c, m, 2)
        tb = (boxes[:, :, None, 2:4] - a) * inv
    t_in = np.fmin(ta, tb)
    t_out = np.fmax(ta, tb)
    t0 = np.maximum(np.fmax(t_in[..., 0], t_in[..., 1]), 0.0)
    t1 = np.minimum(np.fmin(t_out[..., 0], t_out[..., 1]), 1.0)
    return (t0 <= t1).any(axis=-1)


def segment_distances(points, segments):
    """Return ``(p, c, m)``: the distance of points ``(p, c, 2)`` to segments ``(p, m, 2, 2)``."""
    a = segments[:, None, :, 0, :]
    ab = segments[:, None, :, 1, :] - a
    q = points[:, :, None, :] - a
    t = np.clip(np.einsum('...k,...k->...', q, ab)
                / np.maximum(np.einsum('...k,...k->...', ab, ab), 1e-300), 0.0, 1.0)
    r = q - t[..., None] * ab
    return np.sqrt(np.einsum('...k,...k->...', r, r))


def first_passing(ok, test, chunk=LABEL_CHUNK):
    """
    Return ``ok (p, c)`` narrowed by ``test``, exact up to each row's first passing column.

    ``test(rows, cols)`` returns the costly mask; ``argmax`` of the result equals the full test's.
    """
    out = np.zeros_like(ok)
    pending = np.flatnonzero(ok.any(axis=1))
    for start in range(0, ok.shape[1], chunk):
        if not len(pending):
            break
        cols = slice(start, start + chunk)
        sub = ok[pending, cols]
        need = sub.any(axis=1)
        rows = pending[need]
        if len(rows):
            passed = sub[need] & test(rows, cols)
            out[rows, cols] = passed
            pending = np.concatenate([pending[~need], rows[~passed.any(axis=1)]])
    return out
