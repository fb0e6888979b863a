"""PoseData: one scene and its forward flows for a pose refiner.

The whole video is one optimisation problem, so the data lives on the refiner (read in its
``setup`` from ``trainer.datamodule.scene`` and ``.flows``) and the training dataloader only
counts steps: ``steps`` items of one epoch, each a step index. One epoch of N steps costs far
less in Lightning than N epochs of one step each. The validation dataloader has one item: one
evaluation of the current poses.
"""

from __future__ import annotations

import os
from pathlib import Path

import lightning as L
import torch
from torch.utils.data import DataLoader, Dataset

from ..core import Scene
from ..data import load_scene
from .flows import load_flows

__all__ = ["PoseData", "StepIndices", "DEFAULT_STEPS"]

#: The paper's number of optimisation steps.
DEFAULT_STEPS = 1500


class StepIndices(Dataset):
    """``length`` items: the step indices 0 .. length-1 (no data)."""

    def __init__(self, length: int):
        self.length = length

    def __len__(self) -> int:
        return self.length

    def __getitem__(self, index: int) -> int:
        return index


class PoseData(L.LightningDataModule):
    """A scene and its forward flows for :class:`PoseRefiner` / :class:`KeypointRefiner`.

    Args:
        scene: a scene folder (``lit-boot synth`` writes one) or a Scene.
        flows: a folder of ``flow_000000.flo`` ... (one per pair), a ``flows.npz`` (key
            ``flow`` (T-1, 2, H, W), optional ``index``), ``gt`` for the scene's ground-truth
            flow (an oracle), a (T-1, 2, H, W) tensor (or NumPy array), or None (no flow: the
            refiner's flow weight must then be 0).
        steps: optimisation steps, as items of one epoch; None: the trainer's ``max_steps``
            when set, else 1500.
    """

    def __init__(
        self,
        scene: str | os.PathLike | Scene,
        flows: str | os.PathLike | torch.Tensor | None = "gt",
        steps: int | None = None,
    ):
        super().__init__()
        if steps is not None and steps < 1:
            raise ValueError(f"steps: expected a positive number, got {steps}")
        self.scene_arg = scene
        self.flows_arg = flows
        self.steps = steps
        self.scene: Scene | None = scene if isinstance(scene, Scene) else None
        self.flows: torch.Tensor | None = None
        self._loaded = False

    @property
    def name(self) -> str:
        """The scene's name (its folder name before it is loaded)."""
        return self.scene.name if self.scene is not None else Path(self.scene_arg).name

    def setup(self, stage: str | None = None) -> None:
        """Load the scene and the flows once; errors name the path and what was expected."""
        if self._loaded:
            return
        if self.scene is None:
            self.scene = load_scene(self.scene_arg)
        if self.flows_arg is not None:
            if self.scene.num_frames < 2:
                raise ValueError(f"scene {self.scene.name!r}: flows need at least 2 frames, it has 1")
            self.flows = load_flows(self.flows_arg, self.scene)
        self._loaded = True

    def num_steps(self) -> int:
        """Steps of the one epoch: ``steps``, else the trainer's ``max_steps``, else 1500."""
        if self.steps is not None:
            return self.steps
        max_steps = getattr(self.trainer, "max_steps", -1) if self.trainer is not None else -1
        return max_steps if max_steps and max_steps > 0 else DEFAULT_STEPS

    def train_dataloader(self) -> DataLoader:
        return DataLoader(StepIndices(self.num_steps()), batch_size=None, shuffle=False)

    def val_dataloader(self) -> DataLoader:
        return DataLoader(StepIndices(1), batch_size=None, shuffle=False)
