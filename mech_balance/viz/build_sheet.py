"""
The build sheet of a counterweight design: one SVG page a workshop can work from.

Per link with a disc: the link as built with its disc, web and shaft to scale, and the
disc's dimensions, place, layer, material and mass; at the foot the totals and a side view.
Every number is a ``<text>`` with an ``id`` and its ``data-value`` (:func:`read_values`);
``.png``/``.pdf`` by ``rsvg-convert`` (docs/build.md).
"""

import os
import shutil
import subprocess
import xml.etree.ElementTree as ET

from mech_balance.analysis import layers as layer_model
from mech_balance.atomic import write_bytes_atomic, write_text_atomic
from mech_balance.core.planar import drawn
from mech_balance.core.planar.kinematics import Linkage

PAGE_W = 820
"""Page width (px); the height grows with the number of links."""
PANEL_H = 250
"""Height of one link's panel (px)."""
DRAW_W = 420
"""Width of the drawing area of a panel (px)."""
MARGIN_PX = 24
MATERIALS = {7850.0: 'steel', 7200.0: 'cast iron', 2700.0: 'aluminium', 8500.0: 'brass',
             11340.0: 'lead'}
"""Names of common densities (kg/m^3); another density is printed as a number."""
FONT = 'font-family="DejaVu Sans, Arial, sans-serif"'


def material(density_kg_m3):
    """Return a material's name from its density, or the density itself."""
    name = MATERIALS.get(float(density_kg_m3))
    return f'{name} ({density_kg_m3:g} kg/m^3)' if name else f'{density_kg_m3:g} kg/m^3'


def link_axis(link, mount):
    """Return ``(joint, unit, far end)``: the link's axis from its mount joint (complex, m)."""
    j = complex(*link.points[mount])
    others = [(abs(complex(*p) - j), k) for k, p in link.points.items() if k != mount]
    if not others or max(others)[0] == 0.0:
        return j, 1.0 + 0.0j, None
    far = max(others)[1]
    d = complex(*link.points[far]) - j
    return j, d / abs(d), far


def sheet_rows(result):
    """Return the sheet's numbers per disc (dicts, SI and mm; across: left +) and the totals."""
    rows = []
    for d in result.designs:
        link = result.scene.link(d.link)
        mount = layer_model.mount_point(link, d.centre_m, d.mount)[0]
        j, u, far = link_axis(link, mount)
        rel = (complex(*d.centre_m) - j) / u
        rows.append({'link': d.link, 'mount': mount, 'towards': far,
                     'diameter_mm': 2e3 * d.radius_m, 'thickness_mm': 1e3 * d.thickness_m,
                     'along_mm': 1e3 * rel.real, 'across_mm': 1e3 * rel.imag,
                     'layer_mm': 1e3 * d.plane_m, 'mass_kg': d.mass_kg,
                     'material': material(d.density_kg_m3), 'design': d})
    cost = result.cost
    totals = {'added_mass_kg': result.added_mass_kg,
              'force_before_N': cost['shaking_force']['before'],
              'force_after_N': cost['shaking_force']['after'],
              'moment_before_Nm': cost['shaking_moment']['before'],
              'moment_after_Nm': cost['shaking_moment']['after']}
    return rows, totals


def _text(x, y, ident, label, value, fmt, unit, size=13, weight='normal'):
    shown = format(value, fmt)
    if float(shown) == 0.0:   # no '-0.0'
        shown = format(0.0, fmt)
    return (f'<text x="{x:.1f}" y="{y:.1f}" {FONT} font-size="{size}" '
            f'font-weight="{weight}" id="{ident}" data-value="{value!r}">'
            f'{_esc(label)}<tspan class="value">{shown}</tspan>{_esc(unit)}</text>')


def _plain(x, y, words, size=13, weight='normal', fill='#000'):
    return (f'<text x="{x:.1f}" y="{y:.1f}" {FONT} font-size="{size}" font-weight="{weight}" '
            f'fill="{fill}">{_esc(words)}</text>')


def _esc(text):
    return str(text).replace('&', '&amp;').replace('<', '&lt;').replace('>', '&gt;')


