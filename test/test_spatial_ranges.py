"""
The spatial redistribution over its documented option ranges (issue 19 item 3).

Every end of ``--mass-factors`` (defaults.SPATIAL_MASS_FACTOR_RANGE) and ``--extent-factor``
(defaults.EXTENT_FACTOR_RANGE) solves to a certified optimum on each spatial built-in: the
safe lower bound lies below the design's objective and within the package's certification
threshold of it (certificate.CERTIFIED_GAP_REL), and the design meets every constraint to its
stated accuracy.  A value outside a range is refused where it is read (library and command
line), naming the option, its value and the range; ``--help`` shows the ranges.
"""

import math

from mech_balance import schema
from mech_balance.balancing import certificate, defaults, spatial
from mech_balance.balancing.spatial import redistribution as spatial_redistribution, \
    repair as spatial_repair
from mech_balance.cli import main as cli
from mech_balance.core.rig import rig_for
import pytest

SCENES = ('rssr_skew', 'rggr_spatial', 'spatial_two_loop', 'rssp_slider', 'pssr_skew')
"""The spatial built-ins (kind spatial and the RGGR as a spatial scene)."""
LOW_MASS, HIGH_MASS = defaults.SPATIAL_MASS_FACTOR_RANGE
LOW_EXTENT, HIGH_EXTENT = defaults.EXTENT_FACTOR_RANGE
MASS_ENDS = ((LOW_MASS, LOW_MASS), (LOW_MASS, HIGH_MASS), (HIGH_MASS, HIGH_MASS))
"""Every pair of ends of the mass-factor range (lo <= hi)."""
EXTENT_ENDS = (LOW_EXTENT, spatial_redistribution.EXTENT_FACTOR, HIGH_EXTENT)
"""Both ends of the extent range, and its default."""
WEIGHTS = ((0.5, 0.5), (1.0, 0.0), (0.0, 1.0))
"""The default weights and the two single-term objectives (force alone: the hardest)."""


@pytest.fixture(scope='module')
def rigs():
    return {name: rig_for(schema.load(name)) for name in SCENES}


@pytest.mark.parametrize('scene_name', SCENES)
@pytest.mark.parametrize('mass_factors', MASS_ENDS)
@pytest.mark.parametrize('weights', WEIGHTS)
def test_range_ends_solve_certified(rigs, scene_name, mass_factors, weights):
    rig = rigs[scene_name]
    for extent_factor in EXTENT_ENDS:
        result = spatial.redistribute(rig, weights=weights, mass_factors=mass_factors,
                                      extent_factor=extent_factor)
        cert = result.certificate
        where = (f'{scene_name} weights {weights} mass_factors {mass_factors} extent_factor '
                 f'{extent_factor}')
        assert math.isfinite(cert.lower_bound), where
        assert cert.lower_bound <= cert.primal, (where, cert)
        assert cert.gap_rel <= certificate.CERTIFIED_GAP_REL, (where, cert.gap_rel)
        assert cert.certified, where
        # the design returned meets every bound (units of each body's mass and reach)
        assert result.options['violation_after_pull'] <= spatial_repair.VIOLATION_TOL, where


@pytest.mark.parametrize('kwargs,match', [
    ({'extent_factor': LOW_EXTENT * 0.99}, r'extent_factor: got 0\.099, expected a number '
                                           r'in \[0\.1, 2\]'),
    ({'extent_factor': 2.5}, r'extent_factor: got 2\.5, expected a number in \[0\.1, 2\]'),
    ({'extent_factor': 1e9}, r'extent_factor: got 1e\+09, expected a number in \[0\.1, 2\]'),
    ({'extent_factor': 1e-3}, r'extent_factor: got 0\.001, expected a number in \[0\.1, 2\]'),
    ({'extent_factor': math.nan}, r'extent_factor: got nan, expected a number in \[0\.1, 2\]'),
    ({'extent_factor': -1.0}, r'extent_factor: got -1, expected a number in \[0\.1, 2\]'),
    ({'mass_factors': (1.0, 1e6)}, r'mass_factors: got 1e\+06, expected a number in '
                                   r'\[1e-06, 100\]'),
    ({'mass_factors': (1e-7, 1.0)}, r'mass_factors: got 1e-07, expected a number in '
                                    r'\[1e-06, 100\]'),
    ({'extent_bounds': {'crank': 1e-4}}, r'extent_bounds\.crank: got 0\.0001 m, expected a '
                                         r'radius in \[0\.1, 2\] x its reach'),
    ({'mass_bounds': {'crank': (1.0, 1e9)}}, r'mass_bounds\.crank: got 1e\+09 kg, expected a '
                                             r'mass in \[1e-06, 100\] x its original')])
def test_out_of_range_refused_by_the_library(rigs, kwargs, match):
    with pytest.raises(ValueError, match=match):
        spatial.redistribute(rigs['rssr_skew'], samples=8, **kwargs)


@pytest.mark.parametrize('argv,message', [
    (['--extent-factor', '1e9'], '--extent-factor: got 1e+09, expected a number in [0.1, 2]'),
    (['--extent-factor', '0.05'], '--extent-factor: got 0.05, expected a number in [0.1, 2]'),
    (['--mass-factors', '1', '1e6'],
     '--mass-factors: got 1e+06, expected a number in [1e-06, 100]')])
def test_out_of_range_refused_by_the_command_line(capsys, argv, message):
    status = cli.main(['balance', '--scene', 'rssr_skew', '--samples', '8', *argv])
    captured = capsys.readouterr()
    assert status == cli.EXIT_USAGE
    assert message in captured.err
    assert captured.out == ''       # refused before any solve: nothing printed


def test_help_shows_the_ranges(capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(['balance', '--help'])
    assert exc.value.code == 0
    text = ' '.join(capsys.readouterr().out.split())
    assert f'range {LOW_EXTENT:g} to {HIGH_EXTENT:g}' in text
    assert f'spatial redistribution {LOW_MASS:g} to {HIGH_MASS:g}' in text
