"""Writing predicted flows: a Lightning prediction-writer callback.

For every pair t -> t+1 it writes ``flow_<t>.flo`` (Middlebury) or one ``flows.npz``, and
optionally ``flow_<t>.png`` colour images (the one flow file format: :mod:`lit_boot.data.flows`), into
``output_dir`` (default: ``<trainer.default_root_dir>/predictions``). Every file is written
atomically; an existing output folder is refused unless ``overwrite``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import lightning as L
import torch
from lightning.pytorch.callbacks import BasePredictionWriter

from ..data.flows import write_flows, write_flows_npz

__all__ = ["FlowWriter", "write_flows", "write_flows_npz"]

FORMATS = ("flo", "npz")


class FlowWriter(BasePredictionWriter):
    """Save FlowTTT predictions.

    Args:
        output_dir: folder for the flows (default: <default_root_dir>/predictions).
        format: flo (one Middlebury file per pair) or npz (one file for the scene).
        png: also write a colour image per flow (torchvision's flow_to_image).
        overwrite: write into an existing, non-empty output folder.
    """

    def __init__(self, output_dir: str | None = None, format: str = "flo", png: bool = True, overwrite: bool = False):
        super().__init__(write_interval="batch")
        if format not in FORMATS:
            raise ValueError(f"format: expected one of {FORMATS}, got {format!r}")
        self.output_dir = output_dir
        self.format = format
        self.png = png
        self.overwrite = overwrite
        self._npz: dict[int, torch.Tensor] = {}

    def folder(self, trainer: L.Trainer) -> Path:
        return Path(self.output_dir) if self.output_dir else Path(trainer.default_root_dir) / "predictions"

    def on_predict_start(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        out = self.folder(trainer)
        if out.exists() and any(out.iterdir()) and not self.overwrite:
            raise FileExistsError(f"{out}: prediction folder exists and is not empty (set overwrite to replace)")
        out.mkdir(parents=True, exist_ok=True)
        self._npz = {}

    def write_on_batch_end(
        self, trainer: L.Trainer, pl_module: L.LightningModule, prediction: Any, batch_indices, batch, batch_idx: int, dataloader_idx: int = 0
    ) -> None:
        indices, flows = prediction["index"].tolist(), prediction["flow"].float().cpu()
        if self.format == "npz":
            self._npz.update(zip(indices, flows))
        write_flows(self.folder(trainer), flows, indices, flo=self.format == "flo", png=self.png)

    def on_predict_end(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        if self.format == "npz" and self._npz:
            order = sorted(self._npz)
            write_flows_npz(self.folder(trainer) / "flows.npz", torch.stack([self._npz[i] for i in order]), order)
