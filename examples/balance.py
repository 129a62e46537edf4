"""
Balance a rig: the certified optimal mass redistribution, and its certificate.

::

    python examples/balance.py [SCENE]      # default: hoeken

``mb.balance`` picks the method the rig supports (planar and spatial rigs: the certified
redistribution of Chaudhary & Saha's problem).  The certificate is a proven lower bound on
the optimum beside the design's objective: their gap says how far from optimal the design
can be (docs/balancing.md).
"""

import sys

import mech_balance as mb

scene = mb.load_scene(sys.argv[1] if len(sys.argv) > 1 else 'hoeken')
design = mb.balance(scene)

print(design.summary())
print(f'method: {design.method}')
print(f'objective: {design.objective:.9g}  ({design.objective_name})')
print(f'lower bound: {design.lower_bound:.9g}')
gap = design.objective - design.lower_bound
print(f'gap: {gap:.3g} (the design is at most this far from the optimum)')
print(f'certified: {design.certified}, status {design.status}: {design.message}')
for link in design.links:
    print(f'link {link["name"]}: mass {link["mass_kg"]:.6g} kg, mass centre',
          ' '.join(f'{x:.6g}' for x in link['mass_centre_m']), 'm')
for row in design.table_in():
    print(f'{row["quantity"]}: {row["before"]:.6g} -> {row["after"]:.6g} {row["unit"]}')
