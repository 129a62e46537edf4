"""Screen-space tests of the label placement, vectorized over samples ``p`` and places ``c``."""

import numpy as np

LABEL_CHUNK = 4
"""Candidate places of a label tested at once at first (:func:`first_place`)."""
CHUNK_GROWTH = 2
"""Each round of :func:`first_place` tests this many times the places of the round before."""


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


def first_place(n, width, cheap, costly, chunk=LABEL_CHUNK):
    """
    Return per row of ``n`` the first of ``width`` columns passing both tests (-1: none).

    ``cheap(rows, cols)`` returns the ``(len(rows), len(cols))`` mask of a column chunk, run
    only on rows still without a place; ``costly(rows, cols)`` returns the ``(q,)`` mask of
    the places ``(rows[i], cols[i])``, run only on places that passed the cheap test.
    """
    first = np.full(n, -1)
    pending = np.arange(n)
    start = 0
    while start < width and len(pending):
        cols = np.arange(start, min(start + chunk, width))
        start, chunk = start + chunk, chunk * CHUNK_GROWTH
        i, j = np.nonzero(cheap(pending, cols))                # row by row, columns in order
        if len(i):
            good = costly(pending[i], cols[j])
            done, at = np.unique(i[good], return_index=True)   # each row's first passing place
            first[pending[done]] = cols[j[good][at]]
            pending = np.delete(pending, done)
    return first
