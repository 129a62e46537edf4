"""
Every module, attribute and file the words name exists (issue 30 item 3).

A dotted ``mech_balance.<module>.<name>`` or a ``mech_balance/<dir>/<module>.py`` path in a
docstring, a comment or any other string of the package, the tests, the examples and the
launch file, in README.md, docs/*.md and config/*.yaml, must be a module, a module's
attribute (a class's attribute: defined on it, annotated in it, or set on ``self`` in its
code) or a file.

Marked ``words``: written while the modules are being split on other branches, it passes
once they are all merged (``pytest test/test_words.py -m words``).
"""

import functools
import importlib
import inspect
import io
from pathlib import Path
import re
import tokenize

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOTTED = re.compile(r'(?<![\w./-])mech_balance(?:\.[A-Za-z_]\w*)+')
PATH = re.compile(r'(?<![\w./-])mech_balance/(?:[A-Za-z_]\w*/)*[A-Za-z_]\w*\.py\b')
PYTHON = [*sorted((ROOT / 'mech_balance').rglob('*.py')), *sorted((ROOT / 'test').glob('*.py')),
          *sorted((ROOT / 'examples').glob('*.py')), *sorted((ROOT / 'launch').glob('*.py')),
          ROOT / 'setup.py']
TEXT = [ROOT / 'README.md', *sorted((ROOT / 'docs').glob('*.md')),
        *sorted((ROOT / 'config').glob('*.yaml'))]


def _lines(path):
    """Yield ``(line number, text)`` of every line of a file."""
    yield from enumerate(path.read_text(encoding='utf-8').splitlines(), 1)


def _words(path):
    """Yield ``(line, text)`` of a file's words: a Python file's comments and strings."""
    if path.suffix != '.py':
        yield from _lines(path)
        return
    source = path.read_text(encoding='utf-8')
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type in (tokenize.COMMENT, tokenize.STRING) or \
                tok.type == getattr(tokenize, 'FSTRING_MIDDLE', None):
            for k, line in enumerate(tok.string.splitlines()):
                yield tok.start[0] + k, line


def _has(obj, name):
    """Return True if ``obj`` has ``name``: an attribute, an annotation or a ``self.`` one."""
    if hasattr(obj, name):
        return True
    if not inspect.isclass(obj):
        return False
    for cls in obj.__mro__:
        if name in getattr(cls, '__annotations__', {}):
            return True
        try:
            source = inspect.getsource(cls)
        except (OSError, TypeError):
            continue
        if re.search(rf'\bself\.{name}\s*(?::[^=\n]*)?=[^=]', source):
            return True
    return False


@functools.lru_cache(maxsize=None)
def _exists(name):
    """Return True if a dotted name is a module or, through its longest module, an attribute."""
    parts = name.split('.')
    for i in range(len(parts), 0, -1):
        module = '.'.join(parts[:i])
        try:
            obj = importlib.import_module(module)
        except ModuleNotFoundError as exc:
            if exc.name is not None and module.startswith(exc.name) and \
                    exc.name.startswith('mech_balance'):
                continue   # not a module of the package: try the shorter prefix
            raise
        for attr in parts[i:]:
            if not _has(obj, attr):
                return False
            obj = getattr(obj, attr, None)
        return True
    return False


def _found(name):
    """Return True if a mentioned name or path exists."""
    return (ROOT / name).is_file() if name.endswith('.py') and '/' in name else _exists(name)


def _scan(path, lines):
    """Return ``(line, name)`` of every name and path in ``lines`` (number, text)."""
    return [(number, match.group(0)) for number, line in lines
            for pattern in (DOTTED, PATH) for match in pattern.finditer(line)]


@functools.lru_cache(maxsize=None)
def _stale():
    """
    Return every ``file:line: name`` mentioned that does not exist.

    A Python file's lines are read whole first (fast); only a file with a missing name is
    tokenized, so that a name in its code (not in its words) is not counted.
    """
    stale = []
    for path in PYTHON + TEXT:
        missing = [m for m in _scan(path, _lines(path)) if not _found(m[1])]
        if missing and path.suffix == '.py':
            missing = [m for m in _scan(path, _words(path)) if not _found(m[1])]
        stale += [f'{path.relative_to(ROOT)}:{number}: {name}' for number, name in missing]
    return stale


def test_the_scan_finds_the_mentions_it_is_for():
    words = _scan(ROOT / 'test' / 'test_words.py', _words(ROOT / 'test' / 'test_words.py'))
    assert any(name == 'mech_balance.core.rig.Rig.capabilities' for _, name in words)
    code = _scan(ROOT / 'test' / 'test_rig.py', _words(ROOT / 'test' / 'test_rig.py'))
    assert not any(name.endswith('no_such_name') for _, name in code)   # code, not words
    assert not _exists('mech_balance' + '.no_such_module')
    assert not _exists('mech_balance.core.rig' + '.no_such_name')
    assert _exists('mech_balance.core.rig.Rig.capabilities')   # a protocol's annotation
    assert _exists('mech_balance.core.planar.kinematics.Linkage.body_names')   # self.x =
    assert _exists('mech_balance.balancing')
    config = dict(_scan(ROOT / 'config' / 'rig_params.yaml',
                        _lines(ROOT / 'config' / 'rig_params.yaml')))
    assert 'mech_balance/ros/params.py' in config.values() and \
        _found('mech_balance/ros/params.py') and not _found('mech_balance/' + 'params.py')


@pytest.mark.words
def test_every_name_and_path_mentioned_exists():
    stale = _stale()
    assert not stale, f'{len(stale)} mentions of what does not exist:\n' + '\n'.join(stale)
