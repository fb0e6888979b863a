"""What a run decided, and where: the pixels each flow stage's target painted (after the guards
and the evidence gate), where its self-check kept the tuned flow, where the zoom stage kept its
zoomed flow, and the stages rolled back.

- :func:`save_mask` / :func:`load_mask`: one (T-1, H, W) bool map (the initial stage's
  ``unjudged.npz``: the pixels the frames cannot judge, :func:`~.selfcheck.unjudged_pixels`).
- :func:`save_decisions` / :func:`load_decisions`: a flow or zoom stage's maps in
  ``stages/<stage>/decisions.npz`` (``painted`` (T-1, H, W) uint8 0/1; ``kept`` (T-1, H, W)
  uint8, the stage's own flow's weight x 255: all 255 without a self-check; the zoom stage's
  painted is all 0, its kept where the zoomed flow was kept).
- :func:`final_decisions`: the stages' maps combined into where the run's flow comes from
  (a tuned flow, the zoomed flow, RAFT's).
- :func:`decision_summary`: the per-stage counts for summary.json and the dashboard.
- :func:`decision_image` / :func:`decision_map`: one pair's maps drawn over its frame (the
  overlay video, TensorBoard, the report), :func:`decision_key` their legend.
- :func:`target_line`: what a flow stage's target painted, in one console line.
"""

from __future__ import annotations

import io
import os
from typing import Any

import numpy as np
import torch

from ..data.atomic import atomic_write_bytes

__all__ = ["save_mask", "load_mask", "save_decisions", "load_decisions", "final_decisions", "decision_summary",
           "decision_image", "decision_map", "decision_key", "target_line", "DECISION_COLOURS"]

#: RGB of the painted target pixels, of where a tuned flow was kept and of where the zoom stage's
#: zoomed flow was kept (RAFT's flow: the frame in grey).
DECISION_COLOURS = {"painted": (255, 140, 0), "kept": (40, 110, 255), "zoom": (225, 40, 200)}


def save_mask(path: str | os.PathLike, mask: torch.Tensor) -> None:
    """Write a (T-1, H, W) bool map atomically (compressed ``mask``, uint8 0/1)."""
    buffer = io.BytesIO()
    np.savez_compressed(buffer, mask=mask.bool().cpu().numpy().astype(np.uint8))
    atomic_write_bytes(path, buffer.getvalue())


def load_mask(path: str | os.PathLike) -> torch.Tensor:
    """The (T-1, H, W) bool map of :func:`save_mask`."""
    with np.load(path) as data:
        return torch.from_numpy(data["mask"] > 0)


def save_decisions(path: str | os.PathLike, painted: torch.Tensor, kept: torch.Tensor) -> None:
    """Write a flow stage's maps atomically: painted (T-1, H, W) bool, kept (T-1, H, W) float in
    [0, 1] (the tuned flow's weight; all ones without a self-check)."""
    kept_u8 = (kept.float().clamp(0, 1) * 255).round().byte().numpy()
    buffer = io.BytesIO()
    np.savez_compressed(buffer, painted=painted.bool().numpy().astype(np.uint8), kept=kept_u8)
    atomic_write_bytes(path, buffer.getvalue())


def load_decisions(path: str | os.PathLike) -> dict[str, torch.Tensor]:
    """{"painted": (T-1, H, W) bool, "kept": (T-1, H, W) float in [0, 1]} from :func:`save_decisions`."""
    with np.load(path) as data:
        return {"painted": torch.from_numpy(data["painted"] > 0), "kept": torch.from_numpy(data["kept"]).float() / 255}


def final_decisions(
    previous: dict[str, torch.Tensor] | None, kind: str, maps: dict[str, torch.Tensor] | None
) -> dict[str, torch.Tensor] | None:
    """Where the run's flow comes from after a stage of ``kind`` whose own maps are ``maps``
    (:func:`load_decisions`'), given ``previous`` (this function's result before it, None at
    first): {"painted": (T-1, H, W) bool, the last flow stage's target; "kept": (T-1, H, W)
    float in [0, 1], the share of a tuned flow; "zoom" (after a zoom stage only): the share of
    the zoomed flow}; RAFT's flow has the rest. A flow stage keeps its tuned flow by its
    ``kept`` and the flow before it elsewhere; the zoom stage's ``kept`` is its zoomed flow over
    RAFT's. Other kinds, or no maps, leave ``previous`` as it is."""
    if kind not in ("flow", "zoom") or maps is None:
        return previous
    weight = maps["kept"].float()
    if kind == "zoom":
        return {"painted": torch.zeros(weight.shape, dtype=torch.bool), "kept": torch.zeros_like(weight),
                "zoom": weight}  # fmt: skip
    out = {"painted": maps["painted"].bool(), "kept": weight}
    if previous is not None:
        out["kept"] = weight + (1 - weight) * previous["kept"]
        if "zoom" in previous:
            out["zoom"] = (1 - weight) * previous["zoom"]
    return out


