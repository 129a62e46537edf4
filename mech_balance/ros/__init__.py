"""
The ros layer of mech_balance.

See the README's design section for what lives here and what it may import.
"""
