"""Atomic results: a folder or file appears complete or not at all, never mixed with another run's."""

import os
from pathlib import Path

import pytest

from fpm_sim.outputs import OutputError, atomic_dir, atomic_file, prove_creatable


def _leftovers(parent: Path) -> list[str]:
    return sorted(p.name for p in parent.iterdir() if p.name.startswith("."))


def test_atomic_dir_appears_on_success_and_replaces_only_with_overwrite(tmp_path):
    target = tmp_path / "run"
    with atomic_dir(target) as tmp:
        assert tmp.parent == tmp_path
        (tmp / "a.csv").write_text("1")
    assert (target / "a.csv").read_text() == "1"
    with pytest.raises(OutputError, match="allow overwrite"), atomic_dir(target) as tmp:
        (tmp / "b.csv").write_text("2")
    assert sorted(p.name for p in target.iterdir()) == ["a.csv"]  # the first run untouched
    with atomic_dir(target, overwrite=True) as tmp:
        (tmp / "b.csv").write_text("2")
    assert sorted(p.name for p in target.iterdir()) == ["b.csv"]  # replaced whole, not mixed
    assert _leftovers(tmp_path) == []


def _interrupted_dir(target: Path) -> None:
    with atomic_dir(target) as tmp:
        (tmp / "half.csv").write_text("partial")
        raise RuntimeError("interrupted")


def _interrupted_file(target: Path) -> None:
    with atomic_file(target) as tmp:
        assert tmp.suffix == target.suffix
        tmp.write_text("half")
        raise KeyError("failed")


def test_atomic_dir_leaves_nothing_when_the_run_fails(tmp_path):
    target = tmp_path / "nested" / "run"
    with pytest.raises(RuntimeError, match="interrupted"):
        _interrupted_dir(target)
    assert not target.exists()
    assert _leftovers(target.parent) == []


def test_atomic_dir_refuses_a_file_in_the_way(tmp_path):
    (tmp_path / "run").write_text("not a folder")
    with pytest.raises(OutputError, match="is a file"), atomic_dir(tmp_path / "run"):
        pass


def test_atomic_file_replaces_on_success_and_keeps_the_old_file_on_failure(tmp_path):
    target = tmp_path / "rom.npz"
    target.write_text("old")
    with pytest.raises(KeyError, match="failed"):
        _interrupted_file(target)
    assert target.read_text() == "old"
    with atomic_file(target) as tmp:
        tmp.write_text("new")
    assert target.read_text() == "new"
    assert _leftovers(tmp_path) == []
    with pytest.raises(OutputError, match="is a folder"), atomic_file(tmp_path):
        pass


def test_prove_creatable_leaves_nothing_and_refuses_what_cannot_be_created(tmp_path):
    prove_creatable(tmp_path / "a" / "b" / "run", folder=True)  # missing parents: proved in the nearest existing
    prove_creatable(tmp_path / "m.xml")
    assert list(tmp_path.iterdir()) == []  # the probes are gone, no parent folder was made
    (tmp_path / "file").write_text("x")
    with pytest.raises(OutputError, match="is a file, not a folder") as exc:
        prove_creatable(tmp_path / "file" / "sub" / "m.xml", parameter="model_path")
    assert exc.value.parameter == "model_path"
    with pytest.raises(OutputError, match="existing file, not a folder"):
        prove_creatable(tmp_path / "file", folder=True)
    with pytest.raises(OutputError, match="is a folder"):
        prove_creatable(tmp_path, parameter="out")
    with pytest.raises(OutputError, match="cannot create /proc/x/y") as exc:
        prove_creatable("/proc/x/y", folder=True)
    assert exc.value.parameter == "out"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_prove_creatable_refuses_a_read_only_folder(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        with pytest.raises(OutputError, match="cannot create"):
            prove_creatable(ro / "out.csv")
    finally:
        ro.chmod(0o700)
