"""
The README and the pages of docs/: every page linked, every command shown parses.

A command in a fenced ``sh``/``bash``/``console`` block is checked by what it calls:
``mech-balance`` commands by the command's own argument parser (so a renamed option fails
here), ``make`` targets against the Makefile, ``ros2 topic|service|param`` commands against
the names and types the node's modules declare (ros2cli is not on PyPI: the node tests drive
the same interfaces through rclpy), ``rig_node`` through its ``--ros-args``.  Lines that are
output (no known command word) are skipped, a ``$ `` prompt is stripped and backslash
continuations are joined.
"""

import ast
import importlib
from pathlib import Path
import re
import shlex

from mech_balance.cli import main as cli
from mech_balance.ros import params
import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / 'README.md'
DOCS = ROOT / 'docs'
PAGES = sorted(p for p in DOCS.glob('*.md') if p.name != 'README.md')
MAX_README_LINES = 260
"""Issue 23 item 4: the README stays about 250 lines."""
SHELLS = ('sh', 'bash', 'console', 'shell')
FENCE = re.compile(r'^```(\w*)\s*$')


def _blocks(path):
    """Yield ``(line number, language, text)`` of every fenced block of a markdown file."""
    lang, start, body = None, 0, []
    for number, line in enumerate(path.read_text(encoding='utf-8').splitlines(), 1):
        match = FENCE.match(line.strip())
        if match and lang is None:
            lang, start, body = match.group(1), number, []
        elif line.strip() == '```' and lang is not None:
            yield start, lang, '\n'.join(body)
            lang = None
        elif lang is not None:
            body.append(line)


def _commands(text):
    """Return the logical command lines of a shell block (continuations joined)."""
    out, pending = [], ''
    for raw in text.splitlines():
        line = raw.rstrip()
        if line.startswith('$ '):
            line = line[2:]
        if pending:
            line = pending + ' ' + line.strip()
            pending = ''
        if line.endswith('\\'):
            pending = line[:-1].rstrip()
            continue
        out.append(line.strip())
    return [c for c in out if c and not c.startswith('#')]


def _words(command):
    """Split a command line into words, dropping a trailing comment."""
    lexer = shlex.shlex(command, posix=True, punctuation_chars=False)
    lexer.whitespace_split = True
    lexer.commenters = '#'
    return list(lexer)


def _all_commands():
    cases = []
    for path in [README] + PAGES:
        for line, lang, text in _blocks(path):
            if lang not in SHELLS:
                continue
            for command in _commands(text):
                cases.append(pytest.param(command, id=f'{path.name}:{line}:{command[:40]}'))
    return cases


def _ros_literals():
    """Return every string literal of the ROS layer's modules (names are spelled there)."""
    found = set()
    for path in (ROOT / 'mech_balance' / 'ros').rglob('*.py'):
        for node in ast.walk(ast.parse(path.read_text(encoding='utf-8'))):
            if isinstance(node, ast.Constant) and isinstance(node.value, str):
                found.add(node.value)
    return found


ROS_NAMES = _ros_literals()


def _check_ros_name(name):
    """Check that a topic or service name shown as /ns/x or /x is declared by the ROS layer."""
    last = name.rstrip('/').rsplit('/', 1)[-1]
    assert any(lit in (last, '~/' + last, '/' + last) for lit in ROS_NAMES), \
        f'{name}: not a topic or service name of mech_balance/ros'


def _check_type(type_name):
    package, kind, name = type_name.split('/')
    module = importlib.import_module(f'{package}.{kind}')
    assert hasattr(module, name), f'{type_name}: no such interface'


def _check_parameter(name):
    if name.startswith(params.LINK_PREFIX):
        option = name.rsplit('.', 1)[-1]
        assert option in params.LINK_OPTIONS, f'{name}: not a per-link option'
        return
    assert name in params.BY_NAME, f'{name}: not a parameter of the rig node'


def _check_ros2(words):
    verb = words[1]
    if verb == 'topic':
        if words[2] in ('echo', 'hz', 'info', 'pub'):
            _check_ros_name(words[3])
        if words[2] == 'pub':
            _check_type(words[4])
    elif verb == 'service':
        if words[2] == 'call':
            _check_ros_name(words[3])
            _check_type(words[4])
    elif verb == 'param':
        if words[2] in ('set', 'get', 'describe'):
            _check_parameter(words[4])
    elif verb in ('run', 'launch'):
        assert words[2] == 'mech_balance', words
        if verb == 'launch':
            assert (ROOT / 'launch' / words[3]).is_file(), words[3]
        else:
            assert words[3] == 'rig_node', words
            _check_ros_args(words[4:])
    elif verb == 'bag':
        assert words[2] in ('record', 'info', 'play'), words
    else:
        raise AssertionError(f'ros2 {verb}: not checked by this test; add it')


def _check_ros_args(args):
    """``--ros-args -p name:=value --params-file F -r x:=y``: names and files must exist."""
    if not args:
        return
    assert args[0] == '--ros-args', args
    i = 1
    while i < len(args):
        flag = args[i]
        if flag == '-p':
            _check_parameter(args[i + 1].split(':=', 1)[0])
        elif flag == '--params-file':
            assert (ROOT / args[i + 1]).is_file(), args[i + 1]
        else:
            assert flag == '-r', f'{flag}: not a --ros-args flag checked here'
        i += 2


def _make_targets():
    text = (ROOT / 'Makefile').read_text(encoding='utf-8')
    return set(re.findall(r'^([a-z][a-z-]*):', text, flags=re.M))


@pytest.mark.parametrize('command', _all_commands())
def test_command_parses(command):
    words = _words(command)
    # environment assignments and `export`/`cd`/`for` scaffolding are shell, not ours
    while words and re.match(r'^[A-Z_]+=', words[0]):
        words = words[1:]
    if not words:
        return
    head = words[0]
    for prefix in ('.venv/bin/', './.venv/bin/'):
        if head.startswith(prefix):
            head = head[len(prefix):]
    if head in ('python', 'python3') and words[1:3] == ['-m', 'mech_balance.cli']:
        head, words = 'mech-balance', ['mech-balance'] + words[3:]
    if head == 'mech-balance':
        argv = [w for w in words[1:] if w not in ('|', '>')]
        try:
            cli.build_parser().parse_args(argv)
        except SystemExit as exc:
            assert exc.code == 0, f'{command}: the parser refused it (exit {exc.code})'
    elif head == 'make':
        for target in words[1:]:
            assert target in _make_targets(), f'make {target}: no such target'
    elif head == 'ros2':
        _check_ros2(words)
    elif head == 'rig_node':
        _check_ros_args(words[1:])


def test_readme_is_short_and_links_every_page():
    text = README.read_text(encoding='utf-8')
    assert text.startswith('```sh\nmake run'), 'the README starts with the two commands'
    assert len(text.splitlines()) <= MAX_README_LINES
    for page in PAGES:
        assert f'](docs/{page.name})' in text, f'docs/{page.name} is not linked from README'


def test_pages_link_back_and_their_links_resolve():
    link = re.compile(r'\]\(([^)#\s]+)(#[^)]*)?\)')
    for page in PAGES + [README]:
        text = page.read_text(encoding='utf-8')
        if page is not README:
            assert '](../README.md)' in text, f'{page.name}: no link back to the README'
        for target, _ in link.findall(text):
            if '://' in target:
                continue
            assert (page.parent / target).resolve().exists(), f'{page.name}: {target} missing'
