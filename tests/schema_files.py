"""What the tests of the user files' schemas share (tests/test_file_schemas_*.py): a file
written with one edit, its refusal checked as one line, and the command line's exit 2."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from qpavoid.cli.commands import main


class RefusedError(Exception):
    """A refusal as :func:`qpavoid.core.schema.convert` hands it to its ``fail``."""

    def __init__(self, name: str, message: str, value: object) -> None:
        super().__init__(message)
        self.name, self.value = name, value


def written(path: Path, text: str, old: str, new: str) -> Path:
    """``text`` with ``old`` replaced by ``new``, written to ``path``."""
    assert old in text
    path.write_text(text.replace(old, new, 1))
    return path


def refused(
    error: type[Exception], load: Callable[[Path], object], path: Path, start: str, message: str
) -> Exception:
    """``load(path)``'s refusal: one line, starting ``start``, saying ``message``."""
    with pytest.raises(error) as info:
        load(path)
    text = str(info.value)
    assert text.startswith(start) and "\n" not in text and message in text, text
    return info.value


def exits_2(capsys, args: list[str], out: Path, message: str) -> str:
    """The command line's refusal of ``args``: exit 2, one line saying ``message``."""
    assert main([*args, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and not out.exists(), err
    return err
