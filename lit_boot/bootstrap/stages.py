"""The method's stages as the orchestrator runs them, each with its own Lightning Trainer.

- :func:`predict_flows`: RAFT's flow for every pair of a scene (the initial flow, and each flow
  stage's result); :func:`predict_backward_flows` the same from frame t+1 to frame t, and
  :func:`unjudged_flows` where the frames cannot judge a flow (the self-check's);
- :func:`fine_tune_flow`: FlowTTT on the stick-man drawn from the scene's current poses;
- :func:`refine_poses_stage`: PoseRefiner (3D) or KeypointRefiner (2D) against a flow.

A training stage that meets a non-finite loss, gradient or weight (see
:class:`~lit_boot.finite.FiniteGuard`) raises :class:`~lit_boot.finite.NonFiniteError`, as does
one whose output (flows, poses) is not finite: the runner then rolls the stage back.

The flow and pose halves meet here and in the runner only.
"""

from __future__ import annotations

from typing import Any

import lightning as L
import torch

from ..core import Scene
from ..finite import NonFiniteError, finite_fault
from ..flow import FlowTTT, SceneFlowData, SketchConfig
from ..flow.data import SOURCE_OF_MODE
from ..pose import KeypointRefiner, PoseData, PoseRefiner, PoseResult
from ..pose.api import make_refiner, make_trainer
from .selfcheck import unjudged_pixels
from ..progress import progress_bar as make_progress_bar

__all__ = ["make_flow_model", "predict_flows", "predict_backward_flows", "unjudged_flows", "fine_tune_flow", "refine_poses_stage", "require_finite",
           "quiet_refiner"]


def make_flow_model(kwargs: dict[str, Any]) -> FlowTTT:
    """A FlowTTT from constructor arguments (``sketch`` may be a dict)."""
    kwargs = dict(kwargs)
    if isinstance(kwargs.get("sketch"), dict):
        kwargs["sketch"] = SketchConfig(**kwargs["sketch"])
    return FlowTTT(**kwargs)


def quiet_refiner(mode: str, kwargs: dict[str, Any]) -> PoseRefiner | KeypointRefiner:
    """The refiner of ``mode`` that saves nothing itself (the runner saves the stage)."""
    return make_refiner(mode, **{**kwargs, "save": False})


def require_finite(what: str, *tensors: torch.Tensor | None) -> None:
    """Raise :class:`NonFiniteError` if any of ``tensors`` (None skipped) holds a NaN or inf."""
    for tensor in tensors:
        if tensor is not None and not bool(torch.isfinite(tensor).all()):
            raise NonFiniteError(f"non-finite {what}", {"what": what, "step": None, "good_steps": None, "value": None})


def _raise_fault(trainer: L.Trainer, stage: str) -> None:
    fault = finite_fault(trainer)
    if fault is not None:
        raise NonFiniteError(f"{stage}: non-finite {fault['what']} at step {fault['step']}", fault)


def _bars(progress_bar: bool) -> list:
    """Lightning's plain (tqdm) progress bar when asked: the same bars whatever else is installed
    (:func:`lit_boot.progress.progress_bar`: redrawn per epoch only in a log file)."""
    return [make_progress_bar()] if progress_bar else []


def _flow_trainer(*, max_epochs: int, accelerator: str, precision: str, loggers: list, progress_bar: bool) -> L.Trainer:
    return L.Trainer(
        max_epochs=max_epochs, accelerator=accelerator, devices=1, precision=precision, logger=loggers or False,
        enable_checkpointing=False, enable_model_summary=False, num_sanity_val_steps=0, limit_val_batches=0,
        enable_progress_bar=progress_bar, log_every_n_steps=1, callbacks=_bars(progress_bar),
    )  # fmt: skip


