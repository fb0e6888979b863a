"""Bootstrap: the whole method on one scene, flow -> pose -> flow, resumable.

A run folder (the input scene folder is never written)::

    config.json            the run's settings (a rerun with other settings is refused)
    stages/<stage>/        initial, flow_1, pose_1, flow_2, ...: each stage's flows.npz,
                           fine-tuned RAFT weights (raft_<member>.pt) or refined poses, and
                           stage.json, written last: a stage with stage.json is done, and a
                           rerun of an interrupted run loads it instead of running it again
    flows/                 the final flows (flow_<t>.flo or flows.npz) and colour PNGs
    poses.npz, poses.json  the final refined poses (see lit_boot.pose.PoseResult)
    raft_finetuned.pt      the final fine-tuned RAFT weights (torchvision format)
    summary.json           settings, device, every metric per stage, timings, guard events
    metrics.png            the metrics per stage; overlay.mp4: frame | flows | skeletons
    logs/tensorboard/, logs/csv/   per stage (training curves) and "summary" (per stage)
"""

from __future__ import annotations

import io
import json
import os
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import lightning as L
import numpy as np
import torch
from lightning.pytorch.loggers import CSVLogger, TensorBoardLogger

from ..core import Scene
from ..data import load_scene
from ..data.atomic import atomic_write_bytes
from ..flow import FlowTTT, write_flows, write_flows_npz
from ..pose import PoseResult, load_pose_result
from .config import BootstrapConfig
from .ensemble import average_poses
from .evaluate import agreement, drift, flow_metrics, pose_metrics, pose_points
from .dashboard import log_stage_images, stage_header
from .outputs import write_outputs
from .stages import fine_tune_flow, make_flow_model, predict_flows, refine_poses_stage

__all__ = ["Bootstrap", "BootstrapResult", "bootstrap"]

STAGE_JSON = "stage.json"


@dataclass
class BootstrapResult:
    """What a run gives: the refined scene (its estimates replaced by the refined poses), the
    initial and final flows (T-1, 2, H, W) px, the final PoseResult (None without a pose
    stage), one metrics record per stage (see :mod:`lit_boot.bootstrap.evaluate`), the run
    folder, seconds per stage, and the scene as the run started (initial estimates)."""

    run_dir: Path
    scene: Scene
    initial_scene: Scene
    initial_flows: torch.Tensor
    flows: torch.Tensor
    poses: PoseResult | None
    history: list[dict[str, Any]] = field(default_factory=list)
    seconds: dict[str, float] = field(default_factory=dict)

    def before_after(self) -> dict[str, tuple[float, float]]:
        """Each metric's value at the start and at its last stage."""
        first: dict[str, float] = {}
        last: dict[str, float] = {}
        for record in self.history:
            if record.get("rolled_back"):
                continue
            for k, v in record.items():
                if isinstance(v, float) and k != "cycle":
                    first.setdefault(k, v)
                    last[k] = v
        return {k: (first[k], last[k]) for k in first}

    def table(self) -> str:
        """A before/after table (markdown) of every metric."""
        rows = ["| metric | before | after | change |", "| --- | --- | --- | --- |"]
        for k, (a, b) in self.before_after().items():
            change = f"{100 * (b - a) / a:+.1f}%" if a and np.isfinite(a) and np.isfinite(b) else ""
            rows.append(f"| {k} | {a:.3f} | {b:.3f} | {change} |")
        return "\n".join(rows)


def _save_tensor(path: Path, state: dict[str, torch.Tensor]) -> None:
    buffer = io.BytesIO()
    torch.save(state, buffer)
    atomic_write_bytes(path, buffer.getvalue())


def _load_flows(path: Path) -> torch.Tensor:
    with np.load(path) as data:
        return torch.from_numpy(np.array(data["flow"]))


