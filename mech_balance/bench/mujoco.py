"""
``mech-balance bench --compare mujoco``: this package against MuJoCo, side by side.

The planar rigs (:class:`MujocoRig`), then :mod:`mech_balance.bench.mujoco_spatial`; the
models: docs/benchmarks.md#the-mujoco-models-in-detail.  Without :mod:`mujoco` (optional,
``make bench-mujoco``) the command says how to install it and exits with status 2.
"""

import math
import statistics
import sys
import time

from mech_balance import schema as scene_mod
from mech_balance.analysis import cycle as analysis
from mech_balance.bench import chains as chain
from mech_balance.bench.core import peak_bytes
from mech_balance.bench.mujoco_model import agreement, agreement_rows, import_mujoco, mjcf, \
    MujocoMissing, MujocoModel, relative_difference, solve, TIMED, us_rows, worst, xml_numbers
from mech_balance.conventions import cycle_angles
from mech_balance.core.planar import dynamics, kinematics
import numpy as np

AGREEMENT_TOL = 1e-9
"""Largest relative difference (to the cycle's peak) accepted between the two engines."""
SPEEDUP_GOAL = 20.0
"""This package's full pipeline must be at least this many times faster than MuJoCo's."""
MUJOCO_REPEAT_DIVISOR = 5
"""MuJoCo's per-angle Python loop is timed ``repeat / this`` times (at least 5)."""
CHAIN_LOOPS = (1, 3, 4, 9, 19)
"""Generated chains of the scaling table: 4, 8, 10, 20 and 40 links counting the frame."""
TIMING_ROUNDS = 5
"""Rounds of interleaved warm blocks per timed figure (:func:`interleaved_rounds`)."""
GROWTH_LIMIT = 1.0
"""Largest growth exponent of this package's full pipeline from the smallest to the largest
chain (cost ~ links^e): linear in the number of links (issue 22)."""
RATIO_GOALS = {20: 30.0, 40: 20.0}
"""Links (with the frame) -> smallest full-pipeline ratio against MuJoCo (issue 22)."""
NEWTON_MAX_ITER = kinematics.NEWTON_MAX_ITER
NEWTON_TOL = kinematics.NEWTON_TOL
"""MuJoCo's Newton stops where this package's does (residual / characteristic length)."""
EXIT_MISSING = 2
EXIT_DISAGREE = 1
"""Exit status of ``--compare mujoco`` when an agreement figure is above AGREEMENT_TOL."""
EXIT_TARGET_FAILED = 3
"""Exit status of ``--compare mujoco`` when a timing target printed FAIL (as ``bench``)."""


