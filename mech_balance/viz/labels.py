"""The labels of a rig view (no rerun): their boxes on screen, their places at every sample."""

from dataclasses import dataclass
import functools
import math

from mech_balance.viz.hits import first_place, segment_distances, segments_hit_boxes
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
LABEL_OFFSETS_PX = (LABEL_OFFSET_PX, 2.5 * LABEL_OFFSET_PX, 5.0 * LABEL_OFFSET_PX)
"""The rings of places tried around a feature (the nearer first; the farther clear a
slider's block or a crowded joint; the farthest only where the others hold no clean place)."""
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
    """Return the box ``(x0, y0, x1, y1)`` (px) of a label at ``anchor_px`` (centred under it)."""
    a = np.asarray(anchor_px, dtype=float)
    w, h = label_size_px(text)
    top = a[..., 1] + LABEL_DROP_PX
    return np.array([a[..., 0] - w / 2, top, a[..., 0] + w / 2, top + h])


def label_point_px(centre_px, text):
    """Return the point (px) whose label (drawn centred under it) is centred at ``centre_px``."""
    h = label_size_px(text)[1]
    return np.array([centre_px[0], centre_px[1] - LABEL_DROP_PX - 0.5 * h])


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
    mm = moved * 1e3
    return f'moved {mm:.0f} mm' if mm >= 1.0 else f'moved {mm:.2g} mm'


def slide_readout(stroke_m, motion, variant):
    """Return the readout of a prismatic input: ``deg -> 'slide 30.0 mm, force +12.3 N'``."""
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


