"""One call from Python: refine a scene's poses with a ready-made Lightning Trainer."""

from __future__ import annotations

import os
import tempfile
from typing import Any

import lightning as L
import torch

from ..core import Scene
from .data import DEFAULT_STEPS, PoseData
from .refiner import PoseRefiner
from .refiner2d import KeypointRefiner
from .result import PoseResult
from .stopping import LossPlateauStopping

__all__ = ["refine_poses", "make_trainer", "REFINERS", "make_refiner"]

#: The refiner of each mode: 3D joints and cameras, or 2D keypoints alone.
REFINERS: dict[str, type[PoseRefiner] | type[KeypointRefiner]] = {"3d": PoseRefiner, "2d": KeypointRefiner}


def make_refiner(mode: str, **kwargs: Any) -> PoseRefiner | KeypointRefiner:
    """The refiner of ``mode`` ("3d" or "2d") built from ``kwargs``."""
    if mode not in REFINERS:
        raise ValueError(f"mode: expected one of {tuple(REFINERS)}, got {mode!r}")
    return REFINERS[mode](**kwargs)


def make_trainer(
    steps: int = DEFAULT_STEPS,
    early_stop: bool = True,
    default_root_dir: str | os.PathLike | None = None,
    logger: Any = False,
    **trainer_kwargs: Any,
) -> L.Trainer:
    """A CPU-friendly Trainer for a refiner: one epoch of ``steps`` steps, no validation, no
    checkpoints, no progress bar; the authors' early stop unless ``early_stop`` is False."""
    callbacks = list(trainer_kwargs.pop("callbacks", []))
    if early_stop:
        callbacks.append(LossPlateauStopping())
    options = dict(
        max_epochs=1, max_steps=steps, logger=logger, enable_checkpointing=False, enable_progress_bar=False,
        enable_model_summary=False, num_sanity_val_steps=0, limit_val_batches=0, log_every_n_steps=50,
        accelerator="auto", devices=1,
    )  # fmt: skip
    options.update(trainer_kwargs)
    return L.Trainer(default_root_dir=default_root_dir, callbacks=callbacks, **options)


def refine_poses(
    scene: str | os.PathLike | Scene,
    flows: str | os.PathLike | torch.Tensor | None = "gt",
    mode: str = "3d",
    steps: int = DEFAULT_STEPS,
    early_stop: bool = True,
    trainer: L.Trainer | None = None,
    **refiner_kwargs: Any,
) -> PoseResult:
    """Refine ``scene``'s 3D joints and cameras (mode "3d", :class:`PoseRefiner`) or its 2D
    keypoints (mode "2d", :class:`KeypointRefiner`) against ``flows`` (see :class:`PoseData`).

    ``refiner_kwargs`` go to the refiner (loss_weights, lr, ...); without ``output_dir`` nothing is
    saved. Returns the :class:`PoseResult`.
    """
    refiner_kwargs.setdefault("save", "output_dir" in refiner_kwargs)
    model = make_refiner(mode, **refiner_kwargs)
    with tempfile.TemporaryDirectory(prefix="lit_boot_pose_") as tmp:
        trainer = trainer or make_trainer(steps, early_stop, default_root_dir=tmp)
        trainer.fit(model, datamodule=PoseData(scene, flows, steps=steps))
    return model.result
