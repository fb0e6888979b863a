"""A bootstrap run folder: its settings, its finished stages, and what a rerun may do with it.

The runner checks the folder before it writes anything (:meth:`RunFolder.check`), takes the
folder's lock (:class:`~lit_boot.bootstrap.lock.RunLock`), then :meth:`RunFolder.prepare`
decides: same settings resume; other settings are refused once a stage has finished (its
stage.json exists) and replace the run otherwise (it had produced nothing); ``overwrite``
starts again. Only a folder holding a lit-boot run (config.json) or an empty one is ever
cleared, even with ``overwrite``.

What a run folder holds (the input scene folder is never written)::

    config.json            the run's settings (a rerun with other settings is refused once a
                           stage has finished; before that it replaces the run)
    .lock                  the lock one run at a time holds (pid and host of the last holder)
    stages/<stage>/        initial, flow_1, pose_1, flow_2, ...: each stage's flows.npz,
                           fine-tuned RAFT weights (raft_<member>.pt) or refined poses, and
                           stage.json, written last: a stage with stage.json is done, and a
                           rerun of an interrupted run loads it instead of running it again
    flows/                 the final flows (flow_<t>.flo or flows.npz) and colour PNGs
    poses.npz, pose_report.json  the final refined poses (a lit-boot pose file) and their report
    raft_finetuned.pt      the final fine-tuned RAFT weights (torchvision format)
    summary.json           settings, device, every metric per stage, timings, guard events
    metrics.png            the metrics per stage
    overlay.mp4            frame, flows (RAFT, refined, GT), EPE change, skeletons (overlay.py)
    report.html            whether the video got better, and where (html_report.py; written last)
    logs/tensorboard/, logs/csv/   per stage (training curves) and "summary" (per stage)
"""

from __future__ import annotations

import io
import json
import logging
import os
import shutil
import uuid
from pathlib import Path
from typing import Any

import torch

from ..data.atomic import atomic_write_bytes, remove_partials
from ..data.flows import write_flows_npz
from .decisions import save_decisions
from .lock import LOCK_FILE

__all__ = ["RunFolder", "CONFIG_JSON", "STAGE_JSON"]

log = logging.getLogger(__name__)

CONFIG_JSON = "config.json"
STAGE_JSON = "stage.json"


