"""Where a dataset run's tasks run: :class:`LocalEngine` (this machine) and :class:`RayEngine`.

An engine takes the tasks to run and calls ``on_start(name)`` and ``on_end(name, record)`` (in
the driver's process, one at a time) with each task's record: ``{"state": "done", "result": ...}``
or ``{"state": "failed", "error": ...}`` from :func:`lit_boot.dataset.worker.run_task`, or
``{"state": "lost", "error": ...}`` when the worker died without one (killed, out of memory):
the driver retries lost tasks.

- ``LocalEngine(workers=0)``: tasks one after the other in this process.
- ``LocalEngine(workers=N)``: N worker processes (spawned, one per task, so a crash or a kill
  loses only its task), over the visible GPUs (worker i uses GPU i mod the number of GPUs) or
  the CPU, the CPU's cores split fairly between the workers (``OMP_NUM_THREADS``).
- ``RayEngine``: one Ray task per scene (a GPU each when the cluster has GPUs), on an existing
  cluster (``address``) or a local Ray instance; Ray retries tasks whose worker was lost
  (``max_retries``). Needs the ``ray`` extra (``pip install "lit-boot[ray]"``); the dataset
  folder must be on storage every node sees. A task is started (``on_start``) when its worker
  has written its start marker (:func:`~lit_boot.dataset.worker.started_file`), not when Ray
  queues it.
"""

from __future__ import annotations

import logging
import multiprocessing as mp
import os
import time
from dataclasses import dataclass, field
from typing import Any, Callable

from .worker import read_record, run_task, started_file, task_files

__all__ = ["Job", "LocalEngine", "RayEngine", "visible_gpus", "make_engine", "ENGINES"]

log = logging.getLogger(__name__)

ENGINES = ("local", "ray")
Start = Callable[[str], None]
End = Callable[[str, dict[str, Any]], None]


@dataclass
class Job:
    """What a worker needs for one task: the task (a dict), the dataset folder, the config (a dict)."""

    task: dict[str, Any]
    out: str
    config: dict[str, Any] = field(default_factory=dict)

    @property
    def name(self) -> str:
        return self.task["name"]


def visible_gpus() -> list[str]:
    """The CUDA devices this process may use, as ``CUDA_VISIBLE_DEVICES`` entries ([] on a CPU)."""
    import torch

    if not torch.cuda.is_available():
        return []
    listed = os.environ.get("CUDA_VISIBLE_DEVICES")
    if listed:
        return [d.strip() for d in listed.split(",") if d.strip()][: torch.cuda.device_count()]
    return [str(i) for i in range(torch.cuda.device_count())]


def _exit_with_parent(poll_s: float = 1.0) -> None:
    """End this process (at once, as a kill would) when its parent is gone: a driver killed with
    SIGKILL leaves no worker running on, so its rerun finds the task's run folder free."""
    import threading

    parent = os.getppid()

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(poll_s)
        os._exit(1)

    threading.Thread(target=watch, name="lit-boot parent watch", daemon=True).start()


