"""
Forward dynamics of any single-input rig, from its own inverse dynamics (seed 000 eqs. 39, 43).

The equation, the stiffness test and the energy balance: docs/core.md#the-equation-of-motion;
the drive schema: docs/simulation.md.
"""

from dataclasses import dataclass
import math
import time

from mech_balance import schema as scene_mod
from mech_balance.core.integrators import DEFAULT_RTOL, EXPLICIT_METHODS, IMPLICIT_METHODS, \
    METHODS, REFERENCE_RTOL  # noqa: F401 - read as forward.EXPLICIT_METHODS, ...
from mech_balance.core.rig import rig_for
from mech_balance.schema import fields
from mech_balance.schema.drive import Drive, drive_from_dict, DriveError, Motor, SpeedController
import numpy as np

STIFFNESS_RATIO_LIMIT = 100.0
"""Largest |eigenvalue| / crank speed for which ``method='auto'`` integrates explicitly."""
TABLE_TOL = 1e-14
"""Fourier coefficients below this fraction of a function's scale are dropped."""
TABLE_CHECK_TOL = 1e-11
"""Largest relative deviation of a table from the rig (mid-point check) that is accepted."""
TABLE_MIN_SAMPLES = 64
TABLE_MAX_SAMPLES = 4096
"""Samples per turn when tabulating; doubled from the minimum until the series converges."""
INERTIA_FLOOR_REL = 1e-9
"""Smallest total generalized inertia over a turn, relative to its largest, that is accepted."""
POTENTIAL_NODES = 16
"""Gauss-Legendre nodes per panel of the direct path's potential quadrature."""
POTENTIAL_PANEL_RAD = math.pi / 4.0
"""Widest panel of that quadrature (the integrand is analytic: 16 nodes reach round-off)."""
STIFFNESS_PROBE_ANGLES = 16
"""Crank angles per turn at which the ODE Jacobian's eigenvalues are computed."""
OMEGA_FLOOR_REL = 1e-9
"""Speeds below this fraction of the scene's crank speed do not set the operating speed."""
MAX_SIMULATED_TURNS = 1e5
"""Most crank turns a simulation may cover (at the largest speed the drive can reach)."""
MAX_RHS_EVALUATIONS = 1_000_000
"""Right-hand-side evaluations after which a simulation is abandoned (about 30 s)."""


class _TooManyEvaluations(Exception):
    """Raised inside the right-hand side to stop a runaway integration."""


def load(name_or_path):
    """Return ``(scene, drive)`` of a scene of any kind by built-in name or path."""
    sc = scene_mod.load(name_or_path)
    return sc, drive_of(sc)


def drive_of(sc, joint_names=None):
    """Return the validated :class:`Drive` of a scene's ``drive`` key (empty without one)."""
    return drive_from_dict(getattr(sc, 'drive', None), joint_names=joint_names)


def rig_of(scene_or_rig):
    """Return the rig to simulate (a rig as given, a scene's through :func:`rig_for`)."""
    rig = scene_or_rig if hasattr(scene_or_rig, 'at') else rig_for(scene_or_rig)
    if 'driving_torque' not in rig.capabilities:
        raise ValueError(
            f'simulate: rig {rig.name!r} of kind {scene_mod.kind_of(rig).name!r} lacks the '
            'capability driving_torque (its inverse dynamics), which the forward dynamics '
            'is built from')
    return rig


FUNCTIONS = ('inertia', 'c1', 'tau_gravity', 'damping', 'potential')
"""The functions of the ODE per crank angle (SI): I, c1 (kg*m^2), tau_G (N*m), c_eff
(N*m*s/rad), V (J)."""


def _reference_speed(rig):
    """Return w0 (rad/s) of :func:`rig_functions`: the scene's crank speed, else 1."""
    w0 = abs(float(rig.scene.crank_speed_rad_s))
    return w0 if math.isfinite(w0) and w0 > 0.0 else 1.0