def render(result):
    """Return the build sheet of a :class:`CounterweightResult` as SVG text."""
    rows, totals = sheet_rows(result)
    sc = result.scene
    linkage = Linkage(sc)
    lay = layer_model.Layers.of(sc, linkage)
    # one scale for every panel: the largest extent of a link with its disc fits DRAW_W
    extents = []
    for r in rows:
        link, d = sc.link(r['link']), r['design']
        j, u, _ = link_axis(link, r['mount'])
        pts = [(complex(*p) - j) / u for p in link.points.values()]
        c = (complex(*d.centre_m) - j) / u
        xs = [p.real for p in pts] + [c.real - d.radius_m, c.real + d.radius_m]
        ys = [p.imag for p in pts] + [c.imag - d.radius_m, c.imag + d.radius_m]
        extents.append((min(xs), max(xs), min(ys), max(ys)))
    pad = 2.0 * lay.pin_radius_m
    span_x = max((e[1] - e[0] for e in extents), default=1.0) + 2 * pad
    span_y = max((e[3] - e[2] for e in extents), default=1.0) + 2 * pad
    px_per_m = min((DRAW_W - 2 * MARGIN_PX) / span_x, (PANEL_H - 60) / span_y)
    head_h, foot_h = 70, 110 + SIDE_H
    height = head_h + PANEL_H * len(rows) + foot_h
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{PAGE_W}" height="{height}" '
           f'viewBox="0 0 {PAGE_W} {height}">',
           f'<rect width="{PAGE_W}" height="{height}" fill="white"/>',
           _plain(MARGIN_PX, 30, f'Counterweight build sheet: {sc.name}', 18, 'bold'),
           _plain(MARGIN_PX, 52, f'drawn to scale, 1 mm = {px_per_m / 1e3:.3g} px; '
                  'link axis horizontal from the mount joint; all dimensions in mm', 12,
                  fill='#333')]
    bar_mm = _scale_bar_mm(px_per_m)
    x0 = PAGE_W - MARGIN_PX - bar_mm * px_per_m / 1e3
    out.append(f'<line x1="{x0:.1f}" y1="46" x2="{PAGE_W - MARGIN_PX:.1f}" y2="46" '
               'stroke="black" stroke-width="3"/>')
    out.append(_plain(x0, 40, f'{bar_mm:g} mm', 11))
    for k, (r, e) in enumerate(zip(rows, extents)):
        top = head_h + k * PANEL_H
        out += _panel(sc, lay, r, e, top, px_per_m, pad)
    y = head_h + PANEL_H * len(rows) + 24
    out.append(f'<line x1="{MARGIN_PX}" y1="{y - 16}" x2="{PAGE_W - MARGIN_PX}" y2="{y - 16}" '
               'stroke="#888"/>')
    out.append(_text(MARGIN_PX, y + 4, 'total-added-mass-kg', 'total added mass ',
                     totals['added_mass_kg'], '.4g', ' kg', 14, 'bold'))
    for dy, what, key, unit in ((28, 'force', 'force_{}_N', ' N'),
                                (50, 'moment', 'moment_{}_Nm', ' N m')):
        for dx, when in ((0, 'before'), (300, 'after')):
            label = f'RMS shaking {what}: before ' if when == 'before' else 'after '
            out.append(_text(MARGIN_PX + dx, y + dy, key.format(when).replace('_', '-'),
                             label, totals[key.format(when)], '.4g', unit))
    clear = result.clearance
    if clear is not None and clear.least is not None:
        out.append(_text(MARGIN_PX, y + 72, 'least-clearance-mm', 'least clearance over the '
                         'cycle ', clear.least.clearance_m * 1e3, '.3g',
                         f' mm (margin {clear.margin_m * 1e3:g} mm)', 12))
    out += side_view(result, MARGIN_PX, y + 90, PAGE_W - 2 * MARGIN_PX, SIDE_H - 20)
    out.append('</svg>')
    return '\n'.join(out) + '\n'


def _scale_bar_mm(px_per_m):
    """Return a round length (mm) whose bar is 60-150 px long."""
    for mm in (1, 2, 5, 10, 20, 50, 100, 200, 500, 1000):
        if mm * px_per_m / 1e3 >= 60:
            return mm
    return 1000