def _child(job: Job, threads: int, gpu: str | None) -> None:
    """A worker process: its output goes to the task's log file; the record to its record file;
    it ends when the driver does."""
    _exit_with_parent()
    _, _, log_file = task_files(job.out, job.name)
    log_file.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(log_file, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    run_task(job.task, job.out, job.config, threads=threads, gpu=gpu)


class LocalEngine:
    """Tasks on this machine: in this process (``workers=0``) or in ``workers`` processes (see the
    module doc). ``threads``: CPU threads per worker (default: the cores split fairly)."""

    def __init__(self, workers: int = 1, threads: int | None = None, gpus: list[str] | None = None, poll_s: float = 0.2):
        if workers < 0:
            raise ValueError(f"workers must be >= 0, got {workers}")
        self.workers = workers
        self.gpus = visible_gpus() if gpus is None else list(gpus)
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
        self.threads = threads or max(1, cores // max(1, workers))
        self.poll_s = poll_s

    def describe(self) -> str:
        where = f"{len(self.gpus)} GPU(s)" if self.gpus else "CPU"
        if self.workers == 0:
            return f"local, in this process, {where}"
        return f"local, {self.workers} worker process(es), {where}, {self.threads} CPU thread(s) each"

    def run(self, jobs: list[Job], on_start: Start, on_end: End) -> None:
        if self.workers == 0:
            for job in jobs:
                on_start(job.name)
                on_end(job.name, run_task(job.task, job.out, job.config, gpu=None))
            return
        self._run_processes(jobs, on_start, on_end)

    def _run_processes(self, jobs: list[Job], on_start: Start, on_end: End) -> None:
        context = mp.get_context("spawn")  # a fresh interpreter: no CUDA or thread state inherited
        queue, running = list(jobs), {}  # slot -> (job, process)
        while queue or running:
            for slot in range(self.workers):
                if slot in running or not queue:
                    continue
                job = queue.pop(0)
                gpu = self.gpus[slot % len(self.gpus)] if self.gpus else None
                _, record_file, _ = task_files(job.out, job.name)
                record_file.unlink(missing_ok=True)  # a result from an earlier attempt is not this one's
                process = context.Process(target=_child, args=(job, self.threads, gpu), name=f"lit-boot {job.name}")
                process.start()
                running[slot] = (job, process)
                on_start(job.name)
            time.sleep(self.poll_s)
            for slot, (job, process) in list(running.items()):
                if process.is_alive():
                    continue
                process.join()
                del running[slot]
                record = read_record(task_files(job.out, job.name)[1])
                if record is None:
                    record = {"state": "lost", "error": f"worker process ended with exit code {process.exitcode} "
                              "and no result (killed, out of memory or crashed)"}  # fmt: skip
                on_end(job.name, record)


def _ray_task(job: Job, threads: int) -> dict[str, Any]:
    """The body of a Ray task (in a Ray worker process)."""
    return run_task(job.task, job.out, job.config, threads=threads)


class RayEngine:
    """One Ray task per scene (see the module doc). ``address``: a cluster to join (None: a
    local Ray instance); ``gpus_per_task``: None = 1 when the cluster has GPUs, else 0;
    ``cpus_per_task``: CPU threads of each task; ``retries``: Ray's retries of a lost worker;
    ``poll_s``: how often the driver looks for tasks that have started."""

    def __init__(self, address: str | None = None, gpus_per_task: float | None = None, cpus_per_task: int = 1,
                 retries: int = 2, workers: int | None = None, poll_s: float = 0.5):  # fmt: skip
        try:
            import ray  # noqa: F401
        except ImportError:
            raise ImportError('the ray engine needs Ray: pip install "lit-boot[ray]"') from None
        self.address, self.gpus_per_task, self.cpus_per_task = address, gpus_per_task, cpus_per_task
        self.retries, self.workers, self.poll_s = retries, workers, poll_s

    def describe(self) -> str:
        return f"ray ({self.address or 'a local instance'}), {self.cpus_per_task} CPU(s) per task"

    def _init(self) -> None:
        import ray

        if ray.is_initialized():
            return
        options: dict[str, Any] = {"address": self.address, "include_dashboard": False, "log_to_driver": False,
                                   "logging_level": logging.ERROR, "configure_logging": True}  # fmt: skip
        if self.address is None and self.workers:
            options["num_cpus"] = self.workers * self.cpus_per_task
        ray.init(**options)

    def run(self, jobs: list[Job], on_start: Start, on_end: End) -> None:
        import ray

        self._init()
        gpus = self.gpus_per_task
        if gpus is None:
            gpus = 1 if ray.cluster_resources().get("GPU", 0) >= 1 else 0
        remote = ray.remote(_ray_task).options(num_cpus=self.cpus_per_task, num_gpus=gpus, max_retries=self.retries,
                                               retry_exceptions=False)  # fmt: skip
        pending, started = {}, set()
        for job in jobs:
            started_file(job.out, job.name).unlink(missing_ok=True)  # an earlier attempt's
            pending[remote.remote(job, self.cpus_per_task)] = job
        tasks_dir = started_file(jobs[0].out, "").parent if jobs else None  # every job's: one dataset folder
        while pending:  # a task is "running" once its worker has started it, not while Ray queues it
            done, _ = ray.wait(list(pending), num_returns=1, timeout=self.poll_s)
            markers = {p.stem for p in tasks_dir.glob("*.started")}  # one listing per poll, not a stat per task
            for ref, job in pending.items():
                if job.name not in started and (ref in done or job.name in markers):
                    started.add(job.name)
                    on_start(job.name)
            for ref in done:
                job = pending.pop(ref)
                try:
                    record = ray.get(ref)
                except ray.exceptions.RayError as err:  # the worker was lost more than `retries` times
                    why = f"{type(err).__name__}: {str(err).splitlines()[0]}"
                    record = {"state": "lost", "error": f"Ray task lost: {why}"}
                on_end(job.name, record)


def make_engine(engine: str, workers: int = 1, ray_address: str | None = None, retries: int = 2,
                threads: int | None = None) -> LocalEngine | RayEngine:  # fmt: skip
    """The engine named ``engine`` ("local" or "ray")."""
    if engine == "local":
        return LocalEngine(workers=workers, threads=threads)
    if engine == "ray":
        return RayEngine(address=ray_address, retries=retries, cpus_per_task=threads or 1,
                         workers=workers or None)  # fmt: skip
    raise ValueError(f"engine {engine!r}: one of {', '.join(ENGINES)}")
