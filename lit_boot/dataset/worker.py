"""Run one task of a dataset run, in whatever process an engine gives it.

:func:`run_task` reads the task's scene, bootstraps it into ``<out>/scenes/<name>`` (a normal
run folder: an interrupted task resumes from its finished stages) and returns its record:
``{"state": "done", "result": {...}}`` or ``{"state": "failed", "error": "..."}``. The record is
also written to ``<out>/tasks/<name>.json`` (atomically), and the task's log lines (lit-boot's,
Lightning's, warnings) go to ``<out>/tasks/<name>.log``, not to the console.

A result: frames, size [H, W], seconds (the run's stages, summed), the run folder, the metric
states of the initial and the final flows and poses against the scene's ground truth
(:func:`lit_boot.metrics.scene_metric_states`; {} without GT), the before/after values, and
where it ran ("worker": pid, visible GPUs, torch threads).

This module imports nothing heavy at import time: a fresh worker process sets its thread count
and visible GPU (:func:`worker_environment`) before torch is loaded.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import time
import traceback
import warnings
from pathlib import Path
from typing import Any, Iterator

__all__ = ["run_task", "worker_environment", "task_files", "started_file", "read_record", "write_record"]


def task_files(out: str | os.PathLike, name: str) -> tuple[Path, Path, Path]:
    """(run folder, record file, log file) of task ``name`` in the dataset folder ``out``."""
    out = Path(out)
    return out / "scenes" / name, out / "tasks" / f"{name}.json", out / "tasks" / f"{name}.log"


def started_file(out: str | os.PathLike, name: str) -> Path:
    """The marker task ``name``'s worker writes when it starts ({"pid": ...}): how an engine
    whose workers start on their own schedule (Ray) tells a running task from a queued one."""
    return Path(out) / "tasks" / f"{name}.started"


def write_record(path: Path, record: dict[str, Any]) -> None:
    from ..data.atomic import atomic_write_bytes

    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(path, (json.dumps(record, indent=1, default=str) + "\n").encode())


def read_record(path: Path) -> dict[str, Any] | None:
    """The record a worker wrote (done, failed, or lost with ``retry``: it ran out of memory);
    None if none, or unreadable (a write cut short)."""
    try:
        record = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return record if isinstance(record, dict) and record.get("state") in ("done", "failed", "lost") else None


def worker_environment(threads: int | None, gpu: str | None) -> None:
    """Set this process's CPU threads and visible GPU: before torch is imported in a fresh
    process (environment variables), or through torch when it already is."""
    if gpu is not None:
        os.environ["CUDA_VISIBLE_DEVICES"] = gpu
    if threads:
        os.environ["OMP_NUM_THREADS"] = os.environ["MKL_NUM_THREADS"] = str(threads)
        import torch

        torch.set_num_threads(threads)


@contextlib.contextmanager
def _task_log(path: Path) -> Iterator[None]:
    """lit-boot's and Lightning's log records, and warnings, into ``path`` while running."""
    path.parent.mkdir(parents=True, exist_ok=True)
    handler = logging.FileHandler(path, mode="a", encoding="utf-8")
    handler.setFormatter(logging.Formatter("%(asctime)s %(name)s %(levelname)s: %(message)s"))
    loggers = [logging.getLogger(n) for n in ("lit_boot", "lightning", "lightning.pytorch", "lightning.fabric")]
    saved = [(lg.handlers[:], lg.propagate, lg.level) for lg in loggers]
    for lg in loggers:
        lg.handlers, lg.propagate = [handler], False
        lg.setLevel(logging.INFO)
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        logging.captureWarnings(True)
        logging.getLogger("py.warnings").addHandler(handler)
        try:
            yield
        finally:
            logging.getLogger("py.warnings").removeHandler(handler)
            logging.captureWarnings(False)
            for lg, (handlers, propagate, level) in zip(loggers, saved):
                lg.handlers, lg.propagate = handlers, propagate
                lg.setLevel(level)
            handler.close()


def run_task(task: dict[str, Any], out: str, config: dict[str, Any], threads: int | None = None,
             gpu: str | None = None) -> dict[str, Any]:  # fmt: skip
    """Run one task (a :meth:`Task.to_dict`) with :class:`BootstrapConfig` ``config`` (a dict) into
    the dataset folder ``out``; returns (and writes) its record. An error fails this task only:
    it is recorded with its message, and the traceback goes to the task's log. Running out of
    memory (CUDA's or the host's) is recorded as ``{"state": "lost", "retry": True}``: the
    driver runs the task again, as it does a lost worker's."""
    worker_environment(threads, gpu)
    import torch  # after worker_environment: its threads and GPU are set

    from .tasks import Task

    spec = Task.from_dict(task)
    run_dir, record_file, log_file = task_files(out, spec.name)
    write_record(started_file(out, spec.name), {"pid": os.getpid()})
    with _task_log(log_file):
        log = logging.getLogger("lit_boot.dataset")
        log.info("task %s: start (pid %d)", spec.name, os.getpid())
        try:
            record = {"state": "done", "result": {**_bootstrap(spec, run_dir, config), "worker": _worker_info()}}
        except (MemoryError, torch.OutOfMemoryError) as err:  # the device (or RAM) was full now, maybe not later
            log.error("task %s ran out of memory:\n%s", spec.name, traceback.format_exc())
            record = {"state": "lost", "retry": True, "error": f"out of memory: {type(err).__name__}: {err}"}
        except Exception as err:  # a bad input fails its own task; the others go on
            log.error("task %s failed:\n%s", spec.name, traceback.format_exc())
            record = {"state": "failed", "error": f"{type(err).__name__}: {err}"}
        log.info("task %s: %s", spec.name, record["state"])
    write_record(record_file, record)
    return record


