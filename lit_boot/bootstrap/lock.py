"""One run at a time per run folder: an exclusive lock on ``<run folder>/.lock``.

The lock is ``fcntl.flock`` on that file, so the kernel releases it when the holding process
ends in any way (SIGKILL, a crash, a power cut): a stale lock never blocks a resume. The file
holds the holder's "pid N on HOST since TIME" for the error a second run gets; it stays in the
folder (deleting it would let two runs lock two different files). Where ``fcntl`` or file
locks are unavailable (Windows, some network file systems) a warning says the folder is not
protected against concurrent runs, and the run goes on.
"""

from __future__ import annotations

import os
import socket
import time
import warnings
from pathlib import Path

try:
    import fcntl
except ImportError:  # not POSIX
    fcntl = None

__all__ = ["LOCK_FILE", "RunLock", "RunLockedError"]

LOCK_FILE = ".lock"


class RunLockedError(OSError):
    """Another process holds the run folder's lock (an OSError: the command line reports it as
    one line)."""


class RunLock:
    """An exclusive, non-blocking lock on a run folder (created if needed); a context manager.

    ``acquire`` raises :class:`RunLockedError` naming the folder and the holder when another
    process (or another open of the same folder in this process) holds it.
    """

    def __init__(self, folder: str | os.PathLike):
        self.folder = Path(folder)
        self.path = self.folder / LOCK_FILE
        self._fd: int | None = None

    def acquire(self) -> RunLock:
        self.folder.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        if fcntl is None:
            os.close(fd)
            warnings.warn(f"{self.folder}: no file locks here; concurrent runs into it are not prevented")
            return self
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.read(fd, 200).decode(errors="replace").strip() or "holder unknown"
            os.close(fd)
            raise RunLockedError(
                f"{self.folder}: another lit-boot run is writing into this folder ({holder}); "
                "wait for it to end or choose another output folder"
            ) from None
        except OSError as err:  # a file system without locks
            os.close(fd)
            warnings.warn(f"{self.folder}: cannot lock it ({err}); concurrent runs into it are not prevented")
            return self
        os.ftruncate(fd, 0)
        since = time.strftime("%Y-%m-%d %H:%M:%S")
        os.write(fd, f"pid {os.getpid()} on {socket.gethostname()} since {since}\n".encode())
        self._fd = fd
        return self

    def release(self) -> None:
        if self._fd is not None:
            fcntl.flock(self._fd, fcntl.LOCK_UN)
            os.close(self._fd)
            self._fd = None

    @property
    def held(self) -> bool:
        return self._fd is not None

    def __enter__(self) -> RunLock:
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()
