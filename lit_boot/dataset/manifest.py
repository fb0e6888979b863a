"""The manifest of a dataset run: ``<out>/manifest.json``, every task's state, settings and result.

One writer (the driver) holds the dataset folder's lock and rewrites the file atomically after
every change, so a run killed at any point leaves a readable manifest. A task is ``pending``
(not started, or lost with its worker), ``running``, ``done`` (its record holds the result) or
``failed`` (its record holds the error); a rerun runs every task that is not ``done``. The
settings (the bootstrap config and the chunking) are stored once; a rerun with other settings
is refused, naming what differs, unless it starts again (``overwrite``): results made with other
settings are never mixed into one table.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any

from ..data.atomic import atomic_write_bytes
from .tasks import Task

__all__ = ["Manifest", "MANIFEST_JSON", "STATES", "SettingsChangedError"]

MANIFEST_JSON = "manifest.json"
STATES = ("pending", "running", "done", "failed")


class SettingsChangedError(ValueError):
    """The dataset folder holds results made with other settings."""


def _plain(value: Any) -> Any:
    """``value`` as JSON gives it back (tuples -> lists, paths -> strings)."""
    return json.loads(json.dumps(value, default=str))


class Manifest:
    """``<folder>/manifest.json``: {"format", "version", "settings", "tasks": {name: record}}.

    A record: {"task": Task.to_dict(), "state", "attempts" (starts that ended without a result:
    lost workers), "error", "result" (the worker's, see :mod:`lit_boot.dataset.worker`),
    "updated" (local time)}.
    """

    def __init__(self, folder: str | os.PathLike, settings: dict[str, Any], tasks: dict[str, dict[str, Any]]):
        self.folder = Path(folder)
        self.settings = _plain(settings)
        self.tasks = tasks

    @property
    def path(self) -> Path:
        return self.folder / MANIFEST_JSON

    # --- open, check, save -----------------------------------------------------------------------
    @classmethod
    def open(cls, folder: str | os.PathLike, settings: dict[str, Any], overwrite: bool = False) -> Manifest:
        """The manifest in ``folder`` (a new, empty one if there is none or ``overwrite``).
        SettingsChangedError if it was made with other ``settings``."""
        path = Path(folder) / MANIFEST_JSON
        if overwrite or not path.is_file():
            return cls(folder, settings, {})
        try:
            data = json.loads(path.read_text())
            old, tasks = data["settings"], data["tasks"]
        except (ValueError, KeyError, TypeError, UnicodeDecodeError) as err:
            raise ValueError(f"{path}: unreadable dataset manifest ({type(err).__name__}: {err}); "
                             "start again with overwrite (--overwrite true) or choose another folder") from None  # fmt: skip
        settings = _plain(settings)
        if old != settings:
            differ = ", ".join(_differences(old, settings))
            raise SettingsChangedError(
                f"{Path(folder)}: holds results made with other settings ({differ} differ); rerun with the same "
                "settings to resume, start again with overwrite (--overwrite true), or choose another folder"
            )
        return cls(folder, settings, tasks)

    def save(self) -> None:
        """Write manifest.json atomically."""
        data = {"format": "lit-boot-dataset", "version": 1, "settings": self.settings, "tasks": self.tasks}
        atomic_write_bytes(self.path, (json.dumps(data, indent=1, default=str) + "\n").encode())

    # --- tasks -------------------------------------------------------------------------------------
    def add(self, tasks: list[Task]) -> int:
        """Record the tasks not yet known (pending); a known name with another spec raises.
        Returns how many were new."""
        new = 0
        for task in tasks:
            spec = _plain(task.to_dict())
            record = self.tasks.get(task.name)
            if record is None:
                self.tasks[task.name] = {"task": spec, "state": "pending", "attempts": 0, "error": None,
                                         "result": None, "updated": _now()}  # fmt: skip
                new += 1
            elif record["task"] != spec:
                raise SettingsChangedError(
                    f"{self.path}: task {task.name!r} was recorded with another source ({record['task']}, now {spec}); "
                    "start again with overwrite (--overwrite true) or choose another folder"
                )
        return new

    def task(self, name: str) -> Task:
        return Task.from_dict(self.tasks[name]["task"])

    def names(self, *states: str) -> list[str]:
        """Task names in the given states (all if none), in the order they were added."""
        return [n for n, r in self.tasks.items() if not states or r["state"] in states]

    def todo(self) -> list[str]:
        """What a run still has to do: every task not done (a ``running`` one was cut short)."""
        return [n for n, r in self.tasks.items() if r["state"] != "done"]

    def mark(self, name: str, state: str, **fields: Any) -> None:
        """Set task ``name``'s state (and record fields, e.g. result=..., error=...); saves."""
        if state not in STATES:
            raise ValueError(f"state {state!r} is not one of {STATES}")
        record = self.tasks[name]
        record.update(_plain(fields))
        record["state"], record["updated"] = state, _now()
        if state == "done":
            record["error"] = None
        self.save()

    def counts(self) -> dict[str, int]:
        """{state: number of tasks} for every state."""
        out = dict.fromkeys(STATES, 0)
        for record in self.tasks.values():
            out[record["state"]] += 1
        return out


def _differences(old: dict[str, Any], new: dict[str, Any], prefix: str = "") -> list[str]:
    """The keys (dotted for nested dicts) whose values differ."""
    out = []
    for key in sorted(set(old) | set(new)):
        a, b = old.get(key), new.get(key)
        if isinstance(a, dict) and isinstance(b, dict):
            out += _differences(a, b, f"{prefix}{key}.")
        elif a != b:
            out.append(prefix + key)
    return out


def _now() -> str:
    return time.strftime("%Y-%m-%d %H:%M:%S")
