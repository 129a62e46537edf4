"""
Timings for ``mech-balance bench``: median of repeated runs after warm-up.

Only this module (and the command that prints it) measures time; tests never do.
"""

import statistics
import time

from mech_balance import analysis, scene as scene_mod
from mech_balance.conventions import cycle_angles

WARMUP = 3
"""Runs discarded before timing (caches, branch tracing, allocator)."""
DEFAULT_REPEAT = 50
"""Timed runs per figure; the median is reported."""

SECTIONS = ('mech_balance.cli_balance', 'mech_balance.cli_record', 'mech_balance.bench_node',
            'mech_balance.cli_identify')
"""Modules that add bench sections: each has ``bench_section(args, progress) -> str``
returning its printed table; ``mech-balance bench`` prints them after the core timings."""


def median_seconds(fn, repeat=DEFAULT_REPEAT, warmup=WARMUP):
    """Return the median wall time of ``fn()`` over ``repeat`` runs after ``warmup`` runs."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def cycle_timing(scene, samples=360, outputs=None, repeat=DEFAULT_REPEAT):
    """
    Return timing figures of one full cycle of a planar scene.

    ``build_s`` is the one-off cost of compiling the linkage and tracing its branch
    (reported apart: it depends on the geometry only); ``cycle_s`` is the median time of
    position, velocity, acceleration and inverse-dynamics analysis at ``samples`` angles.
    """
    t0 = time.perf_counter()
    linkage = analysis.kinematics.Linkage(scene)
    linkage.skeleton  # noqa: B018 - the branch trace is the build cost
    build = time.perf_counter() - t0
    rig = analysis.Rig(scene, linkage)
    psi = cycle_angles(samples, scene.assembly_crank_angle_rad)
    cycle = median_seconds(lambda: rig.evaluate(psi, outputs), repeat=repeat)
    return {'scene': scene.name, 'samples': samples, 'build_s': build, 'cycle_s': cycle,
            'us_per_angle': cycle * 1e6 / samples,
            'outputs': list(outputs or scene.outputs)}


def run(names=None, samples=360, repeat=DEFAULT_REPEAT, progress=print):
    """Return the bench table (list of dicts) for the given built-in scene names."""
    names = names or list(scene_mod.builtin_scenes())
    rows = []
    for name in names:
        sc = scene_mod.load(name)
        if getattr(sc, 'kind', 'planar') != 'planar':
            progress(f'  {name}: skipped here (kind {sc.kind}; timed by its own bench)')
            continue
        progress(f'  timing {name} ...')
        full = sc.with_outputs(scene_mod.OUTPUTS)
        rows.append(cycle_timing(full, samples, repeat=repeat))
        if name == 'hoeken':
            rows.append(cycle_timing(full, samples, outputs=('shaking_wrench',),
                                     repeat=repeat))
    return rows


def format_rows(rows):
    """Return the bench table as text."""
    width = max([16] + [len(r['scene']) + 2 for r in rows])
    lines = [f'{"scene":<{width}}{"outputs":<30}{"us/angle":>10}{"ms/cycle":>10}'
             f'{"build ms":>10}', '-' * (width + 60)]
    for r in rows:
        outs = 'everything' if len(r['outputs']) == len(scene_mod.OUTPUTS) else \
            '+'.join(r['outputs'])
        lines.append(f'{r["scene"]:<{width}}{outs:<30}{r["us_per_angle"]:>10.3f}'
                     f'{r["cycle_s"] * 1e3:>10.3f}{r["build_s"] * 1e3:>10.1f}')
    return '\n'.join(lines)
