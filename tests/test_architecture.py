"""The package's structure: no import cycles, nobody imports the command line, small files."""

from __future__ import annotations

import ast
from pathlib import Path

import qpavoid

PACKAGE = Path(qpavoid.__file__).resolve().parent


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports_of(path: Path) -> set[str]:
    """The qpavoid modules a file imports at module level (relative imports resolved)."""
    name = module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.parse(path.read_text()).body:  # module level only
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                target = f"{base}.{node.module}" if node.module else base
            else:
                target = node.module or ""
            if target.startswith("qpavoid"):
                found.add(target)
                found.update(f"{target}.{a.name}" for a in node.names)
        elif isinstance(node, ast.Import):
            found.update(a.name for a in node.names if a.name.startswith("qpavoid"))
    return found


def import_graph() -> dict[str, set[str]]:
    files = {module_name(p): p for p in PACKAGE.rglob("*.py")}
    return {m: {t for t in imports_of(p) if t in files and t != m} for m, p in files.items()}


def test_no_import_cycles():
    graph = import_graph()
    # A package's __init__ re-exports its modules; a module importing its own package's
    # names (from . import x) goes through it. Cycles through an __init__ that only
    # re-exports are still cycles here: none is allowed.
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m: str) -> None:
        state[m] = 1
        stack.append(m)
        for n in sorted(graph[m]):
            if state.get(n) == 1:
                cycle = [*stack[stack.index(n) :], n]
                raise AssertionError("import cycle: " + " -> ".join(cycle))
            if n not in state:
                visit(n)
        stack.pop()
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m)


def test_nothing_imports_the_command_line():
    graph = import_graph()
    users = sorted(
        m
        for m, deps in graph.items()
        if {"qpavoid.cli", "qpavoid.__main__", "qpavoid.launch"} & deps
        and m not in ("qpavoid.__main__", "qpavoid.launch")  # the entry points
    )
    assert users == []


def test_no_function_level_imports_of_the_package():
    """Imports inside functions only for optional dependencies (matplotlib), never qpavoid's."""
    offenders = []
    for path in PACKAGE.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                for inner in ast.walk(node):
                    if isinstance(inner, ast.ImportFrom) and (
                        inner.level or (inner.module or "").startswith("qpavoid")
                    ):
                        offenders.append(f"{path.name}:{inner.lineno}")
    assert offenders == []


def test_source_files_stay_small():
    sizes = {
        p.relative_to(PACKAGE).as_posix(): len(p.read_text().splitlines())
        for p in PACKAGE.rglob("*.py")
    }
    assert {f: n for f, n in sizes.items() if n > 320} == {}
