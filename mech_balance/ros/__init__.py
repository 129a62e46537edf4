"""The ros layer of mech_balance: docs/design.md says what lives here."""
