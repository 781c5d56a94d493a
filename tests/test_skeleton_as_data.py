"""The skeleton is data: the package's Python code (docstrings aside) holds no Kinect joint
count, no Kinect joint index and no Kinect joint name outside the Kinect v2 format module;
they are in ``qpavoid/human/formats/``."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import qpavoid
from qpavoid.human.kinect_v2 import KINECT_V2

PACKAGE = Path(qpavoid.__file__).parent
#: The one module that may name the Kinect v2's joints by index (the SDK's enums).
FORMAT_MODULE = PACKAGE / "human" / "kinect_v2.py"
#: Names that are Kinect joint indices or the joint count.
INDEX_NAMES = {"JointType", "TrackingState", "N_KINECT_JOINTS"}
#: A 25 that is a number of its own, not part of 0.25 or 2025.
COUNT = re.compile(rf"(?<![\d.]){KINECT_V2.n_joints}(?![\d.])")


def docstring_nodes(tree: ast.AST) -> set[int]:
    """ids of the docstring constants (module, class, function)."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                out.add(id(body[0].value))
    return out


def offences(path: Path, root: Path = PACKAGE) -> list[str]:
    """Where ``path``'s code names a Kinect joint count, index or joint."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    docs = docstring_nodes(tree)
    names = set(INDEX_NAMES)
    for node in ast.walk(tree):  # ``JointType as J``: J is an index too
        if isinstance(node, ast.ImportFrom):
            names |= {a.asname for a in node.names if a.name in INDEX_NAMES and a.asname}
    joints = set(KINECT_V2.joints)
    found = []
    relative = path.relative_to(root)

    def where(node: ast.AST) -> str:  # made for an offence only (a path per node: seconds)
        return f"{relative}:{getattr(node, 'lineno', '?')}"

    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and id(node) not in docs:
            value = node.value
            if type(value) is int and value == KINECT_V2.n_joints:
                found.append(f"{where(node)}: the joint count {value}")
            elif isinstance(value, str):
                if COUNT.search(value):
                    found.append(f"{where(node)}: {value!r}")
                named = joints & set(re.findall(r"[A-Za-z]+", value))
                if named:
                    found.append(f"{where(node)}: joint name(s) {sorted(named)} in {value!r}")
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Load) and node.id in names:
            found.append(f"{where(node)}: {node.id}")
    return found


def test_the_code_holds_no_kinect_joint_count_index_or_name():
    files = sorted(p for p in PACKAGE.rglob("*.py") if p != FORMAT_MODULE)
    assert len(files) > 50  # the whole package, not an empty glob
    found = {}
    for path in files:
        hits = offences(path)
        if hits:
            found[path.relative_to(PACKAGE).as_posix()] = hits
    assert found == {}


def test_the_scan_finds_what_it_looks_for(tmp_path):
    """A second look: each kind of offence, written on purpose, is found; docstrings pass."""
    sample = tmp_path / "sample.py"
    code = (
        '"""A docstring may say 25 joints and SpineBase."""\n'
        "from qpavoid.human.kinect_v2 import JointType as J\n"
        "a = np.zeros((25, 3))\n"
        "b = J.HandRight\n"
        "c = 'joints (N, 25, 3)'\n"
        "d = skeleton.index('WristLeft')\n"
        "e = 0.25\n"
    )
    sample.write_text(code)
    lines = sorted(int(h.split(": ", 1)[0].rsplit(":", 1)[1]) for h in offences(sample, tmp_path))
    assert lines == [3, 4, 5, 6]