class MujocoRig(MujocoModel):
    """A planar rig as a MuJoCo model: hinge tree plus ``connect`` loop closures."""

    def __init__(self, rig):
        self.mj = import_mujoco()
        self.rig = rig
        lk = self.linkage = rig.linkage
        sc = rig.scene
        if lk.has_pri or lk.npc:
            raise ValueError(f'scene {sc.name!r}: the MuJoCo comparison covers revolute joints '
                             'only (this scene has prismatic joints)')
        if any(sc.gravity_m_s2):
            raise ValueError(f'scene {sc.name!r}: gravity_m_s2 is {list(sc.gravity_m_s2)}, '
                             'expected [0, 0] for the MuJoCo comparison')
        self.xml, self.cut_sign = self._mjcf(sc)
        self.model = m = self.mj.MjModel.from_xml_string(self.xml)
        self.data = self.mj.MjData(m)
        self.dof = np.array([m.jnt_dofadr[m.joint(f't{t}').id] for t in range(lk.nt)])
        self.crank = int(self.dof[0])
        self.passive = self.dof[1:]
        self.rows = np.array([3 * k + r for k in range(len(lk.cuts)) for r in (0, 1)])
        self._find_cuts(len(lk.cuts))
        self.pivot = np.array([lk.pivot.real, lk.pivot.imag, 0.0])
        self.length = lk.length_scale
        self.crank_qpos, self.max_iter = self.crank, NEWTON_MAX_ITER
        self.tol = NEWTON_TOL * self.length

    def _mjcf(self, sc):
        lk = self.linkage
        # each body's MuJoCo frame sits at the joint to its tree parent, axes as the link's
        offset = [0j] * lk.nb
        for tj in lk.tree:
            offset[tj.child] = tj.p_child
        links = {i + 1: link for i, link in enumerate(sc.links)}

        def site(body, point):
            pos = point - offset[body]
            return xml_numbers(pos.real, pos.imag, 0)

        def body(t, tj):
            link = links[tj.child]
            pos = tj.p_parent - offset[tj.parent]
            com = complex(*link.com_m) - offset[tj.child]
            return (f'<body name="{lk.body_names[tj.child]}" '
                    f'pos="{xml_numbers(pos.real, pos.imag, 0)}">',
                    f'<joint name="t{t}" type="hinge" axis="0 0 1"/>',
                    f'<inertial pos="{xml_numbers(com.real, com.imag, 0)}" '
                    f'mass="{xml_numbers(link.mass_kg)}" '
                    f'diaginertia="{xml_numbers(*[link.inertia_com_kg_m2] * 3)}"/>')

        return mjcf('mech_balance', lk, [(c.name, c.b, site(c.b, c.p_b), c.a, site(c.a, c.p_a))
                                         for c in lk.cuts], body)

    def _jacobian(self):
        d = self.data
        return d.efc_J[:d.nefc * self.model.nv].reshape(d.nefc, self.model.nv)[self.rows]

    def _bias(self, qvel):
        """Return the connect points' relative acceleration at zero qacc (Jdot qvel)."""
        mj, m, d = self.mj, self.model, self.data
        gamma = np.empty(self.rows.size)
        ends = zip(self.site1, self.site2, self.body1, self.body2)
        for k, (s1, s2, b1, b2) in enumerate(ends):
            mj.mj_jacDot(m, d, self._jac1, None, d.site_xpos[s1], b1)
            acc = self._jac1[:2] @ qvel
            if b2:
                mj.mj_jacDot(m, d, self._jac2, None, d.site_xpos[s2], b2)
                acc -= self._jac2[:2] @ qvel
            gamma[2 * k:2 * k + 2] = acc
        return gamma

    def _rigid(self, jac):
        """From ``mj_inverse``'s outputs: driving torque, multipliers, frame load (planar)."""
        mj, m, d = self.mj, self.model, self.data
        # M qacc + c = tau e_crank + J^T lambda; the passive joints have no applied torque
        gen = d.qfrc_inverse + d.qfrc_constraint
        lam = solve(jac[:, self.passive].T, gen[self.passive])
        tau = float(gen[self.crank] - jac[:, self.crank] @ lam)
        d.efc_force[:] = 0.0
        d.efc_force[self.rows] = lam
        d.qfrc_constraint[:] = jac.T @ lam
        mj.mj_rnePostConstraint(m, d)
        # wrench of the world on the links: hinge reactions (incl. the motor), about the
        # pivot (cfrc_int of a root body is taken about its subtree's centre of mass) ...
        px, py = self.pivot[0], self.pivot[1]
        fx = fy = mz = 0.0
        cfrc, com = d.cfrc_int, d.subtree_com
        for b in self.roots:
            _, _, tz, gx, gy, _ = cfrc[b].tolist()
            cx, cy, _ = com[b].tolist()
            fx += gx
            fy += gy
            mz += tz + (cx - px) * gy - (cy - py) * gx
        # ... and connects to the world (site 2 on the world: +lambda acts on body 1)
        for k in self.world_cuts:
            gx, gy = float(lam[2 * k]), float(lam[2 * k + 1])
            sx, sy, _ = d.site_xpos[self.site1[k]].tolist()
            fx += gx
            fy += gy
            mz += (sx - px) * gy - (sy - py) * gx
        return tau, lam, complex(-fx, -fy), -mz

    def dynamics(self, q, qd, qdd):
        """
        Return MuJoCo's driving torque, shaking force and moment for imposed motion.

        ``q``, ``qd``, ``qdd``: tree coordinates ``(nt, p)``; also the cut forces ``(ncut, p)``.
        """
        p = q.shape[1]
        tau, fsh, nsh = np.empty(p), np.empty(p, dtype=complex), np.empty(p)
        cut = np.empty((len(self.site1), p), dtype=complex)

        def rigid(i):
            tau[i], lam, fsh[i], nsh[i] = self._rigid(self._jacobian())
            cut[:, i] = (lam[0::2] + 1j * lam[1::2]) * self.cut_sign
        self._inverse(*(self.to_dofs(x) for x in (q, qd, qdd)), rigid)
        return tau, fsh, nsh, cut

    def to_dofs(self, x):
        """Return this package's tree coordinates ``(nt, p)`` as MuJoCo dofs ``(p, nv)``."""
        out = np.empty((x.shape[1], self.model.nv))
        out[:, self.dof] = x.T
        return out

    def _closure(self):
        """Return the connect rows' residual (m) and Jacobian at ``data.qpos``."""
        mj, m, d = self.mj, self.model, self.data
        mj.mj_kinematics(m, d)
        mj.mj_comPos(m, d)
        mj.mj_makeConstraint(m, d)
        return d.efc_pos[self.rows], self._jacobian()

    def full(self, psi, speed, accel, q_start):
        """Return MuJoCo's ``(tau, f_sh, n_sh, q, residual, iterations)``, ``q`` in tree order."""
        p = psi.size
        tau, fsh, nsh = np.empty(p), np.empty(p, dtype=complex), np.empty(p)

        def rigid(i):
            tau[i], _, fsh[i], nsh[i] = self._rigid(self._jacobian())
        qpos = np.zeros(self.model.nv)
        qpos[self.dof] = q_start
        q, res, iters = self._solution(psi, speed, accel, (psi, speed, accel), qpos, rigid)
        return tau, fsh, nsh, q[:, self.dof].T, res / self.length, iters


