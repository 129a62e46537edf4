"""
Forward dynamics of a planar rig: DC motor, PI speed controller, joint damping, gravity.

Equation of motion (seed 000 eqs. 39 and 43, generalized to every single-input planar scene)

    (I(psi) + N^2 J_r) psi'' = C(psi, psi') psi' + tau_A + tau_D + tau_G

* ``I(psi) = u^T M u`` and ``C psi' = -u^T M u' psi'`` come from the core
  (:func:`mech_balance.dynamics.generalized_inertia` and ``coriolis_term``).
  ``C psi'`` is quadratic in the crank speed: ``C psi' = c1(psi) psi'^2`` with ``c1`` the
  core's ``C psi'`` at unit speed (and, for any one-degree-of-freedom system,
  ``c1 = -I'(psi) / 2``; tested).
* ``tau_A = N tau_m`` is the motor torque through a gear of ratio N (motor speed N psi');
  ``J_r`` is the rotor inertia.  The motor is a DC motor on its torque-speed line,
  ``tau_line = tau_stall (u - N psi' / omega_0)`` at the voltage fraction u (u = 1: the
  rated line), optionally with an electrical lag ``T_e tau_m' = tau_line - tau_m`` (T_e = L/R).
  u is constant, or set by a PI speed controller ``u = kp e + ki integral(e)``,
  ``e = setpoint - psi'``, clipped to ``|u| <= voltage_limit`` with conditional integration
  (the integral stops while the output is saturated and the error drives it further).
* ``tau_D = -c_eff(psi) psi'``, ``c_eff = sum_j c_j (dq_j/dpsi)^2``: viscous damping of every
  joint j on its relative rate q_j' (revolute: relative angle, N*m*s/rad; prismatic: slide,
  N*s/m), i.e. the generalized force of the dissipation ``sum_j c_j q_j'^2``.
* ``tau_G = sum_i m_i g . v_ci / psi'``: the scene's ``gravity_m_s2``; potential energy
  ``V(psi) = -sum_i m_i g . c_i``.

The right-hand side needs I, c1, tau_G, c_eff (and V for the energy balance) at one crank
angle.  They depend on psi only, are 2 pi-periodic and analytic on a branch that turns
fully, so they are tabulated once as Fourier series from one batched core evaluation
(:class:`RigTables`; the series is truncated where the coefficients fall below
``TABLE_TOL`` and checked against the core at the mid-points between the samples).  One
table lookup costs a few microseconds against about 0.5 ms for a direct core evaluation;
``rhs='direct'`` evaluates the core at every call instead (the check of the tables).

Stiffness: the Jacobian of the ODE is known analytically (table derivatives are exact
Fourier derivatives).  Its largest eigenvalue modulus over a turn at the operating speed,
divided by the crank speed, is the stiffness ratio; above ``STIFFNESS_RATIO_LIMIT`` an
explicit method's step is bounded by stability rather than accuracy, and ``method='auto'``
picks Radau (implicit Runge-Kutta, order 5, L-stable), otherwise DOP853 (explicit, order 8).

Energy balance: motor work - damping dissipation = change of kinetic + potential energy.
Motor work and dissipation are integrated as two extra (quadrature) states, so the
residual measures the integration error, not a post-hoc quadrature.

Drive schema (the scene's optional top-level ``drive:`` key; :func:`drive_from_dict`)::

    drive:
      motor:                              # optional: without it the rig coasts
        stall_torque_Nm: 2.0              # > 0, at rated voltage (u = 1)
        no_load_speed_rad_s: 120.0        # > 0, at rated voltage
        rotor_inertia_kg_m2: 2.0e-5       # >= 0, default 0
        gear_ratio: 1.0                   # > 0, motor speed / crank speed, default 1
        electrical_time_constant_s: 0.0   # >= 0, L/R, default 0 (torque follows at once)
        voltage_fraction: 1.0             # constant u without a speed controller, default 1
      speed_controller:                   # optional PI on the crank speed (needs a motor)
        kp_per_rad_s: 0.05                # >= 0, voltage fraction per rad/s of speed error
        ki_per_rad: 0.5                   # >= 0, voltage fraction per rad of integrated error
        setpoint_rad_s: 31.4              # default: crank.speed_rad_s
        voltage_limit: 1.0                # > 0, |u| <= limit, default 1
      joint_damping: {O: 1.0e-4, S: 0.5}  # >= 0 per joint name, default none
      initial_speed_rad_s: 0.0            # default: 0 with a motor, crank.speed_rad_s without
      initial_crank_angle_deg: 0.0        # default: assembly.crank_angle_deg
"""