class Bootstrap:
    """Run the method on one scene (a folder, or a Scene) into ``out`` (default
    ``runs/<scene name>/bootstrap``).

    Settings: a :class:`BootstrapConfig`, or its fields as keyword arguments. ``overwrite``
    deletes an existing run folder first; otherwise an interrupted run with the same settings
    resumes after its last finished stage, and one with other settings is refused.
    """

    def __init__(
        self,
        scene: str | os.PathLike | Scene,
        out: str | os.PathLike | None = None,
        config: BootstrapConfig | None = None,
        overwrite: bool = False,
        **options: Any,
    ):
        if config is not None and options:
            raise ValueError(f"give either config or options, not both (got options {sorted(options)})")
        self.config = config or BootstrapConfig(**options)
        self.scene_arg = scene
        self.scene = scene if isinstance(scene, Scene) else None
        name = scene.name if isinstance(scene, Scene) else Path(scene).name
        self.out = Path(out) if out is not None else Path("runs") / name / "bootstrap"
        self.overwrite = overwrite
        self.models: list[FlowTTT | None] = []
        self.pending_weights: list[Path | None] = []

    # --- the run folder ----------------------------------------------------------------------------
    def _settings(self) -> dict[str, Any]:
        scene = str(self.scene_arg) if not isinstance(self.scene_arg, Scene) else f"<Scene {self.scene_arg.name}>"
        return {"scene": scene, "config": self.config.to_dict()}

    def _prepare_folder(self) -> None:
        settings = json.loads(json.dumps(self._settings(), default=str))
        path = self.out / "config.json"
        if self.out.exists() and self.overwrite:
            shutil.rmtree(self.out)
        if path.is_file():
            old = json.loads(path.read_text())
            if old != settings:
                diff = sorted(k for k in set(old["config"]) | set(settings["config"])
                              if old["config"].get(k) != settings["config"].get(k))  # fmt: skip
                where = diff or ["scene"]
                raise ValueError(
                    f"{self.out}: holds a run with other settings ({', '.join(where)} differ); "
                    "pass overwrite=True (--overwrite true) or choose another output folder"
                )
        elif self.out.exists() and any(self.out.iterdir()):
            raise FileExistsError(f"{self.out}: exists, is not empty and holds no lit-boot run (choose another folder)")
        self.out.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(path, (json.dumps(settings, indent=2) + "\n").encode())

    def _stage_dir(self, name: str) -> Path:
        return self.out / "stages" / name

    def _loggers(self, version: str) -> list:
        root = self.out / "logs"
        return [TensorBoardLogger(root, name="tensorboard", version=version), CSVLogger(root, name="csv", version=version)]

    # --- devices ---------------------------------------------------------------------------------
    def _accelerator(self) -> str:
        acc = self.config.accelerator
        return ("cuda" if torch.cuda.is_available() else "cpu") if acc == "auto" else acc

    def _precision(self) -> str:
        if self.config.precision is not None:
            return self.config.precision
        return self.config.option("cuda_precision") if self._accelerator() == "cuda" else "32-true"

    # --- flow networks ----------------------------------------------------------------------------
    def _model(self, member: int, person_px: float, fresh: bool = False) -> FlowTTT:
        """Ensemble member ``member``: pretrained when new or ``fresh``, else as last tuned."""
        if fresh or self.models[member] is None:
            model = make_flow_model(self.config.flow_kwargs(member, person_px))
            pending = self.pending_weights[member]
            if pending is not None and not fresh:
                model.raft.load_state_dict(torch.load(pending, map_location="cpu", weights_only=True))
            self.models[member] = model
            self.pending_weights[member] = None
        return self.models[member]

    # --- the stages --------------------------------------------------------------------------------
    def _flow_stage(
        self, name: str, scene: Scene, initial: torch.Tensor, person_px: float, accelerator: str, precision: str
    ) -> tuple[dict[str, Any], torch.Tensor]:
        """Fine-tune every ensemble member on the stick-man of ``scene``'s poses; the record
        and the members' mean flow (T-1, 2, H, W) px."""
        cfg, n = self.config, len(self.models)
        flows, reports = [], []
        for m in range(n):
            model = self._model(m, person_px, fresh=cfg.restart_flow)
            loggers = self._loggers(name + (f"_m{m}" if n > 1 else ""))
            reports.append(fine_tune_flow(model, scene, cfg.mode, cfg.epochs, accelerator, precision, loggers, cfg.progress_bar))
            flows.append(predict_flows(model, scene, accelerator, precision))
        mean = torch.stack(flows).mean(0)
        person = self.models[0].person_region(self.models[0].sketch_masks)
        record = {**flow_metrics(scene, mean), "drift_px": drift(mean, initial, person),
                  "agreement_px": agreement(mean, *pose_points(scene, cfg.mode)),
                  "info": {"target": reports[0], "sketch": self.models[0].hparams["sketch"]}}  # fmt: skip
        return record, mean

    def _pose_stage(self, name: str, scene: Scene, flows: torch.Tensor) -> tuple[dict[str, Any], PoseResult]:
        """Refine ``scene``'s poses against ``flows``; the record and the result."""
        cfg = self.config
        result = refine_poses_stage(scene, flows, cfg.mode, cfg.pose_kwargs(), cfg.pose_steps, cfg.early_stop,
                                    cfg.pose_accelerator, self._loggers(name), cfg.progress_bar)  # fmt: skip
        refined = result.apply_to(scene)
        record = {**pose_metrics(refined, cfg.mode), "agreement_px": agreement(flows, *pose_points(refined, cfg.mode)),
                  "info": {"steps": result.steps, "stopped_early": result.stopped_early, "loss": result.loss}}  # fmt: skip
        return record, result

    # --- the run -----------------------------------------------------------------------------------
    def run(self) -> BootstrapResult:
        """Run (or resume) every stage; write the run's outputs; return the result."""
        cfg = self.config
        scene = self.scene if self.scene is not None else load_scene(self.scene_arg)
        if scene.num_frames < 2:
            raise ValueError(f"scene {scene.name!r}: needs at least 2 frames, has {scene.num_frames}")
        if cfg.mode == "3d" and (scene.joints3d is None or scene.cameras is None):
            raise ValueError(f"scene {scene.name!r}: 3D mode needs 3D joints with cameras (use mode '2d')")
        if cfg.mode == "2d" and scene.keypoints2d is None:
            raise ValueError(f"scene {scene.name!r}: 2D mode needs 2D keypoints")
        self._prepare_folder()
        scene = average_poses(scene, cfg.pose_ensemble, cfg.mode)
        initial_scene = scene
        L.seed_everything(cfg.seed, verbose=False)
        points, keep = pose_points(scene, cfg.mode)
        person_px = _person_height(points, keep)
        n_members = 1 + len(cfg.flow_ensemble)
        self.models, self.pending_weights = [None] * n_members, [None] * n_members
        accelerator, precision = self._accelerator(), self._precision()
        for kind in ("tensorboard", "csv"):  # rebuilt whole on every (resumed) run: no duplicates
            shutil.rmtree(self.out / "logs" / kind / "summary", ignore_errors=True)
        summary_loggers = self._loggers("summary")
        stages = cfg.stages()
        history: list[dict[str, Any]] = []
        seconds: dict[str, float] = {}

        # initial: pretrained RAFT's flow and the initial poses
        initial_dir = self._stage_dir("initial")
        if (initial_dir / STAGE_JSON).is_file():
            initial = _load_flows(initial_dir / "flows.npz")
            record = json.loads((initial_dir / STAGE_JSON).read_text())
        else:
            print(stage_header(0, len(stages), "initial", f"RAFT inference x{n_members} on {accelerator}"), flush=True)
            start = time.perf_counter()
            initial = torch.stack([
                predict_flows(self._model(m, person_px), scene, accelerator, precision) for m in range(n_members)
            ]).mean(0)  # fmt: skip
            record = {"stage": "initial", "kind": "initial", "cycle": 0, **flow_metrics(scene, initial),
                      **pose_metrics(scene, cfg.mode), "agreement_px": agreement(initial, points, keep),
                      "info": {"seconds": time.perf_counter() - start, "person_px": person_px}}  # fmt: skip
            initial_dir.mkdir(parents=True, exist_ok=True)
            write_flows_npz(initial_dir / "flows.npz", initial)
            atomic_write_bytes(initial_dir / STAGE_JSON, json.dumps(record, indent=2).encode())
        history.append(record)
        seconds["initial"] = record["info"]["seconds"]
        log_stage_images(summary_loggers, 0, "initial", scene, initial, cfg.mode)

        flows, result = initial, None
        for index, name in enumerate(stages, start=1):
            kind, cycle = name.split("_")[0], int(name.split("_")[1])
            folder = self._stage_dir(name)
            if (folder / STAGE_JSON).is_file():  # done before: load it
                record = json.loads((folder / STAGE_JSON).read_text())
                if record.get("rolled_back"):
                    history.append(record)
                    break
                if kind == "flow":
                    flows = _load_flows(folder / "flows.npz")
                    self.pending_weights = [folder / f"raft_{m}.pt" for m in range(n_members)]
                    self.models = [None] * n_members
                else:
                    result = load_pose_result(folder)
                    scene = result.apply_to(scene)
                history.append(record)
                seconds[name] = record["info"]["seconds"]
                log_stage_images(summary_loggers, index, name, scene, flows, cfg.mode)
                if "guard" in record:  # the drift guard stopped the run here
                    break
                continue
            L.seed_everything(cfg.seed + index, verbose=False)
            start = time.perf_counter()
            before_agreement = history[-1]["agreement_px"]
            if kind == "flow":
                what = f"FlowTTT x{n_members}, {cfg.epochs} epochs, {precision} on {accelerator}"
                print(stage_header(index, len(stages), name, what), flush=True)
                record, new_flows = self._flow_stage(name, scene, initial, person_px, accelerator, precision)
                new_scene, new_result = scene, result
            else:
                what = f"{'PoseRefiner' if cfg.mode == '3d' else 'KeypointRefiner'}, {cfg.pose_steps} steps on {cfg.pose_accelerator}"
                print(stage_header(index, len(stages), name, what), flush=True)
                record, new_result = self._pose_stage(name, scene, flows)
                new_scene, new_flows = new_result.apply_to(scene), flows
            record = {"stage": name, "kind": kind, "cycle": cycle, **record}
            record["info"]["seconds"] = time.perf_counter() - start
            worse = record["agreement_px"] - before_agreement
            stop = cfg.drift_guard != "record" and worse > cfg.drift_tolerance
            if stop:
                record["guard"] = {"agreement_before": before_agreement, "agreement_after": record["agreement_px"],
                                   "action": cfg.drift_guard}  # fmt: skip
            folder.mkdir(parents=True, exist_ok=True)
            if stop and cfg.drift_guard == "rollback":
                record["rolled_back"] = True
                atomic_write_bytes(folder / STAGE_JSON, json.dumps(record, indent=2, default=str).encode())
                history.append(record)
                print(f"  drift guard: flow-pose agreement {before_agreement:.3f} -> {record['agreement_px']:.3f} px; "
                      f"{name} rolled back, run stopped", flush=True)  # fmt: skip
                break
            if kind == "flow":
                write_flows_npz(folder / "flows.npz", new_flows)
                for m, model in enumerate(self.models):
                    _save_tensor(folder / f"raft_{m}.pt", model.raft.state_dict())
            else:
                new_result.save(folder)
            atomic_write_bytes(folder / STAGE_JSON, json.dumps(record, indent=2, default=str).encode())
            flows, scene, result = new_flows, new_scene, new_result
            history.append(record)
            seconds[name] = record["info"]["seconds"]
            log_stage_images(summary_loggers, index, name, scene, flows, cfg.mode)
            if stop:
                print(f"  drift guard: flow-pose agreement worsened by {worse:.3f} px; run stopped", flush=True)
                break

        for i, record in enumerate(history):
            metrics = {f"bootstrap/{k}": v for k, v in record.items() if isinstance(v, float) and k != "cycle"}
            for logger in summary_loggers:
                logger.log_metrics(metrics, step=i)
        for logger in summary_loggers:
            logger.save()
        guard_events = [{"stage": r["stage"], **r["guard"]} for r in history if "guard" in r]
        out = BootstrapResult(self.out, scene, initial_scene, initial, flows, result, history, seconds)
        write_outputs(out, self._settings(), guard_events, accelerator, precision, self.config)
        return out


def _person_height(points: torch.Tensor, keep: torch.Tensor) -> float:
    """Median over frames of the vertical extent (px) of the kept pose points (0 if none)."""
    heights = []
    for p, k in zip(points, keep):
        if k.sum() >= 2:
            y = p[k, 1]
            heights.append(float(y.max() - y.min()))
    return float(np.median(heights)) if heights else 0.0


def bootstrap(scene: str | os.PathLike | Scene, out: str | os.PathLike | None = None, **options: Any) -> BootstrapResult:
    """Run the method on ``scene`` with :class:`BootstrapConfig` options; see :class:`Bootstrap`."""
    overwrite = options.pop("overwrite", False)
    return Bootstrap(scene, out, overwrite=overwrite, **options).run()
