"""
Timings for ``mech-balance bench``: median of repeated runs after warm-up.

Only this module (and the command that prints it) measures time; tests never do.
"""

import time

from mech_balance import schema as scene_mod
from mech_balance.analysis.timing import DEFAULT_REPEAT, median_seconds, WARMUP  # noqa: F401
from mech_balance.conventions import cycle_angles
from mech_balance.core.rig import rig_for

SECTIONS = ('mech_balance.bench.balancing:bench_section',
            'mech_balance.bench.balancing:counterweights_section',
            'mech_balance.bench.recording:bench_section',
            'mech_balance.bench.node:bench_section',
            'mech_balance.bench.node:live_view_section',
            'mech_balance.bench.node:faults_section',
            'mech_balance.bench.cell:bench_section',
            'mech_balance.bench.identify:bench_section',
            'mech_balance.bench.spatial:bench_section')
"""The bench sections, ``module:function`` with ``function(args, progress) -> str`` returning
its printed table; ``mech-balance bench`` prints them after the core timings."""


def section_name(entry):
    """Return the short name of a :data:`SECTIONS` entry (``balancing``, ``cell``, ...)."""
    module, _, function = entry.partition(':')
    if function != 'bench_section':
        return function.replace('_section', '')
    return module.rsplit('.', 1)[-1]


def cycle_timing(scene, samples=360, outputs=None, repeat=DEFAULT_REPEAT):
    """
    Return timing figures of one full cycle of a scene of any kind.

    ``build_s`` is the one-off cost of building the rig (compiling the linkage and tracing
    its branch: it depends on the geometry only); ``cycle_s`` is the median time of the core's
    position, velocity, acceleration and inverse-dynamics analysis at ``samples`` angles (the
    rig's own ``evaluate`` where it has one, else :meth:`Rig.at`), ``at_s`` that of the Rig
    protocol's :meth:`Rig.at`, which adds the joint coordinates and 3-vector wrench.
    """
    t0 = time.perf_counter()
    rig = rig_for(scene, cache=False)
    build = time.perf_counter() - t0
    everything = outputs is None
    outputs = tuple(outputs or rig.outputs)
    psi = cycle_angles(samples, getattr(scene, 'assembly_crank_angle_rad', 0.0))
    native = getattr(rig, 'evaluate', None)  # the core's cycle, without the protocol's views
    at = median_seconds(lambda: rig.at(psi, outputs=outputs), repeat=repeat)
    cycle = median_seconds(lambda: native(psi, outputs), repeat=repeat) if native else at
    return {'scene': scene.name, 'samples': samples, 'build_s': build, 'cycle_s': cycle,
            'us_per_angle': cycle * 1e6 / samples, 'at_us_per_angle': at * 1e6 / samples,
            'outputs': list(outputs), 'everything': everything}


def run(names=None, samples=360, repeat=DEFAULT_REPEAT, progress=print):
    """Return the bench table (list of dicts) for the given built-in scene names."""
    names = names or list(scene_mod.builtin_scenes())
    rows = []
    for name in names:
        sc = scene_mod.load(name)
        progress(f'  timing {name} ...')
        full = sc.with_outputs(scene_mod.DEFAULT_OUTPUTS) if hasattr(sc, 'with_outputs') \
            else sc
        rows.append(cycle_timing(full, samples, repeat=repeat))
        if name == 'hoeken':
            rows.append(cycle_timing(full, samples, outputs=('shaking_wrench',),
                                     repeat=repeat))
    return rows


def format_rows(rows):
    """Return the bench table as text."""
    width = max([16] + [len(r['scene']) + 2 for r in rows])
    lines = [f'{"scene":<{width}}{"outputs":<30}{"us/angle":>10}{"ms/cycle":>10}'
             f'{"build ms":>10}{"Rig.at us":>11}', '-' * (width + 71)]
    for r in rows:
        outs = 'everything' if r.get('everything') else '+'.join(r['outputs'])
        lines.append(f'{r["scene"]:<{width}}{outs:<30}{r["us_per_angle"]:>10.3f}'
                     f'{r["cycle_s"] * 1e3:>10.3f}{r["build_s"] * 1e3:>10.1f}'
                     f'{r["at_us_per_angle"]:>11.3f}')
    return '\n'.join(lines)