def _worker_info() -> dict[str, Any]:
    """Where the task ran: the process, its visible GPUs (CUDA_VISIBLE_DEVICES), its torch threads."""
    import torch

    return {"pid": os.getpid(), "gpus": os.environ.get("CUDA_VISIBLE_DEVICES"), "threads": torch.get_num_threads()}


def _bootstrap(task: Any, run_dir: Path, config: dict[str, Any]) -> dict[str, Any]:
    from ..bootstrap import Bootstrap, BootstrapConfig

    scene = task.load()
    settings = {**config, "progress_bar": False}
    start = time.perf_counter()
    result = Bootstrap(scene, run_dir, BootstrapConfig(**settings)).run()
    mode = result.poses.mode if result.poses is not None else settings.get("mode", "3d")
    return result_record(task, result.initial_scene, result.initial_flows, result.scene, result.flows, mode,
                         run_dir, seconds=sum(result.seconds.values()), wall=time.perf_counter() - start,
                         before_after=result.before_after())  # fmt: skip


def result_record(task: Any, initial_scene: Any, initial_flows: Any, scene: Any, flows: Any, mode: str,
                  run_dir: Path, seconds: float, wall: float, before_after: dict | None = None) -> dict[str, Any]:  # fmt: skip
    """A done task's result (see the module doc): the metric states of the initial and final
    flows and poses against ``scene``'s ground truth."""
    from ..metrics import compute_metric_states, scene_metric_states

    states = {"initial": scene_metric_states(initial_scene, initial_flows, mode),
              "final": scene_metric_states(scene, flows, mode)}  # fmt: skip
    if before_after is None:
        before, after = (compute_metric_states(states[k]) for k in ("initial", "final"))
        before_after = {k: (before[k], after[k]) for k in before if k in after}
    return {"scene": task.scene_name, "frames": scene.num_frames, "size": [scene.height, scene.width],
            "seconds": seconds, "wall_s": wall, "run_dir": str(run_dir), "states": states,
            "before_after": {k: list(v) for k, v in before_after.items()}}  # fmt: skip
