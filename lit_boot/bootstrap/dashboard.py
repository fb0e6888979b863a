"""What a bootstrap run shows while it runs: one header line per stage, and pictures per stage
in TensorBoard (the flow of the middle pair in colour, the skeleton on its first frame, and what
the flow stage decided there: painted target pixels, where the tuned flow was kept)."""

from __future__ import annotations

import torch
from lightning.pytorch.loggers import TensorBoardLogger

from ..core import Scene
from ..data import draw_skeleton, flow_image
from .decisions import decision_map, decision_summary

__all__ = ["stage_header", "log_stage_images"]


def stage_header(index: int, total: int, name: str, what: str) -> str:
    """``[lit-boot] stage 1/3 flow_1: FlowTTT ...`` (stage 0 is the initial prediction)."""
    return f"[lit-boot] stage {index}/{total} {name}: {what}"


@torch.no_grad()
def log_stage_images(
    loggers: list, step: int, stage: str, scene: Scene, flows: torch.Tensor, mode: str, decisions: dict | None = None
) -> None:
    """Add the middle pair's flow colour image, the current skeleton on its first frame and,
    for a flow or zoom stage, the decision map (:func:`~lit_boot.bootstrap.decisions.decision_map`)
    (3, H, W uint8 each) to every TensorBoard logger, at ``step``, tagged by ``stage``."""
    tensorboards = [lg for lg in loggers if isinstance(lg, TensorBoardLogger)]
    if not tensorboards:
        return
    t = (scene.num_frames - 1) // 2
    points, keep = scene.pose_points(mode)
    layout = scene.pose_layout(mode)
    skeleton = draw_skeleton(scene.frames[t], points[t], layout, confidence=keep[t].float(), threshold=0.5)
    for logger in tensorboards:
        logger.experiment.add_image(f"flow/{stage}", flow_image(flows[t].float()), step)
        logger.experiment.add_image(f"skeleton/{stage}", skeleton, step)
        if decisions is not None and stage.startswith(("flow", "zoom")):
            image = decision_map(scene.frames[t], decisions, t)
            logger.experiment.add_image(f"decisions/{stage}", image, step)


def log_summary(loggers: list, history: list[dict]) -> None:
    """Log every stage's record (its float metrics as ``bootstrap/*``, its decisions as
    ``decisions/*``) to the summary ``loggers``, one step per stage, and save them."""
    for i, record in enumerate(history):
        metrics = {f"bootstrap/{k}": v for k, v in record.items() if isinstance(v, float) and k != "cycle"}
        for entry in decision_summary([record]):  # flow and zoom stages: what was painted, kept, rolled back
            metrics.update({f"decisions/{k}": float(v) for k, v in entry.items() if isinstance(v, (int, float))})
        for logger in loggers:
            logger.log_metrics(metrics, step=i)
    for logger in loggers:
        logger.save()
