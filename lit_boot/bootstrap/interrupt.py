"""Ctrl-C during a run: one exception naming where the run stopped, whatever Lightning did with it.

Lightning turns a KeyboardInterrupt inside a Trainer into ``sys.exit(1)`` and ignores any further
Ctrl-C (SIGINT set to SIG_IGN). Within :func:`interruptible`, a SIGINT handler (main thread only)
notes the signal and raises KeyboardInterrupt; a KeyboardInterrupt, or a SystemExit after the
signal, leaves the block as :class:`RunInterrupted`; the previous handler is restored after.
The run folder then holds every stage that finished (see :mod:`~lit_boot.bootstrap.runner`), and
the same run again resumes after the last of them.

Cheap to import: signal and threading only.
"""

from __future__ import annotations

import os
import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

__all__ = ["RunInterrupted", "interruptible"]


class RunInterrupted(KeyboardInterrupt):
    """A run stopped by Ctrl-C (SIGINT): ``out`` is its folder, ``stage`` the last stage that
    finished (None: none had). A KeyboardInterrupt, so code that stops on Ctrl-C still does."""

    def __init__(self, out: str | os.PathLike, stage: str | None):
        self.out, self.stage = Path(out), stage
        super().__init__(f"{self.out}: interrupted {self.where}; run it again to resume")

    @property
    def where(self) -> str:
        """``after flow_1``, or ``before the first stage finished``."""
        return f"after {self.stage}" if self.stage is not None else "before the first stage finished"


@contextmanager
def interruptible(out: str | os.PathLike, last_stage: Callable[[], str | None]) -> Iterator[None]:
    """Within the block, Ctrl-C raises :class:`RunInterrupted` (``out``, ``last_stage()`` at that
    moment), also where Lightning turned it into SystemExit. Outside the main thread, where no
    signal handler can be set, only a KeyboardInterrupt is turned into it."""
    signalled = threading.Event()

    def on_sigint(signum: int, frame: object) -> None:
        signalled.set()
        raise KeyboardInterrupt

    main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, on_sigint) if main else None
    try:
        yield
    except RunInterrupted:
        raise
    except KeyboardInterrupt:
        raise RunInterrupted(out, last_stage()) from None
    except SystemExit:
        if not signalled.is_set():
            raise
        raise RunInterrupted(out, last_stage()) from None
    finally:
        if main:  # also undoes Lightning's SIG_IGN
            signal.signal(signal.SIGINT, previous if previous is not None else signal.default_int_handler)