def candidates(w, h, rings=LABEL_OFFSETS_PX):
    """Return label-box centre offsets (px) around a feature: sides, corners, between, per ring."""
    out = []
    for offset in rings:
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
    if spec.where == 'change_along':      # along the stalk from the link to the centre
        j = [i for i, _ in layout.changes[variant]].index(spec.index)
        stalk = motion.marks[variant]['stalks'][:, j]
        return [stalk[:, 0] + t * (stalk[:, 1] - stalk[:, 0]) for t in (0.5, 0.25, 0.75)]
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
    """Return every drawn segment ``(p, m, 2, 2)`` on screen: links, frame, a design's marks."""
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
    Return ``(positions (q, 3), texts, colours, counts (p,), tiers (q,))``: a view's labels.

    Tiers 1-5: `docs/recordings.md`, Labels.
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
    placed = []      # (p, 4) boxes
    out = []         # per spec: (p, 3) anchors, tiers (p,), texts, colour
    h = LABEL_TEXT_PX + LABEL_PAD_PX[1]
    for spec in layout.labels:
        if spec.members and variant not in spec.members:
            continue                    # a label of the other design (its discs, changes)
        texts = [spec.text(d) for d in motion.degrees] if callable(spec.text) else None
        w = max(label_size_px(t)[0] for t in (texts or [spec.text]))
        half = np.array([0.5 * w, 0.5 * h])
        if spec.where in ('readout', 'scale'):
            corner = screen.px(layout.scale_bar[2]) if spec.where == 'scale' else \
                LABEL_GAP_PX + half
            placed.append(np.broadcast_to(np.concatenate([corner - half, corner + half]),
                                          (p, 4)))
            base = unproject(screen, np.broadcast_to(corner, (p, 2))
                             - [0.0, LABEL_DROP_PX + 0.5 * h], layout, motion)
            out.append((base, np.ones(p, dtype=int), texts or [spec.text] * p, spec.color))
            continue
        features = [label_anchor(layout, motion, spec, variant, screen)]
        if spec.where in ('link', 'change'):
            features += label_anchor(layout, motion, Label('', (), spec.where + '_along',
                                                           spec.index), variant, screen) or []
        f_px = np.stack([screen.px(f) for f in features], axis=1)  # (p, a, 2)

        others = np.stack(placed, axis=1) if placed else np.zeros((p, 0, 4))   # (p, L, 4)

        def trial(rows, offs):
            """Return the places of ``rows`` at offsets ``offs``: centres, boxes, tests."""
            if spec.where == 'gauge':
                offs = offs[[2, 6, 7, 1, 3, 0, 4, 5] + list(range(8, len(offs)))]
            centres = (f_px[rows, :, None, :] + offs[None, None]).reshape(len(rows), -1, 2)
            boxes = np.concatenate([centres - half, centres + half], axis=-1)

            def cheap(r, cols):
                """Return the masks (inside, free, cheap) of the places ``(r, cols)``."""
                b = boxes[np.ix_(r, cols)]                              # (n, k, 4)
                inside = (b[..., 0] >= 0) & (b[..., 1] >= 0) & \
                    (b[..., 2] <= w_px) & (b[..., 3] <= h_px)
                o, g = others[rows[r], None], LABEL_GAP_PX             # (n, 1, L, 4)
                b = b[:, :, None]
                free = inside & ~((b[..., 0] < o[..., 2] + g) & (b[..., 2] > o[..., 0] - g) &
                                  (b[..., 1] < o[..., 3] + g) & (b[..., 3] > o[..., 1] - g)
                                  ).any(axis=-1)
                if not markers.shape[1]:
                    return inside, free, free
                mx, my = markers[rows[r], None, :, 0], markers[rows[r], None, :, 1]
                m = MARKER_PX
                return inside, free, free & ~(
                    (mx > b[..., 0] - m) & (mx < b[..., 2] + m) &
                    (my > b[..., 1] - m) & (my < b[..., 3] + m)).any(axis=-1)
            which = np.repeat(np.arange(len(features)), len(offs))     # anchor of a place

            def uncrossed(r, cols):
                """Return ``(q,)``: no line crosses the places ``(r[i], cols[i])``."""
                return ~segments_hit_boxes(lines[rows[r]], boxes[r, cols, None])[:, 0]

            def clean(r, cols):
                """Return ``(q,)``: uncrossed, and nearer its own feature than any other."""
                ok = uncrossed(r, cols)
                i = np.flatnonzero(ok)            # the nearness only where no line crosses
                if i.size:
                    at = rows[r[i]]
                    ok[i] = _nearest_own(spec, f_px[at, 0], centres[r[i], cols[i], None],
                                         markers[at], links_px, at)[:, 0]
                return ok
            return centres, which, cheap, (clean, uncrossed)
        # clean places on the near rings: the cheap tests run in column chunks on the samples
        # still without a place, the costly ones only where the cheap ones passed
        rows = np.arange(p)
        near = candidates(w, h, LABEL_OFFSETS_PX[:2])
        centres, which, cheap, (clean, _) = trial(rows, near)
        first = first_place(p, centres.shape[1], lambda r, cols: cheap(r, cols)[2], clean)
        tier = np.where(first >= 0, 1, 0)
        first = np.maximum(first, 0)
        if tier.any():                  # the same place wherever it is clean
            mode = np.bincount(first[tier == 1]).argmax()
            redo = np.flatnonzero((tier == 1) & (first != mode))
            redo = redo[cheap(redo, [mode])[2][:, 0]]
            if redo.size:
                first[redo[clean(redo, np.full(redo.size, mode))]] = mode
        at = centres[rows, first]
        anchor = which[first]
        rest = np.flatnonzero(tier == 0)
        if rest.size:                   # no clean place: every ring, the tests one by one
            every = candidates(w, h)
            c, wh, cheap, (clean, uncrossed) = trial(rest, every)
            inside, free, cheap = cheap(np.arange(rest.size), np.arange(c.shape[1]))
            far = np.tile(np.arange(len(every)) >= len(near), len(features))
            got = np.zeros(rest.size, dtype=int)
            for level, mask, test in ((1, cheap & far, clean), (2, cheap, uncrossed),
                                      (3, free, None), (4, inside, None)):
                todo = np.flatnonzero(got == 0)
                sub = mask[todo]
                if test is None:
                    col = np.where(sub.any(axis=1), np.argmax(sub, axis=1), -1)
                else:
                    col = first_place(todo.size, sub.shape[1],
                                      lambda r, cols: sub[np.ix_(r, cols)],
                                      lambda r, cols: test(todo[r], cols))
                hit = col >= 0
                col = col[hit]
                got[todo[hit]] = level
                at[rest[todo[hit]]] = c[todo[hit], col]
                anchor[rest[todo[hit]]] = wh[col]
            at[rest[got == 0]] = c[got == 0, 0]
            anchor[rest[got == 0]] = 0
            tier[rest] = np.where(got == 0, 5, got)
        placed.append(np.concatenate([at - half, at + half], axis=-1))
        chosen = np.stack(features, axis=1)[rows, anchor]           # (p, 3)
        base = unproject(screen, at - [0.0, LABEL_DROP_PX + 0.5 * h], layout, motion, chosen)
        out.append((base, tier, texts or [spec.text] * p, spec.color))
    if not out:
        return np.zeros((0, 3)), [], [], np.zeros(p, dtype=np.int64), np.zeros(0, dtype=int)
    # sample by sample, each sample's labels in the order of importance
    bases = np.stack([b for b, _, _, _ in out], axis=1)                 # (p, s, 3)
    tiers = np.stack([t for _, t, _, _ in out], axis=1)                 # (p, s)
    texts = np.empty((p, len(out)), dtype=object)
    colors = np.empty((p, len(out)), dtype=object)
    for j, (_, _, t, c) in enumerate(out):
        texts[:, j] = t
        colors[:, j] = [c] * p
    return (bases.reshape(-1, 3), texts.ravel().tolist(), colors.ravel().tolist(),
            np.full(p, len(out), dtype=np.int64), tiers.ravel())


def _nearest_own(spec, feature_px, centres, markers, links_px, rows):
    """
    Return ``(p, c)``: whether labels at ``centres`` are nearer their feature than any other.

    ``links_px`` are every link's segments at every sample, of which the ``rows`` are these.
    """
    if spec.where == 'link':
        own = links_px[spec.index][rows]
        others = [s[rows] for i, s in enumerate(links_px) if i != spec.index and s.shape[1]]
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
