"""Sizes and colours of what a recording draws: shares of the rig's size, radii, colour roles."""

from mech_balance.schema.scene import SERIES
import rerun as rr


FORCE_ARROW_SHARE = 0.14
"""Automatic force scale: the longest shaking-force arrow is at most this share of the rig."""
ARROW_3D_SHARE = 0.35
"""3-D: the longest shaking-force (and moment) arrow is at most this share of the rig."""
ARROW_3D_RADIUS_SHARE = 0.012
"""3-D: radius of the gauge's arrows, as a share of the rig."""
MOMENT_ARC_MAX_DEG = 270.0
"""Automatic moment scale: the largest shaking moment sweeps at most this arc."""
MOMENT_ARC_LIMIT_DEG = 355.0
"""An arc never sweeps more than this (a scene's own scale may ask for more)."""
DIAL_SHARE = 0.12
"""Least radius of the moment dial, as a share of the rig's size."""
DIAL_OVER_ARROW = 1.15
"""The dial's radius is at least this times the longest force arrow (arrows stay inside)."""
MOMENT_HEAD_SHARE = 0.3
"""Length of the arc's arrow head, as a share of the dial radius."""
ARC_POINTS = 33
"""Points of the polyline that draws the shaking-moment arc."""
DIAL_POINTS = 65
"""Points of the dial circle."""
GAUGE_GAP_SHARE = 0.12
"""Gap between the rig and its gauge, as a share of the rig's size."""
GAUGE_LABEL_DROP = 1.15
"""3-D: the gauge's label stands this many reaches (longest arrow) under the gauge's centre."""
BLOCK_SHARE = 0.035
"""Half-size of the square drawn for a one-point link (a slider), as a share of the rig."""
POINT_MASS_RADIUS_SHARE = 0.03
"""Radius of the largest point mass, as a share of the rig (disc area ~ abs(mass))."""
CENTRE_RADIUS_SHARE = 0.012
"""Radius of a body's mass-centre dot, as a share of the rig (the system's: 1.8 times)."""
AXIS_MARGIN_SHARE = 0.12
"""A fixed axis or guide extends this share of the rig beyond what moves along it."""
SCALE_BAR_SHARE = 0.3
"""The scale bar is the roundest length at most this share of the rig."""
LINK_RADIUS_3D_SHARE = 0.014
"""3-D: radius of a link's tube, as a share of the rig."""
FRAME_RADIUS_3D_SHARE = 0.005
"""3-D: radius of the frame's lines and axes, as a share of the rig."""
JOINT_RADIUS_3D_SHARE = 0.026
"""3-D: radius of a joint's sphere, as a share of the rig."""
SAME_POINT_RTOL = 1e-9
"""Two points closer than this share of the rig are one place (their labels merge)."""
LINE_RADIUS_UI = rr.components.Radius.ui_points(2.0)
FRAME_RADIUS_UI = rr.components.Radius.ui_points(1.5)
JOINT_RADIUS_UI = rr.components.Radius.ui_points(4.5)
FRAME_COLOR = (150, 150, 150)
GRID_COLOR = (70, 70, 70)
"""The 3-D grid's lines: darker than the frame."""
PLOT_GRID_COLOR = (55, 55, 60)
"""The plots' grid lines at their ticks."""
GRID_RADIUS_UI = rr.components.Radius.ui_points(0.5)
"""Radius of the 3-D grid's lines."""
JOINT_COLOR = (235, 235, 235)
FORCE_COLOR = (240, 70, 70)
MOMENT_COLOR = (200, 110, 255)
DIAL_COLOR = (90, 90, 100)
SCALE_COLOR = (200, 200, 200)
ADDED_ALPHA = 110
"""Opacity (of 255) of an added body's disc in its link's colour."""
PLANE_ALPHA = 200
"""Opacity of the ring that draws an added body's plane."""
ADDED_DRAW_ORDER = 5.0
"""2-D draw order of the added bodies: behind the links (20) and points (30)."""
POSITIVE_MASS_COLOR = (225, 225, 225)
NEGATIVE_MASS_COLOR = (255, 105, 180)
SYSTEM_CENTRE_COLOR = (255, 255, 255)
READOUT_COLOR = (255, 255, 255)
SERIES_COLORS = {'original': (255, 150, 40), 'balanced': (70, 165, 255)}
SERIES_WIDTHS = {'original': 2.0, 'balanced': 6.0}
"""Line widths (ui points) of the plots: the original's thin line over the balanced wide one,
so a curve two designs share shows both colours (orange and blue mean nothing else)."""
LINK_PALETTE = ((27, 158, 119), (166, 216, 84), (255, 217, 47), (229, 196, 148),
                (141, 211, 199), (188, 189, 34), (166, 118, 29), (178, 223, 138))
"""Link colours: greens, yellows and browns (none is a plot, arrow or mass colour)."""
UNITS = {'force': 'N', 'moment': 'N*m', 'energy': 'J'}
"""SI unit of each dimension of :data:`mech_balance.schema.scene.SERIES`."""


def series_label(name):
    """Return ``(label, SI unit, dimension)`` of a series (its name alone if not listed)."""
    label, dim = SERIES.get(name, (name.replace('_', ' '), ''))
    return label, UNITS.get(dim, ''), dim
