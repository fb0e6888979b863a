"""Runs of consecutive frame numbers: a Sintel scene's windows, a person's frames to check."""

from __future__ import annotations

from collections.abc import Iterable

__all__ = ["frame_runs"]


def frame_runs(numbers: Iterable[int]) -> list[tuple[int, int]]:
    """Increasing ``numbers`` as runs of consecutive ones, (first, last) each: 3, 4, 5, 9 -> (3, 5), (9, 9)."""
    runs: list[list[int]] = []
    for n in numbers:
        if runs and n == runs[-1][1] + 1:
            runs[-1][1] = n
        else:
            runs.append([n, n])
    return [(a, b) for a, b in runs]
