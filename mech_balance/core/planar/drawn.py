"""
The drawn size of a planar rig's parts: bars, joint bosses, slider blocks and their planes.

Fractions of the linkage's length scale L, for the URDF and the clearance check; body k lies
in the plane ``z = LAYER * L * k`` (:func:`plane_z_m`).
"""

PIN_RADIUS = 0.08
"""Planar pins (joint bosses): cylinder radius as a fraction of the length scale."""
BAR_WIDTH = 0.14
"""Planar bars: box width (in the plane) as a fraction of the length scale."""
BAR_THICKNESS = 0.06
"""Planar bars: box thickness (along z) as a fraction of the length scale."""
PIN_LENGTH = 1.5
"""Planar pins: cylinder length as a multiple of the bar thickness."""
LAYER = 0.1
"""Planar links: z step between the links' planes, fraction of the length scale."""
BLOCK_SIZE = (0.8, 0.5)
"""A one-point link (a slider block): box length and width, fractions of the length scale."""


def bar_edges(points):
    """Return the bars ``[(name_a, name_b), ...]`` of a link's points (complex, m): Prim's tree."""
    names = list(points)
    if len(names) < 2:
        return []
    inside, edges = {names[0]}, []
    while len(inside) < len(names):
        best = min(((abs(points[a] - points[b]), a, b) for a in inside for b in names
                    if b not in inside), key=lambda e: e[0])
        edges.append((best[1], best[2]))
        inside.add(best[2])
    return edges


def plane_z_m(linkage, body):
    """Return the z of a body's plane (m): ``LAYER * L * k`` for body k of the linkage."""
    return LAYER * linkage.length_scale * list(linkage.body_names).index(body)
