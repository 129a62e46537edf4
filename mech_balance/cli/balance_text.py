"""The text ``mech-balance balance`` prints of a :class:`~mech_balance.balancing.result.Design`."""

from mech_balance.balancing import paper_tables

NO_CLEAR_MESSAGE = 'no collision-free counterweight design within the bounds'
"""What ``balance --counterweights`` says when :class:`.clearance_design.NoClearDesign`."""


def format_result(design, normalized=False):
    """Return a redistribution :class:`~mech_balance.balancing.result.Design` as readable text."""
    from mech_balance.balancing import counterweights
    result = design.result
    sc = result.scene
    view = normalized and sc.normalization is not None
    lines = [f'scene: {sc.name} ({sc.source}); {result.samples} crank angles per revolution',
             f'problem: minimize {_objective(result)}'
             + ' (Chaudhary & Saha eqs. 42-53, RMS of normalized quantities)',
             f'constraints: case {result.case} ('
             + ('point masses >= 0' if result.case == 'b' else 'point masses of any sign')
             + '), ' + ('paper constraints (eqs. 50/53), realizability not imposed'
                        if result.paper_constraints else
                        'realizable links (centroidal inertia >= margin x I_O)'
                        if result.realizable_constraint else 'realizability not imposed')]
    if result.max_added_mass_kg is not None:
        lines.append(f'total added mass <= {result.max_added_mass_kg:g} kg')
    lines += ['', links_table(result.links, view, sc), '']
    lines.append(before_after_text(result.table, si=not view))
    cert = result.certificate
    lines += ['', *_objective_lines(result), *_failed_lines(cert)]
    if cert.stage2 is not None:
        stage2 = cert.stage2
        lines.append(f"tie-break (optimum not unique): minimized {stage2['minimized']} among "
                     'optimal designs' + (' with the shaking force exactly zero'
                                          if stage2['exact_force_balance'] else '')
                     + f": {stage2['objective']:.6g} (lower bound {stage2['lower_bound']:.6g}; "
                     f"{stage2['status']}, {stage2['iterations']} iterations)")
    lines.append('design realizable: ' + ('yes' if result.realizable else 'NO ('
                 + ', '.join(d.name for d in result.links if not d.realizable) + ')'))
    lines += [counterweights.format_cost(design.report['cost']), _solve_time(result)]
    lines += _paper_comparison(paper_tables.compare_optimum(result))
    confidence = design.report.get('identification_confidence')
    if confidence is not None:
        from mech_balance.analysis import identify
        lines.append(identify.format_balance_confidence(confidence))
    return '\n'.join(lines)


def _objective(problem):
    """Return ``z = w1 f~ + w2 n~`` with the torque and bearing terms that are weighted."""
    w1, w2 = problem.weights
    return (f'z = {w1:g} f~ + {w2:g} n~'
            + (f' + {problem.torque_weight:g} tau~' if problem.torque_weight else '')
            + (f' + {problem.reaction_weight:g} sum f~_bearing' if problem.reaction_weight
               else ''))


def _objective_lines(result):
    """Return the objective's figures and the certificate's lines."""
    obj = result.objective
    return [f"objective z = {obj['z']:.6g} (original {obj['z_original']:.6g}): "
            f"f~ = {obj['shaking_force_rms']:.6g}, n~ = {obj['shaking_moment_rms']:.6g}",
            *certificate_lines(result.certificate)]


def _failed_lines(cert):
    return [f"FAILED stage '{f['stage']}': {f['reason']}; the design is {f['design']}"
            for f in cert.failed_stages or ()]


def _solve_time(result):
    return (f'solve time {result.solve_time_s * 1e3:.1f} ms (linear maps '
            f'{result.maps_time_s * 1e3:.1f} ms, cone programs '
            f'{result.conic_time_s * 1e3:.1f} ms)')


