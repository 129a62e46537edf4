"""The info panel of a recording: the RMS table, the design, how to read the views."""

import math

from mech_balance.conventions import rms
from mech_balance.schema.scene import SERIES
from mech_balance.viz.plots import plot_values
from mech_balance.viz.style import series_label
import numpy as np


def fmt(x):
    return f'{x:.4g}'


def markdown(lines):
    """Return markdown text: a literal ``*`` (as in N*m) is escaped, list bullets are kept."""
    out = []
    for line in lines:
        bullet = '* ' if line.startswith('* ') else ''
        out.append(bullet + line[len(bullet):].replace('*', '\\*'))
    return '\n'.join(out)


def table_cell(text):
    """Return ``text`` safe inside a markdown table cell (pipes escaped)."""
    return str(text).replace('|', '\\|')


def rms_rows(layout, data):
    """Return ``[(quantity, si unit, kind, {variant: values})]`` of the RMS table."""
    rows = []
    ref = data['original']
    if ref.force_N is not None:
        moment = 'shaking moment n_sh' if layout.dim == 2 else '|shaking moment|'
        rows += [('shaking force |f_sh|', 'N', 'force',
                  plot_values(layout, data, 'shaking_force')),
                 (f'{moment} about {layout.pivot_name}', 'N*m', 'moment',
                  plot_values(layout, data, 'shaking_moment'))]
    for k in dict.fromkeys(list(SERIES) + sorted(ref.series)):
        if k in ref.series:
            label, unit, dim = series_label(k)
            rows.append((label, unit, 'force' if dim == 'force' else 'moment',
                         {v: d.series[k] for v, d in data.items()}))
    if ref.reactions:
        scale = max([float(np.max(np.abs(r[3]['original']))) for r in rows if r[2] == 'moment']
                    or [0.0])
        for name in ref.reactions:
            rows.append((f'bearing {name} |f|', 'N', 'force',
                         {v: np.linalg.norm(d.reactions[name][0], axis=1)
                          for v, d in data.items()}))
            moment = {v: np.linalg.norm(d.reactions[name][1], axis=1) for v, d in data.items()}
            if name != layout.rigs['original'].crank_joint and \
                    np.max(moment['original']) > 1e-12 * max(scale, 1e-300):
                rows.append((f'bearing {name} moment', 'N*m', 'moment', moment))
    return rows


def rms_table(rows, title, both, norm):
    """Return the markdown lines of an RMS table of ``rows`` (:func:`rms_rows`)."""
    more = ' balanced | balanced / original |' if both else ''
    head = f'| {title} | SI | original |' + more
    sep = '|---|---|---:|' + ('---:|---:|' if both else '')
    if norm is not None:
        head += ' normalized | original |' + (' balanced |' if both else '')
        sep += '---|---:|' + ('---:|' if both else '')
    lines = [head, sep]
    for quantity, unit, dimension, values in rows:
        r = {v: float(rms(x)) for v, x in values.items()}
        text = f'| {table_cell(quantity)} | {unit or "-"} | {fmt(r["original"])} |'
        if both:
            ratio = r['balanced'] / r['original'] if r['original'] > 0 else float('nan')
            text += f' {fmt(r["balanced"])} | {fmt(ratio)} |'
        if norm is not None:
            f = norm.force if dimension == 'force' else norm.moment
            nunit = 'm1*a1*w^2' if dimension == 'force' else 'm1*a1^2*w^2'
            text += f' {nunit} | {fmt(float(f(r["original"])))} |'
            if both:
                text += f' {fmt(float(f(r["balanced"])))} |'
        lines.append(text)
    return lines


