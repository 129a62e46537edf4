"""
Every number the command line prints as JSON is the one the fixture holds.

The fixture (``test/fixtures/cli_snapshot.json``) was written by ``test/cli_snapshot.py
--write`` before the house was reshaped (issue 30); a refactoring must leave it as it is.
Figures that measure the solver's own accuracy (residuals, roundings, gaps) are compared by
size only: they move with the order of floating-point operations.
"""

import json
import math
import re

import cli_snapshot
import pytest

REL = 1e-8   # a reordered sum moves a figure by round-off; a changed formula by far more
ACCURACY_KEY = re.compile(r'(residual|rounding|shift|violation|gap|check|_term|cond)', re.I)

with open(cli_snapshot.FIXTURE) as f:
    FIXTURE = json.load(f)


def _compare(old, new, where, problems, accuracy=False):
    if isinstance(old, dict) and isinstance(new, dict):
        if sorted(old) != sorted(new):
            problems.append(f'{where}: keys {sorted(set(old) ^ set(new))} differ')
        for k in old.keys() & new.keys():
            _compare(old[k], new[k], f'{where}.{k}', problems,
                     accuracy or bool(ACCURACY_KEY.search(k)))
    elif isinstance(old, list) and isinstance(new, list):
        if len(old) != len(new):
            problems.append(f'{where}: {len(old)} items, now {len(new)}')
        for i, (a, b) in enumerate(zip(old, new)):
            _compare(a, b, f'{where}[{i}]', problems, accuracy)
    elif isinstance(old, (int, float)) and isinstance(new, (int, float)) \
            and not isinstance(old, bool):
        a, b = float(old), float(new)
        if accuracy:
            if abs(b) > max(10.0 * abs(a), 1e-9):
                problems.append(f'{where}: accuracy figure {a!r} grew to {b!r}')
        elif not (a == b or (math.isfinite(a) and abs(a - b) <= REL * max(abs(a), abs(b)))):
            problems.append(f'{where}: {a!r} now {b!r}')
    elif old != new and not accuracy:
        problems.append(f'{where}: {old!r} now {new!r}')


@pytest.mark.parametrize('name,argv', list(cli_snapshot.cases()),
                         ids=[name for name, _ in cli_snapshot.cases()])
def test_cli_numbers_unchanged(name, argv):
    assert name in FIXTURE, f'{name}: not in the fixture; run test/cli_snapshot.py --write'
    code, doc = cli_snapshot.run(argv)
    stored = FIXTURE[name]
    assert code == stored['exit'], f'{name}: exit {code}, stored {stored["exit"]}'
    problems = []
    _compare(stored['json'], cli_snapshot.strip(doc), name, problems)
    assert not problems, '\n'.join(problems[:20])


def test_the_fixture_covers_every_case():
    assert sorted(FIXTURE) == sorted(name for name, _ in cli_snapshot.cases())


def test_the_comparison_sees_a_changed_number():
    problems = []
    _compare({'a': [1.0, 2.0]}, {'a': [1.0, 2.0 * (1 + 1e-6)]}, 'x', problems)
    assert problems
