"""
The labels of a rig view: their boxes on screen and their greedy placement at every sample.

Pure geometry (no rerun): a label's box as the viewer draws it at the default window, the
labels of a view most important first (:func:`label_specs`), and :func:`place_labels`, which
puts each at the first place around its feature that keeps clear of the other labels, of
every drawn point and line, and that names its own feature.
"""

from dataclasses import dataclass
import functools
import math

from mech_balance.viz.hits import first_passing, segment_distances, segments_hit_boxes
from mech_balance.viz.style import (
    FRAME_COLOR, GAUGE_LABEL_DROP, JOINT_COLOR, MOMENT_COLOR, READOUT_COLOR, SAME_POINT_RTOL,
    SCALE_COLOR, SYSTEM_CENTRE_COLOR
)
import numpy as np


LABEL_TEXT_PX = 13.0
"""Height of a label's text in the viewer."""
LABEL_CHAR_PX = {'upper': 10.0, 'digit': 7.0, 'other': 6.6}
"""Width of one character of a label (capitals, digits, the rest), measured on screenshots."""
LABEL_PAD_PX = (12.0, 9.0)
"""Padding of a label's box (width, height) around its text."""
LABEL_DROP_PX = 2.0
"""The viewer draws a point's label box this far below the point, centred on it."""
LABEL_GAP_PX = 3.0
"""Free space kept between two label boxes."""
LABEL_OFFSET_PX = 9.0
"""Distance from a feature to the nearest edge of its label box."""
LABEL_OFFSETS_PX = (LABEL_OFFSET_PX, 2.5 * LABEL_OFFSET_PX)
"""The rings of places tried around a feature (the nearer first; the farther clears a
slider's block or a crowded joint)."""
NEAR_MARGIN_PX = 2.0
"""A label is at least this much nearer its own feature than any other (points, links)."""
SAME_PLACE_PX = 1.0
"""Drawn points closer than this on screen are one place (a joint on a frame pivot)."""
LINK_LABEL_ALONG = (0.3, 0.7, 0.15, 0.85)
"""Besides its middle, a link's name may sit at these fractions of its first segment (at
the first two of them on its other segments)."""
MARKER_PX = 6.0
"""Radius kept free around a drawn point (pivot, joint, mass centre) by the labels."""


@functools.lru_cache(maxsize=4096)
def label_size_px(text):
    """Return the (width, height) in pixels of the box of a label with ``text``."""
    w = sum(LABEL_CHAR_PX['upper'] if c.isupper() else LABEL_CHAR_PX['digit'] if c.isdigit()
            else LABEL_CHAR_PX['other'] for c in text)
    return w + LABEL_PAD_PX[0], LABEL_TEXT_PX + LABEL_PAD_PX[1]


def label_box_px(anchor_px, text):
    """
    Return the box ``(x0, y0, x1, y1)`` (pixels) that a label at ``anchor_px`` covers.

    The viewer draws a point's label centred under it, :data:`LABEL_DROP_PX` below.
    """
    a = np.asarray(anchor_px, dtype=float)
    w, h = label_size_px(text)
    top = a[..., 1] + LABEL_DROP_PX
    return np.array([a[..., 0] - w / 2, top, a[..., 0] + w / 2, top + h])


@dataclass
class Label:
    """A label of a view: text (or texts per sample), colour, the feature it names."""

    text: object          # str, or a function of the sample's crank angle (deg)
    color: tuple
    where: str            # 'frame', 'joint', 'centre', 'link', 'fixed'
    index: int = 0
    members: tuple = ()   # the variants it belongs to (all if empty)


def merged_names(names, positions, size):
    """Return ``[(label, [indices])]``: names at one place (at every sample) merged."""
    tol = SAME_POINT_RTOL * size * 1e3
    groups = []
    for i, name in enumerate(names):
        for g in groups:
            if np.max(np.linalg.norm(positions[:, i] - positions[:, g[1][0]], axis=-1)) <= tol:
                g[1].append(i)
                if name not in g[0]:
                    g[0].append(name)
                break
        else:
            groups.append(([name], [i]))
    return [('/'.join(n), idx) for n, idx in groups]


