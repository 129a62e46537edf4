"""
Equimomental three-point-mass models of planar links (seed 001 eqs. 1-22, 27, 45).

:func:`is_realizable` is the one definition of a buildable link; the model:
docs/core.md#module-overviews.
"""

from dataclasses import dataclass, replace
import math

from mech_balance.schema.fields import MAX_ABS_VALUE
import numpy as np

POINT_ANGLES_RAD = np.array([0.0, 2.0 * math.pi / 3.0, 4.0 * math.pi / 3.0])
"""The angles of the three point masses in the link frame (seed 001 eq. 27)."""
UNIT = np.exp(1j * POINT_ANGLES_RAD)
"""The unit vectors e^(i theta_j) towards the three point masses, shape (3,) complex."""
REALIZABLE_TOL = 1e-6
"""A link whose centroidal moment of inertia is at most this fraction of I_O is a point mass
(an optimum on the bound I_c = 0, seed 001 Table 5 b(2), lands within ~1e-8 I_O of it)."""
COUNTERWEIGHT_TOL = 1e-8
"""With counterweights, point masses down to -this fraction of the link mass count as zero."""


@dataclass(frozen=True)
class PointMasses:
    """Three equimomental point masses of one link (SI: kg and m)."""

    masses_kg: tuple
    distance_m: float

    @property
    def mass_kg(self):
        """Return the link mass, eq. 19."""
        return float(sum(self.masses_kg))

    @property
    def first_moment_kg_m(self):
        """Return m*c as a complex number in the link frame, eqs. 20-21."""
        return complex(self.distance_m * np.dot(self.masses_kg, UNIT))

    @property
    def inertia_origin_kg_m2(self):
        """Return the moment of inertia about the link origin, eq. 22."""
        return self.distance_m ** 2 * self.mass_kg


def point_mass_arrays(mass, first_moment, inertia_origin):
    """Return point masses ``(..., 3)`` and distances l of links (eqs. 8-15; no checks)."""
    m = np.asarray(mass, dtype=float)
    h = np.asarray(first_moment, dtype=complex)
    dist = np.sqrt(np.asarray(inertia_origin, dtype=float) / m)
    masses = m[..., None] / 3.0 + (2.0 / 3.0) * (
        h[..., None] * np.conj(UNIT)).real / dist[..., None]
    return masses, dist


def from_link(mass_kg, com_m, inertia_origin_kg_m2):
    """Return the :class:`PointMasses` of a link, ``com_m`` ``(x, y)`` (seed 001 eqs. 8-15)."""
    if not mass_kg > 0.0:
        raise ValueError(f'mass_kg: got {mass_kg!r}, expected > 0')
    if not inertia_origin_kg_m2 > 0.0:
        raise ValueError(f'inertia_origin_kg_m2: got {inertia_origin_kg_m2!r}, expected > 0')
    masses, dist = point_mass_arrays(mass_kg, complex(*com_m) * mass_kg, inertia_origin_kg_m2)
    return PointMasses(tuple(float(v) for v in masses), float(dist))


def link_properties(point_masses):
    """Return ``(mass_kg, com_m (x, y), inertia_origin_kg_m2)`` (ValueError: mass <= 0)."""
    m = point_masses.mass_kg
    if not m > 0.0:
        raise ValueError(
            f'point masses {list(point_masses.masses_kg)}: total mass {m!r} kg, expected > 0')
    c = point_masses.first_moment_kg_m / m
    return m, (c.real, c.imag), point_masses.inertia_origin_kg_m2


def centroidal_inertia(mass_kg, first_moment_kg_m, inertia_origin_kg_m2):
    """Return I_O - |m c|^2 / m, the moment of inertia about the mass centre."""
    return inertia_origin_kg_m2 - abs(complex(first_moment_kg_m)) ** 2 / mass_kg


def is_realizable(point_masses, counterweights=False):
    """Return ``(ok, reason)``: positive mass, centroidal inertia (and point masses if asked)."""
    pm = point_masses
    m = pm.mass_kg
    if not m > 0.0:
        return False, f'total mass {m:.6g} kg <= 0'
    i_o = pm.inertia_origin_kg_m2
    i_c = centroidal_inertia(m, pm.first_moment_kg_m, i_o)
    if i_c <= 0.0:
        return False, f'centroidal moment of inertia {i_c:.6g} kg*m^2 <= 0'
    if i_c <= REALIZABLE_TOL * i_o:
        return False, (f'centroidal moment of inertia {i_c:.3g} kg*m^2 = {i_c / i_o:.1e} I_O: '
                       'a point mass, no body')
    if counterweights and min(pm.masses_kg) < -COUNTERWEIGHT_TOL * m:
        return False, f'negative point mass {min(pm.masses_kg):.6g} kg (counterweights)'
    return True, 'ok'


def design_vector(scene):
    """Return the seed-001 design vector (eq. 45) of a scene's links, SI."""
    out = []
    for lk in scene.links:
        pm = from_link(lk.mass_kg, lk.com_m, lk.inertia_origin_kg_m2)
        out += list(pm.masses_kg) + [pm.distance_m]
    return np.array(out)


def split_design(values, n_links):
    """Return one :class:`PointMasses` per link from a ``(4 n,)`` design vector (SI)."""
    x = np.asarray(values, dtype=float).ravel()
    if x.size != 4 * n_links:
        raise ValueError(
            f'design: got {x.size} values, expected {4 * n_links} (m_i1, m_i2, m_i3, l_i1 '
            f'for each of the {n_links} links)')
    if not np.all(np.isfinite(x)):
        raise ValueError(f'design: got {x.tolist()}, expected finite numbers')
    if x.size and np.max(np.abs(x)) > MAX_ABS_VALUE:
        raise ValueError(f'design: got {float(x[np.argmax(np.abs(x))])!r}, expected magnitudes '
                         f'<= {MAX_ABS_VALUE:g} (the limit of numbers in scene files)')
    out = []
    for i in range(n_links):
        m1, m2, m3, dist = x[4 * i:4 * i + 4]
        if not dist > 0.0:
            raise ValueError(f'design: l_{i + 1}1 = {dist!r}, expected a distance > 0')
        out.append(PointMasses((float(m1), float(m2), float(m3)), float(dist)))
    return out


def apply_design(scene, values, normalized=False):
    """
    Return ``scene`` with its link inertias replaced by a design vector (eq. 45).

    With ``normalized`` the masses are in units of the scene's m_1 and distances of a_1
    (the papers' tables); the scene must then record its normalization.
    """
    pms = split_design(values, len(scene.links))
    if normalized:
        norm = scene.normalization
        if norm is None:
            raise ValueError(f'design: scene {scene.name!r} records no normalization, so a '
                             'normalized design vector cannot be converted to SI')
        pms = [PointMasses(tuple(m * norm.mass_kg for m in pm.masses_kg),
                           pm.distance_m * norm.length_m) for pm in pms]
    links = []
    for lk, pm in zip(scene.links, pms):
        m, com, i_o = link_properties(pm)
        i_c = i_o - m * (com[0] ** 2 + com[1] ** 2)
        links.append(replace(lk, mass_kg=m, com_m=com, inertia_com_kg_m2=i_c))
    return scene.with_links(links)
