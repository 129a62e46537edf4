"""
``mech-balance bench --section spatial``: the spatial kind's full cycle against its targets.

Per built-in: build, then the median full cycle in us per angle on and off the branch's
nodes, with :data:`TARGETS_US`.
"""

import os
import time

from mech_balance import schema
from mech_balance.analysis.timing import median_seconds
from mech_balance.conventions import cycle_angles
from mech_balance.core.rig import rig_for
from mech_balance.core.spatial import branch
from mech_balance.schema import registry
from mech_balance.schema.scene import OUTPUTS

TARGETS_US = {'rssr_skew': 5.0, 'spatial_two_loop': 10.0}
"""The spatial issue's targets, us per crank angle for the full cycle."""


def bench_section(args, progress):
    """Return the spatial table (``function(args, progress) -> str`` of bench.core)."""
    samples = getattr(args, 'samples', 360)
    repeat = getattr(args, 'repeat', 20)
    spatial = registry.KINDS['spatial']
    names = [n for n in schema.builtin_scenes() if registry.kind_of(schema.load(n)) is spatial]
    lines = [f'spatial kind: full cycle ({", ".join(OUTPUTS)}), {samples} crank angles, '
             f'median of {repeat}; load average {os.getloadavg()[0]:.2f} on '
             f'{os.cpu_count()} cores (figures on a loaded machine are upper bounds)',
             f'{"scene":<18} {"links":>5} {"build ms":>9} {"us/angle":>9} {"target":>7} '
             f'{"off-node":>9}']
    for name in sorted(names):
        progress(f'bench spatial: {name}')
        sc = schema.load(name)
        t0 = time.perf_counter()
        rig = rig_for(sc, cache=False)
        build = time.perf_counter() - t0
        psi = cycle_angles(samples, sc.assembly_crank_angle_rad)
        seconds = median_seconds(lambda: rig.at(psi, outputs=OUTPUTS), repeat=repeat)
        off = psi + 0.5 * branch.DENSE_STEP_RAD
        off_seconds = median_seconds(lambda: rig.at(off, outputs=OUTPUTS), repeat=repeat)
        target = TARGETS_US.get(name)
        lines.append(f'{name:<18} {len(sc.links):>5} {build * 1e3:9.1f} '
                     f'{seconds * 1e6 / samples:9.2f} '
                     f'{"" if target is None else f"<= {target:g}":>7} '
                     f'{off_seconds * 1e6 / samples:9.2f}')
    return '\n'.join(lines)