def _panel(sc, lay, r, extent, top, k, pad):
    """Return the SVG elements of one link's panel."""
    link, d = sc.link(r['link']), r['design']
    j, u, _ = link_axis(link, r['mount'])
    x_lo, _, _, y_hi = extent
    ox = MARGIN_PX + (pad - x_lo) * k
    oy = top + 30 + (pad + y_hi) * k

    def at(p):
        q = (p - j) / u
        return ox + q.real * k, oy - q.imag * k

    name = r['link']
    own = lay.layers[name]
    out = [f'<rect x="{MARGIN_PX / 2}" y="{top + 4}" width="{PAGE_W - MARGIN_PX}" '
           f'height="{PANEL_H - 8}" fill="none" stroke="#bbb"/>',
           _plain(MARGIN_PX, top + 22, f'link {name}', 15, 'bold')]
    local = {p: complex(*v) for p, v in link.points.items()}
    w = own.bar_width_m * k
    for a, b in drawn.bar_edges(local):
        (xa, ya), (xb, yb) = at(local[a]), at(local[b])
        out.append(f'<line x1="{xa:.1f}" y1="{ya:.1f}" x2="{xb:.1f}" y2="{yb:.1f}" '
                   f'stroke="#9aa7b8" stroke-width="{w:.1f}" stroke-linecap="round"/>')
    c = complex(*d.centre_m)
    m = local[r['mount']]
    (xm, ym), (xc, yc) = at(m), at(c)
    if d.plane_m != 0.0 and abs(c - m) > 0.0:   # the web, under the disc
        out.append(f'<line x1="{xm:.1f}" y1="{ym:.1f}" x2="{xc:.1f}" y2="{yc:.1f}" '
                   f'stroke="#c98b4a" stroke-width="{w:.1f}" stroke-linecap="round" '
                   'opacity="0.8"/>')
    out.append(f'<circle cx="{xc:.1f}" cy="{yc:.1f}" r="{d.radius_m * k:.1f}" '
               'fill="#e8b04a" fill-opacity="0.55" stroke="#8a5a00" stroke-width="1.5"/>')
    out.append(f'<line x1="{xc - 5:.1f}" y1="{yc:.1f}" x2="{xc + 5:.1f}" y2="{yc:.1f}" '
               'stroke="black"/>')
    out.append(f'<line x1="{xc:.1f}" y1="{yc - 5:.1f}" x2="{xc:.1f}" y2="{yc + 5:.1f}" '
               'stroke="black"/>')
    for p, v in local.items():
        x, y = at(v)
        out.append(f'<circle cx="{x:.1f}" cy="{y:.1f}" r="{lay.pin_radius_m * k:.1f}" '
                   'fill="white" stroke="#333" stroke-width="1.5"/>')
        out.append(_plain(x + lay.pin_radius_m * k + 3, y - lay.pin_radius_m * k - 2, p, 11,
                          fill='#333'))
    # the centre's offsets from the mount joint: dashed along, then across
    (xa, ya) = at(j + u * ((c - j) / u).real)
    out.append(f'<polyline points="{xm:.1f},{ym:.1f} {xa:.1f},{ya:.1f} {xc:.1f},{yc:.1f}" '
               'fill="none" stroke="#d33" stroke-dasharray="4 3"/>')
    tx, ty, step = DRAW_W + 10, top + 48, 21
    side = 'above' if d.plane_m > 0 else 'below' if d.plane_m < 0 else 'in'
    lines = [
        _text(tx, ty, f'{name}-diameter-mm', 'disc diameter ', r['diameter_mm'], '.1f', ' mm'),
        _text(tx, ty + step, f'{name}-thickness-mm', 'thickness ', r['thickness_mm'], '.1f',
              ' mm'),
        _text(tx, ty + 2 * step, f'{name}-along-mm', f'centre from {r["mount"]}: along ',
              r['along_mm'], '.1f', ' mm' + (f' (towards {r["towards"]})'
                                             if r['towards'] else '')),
        _text(tx, ty + 3 * step, f'{name}-across-mm', 'across (left of the axis) ',
              r['across_mm'], '.1f', ' mm'),
        _text(tx, ty + 4 * step, f'{name}-layer-mm', 'layer offset ', r['layer_mm'], '+.1f',
              f' mm ({side} the linkage)'),
        _plain(tx, ty + 5 * step, f'mounted on a shaft at {r["mount"]}, with a web'
               if d.plane_m != 0.0 else 'bolted to the link in its plane', 12, fill='#333'),
        _plain(tx, ty + 6 * step, f'material {r["material"]}', 13),
        _text(tx, ty + 7 * step, f'{name}-mass-kg', 'mass ', r['mass_kg'], '.4g', ' kg', 13,
              'bold')]
    return out + lines


SIDE_H = 300
"""Height of the side view (px)."""


