"""Writing predicted flows: a Lightning prediction-writer callback.

For every pair t -> t+1 it writes ``flow_<t>.flo`` (Middlebury) or one ``flows.npz`` (key
``flow``, (P, 2, H, W) float32), and optionally ``flow_<t>.png`` colour images, into
``output_dir`` (default: ``<trainer.default_root_dir>/predictions``). Every file is written
atomically; an existing output folder is refused unless ``overwrite``.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import lightning as L
import numpy as np
import torch
from lightning.pytorch.callbacks import BasePredictionWriter

from ..data import flow_image, write_flo, write_png
from ..data.atomic import atomic_write_bytes

__all__ = ["FlowWriter", "write_flows", "write_flows_npz"]

FORMATS = ("flo", "npz")


def write_flows(folder: str | Path, flows: torch.Tensor, indices: list[int] | None = None, flo: bool = True,
                png: bool = True) -> Path:
    """Per pair t of ``indices`` (default 0..P-1) write ``flow_<t>.flo`` and/or the colour image
    ``flow_<t>.png`` of flows (P, 2, H, W) px into ``folder``, atomically; returns the folder."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    indices = list(range(len(flows))) if indices is None else list(indices)
    for i, flow in zip(indices, flows.detach().float().cpu()):
        if flo:
            write_flo(folder / f"flow_{i:06d}.flo", flow)
        if png:
            write_png(folder / f"flow_{i:06d}.png", flow_image(flow))
    return folder


def write_flows_npz(path: str | Path, flows: torch.Tensor, indices: list[int] | None = None) -> Path:
    """One npz (keys ``flow`` (P, 2, H, W) float32, ``index`` (P,)), written atomically."""
    indices = list(range(len(flows))) if indices is None else list(indices)
    buffer = io.BytesIO()
    np.savez(buffer, flow=flows.detach().float().cpu().numpy(), index=np.array(indices))
    return atomic_write_bytes(path, buffer.getvalue())


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
