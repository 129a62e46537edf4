"""
The package's layers, read from its source: import cycles, layer rules, private imports, kinds.

The layer table (also in the README's design section)::

    layer      may import (besides the standard library, numpy, scipy, yaml, clarabel)
    base       conventions, paths, atomic: nothing of the package
    schema     base
    core       base, schema
    analysis   base, schema, core
    balancing  base, schema, core, analysis
    ros        everything below, rclpy and the ROS messages; viz only lazily, from the
               recording hook inside a function of ros/node.py
    viz        everything below, rerun
    cli        everything
    bench      everything

``schema``, ``core``, ``analysis`` and ``balancing`` never import ``ros``, ``viz``, ``cli``,
``bench``, ``rclpy`` or ``rerun``.  ``balancing`` stands above ``analysis`` (it evaluates its
designs with the cycle analysis); ``analysis`` never imports ``balancing``, not even inside a
function.
"""

import ast
import functools
from pathlib import Path
import re

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / 'mech_balance'
LOWER = ('schema', 'core', 'analysis', 'balancing')
UPPER = ('ros', 'viz', 'cli', 'bench')
FORBIDDEN_BELOW = tuple(f'mech_balance.{u}' for u in UPPER) + ('rclpy', 'rerun')
KIND_TEST = re.compile(r"kind\s*==|==\s*'rggr'|getattr\([^)]*'kind'")
REGISTRY = PACKAGE / 'schema' / 'registry.py'
ALLOWED = {
    'base': {'base'},
    'schema': {'base', 'schema'},
    'core': {'base', 'schema', 'core'},
    'analysis': {'base', 'schema', 'core', 'analysis'},
    'balancing': {'base', 'schema', 'core', 'analysis', 'balancing'},
    'ros': {'base', 'schema', 'core', 'balancing', 'analysis', 'ros'},
    'viz': {'base', 'schema', 'core', 'balancing', 'analysis', 'viz'},
    'cli': set(LOWER + UPPER) | {'base'},
    'bench': set(LOWER + UPPER) | {'base'},
}
"""The layer table: what each layer may import of the package (viz from ros: the hook)."""
VIZ_HOOK = ('mech_balance/ros/node.py',)
"""The modules of ros/ allowed to import viz, and only inside a function (the recording)."""


def _modules():
    """Return ``{dotted name: path}`` of every module of the package."""
    out = {}
    for path in sorted(PACKAGE.rglob('*.py')):
        parts = list(path.relative_to(ROOT).with_suffix('').parts)
        if parts[-1] == '__init__':
            parts = parts[:-1]
        out['.'.join(parts)] = path
    return out


MODULES = _modules()


@functools.lru_cache(maxsize=None)
def _imports(path):
    """
    Return ``((target module, imported names, top_level, lineno), ...)`` of a module's imports.

    Parsed once per file and run (the checks below each walk every module).
    """
    tree = ast.parse(path.read_text(), str(path))
    top = {id(n) for n in tree.body}
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                found.append((alias.name, (), id(node) in top, node.lineno))
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            for alias in node.names:
                sub = f'{node.module}.{alias.name}'
                if sub in MODULES:  # `from pkg import module`
                    found.append((sub, (), id(node) in top, node.lineno))
                else:
                    found.append((node.module, (alias.name,), id(node) in top, node.lineno))
    return tuple(found)


def _graph():
    graph = {}
    for name, path in MODULES.items():
        graph[name] = {t for t, _, _, _ in _imports(path) if t in MODULES and t != name}
    return graph


def _layer(module):
    parts = module.split('.')
    return parts[1] if len(parts) > 2 or (len(parts) == 2 and parts[1] in LOWER + UPPER) \
        else 'base'


def test_the_package_has_its_layers():
    layers = {_layer(m) for m in MODULES}
    assert set(LOWER + UPPER) <= layers, layers


def test_no_import_cycles():
    graph = _graph()
    state, stack, cycles = {}, [], []

    def visit(node):
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                cycles.append(stack[stack.index(nxt):] + [nxt])
            elif nxt not in state:
                visit(nxt)
        stack.pop()
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node)
    assert not cycles, '\n'.join(' -> '.join(c) for c in cycles)


