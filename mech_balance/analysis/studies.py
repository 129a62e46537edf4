"""The names and defaults of the accuracy studies (no imports)."""


ACCURACY_TURNS = 2.0
"""Default simulated time of the integrator study, in crank turns at the operating speed."""


SECTIONS = ('rms', 'integrators', 'position', 'balancing')
