"""Bootstrap: the whole method on one scene, flow -> pose -> flow, resumable.

The run folder's layout: :mod:`.folder` (the input scene folder is never written).

Faults. Every file is written atomically and a stage's stage.json last, so a run killed at any
point (SIGKILL included) resumes to the same result as an uninterrupted run; leftovers of
interrupted writes are deleted on resume. A stage whose training meets a non-finite loss,
gradient or weight (:class:`~lit_boot.finite.FiniteGuard`), or whose output is not finite, is
rolled back: its output is discarded, the previous stage's flows, poses and weights are kept
(the final outputs are theirs), the stage's record in summary.json says ``rolled_back`` with a
``guard`` event ``{"guard": "finite", "what": ..., "step": ...}``, and the run stops, as the
drift guard's ``rollback`` does (a rerun logs it again; ``overwrite`` tries again). Ctrl-C stops
a run with :class:`RunInterrupted` naming the last finished stage (:mod:`.interrupt`); a rerun
logs which stages it loads instead of running them.
"""

from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import lightning as L
import torch
from lightning.pytorch.loggers import CSVLogger, TensorBoardLogger

from .._version import __version__
from ..core import Scene
from ..data import load_scene
from ..finite import NonFiniteError
from ..data.flows import read_flows, write_flows_npz
from ..flow import FlowTTT, person_region
from ..metrics import scene_flow_metrics, scene_pose_metrics
from ..pose import REFINERS, PoseResult, load_pose_result
from ..quiet import quiet_lightning
from .config import BootstrapConfig
from .dashboard import log_stage_images, log_summary, stage_header
from .decisions import final_decisions, load_decisions, load_mask, save_mask, target_line
from .ensemble import average_poses
from .evaluate import agreement, drift, person_height, photo_error, pose_evidence, pose_track_error
from .folder import STAGE_JSON, RunFolder
from .guard import drift_guard, guard_text
from .interrupt import RunInterrupted, interruptible
from .lock import RunLock
from .outputs import write_outputs
from .plan import Plan, plan_run
from .result import BootstrapResult
from .selfcheck import check_stage, people_shares, summary_line
from .stages import fine_tune_flow, make_flow_model, predict_flows, quiet_refiner, refine_poses_stage, unjudged_flows
from .zoom import zoom_line, zoom_stage

__all__ = ["Bootstrap", "BootstrapResult", "RunInterrupted", "bootstrap", "STAGE_JSON"]

log = logging.getLogger(__name__)


@dataclass
class _RunState:
    """What a run carries from stage to stage: the current scene (its estimates the latest
    poses), flows (T-1, 2, H, W) px and PoseResult, the records so far, and the run's fixed
    facts. ``initial`` is pretrained RAFT's flow, ``reference`` the flow the next flow stage is
    checked against and taught from: the last flow-making stage's (initial, zoom or flow), so
    that a stage cannot undo what the one before it gained where the frames can tell;
    ``decisions`` where the flow so far comes from (:func:`~.decisions.final_decisions`);
    ``unjudged`` the pixels the frames cannot judge (:func:`~.selfcheck.unjudged_pixels`, when the
    flow stages are self-checked)."""

    scene: Scene
    initial_scene: Scene
    person_px: float
    accelerator: str
    precision: str
    loggers: list
    initial: torch.Tensor | None = None
    reference: torch.Tensor | None = None
    zoom_kept: torch.Tensor | None = None
    flows: torch.Tensor | None = None
    result: PoseResult | None = None
    history: list[dict[str, Any]] = field(default_factory=list)
    seconds: dict[str, float] = field(default_factory=dict)
    decisions: dict[str, torch.Tensor] | None = None
    unjudged: torch.Tensor | None = None


