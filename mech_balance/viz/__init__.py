"""The viz layer of mech_balance (its scope and imports: docs/design.md#layers)."""
