"""The balancing bench sections of ``mech-balance bench``: medians of whole solves."""

from mech_balance import schema as scene_mod
from mech_balance.balancing import counterweights as cw_mod, paper_tables as seed_tables, \
    redistribution
from mech_balance.bench import core as bench

BENCH_REPEAT_MAX = 20
"""Most timed optimizations per case (each takes milliseconds to a second)."""


COUNTERWEIGHT_BENCH = {'hoeken': (('crank', 'rocker'), 20.0), 'carpet_scraper': (None, 300.0)}
"""Bench cases of --counterweights: scene -> (links, None for every link; median limit ms)."""


def bench_section(args, progress):
    """Return the redistribution's bench table: median wall time per weight case."""
    names = args.scene or ['hoeken', 'carpet_scraper']
    repeat = min(int(args.repeat), BENCH_REPEAT_MAX)
    head = (f"{'balance: scene':<18}{'case':<6}{'weights':<12}{'constraints':<13}"
            f"{'z':>12}{'rel. gap':>10}{'median ms':>11}{'cone ms':>9}")
    lines = [f'balance (Chaudhary & Saha SOCP): median of {repeat} optimizations after '
             f'{bench.WARMUP} warm-up runs, {args.samples} crank angles'
             + (f' (--repeat {args.repeat} capped at {BENCH_REPEAT_MAX})'
                if args.repeat > repeat else ''),
             head, '-' * len(head)]
    header_lines = len(lines)
    for name in names:
        if name not in ('hoeken', 'carpet_scraper'):
            continue
        sc = scene_mod.load(name)
        cases = ('a', 'b') if name == 'hoeken' else ('a',)
        for case in cases:
            for w in seed_tables.WEIGHT_CASES:
                for paper in (True, False):
                    progress(f'  timing balance {name} {case} {w} '
                             f'{"paper" if paper else "realizable"} ...')
                    sec, r = bench.median_and_result(lambda: redistribution.optimize(
                        sc, w, case, paper_constraints=paper, samples=args.samples), repeat)
                    lines.append(f"{name:<18}{case:<6}{f'({w[0]:g}, {w[1]:g})':<12}"
                                 f"{'paper' if paper else 'realizable':<13}"
                                 f"{r.objective['z']:>12.6g}{r.certificate.gap_rel:>10.1e}"
                                 f'{sec * 1e3:>11.1f}{r.conic_time_s * 1e3:>9.1f}')
    if len(lines) == header_lines:
        lines.append('(no balancing benchmark for the selected scenes)')
    return '\n'.join(lines)


def counterweights_section(args, progress):
    """Return the counterweight rows: median solve time against its limit."""
    names = args.scene or list(COUNTERWEIGHT_BENCH)
    repeat = min(int(args.repeat), BENCH_REPEAT_MAX)
    head = (f"{'counterweights: scene':<22}{'links':<22}{'weights':<12}{'rel. gap':>10}"
            f"{'median ms':>11}{'limit ms':>10}{'cone ms':>9}  within")
    lines = [f'counterweights (add-only discs, SOCP): median of {repeat} solves after '
             f'{bench.WARMUP} warm-up runs, {args.samples} crank angles', head,
             '-' * len(head)]
    for name in names:
        if name not in COUNTERWEIGHT_BENCH:
            continue
        sc = scene_mod.load(name)
        links, limit_ms = COUNTERWEIGHT_BENCH[name]
        links = links or tuple(lk.name for lk in sc.links)
        for w in seed_tables.WEIGHT_CASES:
            progress(f'  timing counterweights {name} {w} ...')
            sec, r = bench.median_and_result(lambda: cw_mod.balance_with_counterweights(
                sc, links, w, samples=args.samples), repeat)
            label = ','.join(links) if len(links) <= 3 else f'all {len(links)}'
            lines.append(f"{name:<22}{label:<22}{f'({w[0]:g}, {w[1]:g})':<12}"
                         f'{r.certificate.gap_rel:>10.1e}{sec * 1e3:>11.1f}{limit_ms:>10.0f}'
                         f'{r.conic_time_s * 1e3:>9.1f}  '
                         + ('yes' if sec * 1e3 <= limit_ms else 'NO'))
    return '\n'.join(lines)