def links_table(links, view, sc):
    """Return the design per link (point masses, mass, centre, inertias, realizable)."""
    u = sc.normalization
    if view:
        head = (f"{'link':<10}{'m_1':>9}{'m_2':>9}{'m_3':>9}{'l':>9}{'mass':>9}{'d':>9}"
                f"{'theta':>8}{'I_O':>10}{'I_C':>10}  realizable")
        unit = '(normalized: masses by m1, lengths by a1, inertias by m1 a1^2; theta in deg)'
    else:
        head = (f"{'link':<10}{'m_1 kg':>10}{'m_2 kg':>10}{'m_3 kg':>10}{'l m':>10}"
                f"{'mass kg':>10}{'d m':>10}{'theta':>8}{'I_O kgm2':>11}{'I_C kgm2':>11}"
                '  realizable')
        unit = '(SI; theta in deg)'
    out = [unit, head, '-' * len(head)]
    for d in links:
        ok = 'yes' if d.realizable else f'NO: {d.reason}'
        if view:
            ms, ls = u.mass_kg, u.length_m
            i_s = ms * ls * ls
            pm = [m / ms for m in d.point_masses_kg]
            out.append(f'{d.name:<10}' + ''.join(f'{v:>9.4f}' for v in pm)
                       + f'{d.distance_m / ls:>9.4f}{d.mass_kg / ms:>9.4f}'
                       f'{d.com_distance_m / ls:>9.4f}{d.com_angle_deg:>8.2f}'
                       f'{d.inertia_origin_kg_m2 / i_s:>10.4f}'
                       f'{d.inertia_com_kg_m2 / i_s:>10.4f}  {ok}')
        else:
            out.append(f'{d.name:<10}' + ''.join(f'{v:>10.4g}' for v in d.point_masses_kg)
                       + f'{d.distance_m:>10.4g}{d.mass_kg:>10.4g}{d.com_distance_m:>10.4g}'
                       f'{d.com_angle_deg:>8.2f}{d.inertia_origin_kg_m2:>11.4g}'
                       f'{d.inertia_com_kg_m2:>11.4g}  {ok}')
    return '\n'.join(out)


def before_after_text(table, si=False):
    """Return the before/after RMS rows in SI (``si``) or the papers' normalized units."""
    head = f"{'RMS over the cycle':<26}{'unit':>13}{'before':>13}{'after':>13}{'change':>10}"
    out = [head, '-' * len(head)]
    sfx = '_si' if si else ''
    for r in table:
        ch = 'n/a' if r['change_percent'] is None else f"{r['change_percent']:+.1f}%"
        out.append(f"{r['quantity']:<26}{r['unit' + sfx]:>13}{r['before' + sfx]:>13.6g}"
                   f"{r['after' + sfx]:>13.6g}{ch:>10}")
    return '\n'.join(out)


def _paper_comparison(comparison):
    """Return lines comparing with seed 001 Tables 5/7 (Hoeken) or 9/10 (carpet scraper)."""
    if comparison is None:
        return []
    c = comparison
    bad = [f'{name} ({reason})' for name, reason in c['unrealizable'].items()]
    return ['', f"Chaudhary & Saha {c['label']}: f~ = {c['f']:g}, n~ = {c['n']:g}, z = "
                f"{c['z_paper']:.6g}; this optimum z = {c['z']:.6g} ({c['change_percent']:+.3f}%)"
                + ('' if c['paper_constraints'] else
                   ' [other constraints than the paper: see --paper-constraints]'),
            "the paper's design vector: " + ('realizable' if not bad else
                                             'NOT realizable: ' + '; '.join(bad))]


def certificate_lines(cert):
    """Return the certificate as text: primal, safe lower bound, gap, stages, violations."""
    lines = [f'certificate ({cert.solver}): status {cert.status}'
             + (f' (attempts: {", ".join(cert.attempts)})' if cert.attempts and
                len(cert.attempts) > 1 else '')
             + f', primal {cert.primal:.9g}, lower bound {cert.lower_bound:.9g}, gap '
             f'{cert.gap_abs:.2e} (relative {cert.gap_rel:.2e}), '
             + ('certified' if cert.certified else 'NOT certified')
             + f'; {cert.iterations} iterations, residuals {cert.residual_primal:.1e} / '
             f'{cert.residual_dual:.1e}',
             f"max constraint violation of the solver's design {cert.max_violation:.1e}"
             + (f' (moved {cert.feasibility_pull:.0e} of the way to a feasible anchor; the '
                'design reported satisfies every constraint)' if cert.feasibility_pull else
                ' (the design reported satisfies every constraint)'
                if cert.max_violation else '')]
    return lines