def info_text(layout, scene, data, samples, balanced_source):
    both = 'balanced' in data
    norm = getattr(scene, 'normalization', None)
    rig = layout.rigs['original']
    lines = [f'# {scene.name}: ' + ('original vs balanced' if both else 'original'), '']
    rows = rms_rows(layout, data)
    # the shaking wrench and the driving effort first, where the panel opens; the bearing
    # loads in a table of their own after the design (below the fold at the default window)
    main = [r for r in rows if not r[0].startswith('bearing ')]
    bearings = [r for r in rows if r[0].startswith('bearing ')]
    if rows:
        lines += rms_table(main or bearings, 'RMS over one turn', both, norm)
        lines += ['', 'True RMS (mech_balance.conventions); normalized by m1, a1, omega '
                  '(Chaudhary & Saha sec. 3.4).' if norm is not None else
                  'True RMS (mech_balance.conventions).']
    else:
        lines.append('No RMS table: the scene asks for kinematics only.')
    lines += ['', f'{scene.description}', '',
              f'Scene file `{getattr(scene, "source", "?")}`; crank joint {rig.crank_joint} at '
              f'{fmt(scene.crank_speed_rad_s)} rad/s '
              f'({fmt(scene.crank_speed_rad_s * 60.0 / (2.0 * math.pi))} rpm); {samples} '
              'samples per crank turn.']
    if both:
        src = balanced_source or getattr(layout.rigs['balanced'].scene, 'source', '?')
        lines.append(f'Balanced design: {src}.')
    if main and bearings:
        lines += [''] + rms_table(bearings, 'bearing loads, RMS', both, norm)
    lines += ['', '## How to read the views', '']
    if both:
        lines.append('* Left: the original rig; right: the balanced rig. They move alike (same '
                     'geometry); only the mass distribution differs.')
    if layout.dim == 2:
        lines.append('* Grey: the frame, its pivots, fixed axes and guides; coloured: the '
                     'links; white dots: the joints.'
                     + (f' The bar under the rig is a length scale ({layout.scale_bar[1]}).'
                        if layout.scale_bar is not None else ''))
    else:
        lines.append('* Grey: the frame, its pivots and fixed axes; coloured tubes: the links; '
                     "white spheres: the joints. The grid lies in the frame's x-y plane "
                     f'(z = 0, z up), one line every {layout.grid_text}.')
    if layout.on('mass_centres'):
        lines.append("* Dots in a link's colour: its mass centre; the large white dot CoM: the "
                     'mass centre of all moving links (it stands still when the rig is force '
                     'balanced).')
    if layout.has_added:
        shape = 'discs' if layout.dim == 2 else 'spheres'
        lines.append(f"* See-through {shape} in a link's colour, labelled in kg: the "
                     'counterweights and balancing weights of the design, at true size on '
                     "their links; the ring around each is its plane (the link's x-y plane at "
                     'the offset z of its centre'
                     + (', written after the mass when not 0' if layout.dim == 2 else '')
                     + ').')
    if any((layout.changes or {}).values()):
        lines.append("* A thin line in a link's colour from the link to a dot, labelled "
                     "+/- kg: where the design moved that link's mass centre, and the mass it "
                     "added (+) or removed (-) there ('moved 214 mm': its mass kept, only moved "
                     'that far).')
    if layout.on('point_masses'):
        lines.append('* Blue and red discs: the three equimomental point masses of each link '
                     '(Chaudhary & Saha eqs. 13-15); disc area proportional to the mass, light '
                     'positive, pink negative.')
    if layout.on('shaking_force_arrow'):
        lines.append(f'* Red arrow in the gauge beside the rig: the shaking force on the frame; '
                     f'scale {fmt(layout.force_scale_m_per_N)} m per N, i.e. 1 cm of arrow '
                     f'= {fmt(0.01 / layout.force_scale_m_per_N)} N.')
    if layout.on('shaking_moment_arc'):
        if layout.dim == 2:
            lines.append(f"* Purple arc on the gauge's dial: the shaking moment about "
                         f"{layout.pivot_name}, counter-clockwise positive from 12 o'clock; "
                         f'90 deg of arc = {fmt(90.0 / layout.moment_scale)} N*m.')
        else:
            lines.append(f'* Purple arrow in the gauge: the shaking moment vector about '
                         f'{layout.pivot_name}; {fmt(layout.moment_scale)} m per N*m (1 cm = '
                         f'{fmt(0.01 / layout.moment_scale)} N*m).')
    if layout.plots:
        lines.append('* Plots: ' + ', '.join(p.title for p in layout.plots)
                     + (' over time (s)' if layout.live else ' over the crank angle (deg), '
                        'the cursor at the current angle')
                     + '; orange (thin) = original, blue (wide, under it) = balanced: where '
                     'the two agree the orange line runs inside the blue one.')
    lines.append('* Timelines: `crank_angle_deg` (the default; `crank_angle` holds the same) = '
                 'whole degrees turned from crank angle 0, so `#90` is 90 deg (the exact angle '
                 'is written in each rig view), `time` = seconds at '
                 f'{fmt(abs(scene.crank_speed_rad_s))} rad/s.')
    lines += ['', '## Design (bodies with what is fixed to them; SI)', '',
              '| body | design | mass kg | mass centre m | added bodies |',
              '|---|---|---:|---|---|']
    for i, name in enumerate(layout.link_names):
        for v in layout.variants:
            b = layout.drawings[v].bodies[i]
            added = '; '.join(f'{a.mass_kg:.4g} kg r {a.radius_m * 1e3:.3g} mm at ('
                              + ', '.join(fmt(x) for x in a.centre_m[:layout.dim]) + ')'
                              for a in b.added) or '-'
            lines.append(f'| {name} | {v} | {fmt(b.mass_kg or 0.0)} | '
                         + ', '.join(fmt(x) for x in b.mass_centre_m[:layout.dim])
                         + f' | {added} |')
    return markdown(lines)
