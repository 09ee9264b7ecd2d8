"""The code's shape, read statically with `ast` (nothing is imported or run): file and function
sizes, no import cycles, the engine below everything, the viewer off the compiled kernels.

Imports are counted wherever they stand: at the top, inside functions and under TYPE_CHECKING
(a cycle that only a function-level import closes is still two modules that need each other).
A failing test names what breaks its rule: the file and function with their lengths, the cycle.
"""

from __future__ import annotations

import ast
from functools import cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("collide", "viewer", "cli")
MAX_FILE_LINES = 1000
MAX_FUNCTION_LINES = 150
ENGINE = "collide.engine"
# The engine's modules that hold no kernels of their own: the tables' layout, the choice between
# compiled and interpreted, the decorators. The viewer may read them.
KERNEL_FREE = {f"{ENGINE}.layout", f"{ENGINE}.tier", f"{ENGINE}.jit"}
JIT_DECORATORS = {"jit", "jit_inline", "njit"}


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


@cache
def _modules() -> dict[str, Path]:
    """Every module of the packages checked, by dotted name."""
    out = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            if "__pycache__" not in path.parts:
                out[_module_name(path)] = path
    return out


@cache
def _tree(name: str) -> ast.Module:
    path = _modules()[name]
    return ast.parse(path.read_text(), str(path))


def _rel(name: str) -> str:
    return _modules()[name].relative_to(ROOT).as_posix()


def _resolve(name: str, node: ast.ImportFrom) -> str:
    """The module a `from ... import` names, relative imports resolved against `name`."""
    if not node.level:
        return node.module or ""
    package = name.split(".") if _modules()[name].name == "__init__.py" else name.split(".")[:-1]
    base = package[:len(package) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


@cache
def _imports(name: str) -> dict[str, int]:
    """The checked modules `name` imports (to the line of the first import), anywhere in it:
    `import a.b` names a.b, `from a import b` names the module a.b if there is one, else a."""
    modules = _modules()
    out: dict[str, int] = {}
    for node in ast.walk(_tree(name)):
        targets = []
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = _resolve(name, node)
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names]
        for target in targets:
            if target in modules and target != name:
                out.setdefault(target, node.lineno)
    return out


def _imports_numba(name: str) -> bool:
    for node in ast.walk(_tree(name)):
        if isinstance(node, ast.Import) and any(a.name.split(".")[0] == "numba" for a in node.names):
            return True
        if isinstance(node, ast.ImportFrom) and not node.level and (node.module or "").split(".")[0] == "numba":
            return True
    return False


def _path_to(start: str, goal: set[str]) -> list[str] | None:
    """The shortest chain of imports from `start` to a module in `goal` (both included)."""
    previous: dict[str, str | None] = {start: None}
    queue = [start]
    for current in queue:
        if current in goal and current != start:
            chain = [current]
            while previous[chain[-1]] is not None:
                chain.append(previous[chain[-1]])
            return chain[::-1]
        for target in sorted(_imports(current)):
            if target not in previous:
                previous[target] = current
                queue.append(target)
    return None