def predict_flows(
    model: FlowTTT, scene: Scene, *, accelerator: str, precision: str, progress_bar: bool = False
) -> torch.Tensor:
    """``model``'s flow (T-1, 2, H, W) px for every pair, with its ``predict_updates``."""
    trainer = _flow_trainer(max_epochs=1, accelerator=accelerator, precision=precision, loggers=[],
                            progress_bar=progress_bar)  # fmt: skip
    out = trainer.predict(model, datamodule=SceneFlowData(scene, shuffle=False))
    order = torch.cat([o["index"] for o in out]).argsort()
    flows = torch.cat([o["flow"].float().cpu() for o in out])[order]
    require_finite("flows", flows)
    return flows


def predict_backward_flows(
    model: FlowTTT, scene: Scene, *, accelerator: str, precision: str
) -> torch.Tensor:
    """``model``'s flow t+1 -> t (T-1, 2, H, W) px for every pair t (the frames run in reverse)."""
    reverse = Scene(frames=scene.frames.flip(0), fps=scene.fps, name=scene.name)
    return predict_flows(model, reverse, accelerator=accelerator, precision=precision).flip(0)


def unjudged_flows(models: list[FlowTTT], scene: Scene, forward: torch.Tensor, *, accelerator: str,
                   precision: str) -> torch.Tensor:  # fmt: skip
    """Where the frames cannot judge a change of ``forward`` (T-1, 2, H, W) px, the models' mean
    flow: (T-1, H, W) bool, the forward-backward check against the models' mean backward flow
    (:func:`~.selfcheck.unjudged_pixels`; one more RAFT pass per model)."""
    backward = [predict_backward_flows(m, scene, accelerator=accelerator, precision=precision) for m in models]
    return unjudged_pixels(forward, torch.stack(backward).mean(0))


def fine_tune_flow(
    model: FlowTTT,
    scene: Scene,
    *,
    mode: str,
    epochs: int,
    accelerator: str,
    precision: str,
    loggers: list,
    progress_bar: bool = True,
    teacher: torch.Tensor | None = None,
    confirmed: torch.Tensor | None = None,
) -> dict[str, float]:
    """Fine-tune ``model`` in place on the stick-man from ``scene``'s current poses; returns
    FlowTTT's target report (bones rejected by the guard, painted fraction, ...) with
    ``train/epochs``, the epochs run (fewer than ``epochs`` when the plateau stop ended the fit).
    With a ``teacher`` flow (T-1, 2, H, W) px the stick-man is painted over it, and not where
    ``confirmed`` (T-1, H, W) bool (:meth:`FlowTTT.prepare`). A non-finite value raises
    NonFiniteError (the model holds the last good step's weights)."""
    model.forget_targets()  # rebuilt from these poses
    data = SceneFlowData(scene, pose_source=SOURCE_OF_MODE[mode])
    if teacher is not None:
        model.prepare(scene, data.sketch_inputs(), teacher=teacher, confirmed=confirmed)
    trainer = _flow_trainer(max_epochs=epochs, accelerator=accelerator, precision=precision, loggers=loggers,
                            progress_bar=progress_bar)  # fmt: skip
    trainer.fit(model, datamodule=data)
    _raise_fault(trainer, "FlowTTT")
    return {**model.target_report, "train/epochs": float(trainer.current_epoch)}


def refine_poses_stage(
    scene: Scene,
    flows: torch.Tensor,
    *,
    mode: str,
    kwargs: dict[str, Any],
    steps: int,
    early_stop: bool,
    accelerator: str,
    loggers: list,
    progress_bar: bool = True,
) -> PoseResult:
    """Refine ``scene``'s poses against ``flows`` (T-1, 2, H, W) px; returns the result. A
    non-finite value raises NonFiniteError."""
    refiner = quiet_refiner(mode, kwargs)
    trainer = make_trainer(
        steps, early_stop, logger=loggers or False, accelerator=accelerator, enable_progress_bar=progress_bar,
        log_every_n_steps=min(50, steps), callbacks=_bars(progress_bar),
    )  # fmt: skip
    trainer.fit(refiner, datamodule=PoseData(scene, flows, steps=steps))
    _raise_fault(trainer, type(refiner).__name__)
    result = refiner.result
    cameras = None if result.cameras is None else result.cameras.params
    require_finite("poses", result.joints3d, result.keypoints2d, cameras)
    return result
