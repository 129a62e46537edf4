"""
Timings for ``mech-balance bench``: median of repeated runs after warm-up.

Only this module (and the command that prints it) measures time; tests never do.
"""

import time

from mech_balance import schema as scene_mod
from mech_balance.analysis import cycle as analysis
from mech_balance.analysis.timing import DEFAULT_REPEAT, median_seconds, WARMUP  # noqa: F401
from mech_balance.conventions import cycle_angles

SECTIONS = ('mech_balance.bench.balancing:bench_section',
            'mech_balance.bench.balancing:counterweights_section',
            'mech_balance.bench.recording:bench_section',
            'mech_balance.bench.node:bench_section',
            'mech_balance.bench.node:live_view_section',
            'mech_balance.bench.identify:bench_section')
"""The bench sections, ``module:function`` with ``function(args, progress) -> str`` returning
its printed table; ``mech-balance bench`` prints them after the core timings."""


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
