"""The default blueprint: rigs side by side over the RMS table, plots right."""

from mech_balance.viz.drawing import DEGREE_TIMELINE
from mech_balance.viz.layout import INSET_SHARE, LEFT_SHARE, RIG_ROW_SHARE
from mech_balance.viz.plots import ANGLE_ROOT
from mech_balance.viz.text import fmt
import rerun.blueprint as rrb


DRAWN_STREAMS = ('frame', 'links', 'joints', 'mass_centres', 'point_masses',
                 'shaking_force_arrow', 'shaking_moment_arc')


def spatial_name(layout, variant):
    """Return a rig view's title: the design, then the scales of what it draws (3-D: short)."""
    force, moment = layout.on('shaking_force_arrow'), layout.on('shaking_moment_arc')
    if layout.dim == 3:
        scales = ([f'{fmt(0.01 / layout.force_scale_m_per_N)} N'] if force else []) + \
            ([f'{fmt(0.01 / layout.moment_scale)} N*m'] if moment else [])
        return ' | '.join([variant, f'grid {layout.grid_text}']
                          + ([f'arrows 1 cm: {", ".join(scales)}'] if scales else []))
    parts = [variant]
    if force:
        parts.append(f'force arrow 1 cm = {fmt(0.01 / layout.force_scale_m_per_N)} N')
    if moment:
        parts.append(f'moment arc 90 deg = {fmt(90.0 / layout.moment_scale)} N*m')
    return ' | '.join(parts)


def blueprint(layout):
    """Return the default blueprint: rigs side by side over the RMS table, plots right."""
    spatial = []
    if set(DRAWN_STREAMS) & set(layout.streams):
        for v in layout.variants:
            contents = ['/rig/**', f'/{v}/**']
            screen = layout.screens[v]
            name = spatial_name(layout, v)
            if layout.dim == 2:
                (x0, x1), (y0, y1) = screen.bounds
                spatial.append(rrb.Spatial2DView(
                    origin='/', contents=contents, name=name,
                    visual_bounds=rrb.VisualBounds2D(x_range=[x0, x1], y_range=[-y1, -y0])))
            else:
                spatial.append(rrb.Spatial3DView(
                    origin='/', contents=contents, name=name,
                    eye_controls=rrb.EyeControls3D(
                        kind=rrb.Eye3DKind.Orbital, position=screen.eye_m,
                        look_target=screen.target_m, eye_up=screen.up),
                    # the rig's own grid (rig/grid, sized to it) instead of the endless one
                    line_grid=rrb.LineGrid3D(visible=False)))
    # the title names the curves' colours in the order of the rig views (original left)
    key = ': orange original, blue balanced' if len(layout.variants) > 1 else ''
    if layout.live:     # a live view plots over its time timeline (seconds)
        plots = [rrb.TimeSeriesView(origin=f'/plots/{p.entity}', name=p.title + key,
                                    plot_legend=rrb.PlotLegend(visible=False))
                 for p in layout.plots]
    else:               # over the crank angle: 2-D views in pixels of the default window
        plots = [rrb.Spatial2DView(origin=f'/{ANGLE_ROOT}/{p.entity}', name=p.title + key,
                                   visual_bounds=rrb.VisualBounds2D(
                                       x_range=[0.0, p.axes.size_px[0]],
                                       y_range=[0.0, p.axes.size_px[1]]))
                 for p in layout.plots]
    left = []
    if spatial:
        left.append(rrb.Horizontal(*spatial) if len(spatial) > 1 else spatial[0])
    if layout.on('info'):
        left.append(rrb.TextDocumentView(origin='/info', name='RMS, design, how to read'))
    columns = []
    if left:
        columns.append(rrb.Vertical(*left, row_shares=[RIG_ROW_SHARE, 1.0 - RIG_ROW_SHARE])
                       if len(left) > 1 else left[0])
    if layout.inset is not None:
        (x0, x1), (y0, y1) = layout.inset.bounds
        zoom = layout.screens['original'].metres_per_px / layout.inset.metres_per_px
        plots.insert(0, rrb.Spatial2DView(
            origin='/', name=f'zoom x{zoom:.1f} on the crowded core (its names)',
            contents=['/rig/**', '- /rig/gauge', '- /rig/scale', '/inset/**'],
            visual_bounds=rrb.VisualBounds2D(x_range=[x0, x1], y_range=[-y1, -y0])))
        shares = [INSET_SHARE] + [(1.0 - INSET_SHARE) / len(layout.plots)] * len(layout.plots)
    if plots:
        columns.append(rrb.Vertical(*plots, row_shares=shares) if layout.inset is not None
                       else rrb.Vertical(*plots))
    root = rrb.Horizontal(*columns, column_shares=[LEFT_SHARE, 1.0 - LEFT_SHARE][:len(columns)])
    return rrb.Blueprint(
        root, rrb.BlueprintPanel(state='collapsed'), rrb.SelectionPanel(state='collapsed'),
        rrb.TimePanel(state='collapsed', timeline='time' if layout.live else DEGREE_TIMELINE,
                      play_state='following' if layout.live else 'playing',
                      loop_mode='off' if layout.live else 'all'))