@pytest.mark.parametrize('layer', LOWER)
def test_lower_layers_never_import_ros_viz_cli_bench_rclpy_or_rerun(layer):
    bad = []
    for name, path in MODULES.items():
        if _layer(name) != layer:
            continue
        for target, _, _, line in _imports(path):
            if target.startswith(FORBIDDEN_BELOW) or target.split('.')[0] in ('rclpy', 'rerun'):
                bad.append(f'{path.relative_to(ROOT)}:{line} imports {target}')
    assert not bad, '\n'.join(bad)


def test_every_import_follows_the_layer_table():
    bad = []
    for name, path in MODULES.items():
        mine = _layer(name)
        for target, _, _, line in _imports(path):
            if target not in MODULES:
                continue
            theirs = _layer(target)
            if theirs not in ALLOWED[mine] and not (mine == 'ros' and theirs == 'viz'):
                bad.append(f'{path.relative_to(ROOT)}:{line}: {mine} imports {theirs} '
                           f'({target})')
    assert not bad, '\n'.join(bad)


def test_balancing_and_analysis_are_one_way():
    """Balancing imports analysis; no module of analysis imports balancing, at any depth."""
    down = [f'{path.relative_to(ROOT)}:{line} imports {target}'
            for name, path in MODULES.items() if _layer(name) == 'balancing'
            for target, _, _, line in _imports(path) if _layer(target) == 'analysis'
            and target in MODULES]
    up = [f'{path.relative_to(ROOT)}:{line} imports {target}'
          for name, path in MODULES.items() if _layer(name) == 'analysis'
          for target, _, _, line in _imports(path) if target in MODULES
          and _layer(target) == 'balancing']
    assert down, 'balancing no longer uses analysis: the layer table should say so'
    assert not up, '\n'.join(up)


def test_ros_imports_viz_only_through_the_recording_hook():
    bad = []
    for name, path in MODULES.items():
        if _layer(name) != 'ros':
            continue
        rel = str(path.relative_to(ROOT))
        for target, _, top_level, line in _imports(path):
            if target.startswith('mech_balance.viz') and (rel not in VIZ_HOOK or top_level):
                bad.append(f'{rel}:{line} imports {target}')
    assert not bad, '\n'.join(bad)


def test_no_private_name_is_imported_from_another_module():
    bad = []
    for name, path in MODULES.items():
        for target, names, _, line in _imports(path):
            private = [n for n in names if n.startswith('_')]
            if target.split('.')[-1].startswith('_') and target.startswith('mech_balance'):
                private.append(target)
            if private and target.startswith('mech_balance'):
                bad.append(f'{path.relative_to(ROOT)}:{line}: {", ".join(private)} from '
                           f'{target}')
    assert not bad, '\n'.join(bad)


def test_no_kind_tests_outside_the_registry():
    found = []
    for path in MODULES.values():
        if path == REGISTRY:
            continue
        for k, line in enumerate(path.read_text().splitlines(), 1):
            if KIND_TEST.search(line):
                found.append(f'{path.relative_to(ROOT)}:{k}: {line.strip()}')
    assert not found, '\n'.join(found)


def test_the_checks_find_what_they_look_for(tmp_path):
    """The detectors themselves: a cycle, a kind test and a private import are seen."""
    assert KIND_TEST.search("if sc.kind == 'planar':")
    assert KIND_TEST.search("getattr(scene, 'kind', 'planar')")
    assert not KIND_TEST.search('if joint.prismatic:')
    probe = tmp_path / 'probe.py'
    probe.write_text('from mech_balance.core.rig import _hidden\n'
                     'def f():\n    from mech_balance.viz import recording\n')
    found = _imports(probe)
    assert ('mech_balance.core.rig', ('_hidden',), True, 1) in found
    assert ('mech_balance.viz.recording', (), False, 3) in found


def test_every_import_of_the_package_names_a_module_of_this_tree():
    """No import of a module that moved away (an old flat path would load another checkout)."""
    bad = []
    for path in list(MODULES.values()) + sorted((ROOT / 'test').glob('*.py')) + \
            sorted((ROOT / 'launch').glob('*.py')):
        for target, names, _, line in _imports(path):
            if target.split('.')[0] != 'mech_balance':
                continue
            if target not in MODULES:
                bad.append(f'{path.relative_to(ROOT)}:{line}: no module {target}')
    assert not bad, '\n'.join(bad)