class Bootstrap:
    """Run the method on one scene (a folder, or a Scene) into ``out`` (default
    ``runs/<scene name>/bootstrap``).

    Settings: a :class:`BootstrapConfig`, or its fields as keyword arguments. A missing or
    unfit scene, missing or bad weights and bad settings fail before the run folder is
    touched. ``overwrite`` clears a run found in ``out`` first; otherwise an interrupted run
    with the same settings resumes after its last finished stage, one with other settings is
    replaced if it finished no stage and refused if it did. A folder holding anything but a
    lit-boot run is never written, and a folder another run is writing into is refused
    (:class:`~lit_boot.bootstrap.lock.RunLockedError`). A stage that meets a non-finite value
    is rolled back and the run stops (see the module doc).
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
        self.requested = self.config = config or BootstrapConfig(**options)
        self.plan: Plan | None = None  # what the scene's evidence lets the run do (set by run())
        self.scene_arg = scene
        self.scene = scene if isinstance(scene, Scene) else None
        name = scene.name if isinstance(scene, Scene) else Path(scene).name
        self.out = Path(out) if out is not None else Path("runs") / name / "bootstrap"
        self.overwrite = overwrite
        self.folder = RunFolder(self.out, overwrite)
        self.models: list[FlowTTT] = []
        self.pending_weights: list[Path | None] = []

    # --- inputs and settings: checked before anything is written ----------------------------------
    def _settings(self) -> dict[str, Any]:
        scene = str(self.scene_arg) if not isinstance(self.scene_arg, Scene) else f"<Scene {self.scene_arg.name}>"
        return {"lit_boot": __version__, "scene": scene, "config": self.requested.to_dict()}

    def _inputs(self) -> Scene:
        """The scene (loaded) with the pose ensemble averaged in; sets the run's :class:`Plan`
        (what the scene's evidence allows: :func:`~.plan.plan_run`) and ``config`` to the
        requested one in the plan's mode."""
        scene = self.scene if self.scene is not None else load_scene(self.scene_arg)
        if scene.num_frames < 2:
            raise ValueError(f"scene {scene.name!r}: needs at least 2 frames, has {scene.num_frames}")
        self.plan = plan_run(self.requested, scene)
        self.config = replace(self.requested, mode=self.plan.mode)
        return average_poses(scene, self.config.pose_ensemble, self.config.mode)

    def _build(self, person_px: float) -> None:
        """Build every ensemble member (loading its weights: missing, unreadable, unfit or
        non-finite weights raise) and a refiner from the settings (bad arguments raise)."""
        cfg = self.config
        self.models = [make_flow_model(cfg.flow_kwargs(m, person_px)) for m in range(1 + len(cfg.flow_ensemble))]
        self.pending_weights = [None] * len(self.models)
        for m, model in enumerate(self.models):
            if not all(torch.isfinite(t).all() for t in model.raft.state_dict().values() if t.is_floating_point()):
                raise ValueError(f"RAFT weights {cfg.flow_kwargs(m).get('weights')}: hold NaN or infinite values")
        quiet_refiner(cfg.mode, cfg.pose_kwargs())

    # --- logging and devices -------------------------------------------------------------------------
    def _loggers(self, version: str) -> list:
        """Fresh TensorBoard and CSV loggers for ``version`` (an interrupted attempt's logs go)."""
        self.folder.clear_logs(version)
        root = self.out / "logs"
        return [TensorBoardLogger(root, name="tensorboard", version=version),
                CSVLogger(root, name="csv", version=version)]

    def _accelerator(self) -> str:
        """The flow stages' device kind: auto is CUDA when available, else the CPU; gpu is CUDA
        when available, else MPS (as Lightning's)."""
        acc = self.config.accelerator
        if acc in ("auto", "gpu"):
            return "cuda" if torch.cuda.is_available() else ("cpu" if acc == "auto" else "mps")
        return acc

    def _precision(self) -> str:
        if self.config.precision is not None:
            return self.config.precision
        return self.config.option("cuda_precision") if self._accelerator() == "cuda" else "32-true"

    # --- flow networks ----------------------------------------------------------------------------
    def _model(self, member: int, person_px: float, fresh: bool = False) -> FlowTTT:
        """Ensemble member ``member``: pretrained if ``fresh``, else as last tuned (loaded from
        a finished stage's weights on a resumed run)."""
        if fresh:
            self.models[member] = make_flow_model(self.config.flow_kwargs(member, person_px))
            self.pending_weights[member] = None
        pending = self.pending_weights[member]
        if pending is not None:
            self.models[member].raft.load_state_dict(torch.load(pending, map_location="cpu", weights_only=True))
            self.pending_weights[member] = None
        return self.models[member]

    # --- the stages --------------------------------------------------------------------------------
    def _flow_stage(self, name: str, index: int, st: _RunState) -> tuple[dict[str, Any], torch.Tensor, dict]:
        """Fine-tune every ensemble member on the stick-man of the current poses; the record,
        the members' mean flow (T-1, 2, H, W) px, self-checked against the initial flow when
        the config says so (:mod:`~lit_boot.bootstrap.selfcheck`), and the decision maps
        (:mod:`~lit_boot.bootstrap.decisions`)."""
        cfg, n = self.config, len(self.models)
        what = f"FlowTTT x{n}, {cfg.epochs} epochs, {st.precision} on {st.accelerator}"
        log.info(stage_header(index, len(self.plan.stages), name, what))
        flows, reports = [], []
        for m in range(n):
            model = self._model(m, st.person_px, fresh=cfg.restart_flow)
            loggers = self._loggers(name + (f"_m{m}" if n > 1 else ""))
            reports.append(fine_tune_flow(model, st.scene, mode=cfg.mode, epochs=cfg.epochs, accelerator=st.accelerator,
                                          precision=st.precision, loggers=loggers, progress_bar=cfg.progress_bar,
                                          **self._teaching(st)))
            flows.append(predict_flows(model, st.scene, accelerator=st.accelerator, precision=st.precision))
        mean = torch.stack(flows).mean(0)
        person = person_region(self.models[0].sketch_masks)
        mean, check, kept = check_stage(cfg, st.scene, st.reference, mean, person, st.unjudged)
        record = {**scene_flow_metrics(st.scene.gt, mean, st.scene.track_id),
                  "drift_px": drift(mean, st.initial, person),
                  "agreement_px": agreement(mean, *st.scene.pose_points(cfg.mode)),
                  "photo_error": photo_error(st.scene.frames, mean),
                  "info": {"target": reports[0], "sketch": self.models[0].hparams["sketch"]}}  # fmt: skip
        log.info(target_line(reports[0]))
        run = int(reports[0]["train/epochs"])
        if 0 < run < cfg.epochs:
            log.info(f"  plateau: the training loss stopped falling; stopped after {run} of {cfg.epochs} epochs")
        if check is not None:
            painted_by = self.models[0].sketch_people
            if painted_by is not None:  # several people: each one's share kept
                check["people"] = people_shares(kept, painted_by, [p.track_id for p in st.scene.people()])
            record["info"]["self_check"] = check
            log.info(summary_line(check))
        kept = kept if kept is not None else torch.ones(mean.shape[0], *mean.shape[-2:])
        return record, mean, {"painted": self.models[0].sketch_masks.cpu(), "kept": kept}

    def _teaching(self, st: _RunState) -> dict[str, torch.Tensor | None]:
        """What a flow stage learns from the zoom stage (``zoom.teach``): fine_tune_flow's
        ``teacher`` and ``confirmed``."""
        teach = self.config.zoom.teach if st.zoom_kept is not None else "off"
        return {"teacher": st.reference if teach != "off" else None,
                "confirmed": st.zoom_kept if teach == "confirmed" else None}

    def _zoom_stage(self, name: str, index: int, st: _RunState) -> tuple[dict[str, Any], torch.Tensor, dict]:
        """RAFT (ensemble member 0, pretrained) on a zoomed crop around the person of every pair,
        kept unless the frames refuse it (:func:`~lit_boot.bootstrap.zoom.zoom_stage`)."""
        cfg = self.config
        log.info(stage_header(index, len(self.plan.stages), name, f"RAFT zoomed on the person, on {st.accelerator}"))
        record, flows, decisions = zoom_stage(self._model(0, st.person_px).raft, st.scene, st.initial, mode=cfg.mode,
                                              config=cfg.zoom, device="cuda" if st.accelerator == "cuda" else "cpu")
        log.info(zoom_line(record["info"]["zoom"], flows.shape[0]))
        return record, flows, decisions

    def _pose_stage(self, name: str, index: int, st: _RunState) -> tuple[dict[str, Any], PoseResult, Scene]:
        """Refine the current poses against the current flows; the record, the result and the
        scene with the refined poses."""
        cfg = self.config
        what = f"{REFINERS[cfg.mode].__name__}, {cfg.pose_steps} steps on {cfg.pose_accelerator}"
        log.info(stage_header(index, len(self.plan.stages), name, what))
        result = refine_poses_stage(st.scene, st.flows, mode=cfg.mode, kwargs=cfg.pose_kwargs(), steps=cfg.pose_steps,
                                    early_stop=cfg.early_stop, accelerator=cfg.pose_accelerator,
                                    loggers=self._loggers(name), progress_bar=cfg.progress_bar)  # fmt: skip
        refined = result.apply_to(st.scene)
        points = refined.pose_points(cfg.mode)
        record = {**scene_pose_metrics(refined, cfg.mode), "agreement_px": agreement(st.flows, *points),
                  "track_error": pose_track_error(refined.frames, *points), **pose_evidence(refined, cfg.mode),
                  "info": {"steps": result.steps, "stopped_early": result.stopped_early,
                           "loss": result.loss}}  # fmt: skip
        return record, result, refined

    def _initial_stage(self, st: _RunState) -> None:
        """Pretrained RAFT's flow (the members' mean) and the initial poses' metrics: loaded if
        done, else computed and saved."""
        cfg, folder = self.config, self.folder.stage_dir("initial")
        record = self.folder.record("initial")
        if record is not None:
            st.initial = read_flows(folder / "flows.npz")
        else:
            models = [self._model(m, st.person_px) for m in range(len(self.models))]
            what = f"RAFT inference x{len(models)} on {st.accelerator}"
            log.info(stage_header(0, len(self.plan.stages), "initial", what))
            start = time.perf_counter()
            try:
                flows = [predict_flows(model, st.scene, accelerator=st.accelerator, precision=st.precision)
                         for model in models]  # fmt: skip
            except NonFiniteError as err:
                raise NonFiniteError(f"{self.out}: pretrained RAFT's flow is not finite at precision {st.precision} "
                                     "(try precision 32-true)", err.fault) from None  # fmt: skip
            st.initial = torch.stack(flows).mean(0)
            points = st.scene.pose_points(cfg.mode)
            record = {"stage": "initial", "kind": "initial", "cycle": 0,
                      **scene_flow_metrics(st.scene.gt, st.initial, st.scene.track_id),
                      **scene_pose_metrics(st.scene, cfg.mode),
                      "agreement_px": agreement(st.initial, *points),
                      "photo_error": photo_error(st.scene.frames, st.initial),
                      "track_error": pose_track_error(st.scene.frames, *points), **pose_evidence(st.scene, cfg.mode),
                      "info": {"seconds": time.perf_counter() - start, "person_px": st.person_px}}  # fmt: skip
            record["info"]["raft_seconds"] = record["info"]["seconds"]  # the forward pass alone
            folder.mkdir(parents=True, exist_ok=True)
            write_flows_npz(folder / "flows.npz", st.initial)
            if cfg.checking != "off":
                st.unjudged = unjudged_flows(models, st.scene, st.initial, accelerator=st.accelerator,
                                             precision=st.precision)  # fmt: skip
                save_mask(folder / "unjudged.npz", st.unjudged)
                record["info"]["seconds"] = time.perf_counter() - start
            self.folder.write_record("initial", record)
        if cfg.checking != "off" and st.unjudged is None and (folder / "unjudged.npz").is_file():
            st.unjudged = load_mask(folder / "unjudged.npz")  # a resumed run's
        st.flows = st.reference = st.initial
        st.history.append(record)
        st.seconds["initial"] = record["info"]["seconds"]
        log_stage_images(st.loggers, 0, "initial", st.scene, st.initial, cfg.mode)

    def _load_stage(self, st: _RunState, index: int, name: str, record: dict[str, Any]) -> bool:
        """Take a finished stage's results; False if the run stopped there."""
        st.history.append(record)
        if record.get("rolled_back"):
            return False
        folder = self.folder.stage_dir(name)
        if record["kind"] in ("flow", "zoom"):
            st.flows = read_flows(folder / "flows.npz")
            own = load_decisions(folder / "decisions.npz") if (folder / "decisions.npz").is_file() else None
            st.decisions = final_decisions(st.decisions, record["kind"], own)
            st.reference = st.flows  # the next flow stage is checked against this stage's flow
            if record["kind"] == "zoom":
                st.zoom_kept = own["kept"] > 0
            else:
                self.pending_weights = [folder / f"raft_{m}.pt" for m in range(len(self.models))]
        else:
            st.result = load_pose_result(folder)
            st.scene = st.result.apply_to(st.scene)
        st.seconds[name] = record["info"]["seconds"]
        log_stage_images(st.loggers, index, name, st.scene, st.flows, self.config.mode, st.decisions)
        return record.get("guard", {}).get("action") != "stop"  # the drift guard stopped the run here

    def _run_stage(self, st: _RunState, index: int, name: str) -> bool:
        """Run a stage; save its results, stage.json last; False if the run stops here."""
        cfg = self.config
        kind, _, cycle = name.partition("_")
        cycle = int(cycle or 0)
        head = {"stage": name, "kind": kind, "cycle": cycle}
        L.seed_everything(cfg.seed + index, verbose=False)
        start = time.perf_counter()
        try:
            if kind == "flow":
                record, flows, decisions = self._flow_stage(name, index, st)
                scene, result = st.scene, st.result
            elif kind == "zoom":
                record, flows, decisions = self._zoom_stage(name, index, st)
                scene, result = st.scene, st.result
            else:
                record, result, scene = self._pose_stage(name, index, st)
                flows, decisions = st.flows, st.decisions
        except NonFiniteError as err:
            return self._roll_back(st, head, start, err)
        record = {**head, **record}
        record["info"]["seconds"] = time.perf_counter() - start
        guard = drift_guard(self.config, record, st.history)
        if guard is not None:
            record["guard"] = guard
            if guard["action"] == "rollback":
                record["rolled_back"] = True
                self.folder.write_record(name, record)
                st.history.append(record)
                log.warning(f"  drift guard: {guard_text(guard)}; {name} rolled back, run stopped")
                return False
        weights = [model.raft.state_dict() for model in self.models] if kind == "flow" else []
        self.folder.save_stage(name, kind, flows=flows, result=result, decisions=decisions, weights=weights)
        self.folder.write_record(name, record)
        st.flows, st.scene, st.result = flows, scene, result
        st.decisions = final_decisions(st.decisions, kind, decisions)  # where the flow so far comes from
        if kind in ("zoom", "flow"):
            st.reference = flows  # the next flow stage is checked against this stage's flow
        if kind == "zoom":
            st.zoom_kept = decisions["kept"] > 0
        st.history.append(record)
        st.seconds[name] = record["info"]["seconds"]
        log_stage_images(st.loggers, index, name, st.scene, st.flows, cfg.mode, st.decisions)
        if guard is not None and guard["action"] == "stop":
            log.warning(f"  drift guard: {guard_text(guard)}; run stopped")
            return False
        if guard is not None:
            log.info(f"  drift guard: {guard_text(guard)} (recorded; drift_guard stop or rollback ends the run here)")
        return True

    def _roll_back(self, st: _RunState, head: dict[str, Any], start: float, err: NonFiniteError) -> bool:
        """Record a stage stopped by a non-finite value as rolled back (its output discarded,
        the previous stage's kept); the run stops. Returns False."""
        record = {**head, "rolled_back": True, "guard": {"guard": "finite", "action": "rollback", **err.fault},
                  "info": {"seconds": time.perf_counter() - start, "error": str(err)}}  # fmt: skip
        self.folder.write_record(head["stage"], record)
        st.history.append(record)
        log.warning(f"  finite guard: {err}; {head['stage']} rolled back (its output discarded), run stopped")
        return False

    # --- the run -----------------------------------------------------------------------------------
    def run(self) -> BootstrapResult:
        """Run (or resume) every stage; write the run's outputs; return the result. Lightning's
        info lines and known warnings are off (:func:`~lit_boot.quiet.quiet_lightning`); a rerun
        logs which stages it loads; Ctrl-C raises :class:`~lit_boot.bootstrap.interrupt.RunInterrupted`
        naming the last finished stage (see :mod:`~lit_boot.bootstrap.interrupt`)."""
        with quiet_lightning():
            return self._run()

    def _run(self) -> BootstrapResult:
        self.folder.check(self._settings())  # nothing is written before inputs and settings are known good
        scene = self._inputs()
        cfg = self.config  # the requested settings in the plan's mode
        log.info(f"[lit-boot] {self.plan.why}")
        L.seed_everything(cfg.seed, verbose=False)
        person_px = person_height(*scene.pose_points(cfg.mode))
        self._build(person_px)
        with RunLock(self.out):
            self.folder.prepare(self._settings())
            stages = ["initial", *self.plan.stages]
            if done := self.folder.finished(stages):
                log.info(f"[lit-boot] resuming {self.out}: {', '.join(done)} already done (loaded, not run again)")
            with interruptible(self.out, lambda: ([None, *self.folder.finished(stages)])[-1]):  # Ctrl-C
                loggers = self._loggers("summary")  # rebuilt whole on every (resumed) run: no duplicates
                st = _RunState(scene, scene, person_px, self._accelerator(), self._precision(), loggers)
                self._initial_stage(st)
                for index, name in enumerate(self.plan.stages, start=1):
                    record = self.folder.record(name)
                    go_on = self._run_stage(st, index, name) if record is None else \
                        self._load_stage(st, index, name, record)  # fmt: skip
                    if not go_on:
                        break
                return self._finish(st)

    def _finish(self, st: _RunState) -> BootstrapResult:
        """Log the per-stage metrics to the summary loggers; write the run's outputs."""
        log_summary(st.loggers, st.history)
        guard_events = [{"stage": r["stage"], **r["guard"]} for r in st.history if "guard" in r]
        out = BootstrapResult(run_dir=self.out, scene=st.scene, initial_scene=st.initial_scene,
                              initial_flows=st.initial, flows=st.flows, poses=st.result, history=st.history,
                              seconds=st.seconds, decisions=st.decisions)  # fmt: skip
        write_outputs(out, settings=self._settings(), plan=self.plan, guard_events=guard_events,
                      accelerator=st.accelerator, precision=st.precision, config=self.config)  # fmt: skip
        return out


def bootstrap(scene: str | os.PathLike | Scene, out: str | os.PathLike | None = None, **options: Any) -> BootstrapResult:
    """Run the method on ``scene`` with :class:`BootstrapConfig` options; see :class:`Bootstrap`."""
    overwrite = options.pop("overwrite", False)
    return Bootstrap(scene, out, overwrite=overwrite, **options).run()
