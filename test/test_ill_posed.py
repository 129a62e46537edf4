"""
Issue 32 item 8: a failed cone program names the scene value that makes it ill-posed.

Each cause is a mutated built-in scene whose program Clarabel cannot solve (NumericalError or
InsufficientProgress after every retry): the answer names the field, its value and what was
expected (:mod:`mech_balance.balancing.conditioning`).  The crank speed far above its
normalization is ``test_error_texts``'s.
"""

import copy

from mech_balance import schema
from mech_balance.balancing import conditioning, redistribution, spatial
from mech_balance.core.rig import rig_for
from mech_balance.schema.registry import from_dict
import pytest


def _scene(name, body=None, factor=1.0, **normalization):
    """Return a built-in scene with one link (mass and inertia) x factor, units changed."""
    data, _ = schema.load_data(name)
    data = copy.deepcopy(data)
    # a name of its own: the planar core caches a compiled linkage by the scene's name and
    # geometry (core.planar.rig.linkage_for), and the linkage keeps its scene's crank speed
    data['name'] = f'{name}_ill_posed'
    if body is not None:
        link = data['links'][body]
        link['mass_kg'] *= factor
        for key in ('inertia_origin_kg_m2', 'inertia_com_kg_m2'):
            if isinstance(link.get(key), list):
                link[key] = [x * factor for x in link[key]]
            elif key in link:
                link[key] *= factor
    for key, scale in normalization.items():
        data['normalization'][key] *= scale
    return from_dict(data)


def _spatial_error(sc):
    with pytest.raises(spatial.SpatialBalanceError) as err:
        spatial.redistribute(rig_for(sc))
    text = str(err.value)
    assert 'Clarabel status' in text, text
    return text


def test_a_link_heavier_by_decades_is_named():
    """
    The crank of rssr_skew 1e8 x heavier: NumericalError.

    Its mass is named against the objective's unit and against the lightest link.
    """
    text = _spatial_error(_scene('rssr_skew', 'crank', 1e8))
    assert ('links.crank.mass_kg = 4e+07 is 1e+08 x normalization.mass_kg = 0.4, the unit of '
            'the objective, expected at most 1e+06 x') in text
    assert ('links.crank.mass_kg = 4e+07 is 1.6e+08 x links.coupler.mass_kg = 0.25, expected '
            'link masses within 1e+06 x of each other') in text


def test_a_mass_unit_far_below_the_links_is_named():
    text = _spatial_error(_scene('rssr_skew', mass_kg=1e-10))
    assert ('links.rocker.mass_kg = 0.6 is 1.5e+10 x normalization.mass_kg = 4e-11') in text
    assert 'links.crank.mass_kg' not in text   # the masses themselves span less than 3 x


def test_a_length_unit_far_below_the_links_is_named():
    text = _spatial_error(_scene('rssr_skew', length_m=1e-8))
    assert 'links.coupler.points reach 0.18 m, 6e+08 x normalization.length_m = 3e-10' in text
    assert f'expected at most {conditioning.LENGTH_UNIT_RATIO_MAX:g} x' in text


def test_the_planar_failed_stage_names_the_heavy_link():
    """
    The crank of hoeken 1e10 x heavier: InsufficientProgress, the design not certified.

    The failed stage's reason names the crank's mass.
    """
    cert = redistribution.optimize(_scene('hoeken', 'crank', 1e10)).certificate
    assert not cert.certified and cert.failed_stages
    reason = cert.failed_stages[0]['reason']
    assert 'Clarabel status' in reason
    assert 'links.crank.mass_kg = 3.26e+09 is 1e+10 x normalization.mass_kg = 0.326' in reason
    assert ('links.crank.mass_kg = 3.26e+09 is 5.26e+09 x links.rocker.mass_kg = 0.6194, '
            'expected link masses within 1e+06 x of each other') in reason


@pytest.mark.parametrize('name', ['hoeken', 'rssr_skew', 'rggr', 'pssr_skew'])
def test_a_well_posed_scene_blames_nothing(name):
    sc = schema.load(name)
    assert conditioning.blame(sc, sc.normalization, sc.crank_speed_rad_s) == ''


def test_mass_bounds_of_zero_are_refused_naming_them():
    """Bounds (0, 0): no body; refused before any solve, naming the option and the link."""
    with pytest.raises(ValueError, match=r'mass_bounds.crank: got \(0, 0\), expected '
                                         r'0 < min <= max'):
        redistribution.optimize(schema.load('hoeken'), mass_bounds={'crank': (0.0, 0.0)})