def format_counterweights(design, normalized=False):
    """Return a counterweight :class:`~mech_balance.balancing.result.Design` as readable text."""
    from mech_balance.balancing import counterweights
    result = design.result
    sc, opt = result.scene, result.options
    view = normalized and sc.normalization is not None
    lines = [f'scene: {sc.name} ({sc.source}); {opt.samples} crank angles per revolution',
             f'problem: add one solid disc to each of {", ".join(opt.links)}; minimize '
             + _objective(opt),
             f'discs: density {opt.density_kg_m3:g} kg/m^3, thickness <= '
             f'{opt.max_thickness_m:g} m, centre <= {opt.max_radius_factor:g} x joint reach, '
             f'mass <= {opt.max_mass_factor:g} x link mass, radius of gyration <= '
             f'{opt.max_gyration_factor:g} x joint reach'
             + ('' if opt.max_rim_radius_factor is None else
                f', rim <= {opt.max_rim_radius_factor:g} x joint reach'), '']
    head = (f"{'link':<10}{'mass kg':>10}{'r m':>10}{'angle':>9}{'x m':>11}{'y m':>11}"
            f"{'disc R m':>10}{'t mm':>8}{'total kg':>10}{'total I_C':>11}")
    lines += ['counterweights (centre in the link frame; disc radius R and thickness t as '
              'built)', head, '-' * len(head)]
    for d in result.designs:
        totals = result.link_totals[d.link]
        lines.append(f'{d.link:<10}{d.mass_kg:>10.5g}{d.centre_radius_m:>10.5g}'
                     f'{d.centre_angle_deg:>9.2f} {d.centre_m[0]:>10.4g} {d.centre_m[1]:>10.4g}'
                     f'{d.radius_m:>10.5g}{d.thickness_m * 1e3:>8.3g}{totals["mass_kg"]:>10.5g}'
                     f'{totals["inertia_com_kg_m2"]:>11.4g}')
    for name in result.omitted:
        lines.append(f'{name:<10}  no counterweight (the optimal disc mass is zero)')
    lines.append(f'total added mass {result.added_mass_kg:.6g} kg')
    if result.clearance is not None:
        lines += result.clearance.lines()
    if result.clearance_design is not None:
        lines += result.clearance_design.lines()
    lines += ['', before_after_text(result.table, si=not view), '', *_objective_lines(result)]
    cert = result.certificate
    if cert.stage2 is not None:
        stage2 = cert.stage2
        lines.append(f"tie-break: minimized {stage2['minimized']} among optimal designs"
                     + (' with the shaking force exactly zero' if stage2['exact_force_balance']
                        else '') + f": {stage2['objective']:.6g} (lower bound "
                     f"{stage2['lower_bound']:.6g}; {stage2['status']})")
    if result.least_mass is not None:
        least = result.least_mass
        lines.append(f"tie-break: least total added mass {least['objective_kg']:.6g} kg "
                     f"(lower bound {least['lower_bound_kg']:.6g} kg; {least['status']})")
    lines += [*_failed_lines(cert), counterweights.format_cost(result.cost), _solve_time(result)]
    return '\n'.join(lines)


def format_table12(table12):
    """Return seed 001 Table 12's comparison (:func:`mech_balance.balancing.two_point.table12`)."""
    w1, w2 = table12.weights
    head = (f"{'Chaudhary & Saha eqs. B.1-B.5':<44}"
            f"{'torque':>10}{'force':>10}{'moment':>10}{'z':>10}")
    lines = [f'two-point-mass model (Chaudhary & Saha Appendix B), weights ({w1:g}, {w2:g}), '
             'normalized RMS', head, '-' * len(head)]
    for label, torque, force, moment, z in paper_tables.table12_rows(table12):
        lines.append(f'{label:<44}{torque:>10.4g}{force:>10.4g}{moment:>10.4g}{z:>10.5g}')
    lines.append(f'certified: {table12.lower_bound_z:.6g} <= two-point optimum <= '
                 f'{table12.upper_bound_z:.6g} (bounds {table12.gap_rel * 100:.2f}% apart; '
                 f'relaxation gap {table12.lower_bound_gap_rel:.1e}); links the relaxation '
                 'leaves outside the two-point set: '
                 f'{", ".join(table12.band_links) or "none"}')
    return '\n'.join(lines)


