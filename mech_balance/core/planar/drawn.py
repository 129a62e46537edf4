"""
The drawn size of a planar rig's parts: bars, joint bosses, slider blocks and their planes.

One place for the sizes that the URDF (:mod:`mech_balance.ros.urdf`) draws and the clearance
check (:mod:`mech_balance.analysis.clearance`) measures, as fractions of the linkage's length
scale L (:attr:`~mech_balance.core.planar.kinematics.Linkage.length_scale`).

Planes: the links of a planar rig move in parallel planes.  Body k of the linkage (the frame
k = 0, then the moving links in :attr:`Linkage.body_names` order) lies in the plane
``z = LAYER * L * k`` (:func:`plane_z_m`); its bars are ``BAR_THICKNESS * L`` thick and its
joint bosses ``PIN_LENGTH * BAR_THICKNESS * L`` long, both centred on that plane.  A
counterweight disc lies in its link's plane offset by its ``plane_m`` along z
(:class:`mech_balance.schema.scene.Counterweight`), ``thickness_m`` thick.
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
    """
    Return the bars of a link: a shortest spanning tree over its points (Prim).

    ``points`` maps names to positions (complex, m); the answer is ``[(name_a, name_b), ...]``.
    """
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