def decision_summary(history: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One entry per flow stage of a run's records: ``painted_fraction`` (pixels its target
    painted), ``gate_kept_fraction`` (of the sketch, after the evidence gate), ``bones_rejected``
    (by the guards and the gate), ``kept_tuned_fraction`` and ``person_tuned_fraction`` (the
    self-check; 1.0 without one), ``rolled_back`` and the guard that acted, if any."""
    out = []
    for record in history:
        if record.get("kind") == "zoom":
            zoom = record.get("info", {}).get("zoom", {})
            out.append({"stage": record["stage"], "painted_fraction": 0.0, "gate_kept_fraction": 1.0,
                        "bones_rejected": 0.0, "kept_tuned_fraction": zoom.get("kept_fraction", 0.0),
                        "person_tuned_fraction": zoom.get("kept_fraction", 0.0),
                        "rolled_back": bool(record.get("rolled_back", False)),
                        "guard": record.get("guard", {}).get("guard")})  # fmt: skip
            continue
        if record.get("kind") != "flow":
            continue
        info = record.get("info", {})
        target, check = info.get("target", {}), info.get("self_check")
        rejected = sum(v for k, v in target.items() if k.startswith("target/rejected_"))
        out.append({
            "stage": record["stage"],
            "painted_fraction": target.get("target/painted_fraction"),
            "gate_kept_fraction": target.get("target/gate_kept_fraction", 1.0),
            "bones_rejected": rejected + target.get("target/gate_rejected_bones", 0.0),
            "kept_tuned_fraction": check["kept_tuned_fraction"] if check else 1.0,
            "person_tuned_fraction": check["person_tuned_fraction"] if check else 1.0,
            "rolled_back": bool(record.get("rolled_back", False)),
            "guard": record.get("guard", {}).get("guard"),
        })  # fmt: skip
    return out


def decision_image(
    frame: torch.Tensor, painted: torch.Tensor, kept: torch.Tensor, zoom: torch.Tensor | None = None
) -> torch.Tensor:
    """Frame t (3, H, W) uint8 in grey, tinted magenta by the zoomed flow's share ``zoom`` and
    blue by the tuned flow's ``kept`` ((H, W) floats in [0, 1]), with the target's ``painted``
    (H, W) bool pixels in orange on top: (3, H, W) uint8 (:data:`DECISION_COLOURS`)."""
    grey = frame.float().mean(0, keepdim=True).expand(3, -1, -1) * 0.6 + 40
    colour = {k: torch.tensor(v, dtype=torch.float32)[:, None, None] for k, v in DECISION_COLOURS.items()}
    image = grey + 0.45 * kept.float()[None] * (colour["kept"] - grey)
    if zoom is not None:
        image = image + 0.45 * zoom.float()[None] * (colour["zoom"] - grey)
    image = torch.where(painted[None], colour["painted"], image)
    return image.round().clamp(0, 255).byte()


def decision_map(frame: torch.Tensor, decisions: dict[str, torch.Tensor], t: int) -> torch.Tensor:
    """Pair ``t``'s :func:`decision_image` of ``decisions`` (a stage's maps or
    :func:`final_decisions`') over ``frame`` (3, H, W) uint8."""
    zoom = decisions.get("zoom")
    return decision_image(frame, decisions["painted"][t], decisions["kept"][t], None if zoom is None else zoom[t])


def decision_key(zoom: bool) -> list[tuple[tuple[int, int, int], str]]:
    """The decision map's legend, (RGB, words) per colour; the zoom's row when ``zoom``."""
    key = [(DECISION_COLOURS["painted"], "the target painted"), (DECISION_COLOURS["kept"], "a tuned flow kept")]
    if zoom:
        key.append((DECISION_COLOURS["zoom"], "the zoomed flow kept (zoom stage)"))
    return key + [((120, 120, 120), "RAFT's flow kept (the frame in grey)")]


def target_line(report: dict[str, float]) -> str:
    """One line for the console from FlowTTT's target report: the share of pixels painted, the
    bones the guards rejected and, with the evidence gate, the share of the sketch it kept."""
    guards = int(sum(v for k, v in report.items() if k.startswith("target/rejected_")))
    line = f"  target: painted {100 * report.get('target/painted_fraction', 0.0):.1f}% of the pixels"
    line += f"; the guards rejected {guards} bone(s)"
    if "target/gate_kept_fraction" in report:
        line += (f"; the evidence gate kept {100 * report['target/gate_kept_fraction']:.0f}% of the sketch "
                 f"({int(report.get('target/gate_rejected_bones', 0))} more bone(s) rejected)")
    return line
