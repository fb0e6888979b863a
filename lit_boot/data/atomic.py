"""Atomic writes: a file or a folder appears under its final name complete, or not at all.

Everything is first written beside the target (same folder, hence same file system) under a
hidden temporary name ``.<name>.<random>.partial``, fsynced, and then renamed into place (a
file's folder is fsynced too, so files persist in the order they were written). An interrupted
write leaves at most such a temporary entry behind, never a half-written target;
:func:`remove_partials` clears those from a folder whose writer is known to be gone.
"""

from __future__ import annotations

import os
import re
import shutil
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

__all__ = ["atomic_directory", "atomic_file", "atomic_write_bytes", "remove_partials"]

#: A temporary entry of an unfinished write (never a complete target: those have their own name).
_PARTIAL = re.compile(r"^\..+\.[0-9a-f]{12}\.partial(\.[^.]*)?$")


@contextmanager
def atomic_file(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path`` (hidden, same suffix, so writers that pick a
    format from the extension still can); when the block succeeds the file written there is
    fsynced and renamed onto ``path``, when it fails it is removed."""
    path = Path(path)
    tmp = _temp_name(path, "partial" + path.suffix)
    try:
        yield tmp
        with open(tmp, "rb") as f:
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except OSError as err:
        _unlink_quietly(tmp)
        raise _naming(err, tmp, path) from None
    except BaseException:
        _unlink_quietly(tmp)
        raise
    _fsync_dir(path.parent)


def _unlink_quietly(path: Path) -> None:
    try:
        path.unlink(missing_ok=True)
    except OSError:  # e.g. a read-only folder, where it was never made
        pass


def _naming(err: OSError, tmp: Path, path: Path) -> OSError:
    """``err`` naming ``path`` where it named the hidden temporary ``tmp`` (a read-only folder:
    "[Errno 13] Permission denied: 'out/config.json'", not the temporary's name)."""
    if err.filename not in (str(tmp), tmp) or err.errno is None:
        return err
    return type(err)(err.errno, err.strerror, str(path))


def _fsync_dir(folder: Path) -> None:
    """Make a rename in ``folder`` durable (so writes persist in the order they were made, also
    across a power cut); a no-op where folders cannot be opened (Windows)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (temporary file + fsync + ``os.replace``).

    An existing file at ``path`` is replaced only once the new content is complete.
    Returns the path.
    """
    with atomic_file(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def _temp_name(path: Path, kind: str) -> Path:
    """A fresh hidden name beside ``path``: ``.<name>.<random>.<kind>``."""
    return path.parent / f".{path.name}.{uuid.uuid4().hex[:12]}.{kind}"


def remove_partials(folder: str | os.PathLike) -> list[Path]:
    """Delete, under ``folder`` (recursively), the temporary files and folders that interrupted
    writes of this module left (``.<name>.<12 hex>.partial[.suffix]``); returns them. Only for a
    folder no other process is writing into (e.g. one held by a lock). Folders moved aside by a
    replacement (``.old``) are kept: one may be the only copy."""
    removed = []
    for root, dirs, files in os.walk(folder):
        for name in [d for d in dirs if _PARTIAL.match(d)]:
            shutil.rmtree(Path(root) / name, ignore_errors=True)
            dirs.remove(name)
            removed.append(Path(root) / name)
        for name in files:
            if _PARTIAL.match(name):
                (Path(root) / name).unlink(missing_ok=True)
                removed.append(Path(root) / name)
    return removed


def _is_empty_dir(path: Path) -> bool:
    return path.is_dir() and not path.is_symlink() and not any(path.iterdir())


@contextmanager
def atomic_directory(
    path: str | os.PathLike,
    *,
    overwrite: bool = False,
    may_replace: Callable[[Path], bool] | None = None,
    replaceable: str = "replaceable",
) -> Iterator[Path]:
    """Build a folder in a temporary folder beside ``path``; rename it to ``path`` on success.

    Yields the temporary folder to fill. If the block raises, the temporary folder is deleted
    and ``path`` is untouched. An existing empty folder at ``path`` is always replaced; any
    other existing entry raises :class:`FileExistsError`, unless ``overwrite`` is True and it
    is a folder for which ``may_replace(path)`` is True (default: any folder); ``replaceable``
    describes such folders in the error message ("a saved scene"). Replacing
    renames the old folder aside, renames the new one in, then deletes the old one.
    """
    path = Path(path)
    _check_target(path, overwrite, may_replace, replaceable)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _temp_name(path, "partial")
    try:
        tmp.mkdir()
    except OSError as err:
        raise _naming(err, tmp, path) from None
    try:
        yield tmp
        _check_target(path, overwrite, may_replace, replaceable)  # it may have appeared meanwhile
        _swap_in(tmp, path)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _check_target(path: Path, overwrite: bool, may_replace: Callable[[Path], bool] | None, replaceable: str) -> None:
    if not os.path.lexists(path) or _is_empty_dir(path):
        return
    if not path.is_dir() or path.is_symlink():
        raise FileExistsError(f"{path}: exists and is not a folder; refusing to replace it")
    if not overwrite:
        raise FileExistsError(f"{path}: folder exists and is not empty (pass overwrite=True to replace it)")
    if may_replace is not None and not may_replace(path):
        raise FileExistsError(f"{path}: refusing to overwrite a folder that is not {replaceable}")


def _swap_in(tmp: Path, path: Path) -> None:
    """Rename ``tmp`` to ``path``; an existing ``path`` is moved aside first and deleted last."""
    if not os.path.lexists(path):
        os.rename(tmp, path)
        return
    aside = _temp_name(path, "old")
    os.rename(path, aside)
    try:
        os.rename(tmp, path)
    except BaseException:
        os.rename(aside, path)  # put the old one back
        raise
    shutil.rmtree(aside, ignore_errors=True)
