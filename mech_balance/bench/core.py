"""Timings for ``mech-balance bench``: median of repeated runs after warm-up."""

import time
import tracemalloc

from mech_balance import schema as scene_mod
from mech_balance.analysis.timing import DEFAULT_REPEAT, median_seconds, WARMUP  # noqa: F401
from mech_balance.bench import chains as chain
from mech_balance.conventions import cycle_angles
from mech_balance.core.rig import rig_for

CHAIN_LOOPS = (19,)
"""Generated chains timed after the built-in scenes: 19 loops = 40 links with the frame."""
MEMORY_LIMIT_BYTES = 200 * 2 ** 20
"""Largest peak allocation of one cycle of the 40-link chain at 360 angles (issue 22)."""

SECTIONS = ('mech_balance.bench.balancing:bench_section',
            'mech_balance.bench.balancing:counterweights_section',
            'mech_balance.bench.recording:bench_section',
            'mech_balance.bench.node:bench_section',
            'mech_balance.bench.switch:switch_section',
            'mech_balance.bench.node:live_view_section',
            'mech_balance.bench.node:faults_section',
            'mech_balance.bench.identify_stamps:identify_stamps_section',
            'mech_balance.bench.follow_memory:follow_memory_section',
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


def median_and_result(fn, repeat, **timing):
    """Return the median seconds of ``fn()`` (:func:`median_seconds`) and its last result."""
    last = []

    def run():
        last[:] = [fn()]
    return median_seconds(run, repeat=repeat, **timing), last[0]


def peak_bytes(fn):
    """Return the peak memory ``fn()`` allocates beyond what was before, in bytes (tracemalloc)."""
    started = not tracemalloc.is_tracing()
    if started:
        tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        fn()
        return max(tracemalloc.get_traced_memory()[1] - before, 0)
    finally:
        if started:
            tracemalloc.stop()


def cycle_timing(scene, samples=360, outputs=None, repeat=DEFAULT_REPEAT):
    """Return ``build_s``, ``cycle_s`` (median), ``at_us_per_angle``, ``peak_bytes`` of a scene."""
    t0 = time.perf_counter()
    rig = rig_for(scene, cache=False)
    build = time.perf_counter() - t0
    everything = outputs is None
    outputs = tuple(outputs or rig.outputs)
    psi = cycle_angles(samples, getattr(scene, 'assembly_crank_angle_rad', 0.0))
    native = getattr(rig, 'evaluate', None)  # the core's cycle, without the protocol's views
    at = median_seconds(lambda: rig.at(psi, outputs=outputs), repeat=repeat)
    cycle = median_seconds(lambda: native(psi, outputs), repeat=repeat) if native else at
    peak = peak_bytes(lambda: rig.at(psi, outputs=outputs))
    return {'scene': scene.name, 'samples': samples, 'build_s': build, 'cycle_s': cycle,
            'us_per_angle': cycle * 1e6 / samples, 'at_us_per_angle': at * 1e6 / samples,
            'outputs': list(outputs), 'everything': everything, 'peak_bytes': peak,
            'links': len(getattr(scene, 'links', ()))}


def run(names=None, samples=360, repeat=DEFAULT_REPEAT, progress=print, loops=CHAIN_LOOPS):
    """
    Return the bench table (a dict per row, :func:`cycle_timing`) of built-in scenes.

    Without ``names``: every built-in, then the generated chains of ``loops`` loops.
    """
    chains = () if names else loops
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
    for n in chains:
        progress(f'  timing a generated chain of {n} loops ...')
        sc = chain.dyad_chain(n).with_outputs(scene_mod.DEFAULT_OUTPUTS)
        rows.append(cycle_timing(sc, samples, repeat=repeat))
    return rows


def format_rows(rows):
    """Return the bench table as text."""
    width = max([16] + [len(r['scene']) + 2 for r in rows])
    lines = [f'{"scene":<{width}}{"outputs":<30}{"us/angle":>10}{"ms/cycle":>10}'
             f'{"build ms":>10}{"Rig.at us":>11}{"peak MB":>9}', '-' * (width + 80)]
    for r in rows:
        outs = 'everything' if r.get('everything') else '+'.join(r['outputs'])
        lines.append(f'{r["scene"]:<{width}}{outs:<30}{r["us_per_angle"]:>10.3f}'
                     f'{r["cycle_s"] * 1e3:>10.3f}{r["build_s"] * 1e3:>10.1f}'
                     f'{r["at_us_per_angle"]:>11.3f}{r["peak_bytes"] / 2 ** 20:>9.2f}')
    lines.append('peak MB: the largest memory one Rig.at cycle allocates at a time '
                 '(tracemalloc, an untimed run)')
    for r in rows:
        if r['scene'].startswith('dyad_chain') and r['links'] + 1 >= 40:
            ok = r['peak_bytes'] <= MEMORY_LIMIT_BYTES
            lines.append(f'{r["scene"]} ({r["links"] + 1} links, {r["samples"]} angles): peak '
                         f'{r["peak_bytes"] / 2 ** 20:.1f} MB -> {"PASS" if ok else "FAIL"} '
                         f'(<= {MEMORY_LIMIT_BYTES / 2 ** 20:.0f} MB)')
    return '\n'.join(lines)
