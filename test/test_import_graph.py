"""The package's import graph: no circles, and the studies stay below the commands.

Every ``import`` and ``from ... import`` of every module under suspension_tuning/ is
read with ``ast`` (imports inside functions included: a lazy import still ties two
modules together), each resolved to the package module it names.  A circle is a
strongly connected component of more than one module.
"""

from __future__ import annotations

import ast
import functools
import subprocess
import sys
from pathlib import Path

import suspension_tuning

PACKAGE_DIR = Path(suspension_tuning.__file__).resolve().parent
PACKAGE = 'suspension_tuning'
#: Command modules: a command sits on top of the libraries, never under a study.
COMMANDS = ('suspension_tuning.study', 'suspension_tuning.demo', 'suspension_tuning.tune',
            'suspension_tuning.graph')


def _modules() -> dict[str, Path]:
    out = {}
    for path in PACKAGE_DIR.rglob('*.py'):
        parts = list(path.relative_to(PACKAGE_DIR.parent).with_suffix('').parts)
        if parts[-1] == '__init__':
            parts = parts[:-1]
        out['.'.join(parts)] = path
    return out


def _imports(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The package modules ``name`` imports anywhere in its source."""
    found = set()
    is_package = path.name == '__init__.py'
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ''
            if node.level:
                parent = name.split('.') if is_package else name.split('.')[:-1]
                parent = parent[:len(parent) - (node.level - 1)]
                base = '.'.join(parent + ([base] if base else []))
            targets = [base] + [f'{base}.{alias.name}' for alias in node.names]
        else:
            continue
        for target in targets:
            while target and target not in modules:
                target = target.rpartition('.')[0]
            if target.startswith(PACKAGE) and target != name:
                found.add(target)
    return found


@functools.cache  # parsed once for the tests below
def _graph() -> dict[str, set[str]]:
    modules = _modules()
    return {name: _imports(name, path, modules) for name, path in modules.items()}


def _circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    circles = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                circles.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return circles


def test_the_circle_finder_finds_a_lazy_circle():
    # a -> b at the top, b -> a inside a function: one circle of two modules
    graph = {'a': {'b'}, 'b': {'a'}, 'c': {'a'}}
    assert _circles(graph) == [['a', 'b']]


def test_the_package_has_no_import_circles():
    graph = _graph()
    assert 'suspension_tuning.tuning' in graph['suspension_tuning.resume']  # parsed
    assert _circles(graph) == []


def test_no_study_module_imports_a_command_module():
    graph = _graph()
    studies = {n: deps for n, deps in graph.items() if n.startswith(f'{PACKAGE}.studies')}
    assert len(studies) > 5  # the package and its study modules were found
    offending = {n: sorted(deps & set(COMMANDS)) for n, deps in studies.items()
                 if deps & set(COMMANDS)}
    assert offending == {}


def test_importing_the_studies_does_not_import_the_study_command():
    names = sorted(n for n in _modules() if n.startswith(f'{PACKAGE}.studies'))
    code = ('import sys\n' + ''.join(f'import {n}\n' for n in names)
            + f'print(sorted(m for m in sys.modules if m in {COMMANDS!r}))')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         timeout=120, check=True)
    assert out.stdout.strip() == '[]'
