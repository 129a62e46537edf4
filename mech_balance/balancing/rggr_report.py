"""
The RGGR's ``balance`` report (seed 002): the weights, the optimum and a before/after table.

The view (SI or by m_o1, a1 and omega), the metrics and the table are the analyze report's
(:mod:`mech_balance.analysis.rggr_report`).
"""

import dataclasses
import math

from mech_balance.analysis import rggr_report
from mech_balance.balancing import rggr as rggr_balancing
from mech_balance.conventions import cycle_angles, DEFAULT_SAMPLES
from mech_balance.core.rggr import dynamics
import numpy as np


def balance_report(scene, samples=DEFAULT_SAMPLES, normalized=False, result=None):
    """
    Return the force balancing and shaking-moment optimization of ``scene`` as a plain dict.

    The balancing weights (masses, centres, products, output weight radius, I_b3w, alpha,
    gamma), the optimal J1..J4, a before/after table (unbalanced = links without weights,
    force-balanced = weights with zero products, optimized), the least-squares optimum, the
    worst loop residual and the solve time.
    """
    view = rggr_report.ReportView(scene, normalized)
    if result is None:
        result = rggr_balancing.balance_scene(scene, samples)
    angles = cycle_angles(samples)
    bare = dataclasses.replace(scene, crank_weight=None, output_weight=None)
    rows = []
    residual = 0.0
    for label, rig in (('unbalanced', bare), ('force-balanced', result.force_balance.scene),
                       ('optimized', result.design.scene)):
        dyn = dynamics(rig, angles)
        residual = max(residual, float(np.max(np.abs(dyn.kinematics.loop_residual_m))))
        rows.append({'rig': label, **rggr_report.report_metrics(dyn, view)})
    cw, ow, des = result.design.crank_weight, result.design.output_weight, result.design
    opt = result.optimum
    report = rggr_report.report_header(scene, 'balance', samples, view)
    report.update({
        'coupler_mass_fraction': result.force_balance.coupler_mass_fraction,
        'crank_weight': {'mass': view.mass(cw.mass_kg),
                         'centre_uvw': view.length(cw.centre_uvw_m),
                         'product_wu': view.inertia(cw.product_wu_kg_m2),
                         'product_vw': view.inertia(cw.product_vw_kg_m2)},
        'output_weight': {'mass': view.mass(ow.mass_kg),
                          'centre_uvw': view.length(ow.centre_uvw_m),
                          'radius': view.length(des.output_weight_radius_m),
                          'inertia_ww': view.inertia(ow.inertia_ww_kg_m2),
                          'product_wu': view.inertia(ow.product_wu_kg_m2),
                          'product_vw': view.inertia(ow.product_vw_kg_m2),
                          'alpha_deg': math.degrees(des.alpha_rad),
                          'gamma_deg': math.degrees(des.gamma_rad)},
        'inertia_parameters': dict(zip(('I_1wu', 'I_1vw', 'I_3wu', 'I_3vw'),
                                       (view.inertia(x) for x in opt.inertia_parameters_kg_m2))),
        'table': rows,
        'optimum': {'shaking_moment_rms': float(view.moment(opt.moment_rms_optimal_Nm)),
                    'normal_equation_residual': opt.normal_equation_residual,
                    'rank': opt.rank},
        'loop_residual_max_m': residual,
        'solve_time_s': result.solve_time_s,
    })
    return report


def format_report(report):
    """Return a balance report as a readable fixed-width text table."""
    cw, ow, j = report['crank_weight'], report['output_weight'], report['inertia_parameters']
    lines = rggr_report.format_table(report) + [
        f"coupler mass fraction mu = c2/a2: {report['coupler_mass_fraction']:.6g}",
        f"crank weight:  m_b1 {cw['mass']:10.5g}   (u, v, w)_b1 "
        + ' '.join(f'{x:10.5g}' for x in cw['centre_uvw'])
        + f"   I_b1wu {cw['product_wu']:10.5g}   I_b1vw {cw['product_vw']:10.5g}",
        f"output weight: m_b3 {ow['mass']:10.5g}   (u, v, w)_b3 "
        + ' '.join(f'{x:10.5g}' for x in ow['centre_uvw'])
        + f"   r {ow['radius']:10.5g}   I_b3w {ow['inertia_ww']:10.5g}",
        f"               I_b3wu {ow['product_wu']:10.5g}   I_b3vw {ow['product_vw']:10.5g}"
        f"   alpha {ow['alpha_deg']:8.3f} deg   gamma {ow['gamma_deg']:8.3f} deg",
        'optimal products (links with weights): '
        + '   '.join(f'{k} {v:10.5g}' for k, v in j.items()),
        f"least-squares optimum: |n| rms {report['optimum']['shaking_moment_rms']:.6g}, "
        f"normal-equation residual {report['optimum']['normal_equation_residual']:.2e}, "
        f"rank {report['optimum']['rank']}",
        f"solve time: {report['solve_time_s'] * 1e3:.1f} ms",
        f"worst loop residual |BC| - a2: {report['loop_residual_max_m']:.3e} m"]
    return '\n'.join(lines)