def moved_text(layout, variant, i):
    """Return the label of a body whose mass is kept and whose mass centre moved: how far."""
    moved = np.linalg.norm(np.subtract(layout.drawings[variant].bodies[i].mass_centre_m,
                                       layout.drawings['original'].bodies[i].mass_centre_m))
    return f'moved {moved * 1e3:.0f} mm'


def slide_readout(stroke_m, motion, variant):
    """
    Return the readout of a prismatic input: ``deg -> 'slide 30.0 mm, force +12.3 N'``.

    The slide follows the input's stroke law at the cycle angle; the driving force is the
    design's at the recorded samples (a live view's new angles show the slide alone).
    """
    from mech_balance.schema.spatial import stroke_law
    data = (motion.data or {}).get(variant)
    force = getattr(data, 'series', {}).get('driving_force') if data is not None else None
    at = {} if force is None else {round(float(d), 9): float(f)
                                   for d, f in zip(motion.degrees, force)}

    def text(deg):
        slide = float(stroke_law(stroke_m, math.radians(deg))[0])
        f = at.get(round(float(deg), 9))
        return f'slide {slide * 1e3:.1f} mm' + ('' if f is None else f', force {f:+.3g} N')
    return text


def label_specs(layout, motion):
    """Return the labels of a rig view, most important first."""
    stroke = getattr(layout.rigs['original'].scene, 'crank_stroke_m', None)
    if stroke is None:
        specs = [Label(lambda deg: f'crank {deg:.1f} deg', READOUT_COLOR, 'readout')]
    else:   # a prismatic input: its slide and the driving force of each design
        specs = [Label(slide_readout(stroke, motion, v), READOUT_COLOR, 'readout', 0, (v,))
                 for v in layout.variants]
    if layout.scale_bar is not None:
        specs.append(Label(layout.scale_bar[1], SCALE_COLOR, 'scale'))
    if layout.on('shaking_force_arrow') or layout.on('shaking_moment_arc'):
        specs.append(Label('shaking force, moment', MOMENT_COLOR, 'gauge'))
    if layout.on('frame'):
        f = np.broadcast_to(layout.frame_points, (1,) + layout.frame_points.shape)
        for text, idx in merged_names(layout.frame_names, f, layout.size_m):
            specs.append(Label(text, FRAME_COLOR, 'frame', idx[0]))
    if layout.on('mass_centres'):
        specs.append(Label('CoM', SYSTEM_CENTRE_COLOR, 'centre', -1))
    if layout.on('joints') and motion.joints.shape[1]:
        fixed = np.ptp(motion.joints, axis=0).max(axis=-1) <= SAME_POINT_RTOL * layout.size_m
        moving = [i for i in range(motion.joints.shape[1]) if not fixed[i]]
        names = [layout.joint_names[i] for i in moving]
        for text, idx in merged_names(names, motion.joints[:, moving], layout.size_m):
            specs.append(Label(text, JOINT_COLOR, 'joint', moving[idx[0]]))
    if layout.on('links'):
        for i, name in enumerate(layout.link_names):
            specs.append(Label(name, layout.link_colors[i], 'link', i))
    for v in layout.variants:
        added = [(i, a) for i, b in enumerate(layout.drawings[v].bodies) for a in b.added]
        planes = any(abs(a.centre_m[2]) > 0.0 for _, a in added) and layout.dim == 2
        for j, (i, a) in enumerate(added if layout.has_added else ()):
            text = f'{a.mass_kg:.3g} kg' + (f', z {a.centre_m[2] * 1e3:+.3g} mm' if planes
                                            else '')
            specs.append(Label(text, layout.link_colors[i], 'added', j, (v,)))
        if layout.on('links') and layout.on('mass_centres'):
            for i, dm in (layout.changes or {}).get(v, []):
                text = f'{dm:+.3g} kg' if dm else moved_text(layout, v, i)
                specs.append(Label(text, layout.link_colors[i], 'change', i, (v,)))
    return specs


