"""Atomic results: a run's files appear complete, or not at all.

:func:`atomic_dir` hands the writer a temporary sibling folder (same parent, hence the same file system)
and renames it into place when the ``with`` block ends without an exception; :func:`atomic_file` does
the same for one file (write to a temporary sibling, then :func:`os.replace`). An interrupted run (an
exception, Ctrl-C) leaves only what was there before; the temporary is removed.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

from fpm_sim.errors import FpmSimError

__all__ = ["OutputError", "atomic_dir", "atomic_file", "open_for_writing", "prove_creatable", "write_csv_rows"]


class OutputError(FpmSimError):
    """An output path that cannot be written (or would replace another run's results)."""


def _default_mode(mode: int) -> int:
    """``mode`` less the process umask: what a plain ``mkdir``/``open`` would have created."""
    mask = os.umask(0)
    os.umask(mask)
    return mode & ~mask


def _parent(path: Path) -> Path:
    parent = path.parent if str(path.parent) else Path(".")
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError) as exc:
        msg = f"cannot create folder {parent} for {path}: a file is in the way; choose another path"
        raise OutputError(msg) from exc
    except PermissionError as exc:
        msg = f"cannot create folder {parent} for {path}: permission denied; choose a writable place"
        raise OutputError(msg) from exc
    return parent


def prove_creatable(path: str | Path, *, parameter: str = "out", folder: bool = False) -> None:
    """Prove, before any computation, that the output ``path`` (a file, or a folder with ``folder``) can be created.

    The proof is the real thing: a temporary sibling is created where ``path`` will go (in its parent folder, or
    in the nearest existing ancestor when parent folders are still to be made) and removed at once. Nothing is
    left behind. Raises :class:`OutputError` naming ``parameter`` when a file is in the way of a folder, a
    folder is in the way of the file, or the place is not writable (read-only, ``/proc``, permissions).
    """
    target = Path(path)
    if folder and target.exists() and not target.is_dir():
        raise OutputError(
            f"{target} is an existing file, not a folder", parameter=parameter, hint="choose a folder name"
        )
    if not folder and target.is_dir():
        raise OutputError(f"{target} is a folder", parameter=parameter, hint="give a file name")
    probe = target.parent if str(target.parent) else Path(".")
    while not probe.exists() and probe.parent != probe:
        probe = probe.parent
    if not probe.is_dir():
        raise OutputError(
            f"cannot create {target}: {probe} is a file, not a folder", parameter=parameter, hint="choose another path"
        )
    try:
        os.rmdir(tempfile.mkdtemp(prefix=f".{target.name}.probe-", dir=probe))
        if target.is_file() and not os.access(target, os.W_OK):
            raise PermissionError(13, "the file is read-only")
    except OSError as exc:
        raise OutputError(
            f"cannot create {target} ({exc.strerror or exc})", parameter=parameter, hint="choose a writable place"
        ) from exc


@contextmanager
def atomic_dir(target: str | Path, *, overwrite: bool = False) -> Iterator[Path]:
    """Write a folder of results atomically.

    Parameters
    ----------
    target
        The folder the results end up in.
    overwrite
        Replace ``target`` if it exists and is not empty; otherwise that raises :class:`OutputError`
        (checked again at the end: the results are never mixed with another run's).

    Yields
    ------
    Path
        A temporary, empty sibling folder to write into; renamed to ``target`` on success.
    """
    target = Path(target)
    if target.exists() and not target.is_dir():
        raise OutputError(f"{target} is a file, not a folder; choose a folder name")
    parent = _parent(target)
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.tmp-", dir=parent))
    os.chmod(tmp, _default_mode(0o777))  # mkdtemp makes it private (0700)
    try:
        yield tmp
        if target.exists():
            if any(target.iterdir()) and not overwrite:
                raise OutputError(
                    f"{target} already holds another run's results",
                    parameter="out",
                    hint="allow overwrite to replace it, or choose another folder",
                )
            old = Path(tempfile.mkdtemp(prefix=f".{target.name}.old-", dir=parent))
            os.replace(target, old / "run")  # move the old run aside, then the new one in
            os.replace(tmp, target)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, target)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)


@contextmanager
def atomic_file(target: str | Path) -> Iterator[Path]:
    """Write one file atomically: yields a temporary sibling path (same suffix), moved to ``target`` on success."""
    target = Path(target)
    if target.is_dir():
        raise OutputError(f"{target} is a folder; give a file name")
    parent = _parent(target)
    fd, name = tempfile.mkstemp(prefix=f".{target.stem}.tmp-", suffix=target.suffix, dir=parent)
    os.close(fd)
    tmp = Path(name)
    os.chmod(tmp, _default_mode(0o666))  # mkstemp makes it private (0600)
    try:
        yield tmp
        os.replace(tmp, target)
    finally:
        if tmp.exists():
            tmp.unlink()


@contextmanager
def open_for_writing(
    path: str | Path, *, parameter: str = "out", error: type[FpmSimError] = FpmSimError
) -> Iterator[IO[bytes]]:
    """Open ``path`` for binary writing, parent folders created.

    A failure (a read-only place, a folder in the way, ...) becomes ``error`` naming the file and
    ``parameter`` instead of a library's own message.

    Parameters
    ----------
    path
        The file to write.
    parameter
        The parameter the path came from (named in the error).
    error
        The :class:`~fpm_sim.errors.FpmSimError` subclass raised on failure.

    Yields
    ------
    IO[bytes]
        The open file, closed when the ``with`` block ends.
    """
    p = Path(path)
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        handle = open(p, "wb")  # closed below
    except OSError as e:
        raise error(
            f"cannot write {str(p)!r} ({e.strerror or e})", parameter=parameter, hint="choose a writable path"
        ) from e
    with handle:
        yield handle


def write_csv_rows(path: str | Path, rows: list[dict[str, Any]]) -> None:
    """Write ``rows`` (at least one) as CSV, the header from the first row's keys, values as :mod:`csv` writes them.

    For a file inside a folder that :func:`atomic_dir` is writing: the file itself is not atomic.
    """
    import csv

    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)

