"""The RMS quantities of a scene as compressed linear maps of its inertial parameters."""

from dataclasses import dataclass
import math

from mech_balance.analysis import cycle as analysis
from mech_balance.conventions import cycle_angles
from mech_balance.core.planar import dynamics
from mech_balance.core.planar.rig import objective_units
import numpy as np

RANK_REL_TOL = 1e-9
"""Singular values of a compressed map below this fraction of the largest span its null
space."""


@dataclass
class LinearMaps:
    """
    The RMS quantities of a scene as compressed linear maps of its inertial parameters.

    ``theta``: ``(4 n,)`` [m, hx, hy, I_O] per link; ``RMS(quantity(theta)) = ||R theta||``.
    """

    force: np.ndarray                 # (k, 4n) RMS shaking force
    moment: np.ndarray                # (k, 4n) RMS shaking moment
    torque: np.ndarray = None         # (k, 4n) RMS driving torque
    reactions: dict = None            # joint -> (k, 4n) RMS bearing force
    theta_original: np.ndarray = None
    force_rms_original: float = 0.0
    force_row_basis: np.ndarray = None  # (r, 4n) orthonormal rows: force = 0 <=> rows theta = 0

    @property
    def force_null_projector(self):
        """Return the projector onto the force map's row space (theta - P theta: balanced)."""
        return self.force_row_basis.T @ self.force_row_basis

    def terms(self, theta):
        """Return [f~, n~, tau~, sum_j f~_j] of a normalized parameter vector."""
        tau = 0.0 if self.torque is None else np.linalg.norm(self.torque @ theta)
        react = 0.0 if self.reactions is None else sum(
            np.linalg.norm(r @ theta) for r in self.reactions.values())
        return np.array([np.linalg.norm(self.force @ theta),
                         np.linalg.norm(self.moment @ theta), tau, react])


def linear_maps(scene, samples=None, outputs=('shaking_wrench',), units=None):
    """Return the :class:`LinearMaps` of a planar scene over ``samples`` crank angles."""
    units = objective_units(scene) if units is None else units
    samples = scene.samples if samples is None else samples
    rig = analysis.Rig(scene)
    psi = cycle_angles(samples, scene.assembly_crank_angle_rad, links=len(scene.links))
    outputs = set(outputs)
    need = {'shaking_wrench'} | outputs
    if 'bearing_reactions' in outputs:
        need.add('driving_torque')
    # this scene's crank speed, not that of the scene the shared linkage was compiled from
    state = rig.linkage.solve(psi, scene.crank_speed_rad_s, scene.crank_acceleration_rad_s2)
    n = len(scene.links)
    ms, ls, om = units.mass_kg, units.length_m, units.omega_rad_s
    scale = np.tile([ms, ms * ls, ms * ls, ms * ls * ls], n)
    f_unit, n_unit = ms * ls * om ** 2, ms * ls * ls * om ** 2
    cols_f, cols_n, cols_t, cols_r = [], [], [], {}
    gravity = complex(*scene.gravity_m_s2)
    for k in range(4 * n):
        e = np.zeros(4 * n)
        e[k] = scale[k]
        w = dynamics.inverse_dynamics(rig.linkage, state, dynamics.inertia_from_vector(e),
                                      gravity, need)
        f = w.shaking_force / f_unit
        cols_f.append(np.concatenate([f.real, f.imag]))
        cols_n.append(w.shaking_moment / n_unit)
        if 'driving_torque' in outputs or 'bearing_reactions' in outputs:
            cols_t.append(w.driving_torque / n_unit)
        if 'bearing_reactions' in outputs:
            for name, fr in w.reaction_force.items():
                fr = fr / f_unit
                cols_r.setdefault(name, []).append(np.concatenate([fr.real, fr.imag]))
    root = math.sqrt(samples)

    def compress(cols):
        return np.linalg.qr(np.column_stack(cols) / root, mode='r')

    force = compress(cols_f)
    theta0 = dynamics.parameter_vector(rig.inertia) / scale
    _, sv, vt = np.linalg.svd(force)
    rank = int(np.sum(sv > RANK_REL_TOL * sv[0])) if sv.size and sv[0] > 0 else 0
    rows = vt[:rank]
    return LinearMaps(
        force=force, moment=compress(cols_n),
        torque=compress(cols_t) if cols_t else None,
        reactions={k: compress(v) for k, v in cols_r.items()} if cols_r else None,
        theta_original=theta0, force_rms_original=float(np.linalg.norm(force @ theta0)),
        force_row_basis=rows)
