"""
Before/after snapshot of the command line's numbers over every built-in and verb.

`python test/cli_snapshot.py --write` stores the `--json` output of each case in
`test/fixtures/cli_snapshot.json`; `test_cli_snapshot.py` runs the same cases and
compares every number with the stored one.  Fields that measure the machine (times,
rates, memory) are left out.  Re-write the fixture only for a change that is meant to
change a printed number, and say so in the commit.
"""

import argparse
import contextlib
import io
import json
import os
import re
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from mech_balance import schema as scene  # noqa: E402
from mech_balance.cli import main as cli  # noqa: E402
from mech_balance.schema.scene import builtin_scenes  # noqa: E402

_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__))) + os.sep
FIXTURE = os.path.join(os.path.dirname(os.path.abspath(__file__)), 'fixtures',
                       'cli_snapshot.json')

# Keys whose values measure the machine or the run, not the rig.
_MACHINE_KEY = re.compile(
    r'(time|seconds|_s$|_ms$|_us|us_per|per_s|rate|rss|memory|mib|wall|cpu|elapsed|'
    r'iterations|iters|evaluations|nfev|path|file|version|platform|load)', re.I)

PLANAR_COUNTERWEIGHTS = {
    'hoeken': 'crank,rocker',
    'slider_crank': 'crank',
    'carpet_scraper': 'crank,rocker',
}


def cases():
    """Yield (name, argv) for every built-in scene and every verb with `--json`."""
    for name in sorted(builtin_scenes()):
        yield f'{name}/analyze', ['analyze', '--scene', name, '--json']
        yield f'{name}/analyze_normalized', ['analyze', '--scene', name, '--json',
                                             '--normalized']
        yield f'{name}/balance', ['balance', '--scene', name, '--json']
        for weights in ('1 0', '0 1'):
            yield (f'{name}/balance_w{weights.replace(" ", "")}',
                   ['balance', '--scene', name, '--json', '--weights', *weights.split()])
        if name in PLANAR_COUNTERWEIGHTS:
            yield (f'{name}/counterweights',
                   ['balance', '--scene', name, '--json', '--counterweights',
                    PLANAR_COUNTERWEIGHTS[name]])
        yield f'{name}/simulate', ['simulate', '--scene', name, '--json',
                                   '--duration', '0.2']
        if scene.load(name).kind == 'spatial':
            for method in ('force-balance', 'redistribution'):
                yield (f'{name}/balance_{method}',
                       ['balance', '--scene', name, '--json', '--method', method])
            first = scene.load(name).links[0].name
            yield (f'{name}/balance_counterweights',
                   ['balance', '--scene', name, '--json', '--method', 'counterweights',
                    '--counterweights', first])
    for name in ('hoeken', 'slider_crank'):
        yield f'{name}/identify', ['identify', '--scene', name, '--json', '--bag',
                                   RECORDING]


RECORDING = '@recording'   # in an argv: the path of :func:`_recording` of the case's scene


def _recording(name):
    """Write 6 s of a perturbed built-in rig as a real rig's CSV; return its path."""
    import tempfile
    import synthetic_rig
    from mech_balance.ros import bags
    true = synthetic_rig.perturbed(scene.load(name), seed=7)
    turns = 3.0 * 2.0 * 3.141592653589793 / abs(true.crank_speed_rad_s)
    t_ns, position, wrench, _ = synthetic_rig.record_real(true, max(6.0, turns), 4096, seed=7)
    path = os.path.join(tempfile.mkdtemp(prefix='cli_snapshot_'), f'{name}.csv')
    bags.write_csv(path, (t_ns - t_ns[0]) * 1e-9, position, wrench)
    return path


def run(argv):
    """Run one command in this process; return (exit code, parsed JSON or the text)."""
    if RECORDING in argv:
        argv = [_recording(argv[argv.index('--scene') + 1]) if a == RECORDING else a
                for a in argv]
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = cli.main(argv)
        except SystemExit as exc:
            code = exc.code
    text = out.getvalue()
    try:
        return code or 0, json.loads(text)
    except ValueError:
        return code or 0, {'stdout': text.strip().splitlines()[-1:] if text else [],
                           'stderr': err.getvalue().strip().splitlines()[-1:]}


def strip(value):
    """Drop the fields that measure the machine, recursively."""
    if isinstance(value, dict):
        return {k: strip(v) for k, v in value.items() if not _MACHINE_KEY.search(str(k))}
    if isinstance(value, list):
        return [strip(v) for v in value]
    if isinstance(value, str) and 'cli_snapshot_' in value:   # the recording's temporary path
        return re.sub(r'\S*cli_snapshot_\w+/', '', value)
    if isinstance(value, str) and value.startswith(_ROOT):    # the checkout's path
        return os.path.relpath(value, _ROOT)
    return value


def snapshot():
    """Run every case; return {name: {'argv', 'exit', 'json'}}."""
    result = {}
    for name, argv in cases():
        code, doc = run(argv)
        result[name] = {'argv': argv, 'exit': code, 'json': strip(doc)}
        print(f'{name}: exit {code}', file=sys.stderr)
    return result


def main():
    """Write or check the fixture."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0].strip())
    parser.add_argument('--write', action='store_true', help='store the fixture')
    args = parser.parse_args()
    snap = snapshot()
    if args.write:
        os.makedirs(os.path.dirname(FIXTURE), exist_ok=True)
        with open(FIXTURE, 'w') as f:
            json.dump(snap, f, indent=1, sort_keys=True)
            f.write('\n')
        print(f'wrote {FIXTURE} ({len(snap)} cases)', file=sys.stderr)


if __name__ == '__main__':
    main()