def side_view(result, x0, top, width, height):
    """Return the SVG elements of the stack along the joint axes at crank angle 0, side view."""
    from mech_balance.analysis import clearance as clearance_mod
    from mech_balance.core.planar.rig import PlanarRig
    sc = result.balanced_scene
    rig = PlanarRig(result.scene).with_scene(sc)
    lay = layer_model.Layers.of(sc, rig.linkage)
    sweep = clearance_mod.Sweep(rig, [0.0])
    boxes = []
    for b in clearance_mod.bodies(rig, lay):
        k = sweep.index[b.link]
        o, r = sweep.origin[k, 0], sweep.rot[k, 0]
        xs = [(o + r * b.a).real, (o + r * b.b).real]
        boxes.append((b, min(xs) - b.radius_m, max(xs) + b.radius_m,
                      b.z_m - 0.5 * b.thickness_m, b.z_m + 0.5 * b.thickness_m))
    x_lo, x_hi = min(v[1] for v in boxes), max(v[2] for v in boxes)
    z_lo, z_hi = min(v[3] for v in boxes), max(v[4] for v in boxes)
    kx = (width - 180) / (x_hi - x_lo)
    kz = min((height - 50) / (z_hi - z_lo), kx * 4.0)
    colour = {'bar': '#9aa7b8', 'boss': '#6c7a8c', 'block': '#9aa7b8', 'pin': '#333',
              'disc': '#e8b04a', 'shaft': '#8a5a00', 'web': '#c98b4a'}
    out = [_plain(x0, top + 16, 'the stack along the joint axes at crank angle 0 (side view; '
                  f'x 1 mm = {kx / 1e3:.3g} px, z 1 mm = {kz / 1e3:.3g} px)', 13, 'bold')]
    order = {'bar': 0, 'block': 0, 'web': 1, 'disc': 2, 'boss': 3, 'pin': 4, 'shaft': 5}
    for b, xa, xb, za, zb in sorted(boxes, key=lambda v: order[v[0].shape]):
        y = top + 30 + (z_hi - zb) * kz
        out.append(f'<rect x="{x0 + (xa - x_lo) * kx:.1f}" y="{y:.1f}" '
                   f'width="{max((xb - xa) * kx, 1.0):.1f}" '
                   f'height="{max((zb - za) * kz, 1.0):.1f}" '
                   f'fill="{colour[b.shape]}" fill-opacity="{0.6 if b.shape == "disc" else 0.9}" '
                   'stroke="#333" stroke-width="0.5"/>')
    for name, layer in lay.layers.items():
        y = top + 30 + (z_hi - layer.z_m) * kz
        out.append(_plain(x0 + (x_hi - x_lo) * kx + 8, y + 4, f'{name} z {layer.z_m * 1e3:.1f}',
                          11, fill='#333'))
    for d in result.designs:
        z = lay.z_m(d.link) + d.plane_m
        y = top + 30 + (z_hi - z) * kz
        out.append(_plain(x0 + (x_hi - x_lo) * kx + 8, y + 4,
                          f'{d.link} disc z {z * 1e3:.1f}', 11, fill='#8a5a00'))
    return out


FORMATS = ('.svg', '.png', '.pdf')
"""The build sheet's file types: SVG written here, PNG and PDF rendered by ``rsvg-convert``."""
RENDER_TIMEOUT_S = 120.0
"""Longest wait for ``rsvg-convert`` (s)."""


def check_path(path, field='--build-sheet'):
    """Return ``path`` as text if it names a sheet type this machine can write, else raise."""
    path = str(path)
    suffix = os.path.splitext(path)[1].lower()
    if suffix not in FORMATS:
        raise ValueError(f'{field}: got {path!r}, expected a file name ending in '
                         f'{", ".join(FORMATS)}')
    if suffix != '.svg' and shutil.which('rsvg-convert') is None:
        raise ValueError(f'{field}: got {path!r}: {suffix[1:].upper()} needs rsvg-convert '
                         '(Debian librsvg2-bin), not found on PATH; expected FILE.svg')
    return path


def write(result, path):
    """Write the build sheet of ``result`` to ``path`` (SVG, or PNG/PDF by rsvg-convert)."""
    path = check_path(path)
    svg = render(result)
    suffix = os.path.splitext(path)[1].lower()
    if suffix == '.svg':
        write_text_atomic(path, svg)
        return
    run = subprocess.run(['rsvg-convert', '-f', suffix[1:]], input=svg.encode('utf-8'),
                         capture_output=True, timeout=RENDER_TIMEOUT_S, check=False)
    if run.returncode != 0 or not run.stdout:
        raise ValueError(f'--build-sheet: rsvg-convert failed on {path!r} (status '
                         f'{run.returncode}): {run.stderr.decode(errors="replace").strip()}')
    write_bytes_atomic(path, run.stdout)


def read_values(svg_text):
    """Return ``{id: (number as printed, value)}`` of every numbered text of a build sheet."""
    ns = '{http://www.w3.org/2000/svg}'
    root = ET.fromstring(svg_text)
    out = {}
    for el in root.iter(f'{ns}text'):
        if el.get('id'):
            shown = el.find(f'{ns}tspan')
            out[el.get('id')] = (shown.text, float(el.get('data-value')))
    return out