def rig_functions(rig, psi, damping=None, check=False):
    """
    Return the ``(4, p)`` array of I, c1, tau_G, c_eff at crank angles ``psi`` (rad).

    One batched :meth:`Rig.at` (docs/core.md#the-equation-of-motion); a rig that takes
    no crank acceleration gives I by its kinetic energy (``I = 2 T / w0^2``).  With ``check``
    also return the ``(p,)`` residuals (N*m) of the ``structure`` and ``energy`` checks.
    """
    psi = np.atleast_1d(np.asarray(psi, dtype=float))
    p = psi.size
    w0 = _reference_speed(rig)
    a0 = w0 * w0
    speeds = [0.0, 0.0, w0] + ([2.0 * w0] if check else [])
    accels = [0.0, a0, 0.0] + ([-a0] if check else [])
    k = len(speeds)
    energy = 'kinetic_energy' in rig.capabilities
    accel = np.repeat(accels, p)
    data = rig.at(np.tile(psi, k), speed=np.repeat(speeds, p), accel=accel,
                  outputs=('driving_torque', 'kinetic_energy') if energy else
                  ('driving_torque',))
    honoured = np.allclose(data.crank_accel_rad_s2, accel, rtol=1e-12, atol=0.0)
    if not (honoured or energy):
        raise ValueError(
            f'simulate: rig {rig.name!r} of kind {scene_mod.kind_of(rig).name!r} evaluates no '
            'crank acceleration and lacks the capability kinetic_energy; the forward '
            'dynamics needs one of them for the generalized inertia')
    ci = rig.joint_names.index(rig.crank_joint)
    unit = data.joint_velocity[2 * p:3 * p] / w0       # joint rates per unit crank speed
    effort = data.series[rig.driving_series].reshape(k, p) * unit[:, ci]   # Q = e dx/dpsi
    out = np.zeros((4, p))
    by_energy = 2.0 * data.series['kinetic_energy'][2 * p:3 * p] / a0 if energy else None
    out[0] = (effort[1] - effort[0]) / a0 if honoured else by_energy
    out[1] = -(effort[2] - effort[0]) / a0
    out[2] = -effort[0]
    for name, c in (damping or {}).items():
        if c:
            rate = unit[:, rig.joint_names.index(name)]
            out[3] += c * rate * rate
    if not check:
        return out
    model = -4.0 * out[1] * a0 - out[2] - (out[0] * a0 if honoured else 0.0)
    residuals = {'structure': effort[3] - model}
    if honoured and energy:       # two formulations of I: Newton-Euler and the energy
        residuals['energy'] = (out[0] - by_energy) * a0
    return out, residuals


