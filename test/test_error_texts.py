"""
Error texts of issue 32 item 10: plain numbers and the scene's own names.

A CSV recording's errors print plain numbers (never ``np.float64(...)``), in the vectorized
and in the row-by-row parse; a massless link in a spatial redistribution is named as the
scene's link with the way out (fix it or give it a mass), not an internal ``mass_bounds``.
"""

import copy

from mech_balance import schema
from mech_balance.balancing import conditioning, redistribution, spatial
from mech_balance.cli.main import main
from mech_balance.core.rig import rig_for
from mech_balance.ros import bags
from mech_balance.schema.spatial import spatial_from_dict
import pytest

HEADER = 't_s,crank_position_rad,force_x_N,force_y_N,torque_z_Nm'


def _csv(path, rows, late, trailing_newline):
    lines = [HEADER]
    for k in range(rows):
        t = 0.1 if k == late else k * 0.001
        lines.append(f'{t},{k * 0.01},0.5,0.25,0.0')
    path.write_text('\n'.join(lines) + ('\n' if trailing_newline else ''))
    return path


@pytest.mark.parametrize('rows, late, trailing_newline', [
    (1000, 500, False),                                   # numpy's parse of the whole chunk
    (1000, 500, True),                                    # row by row
    (bags.CSV_CHUNK_ROWS + 10, bags.CSV_CHUNK_ROWS, True),  # row by row after a chunk
])
def test_csv_errors_print_plain_numbers(tmp_path, rows, late, trailing_newline):
    """An unsorted row: its time and the previous one as plain numbers, with the line."""
    path = _csv(tmp_path / 'late.csv', rows, late, trailing_newline)
    with pytest.raises(bags.RecordingError) as err:
        bags.read_csv(path)
    text = str(err.value)
    assert 'np.' not in text, text
    previous = f'{(late - 1) / 1000:.3f}'
    assert f"line {late + 2}, column t_s: 0.1 is not after the previous row's {previous}" in text


def _massless(name='rssr_skew', link='coupler'):
    data, _ = schema.load_data(name)
    data = copy.deepcopy(data)
    data['links'][link]['mass_kg'] = 0.0
    data['links'][link]['inertia_com_kg_m2'] = [0.0] * 6
    return data


def test_massless_link_is_named_with_the_way_out():
    """A free massless link: its scene field, its value and what to do."""
    rig = rig_for(spatial_from_dict(_massless()))
    with pytest.raises(spatial.SpatialBalanceError) as err:
        spatial.redistribute(rig)
    text = str(err.value)
    assert 'mass_bounds' not in text
    assert 'links.coupler.mass_kg: got 0, a massless link' in text
    assert '--fix coupler' in text and 'balance.fixed_links: [coupler]' in text


def test_massless_link_fixed_is_balanced_and_stays_massless(tmp_path, capsys):
    """The way out works: fixed, the massless link stays as it is and the rest is balanced."""
    path = tmp_path / 'massless.yaml'
    import yaml
    path.write_text(yaml.safe_dump(_massless()))
    out = tmp_path / 'balanced.yaml'
    assert main(['balance', '--scene', str(path), '--fix', 'coupler',
                 '--output', str(out)]) == 0, capsys.readouterr().err
    written = yaml.safe_load(out.read_text().split('\n', 1)[1])
    assert written['links']['coupler']['mass_kg'] == 0.0
    assert written['links']['coupler']['inertia_com_kg_m2'] == [0.0] * 6


def _spatial(name='rssr_skew', **changes):
    data, _ = schema.load_data(name)
    data = copy.deepcopy(data)
    for key, value in changes.items():
        section, field = key.split('__')
        data[section][field] = value
    return rig_for(spatial_from_dict(data))


def test_ill_scaled_program_names_the_crank_speed():
    """Issue 32 item 8: a crank speed of 1e12 rad/s against its normalization is named."""
    with pytest.raises(spatial.SpatialBalanceError) as err:
        spatial.redistribute(_spatial(crank__speed_rad_s=1e12))
    text = str(err.value)
    assert 'crank.speed_rad_s = 1e+12 is 1.59e+10 x normalization.omega_rad_s = 62.8319' in text
    assert f'expected a crank speed at most {conditioning.SPEED_UNIT_RATIO_MAX:g} x' in text


def test_the_same_speed_in_its_own_units_solves_certified():
    """The way out the error gives: normalization near the crank speed, certified."""
    rig = _spatial(crank__speed_rad_s=1e12, normalization__omega_rad_s=1e12)
    assert spatial.redistribute(rig).certificate.certified


def test_planar_failed_stage_names_the_crank_speed():
    """The planar program: the failed stage's reason names the crank speed too."""
    from mech_balance.schema.registry import from_dict
    data, _ = schema.load_data('hoeken')
    data = copy.deepcopy(data)
    data['crank']['speed_rad_s'] = 1e12
    cert = redistribution.optimize(from_dict(data)).certificate
    assert not cert.certified
    reasons = ' '.join(f['reason'] for f in cert.failed_stages)
    assert 'crank.speed_rad_s = 1e+12 is 1e+12 x normalization.omega_rad_s = 1' in reasons