def candidates(w, h):
    """
    Return label-box centre offsets (px) around a feature: above, right, below, left, ...

    The four sides and four corners first, then eight places between them on the ellipse
    through the sides (a box there keeps about its offset from the feature), for each of
    :data:`LABEL_OFFSETS_PX` in turn.
    """
    out = []
    for offset in LABEL_OFFSETS_PX:
        dx, dy = 0.5 * w + offset, 0.5 * h + offset
        out += [[0, -dy], [dx, 0], [0, dy], [-dx, 0], [dx, -dy], [-dx, -dy], [dx, dy],
                [-dx, dy]]
        out += [[dx * math.cos(a), dy * math.sin(a)]
                for a in np.radians([-67.5, -22.5, 22.5, 67.5, 112.5, 157.5, 202.5, 247.5])]
    return np.array(out, dtype=float)


def label_anchor(layout, motion, spec, variant, screen):
    """Return the feature ``(p, 3)`` a label names, or None."""
    p = motion.size
    if spec.where == 'frame':
        return np.broadcast_to(layout.frame_points[spec.index], (p, 3))
    if spec.where == 'joint':
        return motion.joints[:, spec.index]
    if spec.where in ('centre', 'change'):
        return motion.centres[variant][:, spec.index]
    if spec.where == 'added':
        return motion.added[variant][:, spec.index]
    if spec.where == 'link':
        strip = motion.links[spec.index]
        k = strip.shape[1]
        return strip[:, :max(k - 1, 1)].mean(axis=1) if k > 2 else strip.mean(axis=1)
    if spec.where == 'link_along':
        strip = motion.links[spec.index]
        if strip.shape[1] < 2:
            return None
        # along its first segment, then along the others (a coupler's far arm, a plate's
        # edges): a link crossed where its first segment lies may be free further on
        return [strip[:, j] + t * (strip[:, j + 1] - strip[:, j])
                for j in range(strip.shape[1] - 1)
                for t in (LINK_LABEL_ALONG if j == 0 else LINK_LABEL_ALONG[:2])]
    if spec.where == 'gauge':
        below = np.array([0.0, layout.gauge_reach_m, 0.0] if layout.dim == 2 else   # 3-D:
                         [0.0, 0.0, GAUGE_LABEL_DROP * layout.gauge_reach_m])   # under arrows
        return np.broadcast_to(layout.gauge_m - below, (p, 3))
    if spec.where == 'scale':
        return np.broadcast_to(layout.scale_bar[2], (p, 3))
    return None


def link_segments_px(motion, screen):
    """Return per link its segments ``(p, k - 1, 2, 2)`` on screen (a one-point link: none)."""
    out = []
    for strip in motion.links:
        px = screen.px(strip)                                       # (p, k, 2)
        out.append(np.stack([px[:, :-1], px[:, 1:]], axis=2))
    return out


def segments_px(layout, motion, screen, variant=None):
    """
    Return every drawn line segment of a view ``(p, m, 2, 2)`` on screen.

    The links and the frame; with ``variant``, also that design's marks as drawn: the
    counterweight plane rings and the stalks to moved mass centres (:func:`design_marks`).
    """
    segs = [s for s in link_segments_px(motion, screen) if s.shape[1]]
    for strip in layout.frame_strips:
        px = screen.px(strip)
        seg = np.stack([px[:-1], px[1:]], axis=1)
        segs.append(np.broadcast_to(seg, (motion.size,) + seg.shape))
    marks = (motion.marks or {}).get(variant, {}) if variant is not None else {}
    drawn = {'rings': layout.has_added, 'stalks': layout.on('links')}
    for kind in ('rings', 'stalks'):
        m = marks.get(kind)
        if m is None or not drawn[kind] or not np.size(m):
            continue
        px = screen.px(np.asarray(m, dtype=float))                  # (p, r, k, 2)
        seg = np.stack([px[:, :, :-1], px[:, :, 1:]], axis=3)       # (p, r, k - 1, 2, 2)
        segs.append(seg.reshape(motion.size, -1, 2, 2))
    if not segs:
        return np.zeros((motion.size, 0, 2, 2))
    return np.concatenate(segs, axis=1)


