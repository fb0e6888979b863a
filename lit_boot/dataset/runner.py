"""A whole dataset, one command: :func:`run_dataset` runs the method on every task (scene or
chunk of one) through an engine, records each in the manifest, stitches chunked scenes, and
writes the dataset's summary.

The dataset folder::

    manifest.json         every task's state, settings and result (:mod:`.manifest`)
    scenes/<name>/        each task's bootstrap run folder (resumes when rerun); a chunked
                          scene's folder holds its stitched poses.npz and flows.npz
    tasks/<name>.json     each task's record, as its worker wrote it; tasks/<name>.log its log
    summary.md, summary.csv   one row per scene and the dataset row (:mod:`.summary`)
    report.html           the same rows, linking each scene's report.html (:mod:`.html_report`)
    dataset.json          the dataset metrics (merged from the scenes' metric states), counts
    .lock                 one dataset run at a time per folder

Reruns: a task that is done is never run again; pending, lost and failed ones are; a rerun with
other settings is refused (:class:`~lit_boot.dataset.manifest.SettingsChangedError`). A task
whose worker died without a result (killed, out of memory) is retried up to ``retries`` times
(by the driver for the local engine, by Ray for the ray engine), and so is one that ran out of
memory (a CUDA out-of-memory error: by the driver for both engines).
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .._version import __version__
from ..bootstrap import BootstrapConfig
from ..bootstrap.lock import LOCK_FILE, RunLock
from ..data.atomic import atomic_write_bytes
from .chunks import plan_chunks
from .engines import Job, LocalEngine, RayEngine, make_engine
from .manifest import MANIFEST_JSON, Manifest
from .stitch import stitch_parent
from .summary import dataset_metrics, summary_records, write_summary
from .tasks import Task
from .worker import task_files

__all__ = ["run_dataset", "DatasetResult"]

log = logging.getLogger(__name__)


@dataclass
class DatasetResult:
    """A dataset run's outcome: the folder, each scene's record (chunks folded into their scene),
    the merged dataset metrics ({"initial": {...}, "final": {...}}), the counts per state, and
    the summary files."""

    out: Path
    records: list[dict[str, Any]]
    metrics: dict[str, dict[str, float]]
    counts: dict[str, int]
    summary_md: Path
    summary_csv: Path

    def table(self) -> str:
        """The summary table (markdown)."""
        return self.summary_md.read_text()


def _settings(config: BootstrapConfig, chunk_frames: int | None, chunk_overlap: int) -> dict[str, Any]:
    cfg = {k: v for k, v in config.to_dict().items() if k != "progress_bar"}
    return {"lit_boot": __version__, "config": cfg, "chunk_frames": chunk_frames, "chunk_overlap": chunk_overlap}


def _check_folder(out: Path) -> list[Path]:
    """Refuse a path that is not a folder, or a non-empty folder holding no dataset run; return
    what the folder holds (the lock file aside)."""
    if out.exists() and not out.is_dir():
        raise FileExistsError(f"{out}: exists and is not a folder (choose another output folder)")
    if not out.is_dir():
        return []
    entries = [e for e in out.iterdir() if e.name != LOCK_FILE]
    if entries and not (out / MANIFEST_JSON).is_file():
        raise FileExistsError(f"{out}: exists, is not empty and holds no lit-boot dataset run (choose another folder)")
    return entries


def _clear(entries: list[Path]) -> None:
    """Delete a dataset run's files (``overwrite``; called holding the folder's lock)."""
    for entry in entries:
        shutil.rmtree(entry) if entry.is_dir() else entry.unlink()


def _plan(manifest: Manifest, tasks: list[Task], chunk_frames: int | None, chunk_overlap: int) -> None:
    """Add the tasks (and, for long scenes, their chunks) the manifest does not know yet."""
    names = [t.name for t in tasks]
    if len(set(names)) != len(names):
        twice = sorted({n for n in names if names.count(n) > 1})
        raise ValueError(f"task names must be unique; given more than once: {', '.join(twice)}")
    for task in tasks:
        known = manifest.tasks.get(task.name)
        if known is not None and not known.get("plan_failed"):
            continue
        chunks = [task]
        if chunk_frames is not None:
            try:
                chunks = plan_chunks(task, task.num_frames(), chunk_frames, chunk_overlap)
            except Exception as err:  # an unreadable source fails its own task
                manifest.add([task])
                manifest.mark(task.name, "failed", error=f"{type(err).__name__}: {err}", plan_failed=True)
                continue
        if known is not None:  # planned again: its source can be read now
            del manifest.tasks[task.name]
        manifest.add(chunks)
        if chunks != [task]:
            manifest.add([task])
            manifest.tasks[task.name]["chunks"] = [c.name for c in chunks]
    manifest.save()


def run_dataset(
    tasks: list[Task],
    out: str | os.PathLike,
    config: BootstrapConfig | dict[str, Any] | None = None,
    *,
    engine: str | LocalEngine | RayEngine = "local",
    workers: int = 1,
    threads: int | None = None,
    retries: int = 2,
    ray_address: str | None = None,
    chunk_frames: int | None = None,
    chunk_overlap: int = 8,
    overwrite: bool = False,
    progress: bool = False,
) -> DatasetResult:
    """Run (or resume) the method on every task into the dataset folder ``out``; see the module
    doc. ``config``: the bootstrap settings of every scene; ``engine``: "local" (``workers``
    processes, 0 = this process) or "ray" (``ray_address``: a cluster, None: a local instance),
    or an engine object; ``chunk_frames``: split longer scenes into chunks of this many frames,
    ``chunk_overlap`` shared with the next; ``progress``: an overall progress bar (stderr)."""
    if not isinstance(config, BootstrapConfig):
        config = BootstrapConfig(**(config or {}))
    if not tasks:
        raise ValueError("no tasks: the dataset source gave no scene")
    out = Path(out)
    runner = engine if not isinstance(engine, str) else make_engine(engine, workers, ray_address, retries, threads)
    _check_folder(out)
    with RunLock(out):
        if overwrite:
            _clear(_check_folder(out))
        manifest = Manifest.open(out, _settings(config, chunk_frames, chunk_overlap), overwrite=overwrite)
        _plan(manifest, tasks, chunk_frames, chunk_overlap)
        _run_tasks(manifest, runner, out, config.to_dict(), retries, progress)
        _stitch(manifest, out, config.mode)
        return _finish(manifest, out)


def _run_tasks(manifest: Manifest, engine: Any, out: Path, config: dict, retries: int, progress: bool) -> None:
    """Run every task not done, retrying those whose worker was lost (local engine)."""
    leaves = [n for n in manifest.names() if "chunks" not in manifest.tasks[n]]
    todo = [n for n in manifest.todo() if n in leaves]
    for name in todo:
        manifest.tasks[name]["attempts"] = 0  # a new run gives lost tasks their retries again
    from tqdm.auto import tqdm
    from tqdm.contrib.logging import logging_redirect_tqdm

    log.info("%d task(s), %d to run: %s", len(leaves), len(todo), engine.describe())
    bar = tqdm(total=len(leaves), initial=len(leaves) - len(todo), desc="lit-boot dataset", unit="task",
               disable=not progress, dynamic_ncols=True)  # fmt: skip

    def on_start(name: str) -> None:
        manifest.mark(name, "running")

    def on_end(name: str, record: dict[str, Any]) -> None:
        state = record["state"]
        if state == "lost":
            attempts = manifest.tasks[name]["attempts"] + 1
            # Ray retries its lost workers itself; an out-of-memory record is the driver's to retry
            again = (isinstance(engine, LocalEngine) or bool(record.get("retry"))) and attempts <= retries
            manifest.mark(name, "pending" if again else "failed", attempts=attempts, error=record["error"])
            log.warning("task %s: %s%s", name, record["error"], "; retried" if again else "; not retried")
            if again:
                lost.append(name)
                return
        else:
            manifest.mark(name, state, **{k: v for k, v in record.items() if k != "state"})
            if state == "failed":
                log.warning("task %s failed: %s (log: %s)", name, record["error"], task_files(out, name)[2])
        bar.update(1)
        bar.set_postfix(manifest.counts(), refresh=True)

    jobs = [Job(manifest.tasks[n]["task"], str(out), config) for n in todo]
    with logging_redirect_tqdm([logging.getLogger("lit_boot")]), bar:  # log lines above the bar
        while jobs:
            lost: list[str] = []
            engine.run(jobs, on_start, on_end)
            jobs = [Job(manifest.tasks[n]["task"], str(out), config) for n in lost]


def _stitch(manifest: Manifest, out: Path, mode: str) -> None:
    """Stitch every chunked scene whose chunks are all done (and that is not done yet)."""
    for name in manifest.names():
        record = manifest.tasks[name]
        if "chunks" not in record or record["state"] == "done":
            continue
        states = [manifest.tasks[c]["state"] for c in record["chunks"]]
        if any(s == "failed" for s in states):
            manifest.mark(name, "failed", error="a chunk failed: " + ", ".join(
                c for c in record["chunks"] if manifest.tasks[c]["state"] == "failed"))  # fmt: skip
            continue
        if any(s != "done" for s in states):
            continue
        chunks = [(manifest.task(c), manifest.tasks[c]["result"]) for c in record["chunks"]]
        try:
            manifest.mark(name, "done", result=stitch_parent(manifest.task(name), chunks, out, mode))
        except Exception as err:
            manifest.mark(name, "failed", error=f"{type(err).__name__}: {err}")


def _finish(manifest: Manifest, out: Path) -> DatasetResult:
    """Write summary.md, summary.csv, dataset.json and report.html; the result."""
    records = summary_records(manifest.tasks)
    md, csv = write_summary(out, records)
    metrics = dataset_metrics(records)
    counts = {s: sum(r["state"] == s for r in records) for s in ("done", "failed", "pending", "running")}
    data = {"format": "lit-boot-dataset-metrics", "version": 1, "scenes": counts, "metrics": metrics,
            "written": time.strftime("%Y-%m-%d %H:%M:%S")}  # fmt: skip
    atomic_write_bytes(out / "dataset.json", (json.dumps(data, indent=2) + "\n").encode())
    from .html_report import write_dataset_report  # imports the scene report's drawing (Lightning, OpenCV)

    write_dataset_report(out, scene_reports=False)  # links the scenes' reports (each run writes its own)
    return DatasetResult(out, records, metrics, counts, md, csv)