def _cycles() -> list[tuple[list[str], list[str]]]:
    """Each group of modules that import one another (Tarjan's strongly connected components)
    with one cycle through it: the shortest from the group's first module by name."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    groups: list[list[str]] = []

    def visit(v: str) -> None:  # recursive: the import graph is shallow
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in _imports(v):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                groups.append(sorted(group))

    for name in sorted(_modules()):
        if name not in index:
            visit(name)
    out = []
    for group in sorted(groups):
        first = group[0]
        # The shortest way back to `first` from each module it imports inside the group.
        back = [_path_to(target, {first}) or [target] for target in sorted(_imports(first)) if target in group]
        chain = min((path for path in back if path[-1] == first), key=len)
        out.append((group, [first, *chain]))
    return out


def _describe_chain(chain: list[str]) -> str:
    steps = []
    for a, b in zip(chain, chain[1:]):
        steps.append(f"{_rel(a)}:{_imports(a)[b]} imports {b}")
    return "; ".join(steps)


def _functions(name: str) -> list[tuple[str, int, int]]:
    """(qualified name, first line, lines) of every function and method, nested ones too."""
    out = []

    def walk(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                qual = f"{prefix}{child.name}"
                out.append((qual, child.lineno, child.end_lineno - child.lineno + 1))
                walk(child, f"{qual}.")
            elif isinstance(child, ast.ClassDef):
                walk(child, f"{prefix}{child.name}.")
            else:
                walk(child, prefix)

    walk(_tree(name), "")
    return out


def _has_kernels(name: str) -> bool:
    """Whether a module defines a function compiled by numba (decorated @jit and the like)."""
    for node in ast.walk(_tree(name)):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            for deco in node.decorator_list:
                target = deco.func if isinstance(deco, ast.Call) else deco
                label = target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", "")
                if label in JIT_DECORATORS:
                    return True
    return False


def test_the_packages_are_found() -> None:
    names = _modules()
    assert {"collide.run", "collide.stepper", "viewer.app", "cli.main"} <= set(names)
    assert any(_has_kernels(n) for n in names if n.startswith(ENGINE + "."))  # the detector sees kernels


def test_no_file_is_too_long() -> None:
    long = [f"{_rel(n)}: {lines} lines" for n, p in _modules().items()
            if (lines := len(p.read_text().splitlines())) > MAX_FILE_LINES]
    assert not long, f"files over {MAX_FILE_LINES} lines: " + "; ".join(long)


def test_no_function_is_too_long() -> None:
    long = [f"{_rel(n)}:{line} {qual} ({lines} lines)" for n in _modules()
            for qual, line, lines in _functions(n) if lines > MAX_FUNCTION_LINES]
    assert not long, f"functions over {MAX_FUNCTION_LINES} lines: " + "; ".join(long)


def test_no_import_cycles() -> None:
    cycles = _cycles()
    text = [f"  {len(group)} modules ({', '.join(group)}); a cycle: " + " -> ".join(chain)
            + f"  ({_describe_chain(chain)})" for group, chain in cycles]
    assert not cycles, "modules that import one another:\n" + "\n".join(text)


def test_the_engine_imports_only_the_engine_and_leaves() -> None:
    """An engine module may import engine modules, and leaves: modules outside the engine that
    import no module of collide, the viewer or the CLI, nor numba (collide.integrators,
    collide.errors). Anything more is a layer above the engine, which may come to import it."""
    engine = {n for n in _modules() if n == ENGINE or n.startswith(ENGINE + ".")}
    bad = []
    for name in sorted(engine):
        for target, line in sorted(_imports(name).items()):
            if target in engine:
                continue
            back = _path_to(target, engine)
            if back:
                bad.append(f"{_rel(name)}:{line} imports {target}, which imports the engine ({' -> '.join(back)})")
            elif _imports(target):
                bad.append(f"{_rel(name)}:{line} imports {target}, not a leaf: it imports "
                           + ", ".join(sorted(_imports(target))))
            elif _imports_numba(target):
                bad.append(f"{_rel(name)}:{line} imports {target}, which imports numba")
    assert not bad, "the engine reaches above itself: " + "; ".join(bad)


def test_the_viewer_does_not_import_the_compiled_kernels() -> None:
    """The viewer reads the engine's tables through their layout (collide.engine.layout), never
    by importing a module of kernels (one with @jit functions): those are the engine's inside.
    Direct imports only: the viewer runs scenes through collide.run, which loads the kernels."""
    kernels = {n for n in _modules() if n.startswith(ENGINE + ".") and n not in KERNEL_FREE and _has_kernels(n)}
    bad = [f"{_rel(name)}:{line} imports {target}" for name in sorted(_modules()) if name.split(".")[0] == "viewer"
           for target, line in sorted(_imports(name).items()) if target in kernels]
    assert not bad, "the viewer imports modules of compiled kernels: " + "; ".join(bad)


def _clear() -> None:
    for cached in (_modules, _tree, _imports):
        cached.cache_clear()


def test_the_checker_sees_cycles_closed_in_functions_and_type_checking(tmp_path: Path,
                                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """On a made-up package: a cycle closed by an import inside a function, another closed only
    under TYPE_CHECKING through `from package import module`, and an engine module reaching up."""
    files = {"__init__.py": "", "a.py": "from pkg import b\n",
             "b.py": "def f():\n    from pkg.a import thing\n",
             "c.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pkg import d\n",
             "d.py": "import pkg.c\n", "leaf.py": "import os\n",
             "engine/__init__.py": "", "engine/k.py": "from pkg import leaf, a\n"}
    for name, text in files.items():
        (tmp_path / "pkg" / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / "pkg" / name).write_text(text)
    monkeypatch.setitem(globals(), "ROOT", tmp_path)
    monkeypatch.setitem(globals(), "PACKAGES", ("pkg",))
    monkeypatch.setitem(globals(), "ENGINE", "pkg.engine")
    _clear()
    try:
        assert [chain for _, chain in _cycles()] == [["pkg.a", "pkg.b", "pkg.a"], ["pkg.c", "pkg.d", "pkg.c"]]
        try:
            test_the_engine_imports_only_the_engine_and_leaves()
        except AssertionError as exc:
            assert "pkg/engine/k.py:1 imports pkg.a, not a leaf" in str(exc) and "pkg.leaf" not in str(exc)
        else:
            raise AssertionError("the engine's import of pkg.a was not seen")
    finally:
        _clear()