def place_labels(layout, motion, variant):
    """
    Return ``(positions (q, 3), texts, colours, counts (p,))``: the labels of one view.

    Greedy, most important label first, at each sample: each label takes the first place
    around its feature whose box keeps clear of the boxes already placed, of every drawn
    point and of every drawn line, inside the view, and that is nearer its own feature than
    any other (:func:`_nearest_own`); else it is left out at that sample.  So no two labels
    ever overlap, no line crosses a label and no label names a neighbour's point at the
    default window.
    """
    screen = layout.screens[variant]
    p = motion.size
    w_px, h_px = screen.size_px
    points = []
    if layout.on('frame'):
        points.append(screen.px(np.broadcast_to(layout.frame_points,
                                                (p,) + layout.frame_points.shape)))
    if layout.on('joints') and motion.joints.shape[1]:
        points.append(screen.px(motion.joints))
    if layout.on('mass_centres'):
        points.append(screen.px(motion.centres[variant]))
    markers = np.concatenate(points, axis=1) if points else np.zeros((p, 0, 2))
    lines = segments_px(layout, motion, screen, variant)
    links_px = link_segments_px(motion, screen)
    placed = []      # (p, 4) boxes with (p,) masks
    out = []         # per spec: (p, 3) anchors, mask, texts
    h = LABEL_TEXT_PX + LABEL_PAD_PX[1]
    for spec in layout.labels:
        if spec.members and variant not in spec.members:
            continue                    # a label of the other design (its discs, changes)
        texts = [spec.text(d) for d in motion.degrees] if callable(spec.text) else None
        w = max(label_size_px(t)[0] for t in (texts or [spec.text]))
        if spec.where in ('readout', 'scale'):
            corner = np.array([LABEL_GAP_PX + 0.5 * w, LABEL_GAP_PX + 0.5 * h])
            if spec.where == 'scale':
                corner = screen.px(layout.scale_bar[2])
            box = np.broadcast_to(np.array([corner[0] - w / 2, corner[1] - h / 2,
                                            corner[0] + w / 2, corner[1] + h / 2]), (p, 4))
            ok = np.ones(p, dtype=bool)
            centre_px = np.broadcast_to(corner, (p, 2))
            base = unproject(screen, centre_px - [0.0, LABEL_DROP_PX + 0.5 * h], layout,
                             motion)
            placed.append((box, ok))
            out.append((base, ok, texts or [spec.text] * p, spec.color))
            continue
        feature = label_anchor(layout, motion, spec, variant, screen)
        features = [feature]
        if spec.where == 'link':
            features += label_anchor(layout, motion, Label('', (), 'link_along', spec.index),
                                     variant, screen) or []
        offs = candidates(w, h)                                     # (c, 2)
        if spec.where == 'gauge':
            offs = offs[[2, 6, 7, 1, 3, 0, 4, 5] + list(range(8, len(offs)))]
        f_px = np.stack([screen.px(f) for f in features], axis=1)  # (p, a, 2)
        centres = (f_px[:, :, None, :] + offs[None, None]).reshape(p, -1, 2)   # (p, a c, 2)
        which = np.repeat(np.arange(len(features)), len(offs))     # anchor of each place
        boxes = np.stack([centres[..., 0] - w / 2, centres[..., 1] - h / 2,
                          centres[..., 0] + w / 2, centres[..., 1] + h / 2], axis=-1)
        ok = (boxes[..., 0] >= 0) & (boxes[..., 1] >= 0) & (boxes[..., 2] <= w_px) & \
            (boxes[..., 3] <= h_px)
        for other, mask in placed:
            g = LABEL_GAP_PX
            hit = (boxes[..., 0] < other[:, None, 2] + g) & \
                (boxes[..., 2] > other[:, None, 0] - g) & \
                (boxes[..., 1] < other[:, None, 3] + g) & (boxes[..., 3] > other[:, None, 1] - g)
            ok &= ~(hit & mask[:, None])
        if markers.shape[1]:
            mx, my = markers[:, None, :, 0], markers[:, None, :, 1]
            m = MARKER_PX
            hit = (mx > boxes[..., 0, None] - m) & (mx < boxes[..., 2, None] + m) & \
                (my > boxes[..., 1, None] - m) & (my < boxes[..., 3, None] + m)
            ok &= ~hit.any(axis=-1)
        # no line crosses a label, and it names its own feature: the costly tests, run only
        # where the cheap ones passed and only until each sample's first place is found
        ok = first_passing(ok, lambda rows, cols: (~segments_hit_boxes(
            lines[rows], boxes[rows, cols, None]) & _nearest_own(
            spec, f_px[rows, 0], centres[rows, cols, None], markers[rows],
            [s[rows] for s in links_px]))[:, 0])
        found = ok.any(axis=1)
        first = np.argmax(ok, axis=1)
        rows = np.arange(p)
        box = boxes[rows, first]
        centre_px = centres[rows, first]
        placed.append((box, found))
        chosen = np.stack(features, axis=1)[rows, which[first]]    # (p, 3)
        base = unproject(screen, centre_px - [0.0, LABEL_DROP_PX + 0.5 * h], layout, motion,
                         chosen)
        out.append((base, found, texts or [spec.text] * p, spec.color))
    if not out:
        return np.zeros((0, 3)), [], [], np.zeros(p, dtype=np.int64)
    # sample by sample, each sample's labels in the order of importance
    mask = np.stack([m for _, m, _, _ in out], axis=1)                  # (p, s)
    bases = np.stack([b for b, _, _, _ in out], axis=1)                 # (p, s, 3)
    texts = np.empty((p, len(out)), dtype=object)
    for j, (_, _, t, _) in enumerate(out):
        texts[:, j] = t
    colors = np.empty((p, len(out)), dtype=object)
    for j, (_, _, _, c) in enumerate(out):
        colors[:, j] = [c] * p
    return (bases[mask].reshape(-1, 3), texts[mask].tolist(), colors[mask].tolist(),
            mask.sum(axis=1).astype(np.int64))


