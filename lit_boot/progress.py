"""lit-boot's progress bars: Lightning's plain (tqdm) bar, redrawn only at each epoch's start
and end where the output is not a terminal.

On a terminal tqdm redraws its line in place; in a log file (a cluster job, ``lit-boot ... >
run.log``) every redraw stays, a carriage return and a full line per training step (the demo:
about 2,400 of them, 211 kB). :func:`progress_bar` gives the same bar with a refresh rate so
large that it is drawn at an epoch's start and end only there.
"""

from __future__ import annotations

import sys
from typing import TextIO

__all__ = ["progress_bar", "LOG_REFRESH_RATE"]

#: The bar's refresh rate (steps between redraws) where the output is not a terminal: larger than
#: any epoch, so a bar is drawn when it starts and when it is full.
LOG_REFRESH_RATE = 10**9


def progress_bar(stream: TextIO | None = None):
    """A ``TQDMProgressBar``: refreshed every step when ``stream`` (default: stdout, where
    Lightning's bars write) is a terminal, else only at each epoch's start and end
    (:data:`LOG_REFRESH_RATE`)."""
    from lightning.pytorch.callbacks import TQDMProgressBar

    stream = sys.stdout if stream is None else stream
    terminal = bool(getattr(stream, "isatty", lambda: False)())
    return TQDMProgressBar(refresh_rate=1 if terminal else LOG_REFRESH_RATE)