def format_spatial(design, normalized=False):
    """Return a spatial design (:mod:`mech_balance.balancing.spatial`) as readable text."""
    from mech_balance.balancing import spatial
    rep = design.report
    lines = [design.summary(), '']
    if design.method == 'force_balance':
        lines.append(f"complete force balance: rank {rep['rank']}, {rep['nullity']} free "
                     f"combinations; {'attained' if rep['attainable'] else 'NOT attainable'} "
                     f"by changing {', '.join(rep['free'])}")
        lines.append('conditions (SI: kg, kg m):')
        lines += spatial.format_conditions(rep['conditions'])
        for name, h in rep['added_first_moment_kg_m'].items():
            lines.append(f'  {name}: first moment change (body axes) '
                         + ' '.join(f'{x:.6g}' for x in h) + ' kg m, mass change '
                         f"{rep['added_mass_kg'][name]:.6g} kg")
        for name, reason in rep['unrealizable'].items():
            lines.append(f'  NOT realizable: {name}: {reason}')
        if rep['unrealizable']:
            lines.append('  the least change is no buildable design; a realizable one with zero '
                         'shaking force, if any: balance --method redistribution '
                         '--force-balanced')
    else:
        cert = rep['certificate']
        lines.append(f"{rep['method']}, weights {rep['weights'][0]:g} {rep['weights'][1]:g}")
        lines.append(f"{'body':<12}{'mass kg':>12}{'centre x':>12}{'y':>12}{'z':>12}"
                     f"{'min eig J':>12}")
        for b in rep['bodies']:
            lines.append(f"{b['name']:<12}{b['mass_kg']:>12.6g}"
                         + ''.join(f'{x:>12.5g}' for x in b['mass_centre_m'])
                         + f"{b['pseudo_inertia_min_eigenvalue']:>12.3g}")
        for name, cluster in rep['options'].get('counterweights', {}).items():
            for c in cluster:
                lines.append(f"  counterweight on {name}: sphere {c['mass_kg']:.5g} kg at "
                             + ' '.join(f'{x:.5g}' for x in c['centre_m'])
                             + f" m, outer radius {c['outer_radius_m']:.4g} m, inner "
                             f"{c['inner_radius_m']:.4g} m")
        if rep['options'].get('note'):
            lines.append(f"note: {rep['options']['note']}")
        lines.append(f"certificate: {cert['status']}, primal {cert['primal']:.9g}, lower bound "
                     f"{cert['lower_bound']:.9g}, gap {cert['gap_abs']:.2e} (relative "
                     f"{cert['gap_rel']:.2e}), max violation {cert['max_violation']:.1e}, "
                     f"{'certified' if cert['certified'] else 'NOT certified'}")
    lines += ['', f"{'quantity':<18}{'unit':<16}{'before':>12}{'after':>12}{'change %':>10}"]
    for r in design.table_in(normalized):
        change = 'n/a' if r['change_percent'] is None else f"{r['change_percent']:.1f}"
        lines.append(f"{r['quantity']:<18}{r['unit']:<16}{r['before']:>12.5g}"
                     f"{r['after']:>12.5g}{change:>10}")
    return '\n'.join(lines)


def format_analytic(sc, designs, normalized=False):
    """Return the analytic designs of a scene (one block each) as readable text."""
    from mech_balance.balancing import counterweights
    view = normalized and sc.normalization is not None
    blocks = []
    for d in designs:
        r = d.result
        params = ', '.join(f'{k} = {v:.6g}' if isinstance(v, float) else f'{k} = {v}'
                           for k, v in r.parameters.items())
        blocks.append('\n'.join([
            f'{r.method}', f'parameters: {params}', '',
            links_table(r.links, view, sc), '', before_after_text(r.table, not view), '',
            f'RMS shaking force after / before: {r.force_rms_ratio:.3e}',
            counterweights.format_cost(d.report['cost'])]))
    text = ('\n\n' + '=' * 99 + '\n\n').join(blocks)
    return f'scene: {sc.name} ({sc.source})\n\n{text}'


def format_weights(design, report):
    """Return a balancing-weights design: seed 002's report in its units, the certificate."""
    from mech_balance.balancing import weights
    result = design.result
    return (weights.format_report(report) + '\n'
            f'certificate: RMS shaking moment {result.moment_rms_optimal_Nm:.9g} N m, safe '
            f'lower bound {result.moment_rms_lower_bound_Nm:.9g} N m (least squares, Hedaya '
            'eqs. 89-95)')


def warning_lines(cert):
    """Return one warning per failed stage, and one if the objective is not certified."""
    from mech_balance.balancing.certificate import CERTIFIED_GAP_REL
    lines = [f"warning: stage '{f['stage']}' failed: {f['reason']}; the design is "
             f"{f['design']}" for f in cert.failed_stages or ()]
    if not cert.certified:
        lines.append(f'warning: the primary objective is not certified (relative gap '
                     f'{cert.gap_rel:.1e} > {CERTIFIED_GAP_REL:.0e}); exit status 2')
    return lines


def no_design_dict(sc, result):
    """Return ``balance --json`` of a counterweight problem with no collision-free design."""
    from mech_balance.schema import registry
    return {'scene': sc.name, 'kind': registry.kind_of(sc).name, 'method': 'counterweights',
            'success': False, 'message': NO_CLEAR_MESSAGE, 'report': result.to_dict()}
