"""
The one home of the project's conventions: units, the shaking wrench and the RMS.

SI everywhere inside; the papers' normalized figures are a view (:func:`normalize_force`,
:func:`normalize_moment`); crank angles in messages in degrees in [0, 360).  The shaking
wrench (seed 001 eq. 39) and the RMS over a cycle: docs/core.md#module-overviews.
"""

import math


DEFAULT_SAMPLES = 360
"""Crank angles per revolution when a caller does not say (one per degree)."""

# Bounds on work and input, checked before the work starts; every error names the field and
# the limit (docs/scenes.md, Limits).  The YAML reader's limits are in safe_yaml.py.
MAX_SAMPLES = 100_000
"""Most crank angles per revolution (scene ``samples:``, ``--samples``, ``balance.samples``)."""
MAX_LINK_SAMPLES = 1_000_000
"""Most moving links x crank angles in one evaluation (about 0.6 GB of kinematic state)."""
MAX_LINKS = 64
"""Most moving links of a scene."""
MAX_JOINTS = 128
"""Most joints of a scene (a single-dof planar rig of MAX_LINKS links has 95)."""
MAX_POINTS = 64
"""Most named points of one link (or of the frame)."""
MAX_CYCLES = 100
"""Most crank turns of a recording (``record --cycles``; 360 samples per turn: ~25 MB of .rrd)."""
MAX_RECORD_ROWS = 36_000
"""Most rows of a recording, ``record --samples`` x ``--cycles`` (360 x :data:`MAX_CYCLES`)."""
MAX_WEIGHT = 1e6
"""Largest objective weight (``--weights``, ``--torque-weight``, ``balance.*weight*``)."""
MAX_NAME_LENGTH = 256
"""Longest name accepted where one is given as text (``frame_id``)."""
MAX_TABLE_ROWS = 10_000
"""Most rows of a printed time table (``simulate --rows``)."""
MAX_REPEAT = 10_000
"""Most timed runs per benchmark figure (``bench --repeat``)."""


def check_samples(samples, field='samples', links=1):
    """Return ``samples`` as an int within the limits (``links`` per angle), else ValueError."""
    try:
        count = int(samples)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f'{field}: got {samples!r}, expected an integer') from None
    if count != samples:
        raise ValueError(f'{field}: got {samples!r}, expected an integer')
    if count < 1:
        raise ValueError(f'{field}: got {count}, expected an integer >= 1')
    if count > MAX_SAMPLES:
        raise ValueError(f'{field}: got {count}, expected at most {MAX_SAMPLES} crank angles '
                         'per revolution (a fixed limit of mech_balance)')
    if count * max(int(links), 1) > MAX_LINK_SAMPLES:
        raise ValueError(f'{field}: got {count} crank angles x {int(links)} moving links = '
                         f'{count * int(links)}, expected at most {MAX_LINK_SAMPLES} '
                         '(a fixed limit of mech_balance); use fewer samples')
    return count


def cycle_angles(samples, start_rad=0.0, links=1):
    """Return ``samples`` equally spaced crank angles of one revolution (end excluded), rad."""
    import numpy as np  # on first use: the command line parsers need none
    samples = check_samples(samples, links=links)
    return start_rad + 2.0 * np.pi * np.arange(samples) / samples


def crank_angle_text(angle_rad, digits):
    """Return crank angle ``angle_rad`` as a message prints it: degrees in [0, 360), ``digits``."""
    deg = round(math.degrees(angle_rad) % 360.0, digits) % 360.0
    return f'{deg:.{digits}f}'


def rms(values, axis=0):
    """Return the RMS over ``axis`` of a ``(p,)`` series or of the magnitudes of ``(p, k)``."""
    import numpy as np  # on first use: the command line parsers need none
    v = np.asarray(values, dtype=float)
    if v.ndim == 0:
        raise ValueError('values: got a scalar, expected a series over crank angles')
    sq = v * v if v.ndim == 1 else np.sum(v * v, axis=-1)
    return np.sqrt(np.mean(sq, axis=axis))


def normalize_force(force_N, mass_kg, length_m, omega_rad_s):
    """Return a force in units of m_1 * a_1 * omega^2 (seed 001, section 3.4)."""
    import numpy as np  # on first use: the command line parsers need none
    return np.asarray(force_N, dtype=float) / (mass_kg * length_m * omega_rad_s ** 2)


def normalize_moment(moment_Nm, mass_kg, length_m, omega_rad_s):
    """Return a moment or torque in units of m_1 * a_1^2 * omega^2 (seed 001, section 3.4)."""
    import numpy as np  # on first use: the command line parsers need none
    return np.asarray(moment_Nm, dtype=float) / (mass_kg * length_m ** 2 * omega_rad_s ** 2)
