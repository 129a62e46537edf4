"""
Design bolt-on counterweights: steel discs, collision-free by default, and the price of clearance.

::

    python examples/counterweights.py [SCENE] [LINK ...]   # default: hoeken crank rocker

Each disc goes in a layer of its own beyond the linkage, clear of every body by 3 mm over the
cycle.  The price of clearance is the design's objective beside the convex program's
certified lower bound (docs/build.md).  Forcing every disc above the linkage (``disc_side``)
makes the discs move in the plane, at a price.
"""

import sys

import mech_balance as mb

scene = mb.load_scene(sys.argv[1] if len(sys.argv) > 1 else 'hoeken')
links = tuple(sys.argv[2:]) or ('crank', 'rocker')


def show(title, design):
    """Print the discs, the least clearance and the price of clearance of a design."""
    clear = design.report['clearance_design']
    print(f'{title}: {design.summary()}')
    for link, discs in design.report['counterweights'].items():
        for disc in discs:
            print(f'  {link} disc: mass {disc["mass_kg"]:.6g} kg, radius {disc["radius_m"]:.6g}'
                  f' m, thickness {disc["thickness_m"]:.6g} m, centre',
                  ' '.join(f'{x:.6g}' for x in disc['centre_m']), 'm')
    print(f'  {clear["status"]}: least clearance {clear["least_clearance_m"]:.6g} m '
          f'(margin {clear["margin_m"]:g} m), between {" and ".join(clear["least_pair"])}')
    print(f'  price of clearance: objective {clear["objective"]:.9g} beside the lower bound '
          f'{clear["lower_bound"]:.9g}: {clear["price_of_clearance"]:.3g}')


show('default', mb.balance(scene, 'counterweights', links=links))
show('every disc above', mb.balance(scene, 'counterweights', links=links, disc_side='above'))
