"""
The five-line script of ``mech_balance``'s docstring: load, rig, evaluate, balance, print.

Runs unchanged on every built-in scene (``mech-balance scenes``) and on any scene file::

    python examples/quickstart.py [SCENE]      # default: hoeken

``test/test_conformance.py`` runs it on every built-in.
"""

import sys

import mech_balance as mb

sc = mb.load_scene(sys.argv[1] if len(sys.argv) > 1 else 'hoeken')
rig = mb.rig_for(sc)
data = rig.at([0.0, 0.1], speed=10.0)
design = mb.balance(rig)
print(design.masses_kg)
