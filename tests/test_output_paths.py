"""Where a command writes: checked before the work, replaced whole after it (issue 11's
adversarial tester re-ran a sweep into its own folder, and it failed after the work)."""

from __future__ import annotations

import os

import pytest

from qpavoid.core.errors import InputError
from qpavoid.output.run_files import (
    STAGE_PREFIX,
    check_output_dir,
    check_output_file,
    staged_output,
)


def write(stage, files: dict[str, str]) -> None:
    for name, text in files.items():
        (stage / name).parent.mkdir(parents=True, exist_ok=True)
        (stage / name).write_text(text)


def tree(root) -> dict[str, str]:
    return {str(p.relative_to(root)): p.read_text() for p in sorted(root.rglob("*")) if p.is_file()}


def test_a_second_job_replaces_the_first_folders_whole_and_keeps_other_files(tmp_path):
    out = tmp_path / "c"
    with staged_output(out) as stage:
        write(stage, {"summary.json": "1", "worst/seed1.npz": "a", "worst/seed2.npz": "b"})
    (out / "notes.txt").write_text("mine")
    with staged_output(out) as stage:
        assert stage.parent == out  # staged inside the folder it replaces into
        write(stage, {"summary.json": "2", "worst/seed7.npz": "c"})
    # the old worst/ is gone with all its files, the user's own file is kept
    assert tree(out) == {"notes.txt": "mine", "summary.json": "2", "worst/seed7.npz": "c"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c"]  # no staging left anywhere


def test_a_failed_job_leaves_the_folder_as_it_was(tmp_path):
    out = tmp_path / "c"
    with staged_output(out) as stage:
        write(stage, {"summary.json": "1", "worst/seed1.npz": "a"})
    with pytest.raises(RuntimeError), staged_output(out) as stage:
        write(stage, {"summary.json": "2", "worst/seed7.npz": "c"})
        raise RuntimeError("the job failed")
    assert tree(out) == {"summary.json": "1", "worst/seed1.npz": "a"}
    assert not any(p.name.startswith(STAGE_PREFIX) for p in out.iterdir())


def test_a_new_folder_is_staged_beside_it_and_parents_are_made(tmp_path):
    out = tmp_path / "a" / "b" / "c"
    with staged_output(out) as stage:
        assert stage.parent == out.parent and not out.exists()
        write(stage, {"x.json": "1"})
    assert tree(tmp_path) == {"a/b/c/x.json": "1"}


def test_a_name_as_long_as_the_filesystem_allows_works(tmp_path):
    """The staging folder's name no longer adds to ``--out``'s (250 bytes failed after
    the work); one byte more than the limit is refused before it."""
    longest = os.pathconf(tmp_path, "PC_NAME_MAX")
    out = tmp_path / ("x" * longest)
    with staged_output(out) as stage:
        write(stage, {"x.json": "1"})
    assert (out / "x.json").read_text() == "1"
    with pytest.raises(InputError, match=f"longer than {longest} bytes"):
        check_output_dir(tmp_path / "new" / ("y" * (longest + 1)))
    assert not (tmp_path / "new").exists()


@pytest.mark.parametrize("path", ["", "dangling", "dangling/c", "afile", "afile/c"])
def test_folders_that_cannot_be_made_are_refused_before_the_work(tmp_path, path):
    (tmp_path / "afile").write_text("")
    (tmp_path / "dangling").symlink_to(tmp_path / "nowhere")
    before = sorted(tmp_path.iterdir())
    with pytest.raises(InputError) as caught:
        check_output_dir(tmp_path / path if path else path)
    assert caught.value.name == "--out"
    assert sorted(tmp_path.iterdir()) == before


def test_a_file_path_is_tried_and_left_as_it_was(tmp_path):
    new, old = tmp_path / "new.json", tmp_path / "old.json"
    old.write_text("kept")
    assert check_output_file(str(new), "--json") == new and not new.exists()
    assert check_output_file(str(old), "--json") == old and old.read_text() == "kept"
    (tmp_path / "afile").write_text("")
    for bad in ["", str(tmp_path), f"{tmp_path}/afile/x.json", f"{tmp_path}/no/x.json"]:
        with pytest.raises(InputError, match="--json") as caught:
            check_output_file(bad, "--json")
        assert caught.value.value == bad
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile", "old.json"]


@pytest.mark.parametrize("kind", ["file", "symlink"])
def test_a_file_or_link_is_replaced_by_a_folder_of_its_name(tmp_path, kind):
    out = tmp_path / "c"
    out.mkdir()
    if kind == "file":
        (out / "worst").write_text("mine")
    else:
        (tmp_path / "mine").mkdir()
        (out / "worst").symlink_to(tmp_path / "mine")
    with staged_output(out) as stage:
        write(stage, {"worst/seed1.npz": "a"})
    assert tree(out) == {"worst/seed1.npz": "a"} and not (out / "worst").is_symlink()
    assert kind == "file" or (tmp_path / "mine").is_dir()  # a link's target is not touched


def test_ctrl_c_during_the_move_waits_for_its_end_and_says_so(tmp_path, monkeypatch):
    """An adversary's Ctrl-C within the move's millisecond left a folder without its
    worst/ (the old one removed, the new one never moved in), saying nothing written."""
    import signal

    if signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        pytest.skip("Ctrl-C is not Python's KeyboardInterrupt here")
    out = tmp_path / "c"
    with staged_output(out) as stage:
        write(stage, {"summary.json": "1", "worst/seed1.npz": "a"})
    replace = os.replace
    calls = []

    def interrupted_replace(src, dst):
        if not calls:
            os.kill(os.getpid(), signal.SIGINT)  # held back until the move ends
        calls.append(dst)
        replace(src, dst)

    monkeypatch.setattr(os, "replace", interrupted_replace)
    with pytest.raises(KeyboardInterrupt) as caught, staged_output(out) as stage:
        write(stage, {"summary.json": "2", "worst/seed7.npz": "c"})
    assert caught.value.written == out  # type: ignore[attr-defined]
    assert tree(out) == {"summary.json": "2", "worst/seed7.npz": "c"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c"]


def test_a_failed_job_removes_the_folders_it_made(tmp_path):
    out = tmp_path / "new" / "deeper" / "c"
    with pytest.raises(KeyboardInterrupt), staged_output(out) as stage:
        write(stage, {"x.json": "1"})
        raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "name, why",
    [("", "empty"), ("fifo", "not a regular file"), ("link.json", "symbolic link to nothing"),
     ("x.json/", "a folder")],
)  # fmt: skip
def test_odd_file_paths_are_refused_at_once(tmp_path, name, why):
    """A FIFO blocked the check forever, a dangling link became a file, ``x.json/``
    overwrote ``x.json``."""
    os.mkfifo(tmp_path / "fifo")
    (tmp_path / "link.json").symlink_to(tmp_path / "missing.json")
    (tmp_path / "x.json").write_text("kept")
    path = f"{tmp_path}/{name}" if name else ""
    with pytest.raises(InputError, match=why):
        check_output_file(path, "--json")
    assert (tmp_path / "link.json").is_symlink() and not (tmp_path / "missing.json").exists()
    assert (tmp_path / "x.json").read_text() == "kept"