def _nearest_own(spec, feature_px, centres, markers, links_px):
    """
    Return ``(p, c)``: whether a label box centred at ``centres`` names its own feature.

    A point's label (frame, joint, mass centre) is nearer its point than any other drawn
    point (points at its place excepted), by :data:`NEAR_MARGIN_PX`; a link's name nearer
    its link than any other link.
    """
    if spec.where == 'link':
        own = links_px[spec.index]
        others = [s for i, s in enumerate(links_px) if i != spec.index and s.shape[1]]
        if own.shape[1] == 0 or not others:
            return np.ones(centres.shape[:2], dtype=bool)
        # one distance computation over every link's segments, then the least per link
        d = segment_distances(centres, np.concatenate([own] + others, axis=1))   # (p, c, m)
        mine = d[..., :own.shape[1]].min(axis=-1)
        return mine + NEAR_MARGIN_PX < d[..., own.shape[1]:].min(axis=-1)
    if spec.where not in ('frame', 'joint', 'centre', 'change') or markers.shape[1] == 0:
        return np.ones(centres.shape[:2], dtype=bool)
    mine = np.linalg.norm(centres - feature_px[:, None], axis=-1)              # (p, c)
    same = np.linalg.norm(markers - feature_px[:, None], axis=-1) <= SAME_PLACE_PX
    d = np.linalg.norm(centres[:, :, None] - markers[:, None], axis=-1)        # (p, c, M)
    d = np.where(same[:, None], np.inf, d)
    return mine + NEAR_MARGIN_PX < d.min(axis=-1)


def unproject(screen, centre_px, layout, motion, feature=None):
    """Return scene points ``(p, 3)`` drawn at pixel centres ``(p, 2)``."""
    if screen.bounds is not None:
        (x0, _), (_, y1) = screen.bounds
        s = screen.metres_per_px
        return np.stack([x0 + centre_px[:, 0] * s, y1 - centre_px[:, 1] * s,
                         np.zeros(len(centre_px))], axis=-1)
    if feature is None:
        feature = np.broadcast_to(np.asarray(screen.target_m), (len(centre_px), 3))
    return feature + screen.offset_m(feature, centre_px - screen.px(feature))