from dataclasses import dataclass
import math
import time

from mech_balance import schema as scene_mod
from mech_balance.core.integrators import DEFAULT_RTOL, EXPLICIT_METHODS, IMPLICIT_METHODS, \
    METHODS, REFERENCE_RTOL  # noqa: F401 - read as forward.EXPLICIT_METHODS, ...
from mech_balance.core.planar import dynamics
from mech_balance.core.planar.rig import PlanarRig
from mech_balance.schema import fields
from mech_balance.schema.drive import Drive, drive_from_dict, DriveError, Motor, SpeedController
import numpy as np

STIFFNESS_RATIO_LIMIT = 100.0
"""Largest |eigenvalue| / crank speed for which ``method='auto'`` integrates explicitly.

An explicit Runge-Kutta step must keep h |lambda| below about 3 (RK45) to 6 (DOP853); at the
default tolerance DOP853 takes about 40 steps per crank turn on the built-in rigs, i.e.
h omega ~ 0.15, so stability starts to bind near |lambda| / omega ~ 40; with Radau's higher
cost per step the measured break-even is near 100 (see ``mech-balance accuracy``)."""
TABLE_TOL = 1e-14
"""Fourier coefficients below this fraction of a function's scale are dropped."""
TABLE_CHECK_TOL = 1e-11
"""Largest relative deviation of a table from the core (mid-point check) that is accepted;
beyond it (or beyond ``TABLE_MAX_SAMPLES``) the simulation evaluates the core directly."""
TABLE_MIN_SAMPLES = 64
TABLE_MAX_SAMPLES = 4096
"""Samples per turn when tabulating; doubled from the minimum until the series converges."""
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


# ============================================================================ loading


def load(name_or_path):
    """Return ``(scene, drive)`` of a planar scene by built-in name or path."""
    sc = _planar(scene_mod.load(name_or_path))
    return sc, drive_of(sc)


def drive_of(sc):
    """Return the validated :class:`Drive` of a scene's ``drive`` key (empty without one)."""
    return drive_from_dict(getattr(sc, 'drive', None), sc)


def _planar(sc):
    kind = scene_mod.kind_of(sc)
    if 'forward_dynamics' not in kind.rig_factory().capabilities:
        raise ValueError(f'scene: got {sc.name!r} of kind {kind.name!r}, expected a planar '
                         'scene (the forward dynamics covers planar rigs)')
    return sc


# ============================================================================ rig functions


FUNCTIONS = ('inertia', 'c1', 'tau_gravity', 'damping', 'potential')
"""What :func:`rig_functions` returns per crank angle, in this order (SI, unit crank speed):
I (kg*m^2), c1 = C psi' at psi' = 1 (kg*m^2), tau_G (N*m), c_eff (N*m*s/rad), V (J)."""


def rig_functions(rig, psi, damping=None):
    """
    Return the ``(5, p)`` array of :data:`FUNCTIONS` at crank angles ``psi`` (rad).

    One batched core evaluation at unit crank speed and zero crank acceleration: then
    ``u = t`` (the twists per unit crank speed) and ``C psi' = -u^T M u'`` is the core's
    Coriolis term (seed 000 eq. 39).
    """
    psi = np.atleast_1d(np.asarray(psi, dtype=float))
    data = rig.at(psi, speed=1.0, accel=0.0, outputs=('shaking_wrench',))
    state, wrenches = data.native
    inertia = rig.inertia
    out = np.zeros((len(FUNCTIONS), psi.size))
    out[0] = dynamics.generalized_inertia(state, inertia)
    out[1] = dynamics.coriolis_term(state, inertia, wrenches)
    g = complex(*rig.scene.gravity_m_s2)
    if g:
        # seed 000 eq. 43, tau^G = u^T w^G: power of the weights per unit crank speed
        out[2] = dynamics.gravity_power(state, inertia, g)
        out[4] = dynamics.potential_energy(state, inertia, g)
    if damping:
        # sum_j c_j (dq_j/dpsi)^2: the joint rates at unit crank speed are dq_j/dpsi
        names = list(data.joint_names)
        for name, c in damping.items():
            if c:
                rate = data.joint_velocity[:, names.index(name)]
                out[3] += c * rate * rate
    return out