class RunFolder:
    """The run folder at ``path``; ``overwrite`` clears a run found there (see the module doc)."""

    def __init__(self, path: str | os.PathLike, overwrite: bool = False):
        self.path = Path(path)
        self.overwrite = overwrite

    # --- before and while taking over the folder ------------------------------------------------
    def check(self, settings: dict[str, Any]) -> None:
        """Refuse, writing nothing: a path that is not a folder, a non-empty folder that holds
        no lit-boot run (FileExistsError), a run with other settings that finished a stage
        (ValueError)."""
        p = self.path
        if os.path.lexists(p) and not p.is_dir():
            raise FileExistsError(f"{p}: exists and is not a folder (choose another output folder)")
        if p.is_dir() and not (p / CONFIG_JSON).is_file() and any(e.name != LOCK_FILE for e in p.iterdir()):
            raise FileExistsError(f"{p}: exists, is not empty and holds no lit-boot run (choose another folder)")
        self._decide(settings)

    def prepare(self, settings: dict[str, Any]) -> None:
        """Resume, replace or refuse the run found here (see the module doc); write config.json
        (``settings``); delete what interrupted atomic writes left. Call it holding the lock."""
        action, why = self._decide(settings)
        if action == "replace":
            log.warning("[lit-boot] %s: replacing a run that finished no stage (%s)", self.path, why)
        if action != "resume":
            self._clear()
        self.path.mkdir(parents=True, exist_ok=True)
        remove_partials(self.path)
        settings = json.loads(json.dumps(settings, default=str))
        atomic_write_bytes(self.path / CONFIG_JSON, (json.dumps(settings, indent=2) + "\n").encode())

    def _decide(self, settings: dict[str, Any]) -> tuple[str, str]:
        """("resume", "") for no run or the same settings, ("clear", "") with overwrite,
        ("replace", what differs) for other settings and no finished stage; other settings and
        a finished stage raise ValueError."""
        if self.overwrite:
            return "clear", ""
        settings = json.loads(json.dumps(settings, default=str))
        old, problem = self._read_config()
        if old == settings or (old is None and problem is None):
            return "resume", ""
        differ = problem or f"{', '.join(_differences(old, settings))} differ"
        if self.finished_stages():
            raise ValueError(
                f"{self.path}: holds a run with other settings ({differ}); "
                "pass overwrite=True (--overwrite true) or choose another output folder"
            )
        return "replace", differ

    def _read_config(self) -> tuple[dict[str, Any] | None, str | None]:
        """The settings found here (None if none) and, if config.json is unreadable, why."""
        path = self.path / CONFIG_JSON
        if not path.is_file():
            return None, None
        try:
            old = json.loads(path.read_text())
        except (ValueError, UnicodeDecodeError) as err:
            return None, f"{path} is unreadable: {type(err).__name__}"
        if not isinstance(old, dict) or not isinstance(old.get("config"), dict):
            return None, f"{path} holds no lit-boot settings"
        return old, None

    def _clear(self) -> None:
        """Delete everything in the folder but the lock file (the lock is held on it): moved
        into a temporary folder first, stages/ first and config.json last, so that a clearing
        cut short leaves a run that finished no stage (replaced by any rerun) and no half-
        deleted stage."""
        if not self.path.is_dir():
            return
        trash = self.path / f".cleared.{uuid.uuid4().hex[:12]}.partial"  # remove_partials clears it
        trash.mkdir()
        entries = [e for e in self.path.iterdir() if e.name not in (LOCK_FILE, trash.name)]
        for entry in sorted(entries, key=lambda e: (e.name != "stages", e.name == CONFIG_JSON)):
            os.rename(entry, trash / entry.name)
        shutil.rmtree(trash)

    # --- stages ------------------------------------------------------------------------------------
    def stage_dir(self, name: str) -> Path:
        return self.path / "stages" / name

    def finished_stages(self) -> list[str]:
        """Names of the stages with a stage.json."""
        return sorted(p.parent.name for p in (self.path / "stages").glob(f"*/{STAGE_JSON}"))

    def finished(self, names: list[str]) -> list[str]:
        """Those of ``names`` (in their order) with a stage.json."""
        return [name for name in names if (self.stage_dir(name) / STAGE_JSON).is_file()]

    def record(self, name: str) -> dict[str, Any] | None:
        """Stage ``name``'s record (stage.json), None if it has not finished."""
        path = self.stage_dir(name) / STAGE_JSON
        return json.loads(path.read_text()) if path.is_file() else None

    def write_record(self, name: str, record: dict[str, Any]) -> None:
        """Write stage ``name``'s stage.json (atomically; after the stage's other files)."""
        folder = self.stage_dir(name)
        folder.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(folder / STAGE_JSON, json.dumps(record, indent=2, default=str).encode())

    def clear_logs(self, version: str) -> None:
        """Delete logs/{tensorboard,csv}/<version> (an interrupted attempt's, before a rerun)."""
        for kind in ("tensorboard", "csv"):
            shutil.rmtree(self.path / "logs" / kind / version, ignore_errors=True)

    def save_stage(self, name: str, kind: str, *, flows: torch.Tensor | None, result: Any, decisions: dict | None,
                   weights: list[dict[str, torch.Tensor]]) -> None:  # fmt: skip
        """A finished stage's results in ``stages/<name>/``, each file atomic: a flow or zoom
        stage's ``flows.npz`` (T-1, 2, H, W) px, ``decisions.npz`` and each ensemble member's
        ``weights`` (``raft_<m>.pt``; none for the zoom stage), or a pose stage's ``result``
        (a :class:`~lit_boot.pose.PoseResult`, its own files). stage.json is written after, by
        :meth:`write_record`."""
        folder = self.stage_dir(name)
        folder.mkdir(parents=True, exist_ok=True)
        if kind not in ("flow", "zoom"):
            result.save(folder)
            return
        write_flows_npz(folder / "flows.npz", flows)
        save_decisions(folder / "decisions.npz", decisions["painted"], decisions["kept"])
        for m, state in enumerate(weights):
            buffer = io.BytesIO()
            torch.save(state, buffer)
            atomic_write_bytes(folder / f"raft_{m}.pt", buffer.getvalue())


def _differences(old: dict[str, Any], new: dict[str, Any]) -> list[str]:
    """What differs: the lit-boot version that made the run, the scene, the config keys."""
    a, b = old["config"], new["config"]
    made_by = [f"lit-boot version ({old.get('lit_boot', 'unknown')}, now {new['lit_boot']})"] \
        if old.get("lit_boot") != new.get("lit_boot") else []  # fmt: skip
    scene = ["scene"] if old.get("scene") != new.get("scene") else []
    keys = sorted(k for k in set(a) | set(b) if a.get(k) != b.get(k))
    return made_by + scene + keys or sorted(k for k in set(old) | set(new) if old.get(k) != new.get(k))