class RigTables:
    """
    Fourier series of :data:`FUNCTIONS` over one crank turn, checked against the rig.

    ``errors``: each function's largest relative deviation at the mid-points, ``inertia_slope``
    (seed 000 eq. 41), ``structure``, ``energy``; ``ok``: ``error`` within ``TABLE_CHECK_TOL``.
    """

    def __init__(self, rig, damping=None, tol=TABLE_TOL):
        n = TABLE_MIN_SAMPLES
        psi = 2.0 * math.pi * np.arange(n) / n
        vals = rig_functions(rig, psi, damping)
        while True:
            scale = np.max(np.abs(vals), axis=1)
            scale[1] = max(scale[1], scale[0])          # c1 has the units of I
            scale = np.where(scale > 0.0, scale, 1.0)
            spec = np.fft.rfft(vals, axis=1) / n
            tail = float(np.max(np.abs(spec[:, n // 4:]) / scale[:, None]))
            mid = psi + math.pi / n
            direct, checks = rig_functions(rig, mid, damping, check=True)
            if tail < tol or n >= TABLE_MAX_SAMPLES:
                break
            # the mid-points are the next level's odd samples
            psi = np.column_stack([psi, mid]).ravel()
            vals = np.stack([vals, direct], axis=2).reshape(vals.shape[0], -1)
            n *= 2
        keep = np.abs(spec[:, :n // 4 + 1]) >= tol * scale[:, None]
        k_max = max(int(np.max(np.nonzero(keep.any(axis=0))[0], initial=0)), 1)
        coef = spec[:, :k_max + 1].copy()
        coef[:, 1:] *= 2.0
        self.k = np.arange(k_max + 1)
        # V = -integral tau_G: term by term; the mean of tau_G (zero for weights) is left out
        pot = np.zeros(k_max + 1, dtype=complex)
        pot[1:] = -coef[2, 1:] / (1j * self.k[1:])
        coef = np.vstack([coef, pot])
        self._stack = np.vstack([coef, coef * 1j * self.k])    # values, then d/dpsi
        self.samples, self.harmonics, self.tail = n, k_max, tail
        table, slope = (np.array(v).T for v in zip(*(self.values(x) for x in mid)))
        err = np.max(np.abs(table[:4] - direct), axis=1) / scale
        torque = 4.0 * max(scale[0], scale[1]) * _reference_speed(rig) ** 2 + scale[2]
        self.gravity_mean = float(abs(spec[2, 0]))
        errors = dict(zip(FUNCTIONS, err.tolist()))
        v_scale = float(np.ptp(table[4])) if np.any(vals[2]) else 0.0
        errors['potential'] = 2.0 * math.pi * (errors['tau_gravity'] * scale[2] +
                                               self.gravity_mean) / v_scale if v_scale else 0.0
        # I'(psi) of the series against the rig's c1 (seed 000 eq. 41: c1 = -I'/2)
        errors['inertia_slope'] = float(np.max(np.abs(slope[0] + 2.0 * direct[1]))) / scale[0]
        for name, residual in checks.items():
            errors[name] = float(np.max(np.abs(residual))) / torque
        self.scale = np.append(scale, v_scale or 1.0)
        self.errors = errors
        self.error = float(max(errors.values()))
        self.ok = self.error <= TABLE_CHECK_TOL

    def values(self, psi):
        """Return ``(f, df/dpsi)``: two ``(5,)`` arrays of :data:`FUNCTIONS` at ``psi``."""
        z = np.exp(1j * math.remainder(psi, 2.0 * math.pi) * self.k)
        out = (self._stack @ z).real
        return out[:5], out[5:]

    def potential(self, psi):
        """Return V(psi), J (zero mean over the turn)."""
        return float(self.values(psi)[0][4])


class _DirectFunctions:
    """The rig functions evaluated by the rig at every call (``rhs='direct'``)."""

    SLOPE_STEP_RAD = 1e-6

    def __init__(self, rig, damping):
        self.rig, self.damping = rig, damping
        x, w = np.polynomial.legendre.leggauss(POTENTIAL_NODES)
        self._nodes, self._weights = 0.5 * (x + 1.0), 0.5 * w

    def values(self, psi):
        """Return ``(f, df/dpsi)`` (V left 0: :meth:`potential` computes it)."""
        h = self.SLOPE_STEP_RAD
        f = rig_functions(self.rig, np.array([psi - h, psi, psi + h]), self.damping)
        df = (f[:, 2] - f[:, 0]) / (2.0 * h)
        return np.append(f[:, 1], 0.0), np.append(df, -f[2, 1])

    def values_only(self, psi):
        return np.append(rig_functions(self.rig, np.array([psi]), self.damping)[:, 0], 0.0)

    def potential(self, psi):
        """Return V(psi) = -integral of tau_G from 0 to psi (Gauss-Legendre panels), J."""
        x = math.remainder(psi, 2.0 * math.pi)
        panels = max(int(math.ceil(abs(x) / POTENTIAL_PANEL_RAD)), 1)
        edges = np.linspace(0.0, x, panels + 1)
        width = np.diff(edges)
        nodes = (edges[:-1, None] + width[:, None] * self._nodes).ravel()
        tau = rig_functions(self.rig, nodes)[2].reshape(panels, -1)
        return -float(np.sum(width[:, None] * self._weights * tau))


@dataclass
class Stiffness:
    """The stiffness estimate of a simulation and the method it implies."""

    ratio: float            # max |lambda| / omega_ref
    lambda_max: float       # 1/s, largest eigenvalue modulus over a turn
    omega_ref: float        # rad/s, the operating crank speed
    stiff: bool
    method: str
    reason: str


@dataclass
class Simulation:
    """One integration: the solver's output and its cost."""

    model: object
    method: str
    reason: str
    rtol: float
    t: np.ndarray           # (k,) s
    y: np.ndarray           # (n_states, k)
    nfev: int
    njev: int
    nlu: int
    steps: int
    seconds: float
    success: bool
    message: str
    sol: object = None

    @property
    def final(self):
        """Return the final state vector."""
        return self.y[:, -1]

    def energy_residual(self):
        """Return ``(residual_J, relative)`` of the energy balance at the end of the run."""
        return self.model.energy_residual(self.y[:, 0], self.y[:, -1])


class ForwardDynamics:
    """
    The ODE of a rig with a drive: right-hand side, Jacobian, stiffness and integration.

    States: psi (rad), psi' (rad/s), [PI integral of the speed error (rad)], [motor torque
    (N*m, with an electrical lag)], motor work (J), damping dissipation (J).
    """

    def __init__(self, scene_or_rig, drive=None, rhs='table'):
        self.rig = rig = rig_of(scene_or_rig)
        self.scene = sc = rig.scene
        # no drive given: the scene's own (``drive:`` key); Drive() means none at all
        drive = getattr(sc, 'drive', None) if drive is None else drive
        self.drive = drive = drive_from_dict(drive, joint_names=rig.joint_names)
        if rhs not in ('table', 'direct'):
            raise ValueError(f'rhs: got {rhs!r}, expected "table" or "direct"')
        damping = {k: v for k, v in drive.joint_damping.items() if v}
        tables = RigTables(rig, damping) if rhs == 'table' else None
        self.tables = tables if tables is not None and tables.ok else None
        self.functions = self.tables or _DirectFunctions(rig, damping)
        self.rhs_kind = 'table' if self.tables is not None else 'direct'
        motor, pi = drive.motor, drive.speed_controller
        self.motor, self.pi = motor, pi
        self.gear = motor.gear_ratio if motor else 1.0
        self.rotor = self.gear ** 2 * motor.rotor_inertia_kg_m2 if motor else 0.0
        self.added = self.rotor + drive.input_inertia_kg_m2   # turns with psi
        self.lag = bool(motor and motor.electrical_time_constant_s > 0.0)
        self.setpoint = None if pi is None else (
            sc.crank_speed_rad_s if pi.setpoint_rad_s is None else pi.setpoint_rad_s)
        names = ['psi', 'speed']
        if pi is not None:
            names.append('pi_integral')
        if self.lag:
            names.append('motor_torque')
        names += ['motor_work', 'damping_loss']
        self.names = names
        self.i_z = names.index('pi_integral') if pi is not None else None
        self.i_m = names.index('motor_torque') if self.lag else None
        self.i_w, self.i_d = len(names) - 2, len(names) - 1
        self.n_dyn = len(names) - 2
        self.omega_ref = self._omega_ref()
        self.rhs_calls = 0
        self.max_evaluations = MAX_RHS_EVALUATIONS
        self._check_inertia()

    def _check_inertia(self):
        """Refuse a total generalized inertia that is not positive over the turn."""
        grid = 2.0 * math.pi * np.arange(TABLE_MIN_SAMPLES) / TABLE_MIN_SAMPLES
        if self.tables is not None:
            inertia = np.array([self.tables.values(x)[0][0] for x in grid])
        else:
            inertia = rig_functions(self.rig, grid)[0]
        self._inertia_turn = total = inertia + self.added   # kept for speed_bound
        peak = float(np.max(np.abs(total)))
        low = int(np.argmin(total))
        if not peak > 0.0 or total[low] <= INERTIA_FLOOR_REL * peak:
            where = math.degrees(grid[low])
            raise DriveError(
                f'drive.input_inertia_kg_m2: got {self.drive.input_inertia_kg_m2!r} and a '
                f'rotor of {self.rotor:g} kg*m^2, but the generalized inertia of '
                f'{self.rig.name!r} falls to {total[low]:.3g} kg*m^2 near psi = {where:.4g} '
                f'deg (largest {peak:.3g}): the acceleration is not defined there (the dead '
                'centre of a prismatic input: the ideal yoke is massless); expected a flywheel '
                '(drive.input_inertia_kg_m2 > 0) or a motor with rotor_inertia_kg_m2 > 0')

    def _omega_ref(self):
        """Return the operating crank speed: setpoint, motor speed, initial or scene speed."""
        sc, motor = self.scene, self.motor
        floor = OMEGA_FLOOR_REL * abs(sc.crank_speed_rad_s)
        candidates = []
        if self.setpoint is not None:
            candidates.append(self.setpoint)
        elif motor is not None:
            candidates.append(motor.voltage_fraction * motor.no_load_speed_rad_s / self.gear)
        candidates += [self.initial_speed(), sc.crank_speed_rad_s]
        return next(abs(w) for w in candidates if abs(w) >= floor)

    def speed_bound(self):
        """Return a bound on the crank speed a run can reach (rad/s), for the turn limit."""
        inertia = self._inertia_turn
        bound = abs(self.initial_speed()) * math.sqrt(np.max(inertia) / np.min(inertia))
        bound = max(bound, self.omega_ref)
        if self.motor is not None:
            u = self.pi.voltage_limit if self.pi is not None else abs(
                self.motor.voltage_fraction)
            bound = max(bound, u * self.motor.no_load_speed_rad_s / self.gear)
        if self.pi is not None:
            bound = max(bound, abs(self.setpoint))
        return bound

    def initial_speed(self):
        """Return the initial crank speed (rad/s)."""
        d = self.drive
        if d.initial_speed_rad_s is not None:
            return d.initial_speed_rad_s
        return 0.0 if d.motor is not None else self.scene.crank_speed_rad_s

    def start_angle(self):
        """Return the scene's assembly crank angle (rad; 0 for a scene that states none)."""
        return float(getattr(self.scene, 'assembly_crank_angle_rad', 0.0))

    def initial_state(self):
        """Return the state vector at t = 0."""
        y = np.zeros(len(self.names))
        d = self.drive
        y[0] = self.start_angle() if d.initial_crank_angle_deg is None \
            else math.radians(d.initial_crank_angle_deg)
        y[1] = self.initial_speed()
        return y

    def atol(self, rtol):
        """Return the absolute tolerances per state (scaled by the rig's own units)."""
        w = self.omega_ref
        f0 = self.functions.values(self.start_angle())[0]
        energy = 0.5 * (abs(f0[0]) + self.added) * w * w
        scales = {'psi': 1.0, 'speed': w, 'pi_integral': 1.0,
                  'motor_torque': self.motor.stall_torque_Nm if self.motor else 1.0,
                  'motor_work': energy, 'damping_loss': energy}
        return rtol * np.array([scales[n] for n in self.names])

    def _voltage(self, y, e, saturate=True):
        """Return (u, du/de, du/dz, integrating) of the speed controller or the open loop."""
        if self.pi is None:
            return self.motor.voltage_fraction, 0.0, 0.0, False
        pi = self.pi
        raw = pi.kp_per_rad_s * e + pi.ki_per_rad * y[self.i_z]
        if saturate and abs(raw) > pi.voltage_limit:
            u = math.copysign(pi.voltage_limit, raw)
            return u, 0.0, 0.0, e * raw <= 0.0
        return raw, pi.kp_per_rad_s, pi.ki_per_rad, True

    def _parts(self, y, f, saturate=True):
        """Return the crank torque of the motor, its partials, and the state derivatives."""
        w = y[1]
        motor = self.motor
        dy = np.zeros(len(self.names))
        jac_w = {}      # d(tau_crank)/d(state index)
        if motor is None:
            return 0.0, jac_w, dy
        n_g = self.gear
        e = (self.setpoint - w) if self.pi is not None else 0.0
        u, du_de, du_dz, integrating = self._voltage(y, e, saturate)
        if self.pi is not None:
            dy[self.i_z] = e if integrating else 0.0
        slope = motor.stall_torque_Nm
        line = slope * (u - n_g * w / motor.no_load_speed_rad_s)
        if self.lag:
            te = motor.electrical_time_constant_s
            dy[self.i_m] = (line - y[self.i_m]) / te
            tau = n_g * y[self.i_m]
            jac_w[self.i_m] = n_g
        else:
            tau = n_g * line
            jac_w[1] = n_g * slope * (-du_de - n_g / motor.no_load_speed_rad_s)
            if self.pi is not None:
                jac_w[self.i_z] = n_g * slope * du_dz
        return tau, jac_w, dy

    def rhs(self, t, y):
        """Return dy/dt (seed 000 eq. 39 solved for psi'')."""
        self.rhs_calls += 1
        if self.rhs_calls > self.max_evaluations:
            raise _TooManyEvaluations(t)
        f = self.functions.values(y[0])[0] if self.tables is not None else \
            self.functions.values_only(y[0])
        tau, _, dy = self._parts(y, f)
        w = y[1]
        i_tot = f[0] + self.added
        dy[0] = w
        dy[1] = (f[1] * w * w + tau + f[2] - f[3] * w) / i_tot
        dy[self.i_w] = tau * w
        dy[self.i_d] = f[3] * w * w
        return dy

    def accel(self, y):
        """Return psi'' (rad/s^2) and the crank torque of the motor (N*m) at state y."""
        f = self.functions.values(y[0])[0]
        tau, _, _ = self._parts(y, f)
        w = y[1]
        return (f[1] * w * w + tau + f[2] - f[3] * w) / (f[0] + self.added), tau

    def jac(self, t, y, saturate=True):
        """Return the analytic Jacobian d(dy/dt)/dy (table derivatives are exact)."""
        f, df = self.functions.values(y[0])
        tau, jac_tau, _ = self._parts(y, f, saturate)
        w = y[1]
        n = len(self.names)
        jm = np.zeros((n, n))
        i_tot = f[0] + self.added
        acc = (f[1] * w * w + tau + f[2] - f[3] * w) / i_tot
        jm[0, 1] = 1.0
        jm[1, 0] = (df[1] * w * w + df[2] - df[3] * w - acc * df[0]) / i_tot
        jm[1, 1] = (2.0 * f[1] * w - f[3]) / i_tot
        for k, v in jac_tau.items():
            jm[1, k] += v / i_tot
            jm[self.i_w, k] += v * w
        jm[self.i_w, 1] += tau
        jm[self.i_d, 0] = df[3] * w * w
        jm[self.i_d, 1] = 2.0 * f[3] * w
        if self.pi is not None:
            e = self.setpoint - w
            _, du_de, du_dz, integrating = self._voltage(y, e, saturate)
            if integrating:
                jm[self.i_z, 1] = -1.0
            if self.lag:
                m = self.motor
                jm[self.i_m, 1] = m.stall_torque_Nm * (
                    -du_de - self.gear / m.no_load_speed_rad_s) / m.electrical_time_constant_s
                jm[self.i_m, self.i_z] = m.stall_torque_Nm * du_dz / \
                    m.electrical_time_constant_s
        elif self.lag:
            m = self.motor
            jm[self.i_m, 1] = -m.stall_torque_Nm * self.gear / m.no_load_speed_rad_s / \
                m.electrical_time_constant_s
        if self.lag:
            jm[self.i_m, self.i_m] = -1.0 / self.motor.electrical_time_constant_s
        return jm

    def stiffness(self):
        """Return the :class:`Stiffness` estimate at the operating point."""
        w = self.omega_ref
        sign = math.copysign(1.0, self.setpoint if self.setpoint else
                             (self.initial_speed() or self.scene.crank_speed_rad_s))
        lam = 0.0
        for psi in 2.0 * math.pi * np.arange(STIFFNESS_PROBE_ANGLES) / STIFFNESS_PROBE_ANGLES:
            y = self.initial_state()
            y[0], y[1] = psi, sign * w
            jm = self.jac(0.0, y, saturate=False)[:self.n_dyn, :self.n_dyn]
            lam = max(lam, float(np.max(np.abs(np.linalg.eigvals(jm)))))
        ratio = lam / w if w > 0.0 else math.inf
        period = 2.0 * math.pi / w if w > 0.0 else math.inf
        if ratio > STIFFNESS_RATIO_LIMIT:
            method = 'Radau'
            reason = (f'stiff: largest Jacobian eigenvalue |lambda| = {lam:.3g} 1/s at '
                      f'{w:.4g} rad/s, ratio |lambda|/omega = {ratio:.3g} > '
                      f'{STIFFNESS_RATIO_LIMIT:g}; an explicit step would be held below '
                      f'~{3.0 / lam:.2g} s by stability (a crank turn takes {period:.3g} s), '
                      'so Radau (implicit Runge-Kutta, order 5, L-stable) is used')
        else:
            method = 'DOP853'
            reason = (f'not stiff: |lambda|max = {lam:.3g} 1/s, ratio |lambda|/omega = '
                      f'{ratio:.3g} <= {STIFFNESS_RATIO_LIMIT:g}; accuracy, not stability, '
                      'sets the step, so DOP853 (explicit Runge-Kutta, order 8) is used')
        return Stiffness(ratio, lam, w, ratio > STIFFNESS_RATIO_LIMIT, method, reason)

    def simulate(self, duration_s, method='auto', rtol=DEFAULT_RTOL, t_eval=None,
                 dense_output=False, y0=None, max_evaluations=MAX_RHS_EVALUATIONS):
        """
        Integrate over ``duration_s`` seconds; return a :class:`Simulation`.

        Refuses runs of more than ``MAX_SIMULATED_TURNS`` crank turns and gives up after
        ``max_evaluations`` right-hand-side evaluations (a ``ValueError`` either way).
        """
        duration_s = fields.positive(duration_s, 'duration_s', error=ValueError)
        rtol = fields.positive(rtol, 'rtol', error=ValueError)
        if not 1e-14 <= rtol <= 1e-1:
            raise ValueError(f'rtol: got {rtol!r}, expected 1e-14 <= rtol <= 0.1')
        if method == 'auto':
            st = self.stiffness()
            method, reason = st.method, st.reason
        elif method in METHODS:
            reason = f'method {method} requested'
        else:
            raise ValueError(f'method: got {method!r}, expected auto or one of '
                             f'{", ".join(METHODS)}')
        y0 = self.initial_state() if y0 is None else np.asarray(y0, dtype=float)
        speed = self.speed_bound()
        turns = duration_s * speed / (2.0 * math.pi)
        if not turns <= MAX_SIMULATED_TURNS:
            raise ValueError(
                f'duration_s: got {duration_s!r} s, about {turns:.3g} crank turns at up to '
                f'{speed:.3g} rad/s; expected at most {MAX_SIMULATED_TURNS:g} turns')
        kwargs = {'jac': self.jac} if method in IMPLICIT_METHODS + ('LSODA',) else {}
        self.rhs_calls = 0
        self.max_evaluations = int(max_evaluations)
        t0 = time.perf_counter()
        try:
            with np.errstate(over='raise', invalid='raise'):
                from scipy.integrate import solve_ivp  # imported when a simulation runs
                res = solve_ivp(self.rhs, (0.0, duration_s), y0, method=method, rtol=rtol,
                                atol=self.atol(rtol), t_eval=t_eval,
                                dense_output=dense_output, **kwargs)
        except _TooManyEvaluations as exc:
            raise ValueError(
                f'simulation: {method} gave up after {self.max_evaluations} right-hand-side '
                f'evaluations at t = {float(exc.args[0]):.4g} of {duration_s:g} s; expected '
                'a shorter duration, a looser rtol or an implicit method') from None
        except (ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
            raise ValueError(f'simulation: {method} failed ({exc}); the drive and rig give '
                             'a state that overflows') from None
        seconds = time.perf_counter() - t0
        if not res.success:
            raise ValueError(f'simulation: {method} failed at t = {res.t[-1]:.6g} s: '
                             f'{res.message}')
        if not np.all(np.isfinite(res.y)):
            raise ValueError(f'simulation: {method} produced a non-finite state by t = '
                             f'{res.t[-1]:.6g} s')
        y = res.y
        if t_eval is not None and (y.shape[1] == 0 or res.t[-1] < duration_s):
            y = np.column_stack([y, res.sol(duration_s)]) if res.sol is not None else y
        return Simulation(self, method, reason, rtol, res.t, y, int(res.nfev),
                          int(getattr(res, 'njev', 0)), int(getattr(res, 'nlu', 0)),
                          int(res.t.size), seconds, bool(res.success), res.message,
                          res.sol)

    def energy(self, y):
        """Return the kinetic plus potential energy at state ``y``, in J."""
        f = self.functions.values(y[0])[0]
        return 0.5 * (f[0] + self.added) * y[1] ** 2 + self.functions.potential(y[0])

    def energy_residual(self, y0, y1):
        """Return ``(residual_J, relative)`` of motor work - dissipation - energy change."""
        de = self.energy(y1) - self.energy(y0)
        work, loss = y1[self.i_w] - y0[self.i_w], y1[self.i_d] - y0[self.i_d]
        f0 = self.functions.values(y0[0])[0]
        kinetic = 0.5 * (f0[0] + self.added) * y0[1] ** 2
        scale = max(abs(work), abs(loss), abs(de), kinetic,
                    0.5 * (f0[0] + self.added) * self.omega_ref ** 2, np.finfo(float).tiny)
        res = work - loss - de
        return float(res), float(abs(res) / scale)


__all__ = ['Drive', 'DriveError', 'ForwardDynamics', 'Motor', 'RigTables', 'Simulation',
           'SpeedController', 'Stiffness', 'drive_from_dict', 'drive_of', 'load',
           'rig_functions', 'rig_of']
