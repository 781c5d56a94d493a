"""The package's structure: the stages' import contracts (import-linter), checked and shown to
catch a violation; no function-level imports of the package."""

from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import qpavoid

PACKAGE = Path(qpavoid.__file__).resolve().parent


#: The source tree: its pyproject.toml holds the contracts (the installed package has none).
ROOT = Path(__file__).resolve().parents[1]


def lint_imports(root: Path) -> subprocess.CompletedProcess:
    """import-linter on the package under ``root`` with ``root``'s pyproject contracts."""
    return subprocess.run(
        [
            sys.executable,
            "-c",
            "import sys; from importlinter.cli import lint_imports_command;"
            " sys.exit(lint_imports_command())",
            "--no-cache",
        ],
        cwd=root,
        env={**os.environ, "PYTHONPATH": str(root)},
        capture_output=True,
        text=True,
    )


def test_import_contracts_hold():
    """The stages import only the stages before them, no module is in an import cycle, the QP
    framework knows only core."""
    done = lint_imports(ROOT)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "3 kept, 0 broken" in done.stdout


@pytest.mark.parametrize(
    ("module", "line", "broken"),
    [
        # an upward import: the arm made to know the controllers
        ("arm/braking.py", "from qpavoid.control import controller", "Each stage"),
        # the QP framework made to know the controller's tick
        ("control/qp/pieces.py", "from qpavoid.control import tick", "The QP framework"),
        # nobody imports the command line (the stages' contract again: with the slow ones)
        pytest.param(
            "loop/simulation.py",
            "import qpavoid.cli.commands",
            "Each stage",
            marks=pytest.mark.slow,
        ),
        # a cycle inside a stage: frames made to import people, which imports frames
        ("human/frames.py", "from qpavoid.human import people", "No import cycles"),
    ],
)
def test_import_contracts_catch_a_violation(tmp_path, module, line, broken):
    """In a copy of the package, one added import breaks the contract it should."""
    shutil.copytree(
        ROOT / "qpavoid", tmp_path / "qpavoid", ignore=shutil.ignore_patterns("__pycache__")
    )
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    target = tmp_path / "qpavoid" / module
    text = target.read_text()
    head, sep, rest = text.partition("\nfrom __future__ import annotations\n")
    assert sep, module
    target.write_text(head + sep + line + "\n" + rest)
    done = lint_imports(tmp_path)
    assert done.returncode == 1, done.stdout
    assert f"{broken}" in done.stdout and "BROKEN" in done.stdout


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