def interleaved_rounds(fns, rounds=TIMING_ROUNDS, warmup=2):
    """Return, per ``(function, runs)``, its round medians of wall time (a list of ``rounds``)."""
    for fn, _ in fns:
        for _ in range(warmup):
            fn()
    per_round = [[] for _ in fns]
    for _ in range(rounds):
        for (fn, n), acc in zip(fns, per_round):
            fn()
            block = []
            for _ in range(max(1, math.ceil(n / rounds))):
                t0 = time.perf_counter()
                fn()
                block.append(time.perf_counter() - t0)
            acc.append(statistics.median(block))
    return per_round


def _interleaved_medians(fns, warmup=2):
    """Return the median of the round medians of each function (:func:`interleaved_rounds`)."""
    return [statistics.median(r) for r in interleaved_rounds(fns, warmup=warmup)]


def spread(values):
    """Return (max - min) / median of ``values`` (the rounds' relative spread)."""
    mid = statistics.median(values)
    return (max(values) - min(values)) / mid if mid else 0.0


def compare(sc, samples=360, repeat=50, progress=None):
    """
    Return the agreement and timing figures of one scene, both engines, one process.

    Keys: ``agreement_imposed``, ``agreement_own``, ``cut_forces``, ``us``,
    ``mujoco_residual``, ``mujoco_iterations``, ``ours_residual``, ``ours_cond``.
    """
    sc = sc.with_outputs(scene_mod.OUTPUTS)
    rig = analysis.Rig(sc)
    lk = rig.linkage
    mjr = MujocoRig(rig)
    psi = cycle_angles(samples, sc.assembly_crank_angle_rad)
    speed, accel = sc.crank_speed_rad_s, sc.crank_acceleration_rad_s2
    need = scene_mod.needs(sc.outputs)
    state, w = rig.evaluate(psi)
    tau, fsh, nsh, cut = mjr.dynamics(state.q, state.qd, state.qdd)
    ours_cut = np.array([w.reaction_force[c.name] for c in lk.cuts])
    tau2, fsh2, nsh2, q2, res2, it2 = mjr.full(psi, speed, accel, state.q[:, 0])
    ours = (w.driving_torque, w.shaking_force, w.shaking_moment)
    out = {
        'scene': sc.name, 'links': len(sc.links), 'joints': len(sc.joints),
        'loops': len(lk.cuts), 'samples': samples,
        'agreement_imposed': agreement(ours, (tau, fsh, nsh)),
        'agreement_own': agreement(ours, (tau2, fsh2, nsh2)),
        'cut_forces': relative_difference(ours_cut, cut),
        'positions': float(np.max(np.abs(q2 - state.q))),
        'mujoco_residual': float(np.max(res2)), 'mujoco_iterations': float(np.mean(it2)),
        'ours_residual': float(np.max(state.residual)), 'ours_cond': float(np.max(state.cond)),
        'ours_iterations': float(np.mean(state.iterations)),
    }
    if progress:
        progress(f'  timing {sc.name} ({len(sc.links)} moving links) ...')
    qpos, qvel, qacc = (mjr.to_dofs(x) for x in (state.q, state.qd, state.qdd))
    q_start = state.q[:, 0]
    slow = max(5, repeat // MUJOCO_REPEAT_DIVISOR)
    fns = [
        (lambda: rig.evaluate(psi), repeat),
        (lambda: dynamics.inverse_dynamics(lk, state, rig.inertia, rig.gravity, need), repeat),
        (lambda: mjr.full(psi, speed, accel, q_start), slow),
        (lambda: mjr.inverse_only(qpos, qvel, qacc), slow),
        (lambda: mjr.dynamics(state.q, state.qd, state.qdd), slow),
    ]
    rounds = interleaved_rounds(fns)
    out['us'] = {n: statistics.median(r) * 1e6 / samples for n, r in zip(TIMED, rounds)}
    out['us_rounds'] = {n: [x * 1e6 / samples for x in r] for n, r in zip(TIMED, rounds)}
    out['repeats'] = (repeat, slow)
    out['peak_bytes'] = peak_bytes(lambda: rig.evaluate(psi))
    return out


def format_report(hoeken, chains, mujoco_version, extras=()):
    """Return the printed comparison (``extras``: more scenes for the scaling table)."""
    rep, slow = hoeken['repeats']
    us = hoeken['us']
    lines = [
        f'mech-balance bench --compare mujoco: mech_balance vs MuJoCo {mujoco_version}, '
        f'{hoeken["samples"]} crank angles per cycle, one process; median wall time of '
        f'{rep} runs (MuJoCo: {slow}): the median of {TIMING_ROUNDS} round medians, the '
        'engines timed in interleaved warm blocks',
        '',
        'timed, per crank angle: the full pipeline (mech_balance: Rig.evaluate on all angles at '
        'once; MuJoCo: a Python loop',
        'of Newton, rates, mj_inverse, rigid multipliers and frame load) and the dynamics alone '
        '(motion imposed from',
        'mech_balance; "+ rigid": the same outputs): docs/benchmarks.md#the-mujoco-models-in-'
        'detail',
        '',
        f'{hoeken["scene"]} (Chaudhary & Saha Table 1): {hoeken["links"]} moving links, '
        f'{hoeken["joints"]} joints, {hoeken["loops"]} loop',
        '  agreement, max |MuJoCo - mech_balance| / max |mech_balance| over the cycle:',
        *agreement_rows(hoeken),
    ]
    hoeken_worst = worst(hoeken)
    lines += [
        f'  {"cut joint forces":<18}{hoeken["cut_forces"]:>16.1e}',
        f'  -> {"PASS" if hoeken_worst <= AGREEMENT_TOL else "FAIL"} (worst {hoeken_worst:.1e}, '
        f'limit {AGREEMENT_TOL:.0e}); MuJoCo Newton: residual {hoeken["mujoco_residual"]:.1e}, '
        f'{hoeken["mujoco_iterations"]:.2f} iterations/angle; positions differ by '
        f'{hoeken["positions"]:.1e} rad',
        '  us per crank angle:',
        f'  {"":<26}{"mech_balance":>14}{"MuJoCo":>12}{"ratio":>10}',
        *us_rows(us, 26, 'mj_inverse + rigid'),
        f'  -> full pipeline {us["mj_full"] / us["ours_full"]:.1f}x faster '
        f'({"PASS" if us["mj_full"] >= SPEEDUP_GOAL * us["ours_full"] else "FAIL"}: '
        f'>= {SPEEDUP_GOAL:g}x); dynamics alone '
        f'{"PASS" if us["ours_dyn"] <= us["mj_inverse"] else "FAIL"} (no slower than '
        'mj_inverse)',
        '',
        'scaling: generated chains (mech_balance.bench.chains.dyad_chain: a crank-rocker and '
        'near-parallelogram stages)',
        f'  {"links":>5}{"moving":>7}{"loops":>6} |{"mech_balance us/angle":>22}'
        f'{"":>6}|{"MuJoCo us/angle":>17}{"":>12}|{"ratio":>7} |{"agreement":>10}'
        f'{"peak MB":>9}',
        f'  {"":>5}{"":>7}{"":>6} |{"full":>11}{"dynamics":>11}{"":>6}|'
        f'{"full":>10}{"mj_inverse":>12}{"":>7}|{"full":>7} |{"worst":>10}{"ours":>9}',
    ]
    for r in list(chains) + list(extras):
        u = r['us']
        lines.append(f'  {r["links"] + 1:>5}{r["links"]:>7}{r["loops"]:>6} |'
                     f'{u["ours_full"]:>11.3f}{u["ours_dyn"]:>11.3f}{"":>6}|'
                     f'{u["mj_full"]:>10.2f}{u["mj_inverse"]:>12.2f}{"":>7}|'
                     f'{u["mj_full"] / u["ours_full"]:>6.1f}x |{worst(r):>10.1e}'
                     f'{r.get("peak_bytes", 0) / 2 ** 20:>9.2f}'
                     + ('' if r['scene'].startswith('dyad_chain') else f'  {r["scene"]}'))
    every = [hoeken] + list(chains) + list(extras)
    worst_all = float(np.max([worst(r) for r in every]))
    lines.append(f'  agreement over all {len(every)} rigs (both motions, torque, shaking force '
                 f'and moment): worst {worst_all:.1e} -> '
                 f'{"PASS" if worst_all <= AGREEMENT_TOL else "FAIL"}')
    if len(chains) >= 2:
        a, b = chains[0], chains[-1]
        ratio = (b['links'] + 1) / (a['links'] + 1)
        grow = {k: math.log(b['us'][k] / a['us'][k]) / math.log(ratio)
                for k in ('ours_full', 'ours_dyn', 'mj_full', 'mj_inverse')}
        # the exponent of each round (round k of the small rig against round k of the large)
        per_round = [math.log(y / x) / math.log(ratio) for x, y in
                     zip(a.get('us_rounds', {}).get('ours_full', ()),
                         b.get('us_rounds', {}).get('ours_full', ()))]
        rounds_text = ''
        if per_round:
            widest = max(spread(r['us_rounds']['ours_full']) for r in (a, b))
            rounds_text = (f'; its {len(per_round)} rounds {min(per_round):.2f} to '
                           f'{max(per_round):.2f}, timings spread up to {100 * widest:.0f} %')
        lines += [
            f'  growth exponent {a["links"] + 1} -> {b["links"] + 1} links '
            f'(cost ~ links^e): mech_balance full {grow["ours_full"]:.2f}, dynamics '
            f'{grow["ours_dyn"]:.2f}; MuJoCo full {grow["mj_full"]:.2f}, mj_inverse '
            f'{grow["mj_inverse"]:.2f}  '
            f'({"PASS" if grow["ours_full"] <= GROWTH_LIMIT else "FAIL"}: mech_balance full '
            f'<= {GROWTH_LIMIT:g}, linear)',
            f'  (median of {TIMING_ROUNDS} round medians, the engines in interleaved warm '
            f'blocks{rounds_text})',
            '  links count the frame.  A single-input planar chain of revolute joints has an '
            'odd number of moving',
            '  links (Gruebler: 3 n - 2 j = 1), so 7 links with the frame cannot exist: '
            '8 (7 moving, the carpet',
            "  scraper's count) stands in for it.",
        ]
        for links, goal in RATIO_GOALS.items():
            for r in chains:
                if r['links'] + 1 == links:
                    ratio = r['us']['mj_full'] / r['us']['ours_full']
                    lines.append(f'  {links} links: full pipeline {ratio:.1f}x MuJoCo -> '
                                 f'{"PASS" if ratio >= goal else "FAIL"} (>= {goal:g}x)')
    return '\n'.join(lines)


def run(samples=360, repeat=50, progress=print, loops=CHAIN_LOOPS):
    """
    Return ``(hoeken, chains, extras, version)``: :func:`compare` of each rig.

    ``chains``: the generated chains of ``loops`` loops; ``extras``: the carpet scraper.
    """
    mujoco = import_mujoco()
    progress('  comparing hoeken ...')
    hoeken = compare(scene_mod.load('hoeken'), samples, repeat, progress)
    chains = []
    for n in loops:
        progress(f'  comparing a generated chain with {n} loops ...')
        chains.append(compare(chain.dyad_chain(n), samples, repeat, progress))
    progress('  comparing carpet_scraper ...')
    extras = [compare(scene_mod.load('carpet_scraper'), samples, repeat, progress)]
    return hoeken, chains, extras, mujoco.__version__


def cmd_compare(args, progress):
    """Run ``mech-balance bench --compare mujoco`` (``progress(text)``); return the status."""
    try:
        import_mujoco()
    except MujocoMissing as exc:
        print(str(exc), file=sys.stderr)
        return EXIT_MISSING
    hoeken, chains, extras, version = run(args.samples, args.repeat, progress)
    printed = [format_report(hoeken, chains, version, extras)]
    print(printed[-1], flush=True)
    from mech_balance.bench import mujoco_spatial, settle
    spatial = mujoco_spatial.run(_interleaved_medians, args.samples, args.repeat,
                                 max(5, args.repeat // MUJOCO_REPEAT_DIVISOR), progress,
                                 mj=import_mujoco())
    printed.append(mujoco_spatial.format_report(spatial, AGREEMENT_TOL))
    print(printed[-1], flush=True)
    # exit 1 when the two disagree (a correctness failure), 3 when a timing target FAILs
    worst_all = float(np.max([worst(r) for r in [hoeken, *chains, *extras, *spatial]]))
    if not worst_all <= AGREEMENT_TOL:
        print(f'mech-balance bench --compare mujoco: the models disagree (worst relative '
              f'difference {worst_all:.1e} > {AGREEMENT_TOL:.0e})', file=sys.stderr)
        return EXIT_DISAGREE
    failed = settle.report_failures('mech-balance bench --compare mujoco', printed)
    return EXIT_TARGET_FAILED if failed else 0
