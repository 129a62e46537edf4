"""
The analysis layer of mech_balance.

See docs/design.md for what lives here and what it may import.
"""