class RigTables:
    """
    Fourier series of :data:`FUNCTIONS` over one crank turn, checked against the core.

    ``values(psi)`` returns the five functions and their psi-derivatives at one angle.
    ``samples`` is the number of tabulated angles per turn, ``harmonics`` the kept series
    length, ``error`` the largest relative deviation from the core at the mid-points.
    """

    def __init__(self, rig, damping=None, tol=TABLE_TOL):
        n = TABLE_MIN_SAMPLES
        while True:
            psi = 2.0 * math.pi * np.arange(n) / n
            vals = rig_functions(rig, psi, damping)
            scale = self._scales(vals)
            spec = np.fft.rfft(vals, axis=1) / n
            tail = np.max(np.abs(spec[:, n // 4:]) / scale[:, None])
            if tail < tol or n >= TABLE_MAX_SAMPLES:
                break
            n *= 2
        keep = np.abs(spec[:, :n // 4 + 1]) >= tol * scale[:, None]
        k_max = max(int(np.max(np.nonzero(keep.any(axis=0))[0], initial=0)), 1)
        coef = spec[:, :k_max + 1].copy()
        coef[:, 1:] *= 2.0
        self.k = np.arange(k_max + 1)
        self._stack = np.vstack([coef, coef * 1j * self.k])    # values, then d/dpsi
        self.samples, self.harmonics, self.tail = n, k_max, float(tail)
        self.scale = scale
        mid = psi + math.pi / n
        direct = rig_functions(rig, mid, damping)
        table = np.array([self.values(x)[0] for x in mid]).T
        err = np.max(np.abs(table - direct), axis=1) / scale
        if np.any(vals[4]):       # the potential's constant is irrelevant
            err[4] = np.max(np.abs(np.diff(table[4] - direct[4]))) / scale[4]
        self.errors = dict(zip(FUNCTIONS, err.tolist()))
        self.error = float(np.max(err))
        self.ok = self.error <= TABLE_CHECK_TOL

    @staticmethod
    def _scales(vals):
        scale = np.max(np.abs(vals), axis=1)
        scale[1] = max(scale[1], scale[0])          # c1 has the units of I
        if scale[4] > 0.0:
            scale[4] = max(np.ptp(vals[4]), np.finfo(float).tiny)
        return np.where(scale > 0.0, scale, 1.0)

    def values(self, psi):
        """Return ``(f, df/dpsi)``: two ``(5,)`` arrays of :data:`FUNCTIONS` at ``psi``."""
        z = np.exp(1j * math.remainder(psi, 2.0 * math.pi) * self.k)
        out = (self._stack @ z).real
        return out[:5], out[5:]


class _DirectFunctions:
    """The rig functions evaluated by the core at every call (``rhs='direct'``)."""

    SLOPE_STEP_RAD = 1e-6

    def __init__(self, rig, damping):
        self.rig, self.damping = rig, damping

    def values(self, psi):
        h = self.SLOPE_STEP_RAD
        f = rig_functions(self.rig, np.array([psi - h, psi, psi + h]), self.damping)
        return f[:, 1], (f[:, 2] - f[:, 0]) / (2.0 * h)

    def values_only(self, psi):
        return rig_functions(self.rig, np.array([psi]), self.damping)[:, 0]


# ============================================================================ the ODE


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
        rig = scene_or_rig if isinstance(scene_or_rig, PlanarRig) else \
            PlanarRig(_planar(scene_or_rig))
        self.rig = rig
        self.scene = sc = rig.scene
        # no drive given: the scene's own (``drive:`` key); Drive() means none at all
        self.drive = drive = drive_of(sc) if drive is None else drive_from_dict(drive, sc)
        if rhs not in ('table', 'direct'):
            raise ValueError(f'rhs: got {rhs!r}, expected "table" or "direct"')
        damping = {k: v for k, v in drive.joint_damping.items() if v}
        self.tables = None
        if rhs == 'table':
            tables = RigTables(rig, damping)
            if tables.ok:
                self.tables = tables
        self.functions = self.tables if self.tables is not None else \
            _DirectFunctions(rig, damping)
        self.rhs_kind = 'table' if self.tables is not None else 'direct'
        motor, pi = drive.motor, drive.speed_controller
        self.motor, self.pi = motor, pi
        n_gear = motor.gear_ratio if motor else 1.0
        self.gear = n_gear
        self.rotor = n_gear ** 2 * motor.rotor_inertia_kg_m2 if motor else 0.0
        self.lag = bool(motor and motor.electrical_time_constant_s > 0.0)
        self.setpoint = None
        if pi is not None:
            self.setpoint = sc.crank_speed_rad_s if pi.setpoint_rad_s is None \
                else pi.setpoint_rad_s
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

    # ------------------------------------------------------------------ set-up

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
        """
        Return a bound on the crank speed a run can reach (rad/s), for the turn limit.

        Coasting: energy conservation bounds |psi'| by |psi'_0| sqrt(I_max / I_min); a
        motor brakes beyond its no-load speed at the largest voltage it may apply.
        """
        grid = 2.0 * math.pi * np.arange(64) / 64
        inertia = np.array([self.functions.values(x)[0][0] for x in grid]) + self.rotor
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

    def initial_state(self):
        """Return the state vector at t = 0."""
        y = np.zeros(len(self.names))
        d = self.drive
        y[0] = self.scene.assembly_crank_angle_rad if d.initial_crank_angle_deg is None \
            else math.radians(d.initial_crank_angle_deg)
        y[1] = self.initial_speed()
        return y

    def atol(self, rtol):
        """Return the absolute tolerances per state (scaled by the rig's own units)."""
        w = self.omega_ref
        f0 = self.functions.values(self.scene.assembly_crank_angle_rad)[0]
        energy = 0.5 * (abs(f0[0]) + self.rotor) * w * w
        scales = {'psi': 1.0, 'speed': w, 'pi_integral': 1.0,
                  'motor_torque': self.motor.stall_torque_Nm if self.motor else 1.0,
                  'motor_work': energy, 'damping_loss': energy}
        return rtol * np.array([scales[n] for n in self.names])

    # ------------------------------------------------------------------ right-hand side

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
        i_tot = f[0] + self.rotor
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
        return (f[1] * w * w + tau + f[2] - f[3] * w) / (f[0] + self.rotor), tau

    def jac(self, t, y, saturate=True):
        """Return the analytic Jacobian d(dy/dt)/dy (table derivatives are exact)."""
        f, df = self.functions.values(y[0])
        tau, jac_tau, _ = self._parts(y, f, saturate)
        w = y[1]
        n = len(self.names)
        jm = np.zeros((n, n))
        i_tot = f[0] + self.rotor
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

    # ------------------------------------------------------------------ stiffness

    def stiffness(self):
        """
        Return the :class:`Stiffness` estimate at the operating point.

        Eigenvalues of the dynamic part of the Jacobian (the quadrature states do not feed
        back) at ``STIFFNESS_PROBE_ANGLES`` crank angles, at the operating crank speed with
        the speed controller unsaturated.
        """
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

    # ------------------------------------------------------------------ integration

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
        kwargs = {}
        if method in IMPLICIT_METHODS + ('LSODA',):
            kwargs['jac'] = self.jac
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
        return 0.5 * (f[0] + self.rotor) * y[1] ** 2 + f[4]

    def energy_residual(self, y0, y1):
        """
        Return ``(residual_J, relative)`` of motor work - dissipation - energy change.

        Relative to the largest of the terms (and the kinetic energy at the operating
        speed), so a coasting rig's drift and a driven rig's balance read alike.
        """
        de = self.energy(y1) - self.energy(y0)
        work, loss = y1[self.i_w] - y0[self.i_w], y1[self.i_d] - y0[self.i_d]
        f0 = self.functions.values(y0[0])[0]
        scale = max(abs(work), abs(loss), abs(de), self.energy(y0) - f0[4],
                    0.5 * (f0[0] + self.rotor) * self.omega_ref ** 2, np.finfo(float).tiny)
        res = work - loss - de
        return float(res), float(abs(res) / scale)


__all__ = ['Drive', 'DriveError', 'ForwardDynamics', 'Motor', 'RigTables', 'Simulation',
           'SpeedController', 'Stiffness', 'drive_from_dict', 'drive_of', 'load',
           'rig_functions']
