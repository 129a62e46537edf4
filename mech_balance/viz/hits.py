"""
Screen-space tests of the label placement: segments against boxes, points to segments.

Vectorized over the samples of a turn (``p``) and the candidate places of a label (``c``);
:func:`first_passing` runs a costly test only where it can still change a label's place.
"""

import numpy as np

LABEL_CHUNK = 2
"""Places of a sample that passed the cheap tests, given to the costly tests at once
(:func:`first_passing`; a larger round tests more places than it saves rounds)."""


def segments_hit_boxes(segments, boxes):
    """
    Return ``(p, c)``: whether any segment ``(p, m, 2, 2)`` crosses box ``(p, c, 4)``.

    Liang-Barsky clipping of each segment against each box (x0, y0, x1, y1): the segment's
    parameter interval inside both slabs is not empty.  A segment parallel to an axis has an
    infinite inverse slope there, so its slab is everything or nothing (``fmin``/``fmax``
    skip the 0 * inf of a segment that starts exactly on the slab's edge).
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

    ``test(rows, cols)`` returns the costly test of the places ``(rows[i], cols[i])``, a
    ``(q,)`` mask.  It is run only on places that pass the cheap mask ``ok``, in rounds of
    ``chunk`` such places per row in column order, on the rows still without a passing
    place; a row stops at the round of its first (later places are left False), so
    ``argmax`` of the result is that of the full test.
    """
    out = np.zeros_like(ok)
    rows, cols = np.nonzero(ok)                         # row by row, in column order
    if not len(rows):
        return out
    starts = np.flatnonzero(np.r_[True, rows[1:] != rows[:-1]])
    rank = np.arange(len(rows)) - np.repeat(starts, np.diff(np.r_[starts, len(rows)]))
    order = np.argsort(rank, kind='stable')            # round by round, rows in order
    rows, cols, rank = rows[order], cols[order], rank[order]
    bounds = np.searchsorted(rank, np.arange(0, rank[-1] + chunk + 1, chunk))
    pending = np.ones(len(ok), dtype=bool)
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        take = lo + np.flatnonzero(pending[rows[lo:hi]])
        if not len(take):
            continue
        passed = take[test(rows[take], cols[take])]
        out[rows[passed], cols[passed]] = True
        pending[rows[passed]] = False
    return out
