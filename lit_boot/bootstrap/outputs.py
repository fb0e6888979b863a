"""A finished run's outputs: final flows, poses and weights, summary.json, the metrics plot, the
overlay video and report.html (see :mod:`lit_boot.bootstrap.runner` for the folder layout)."""

from __future__ import annotations

import json
from typing import Any

import torch

from ..data.atomic import atomic_write_bytes
from ..data.flows import write_flows, write_flows_npz
from .config import BootstrapConfig
from .decisions import decision_summary
from .html_report import write_report
from .overlay import other_people
from .plan import Plan
from .report import overlay_frames, plot_history, video_fps, write_video
from .result import BootstrapResult

__all__ = ["write_outputs", "write_overlay_video", "speed_summary"]


def speed_summary(result: BootstrapResult) -> dict[str, float]:
    """Wall time of the stages, RAFT inference alone (the initial stage's forward pass), their
    ratio, and seconds per frame."""
    total = sum(result.seconds.values())
    initial = next((r["info"] for r in result.history if r["stage"] == "initial"), {})
    raft = initial.get("raft_seconds", result.seconds.get("initial", float("nan")))
    frames = result.scene.num_frames
    return {"total_s": total, "raft_inference_s": raft, "ratio_to_raft": total / raft if raft else float("nan"),
            "s_per_frame": total / frames, "frames": frames}  # fmt: skip


def write_outputs(
    result: BootstrapResult,
    *,
    settings: dict[str, Any],
    plan: Plan,
    guard_events: list[dict[str, Any]],
    accelerator: str,
    precision: str,
    config: BootstrapConfig,
) -> None:
    """Write the run folder's final files (each atomically); summary.json holds ``settings`` (as
    asked) and ``plan`` (what the scene's evidence let the run do: :mod:`~.plan`)."""
    out = result.run_dir
    if config.flow_format == "npz":
        write_flows_npz(out / "flows" / "flows.npz", result.flows)
    write_flows(out / "flows", result.flows, flo=config.flow_format == "flo", png=True)
    if result.poses is not None:
        result.poses.save(out)
    flow_stages = [r["stage"] for r in result.history if r["kind"] == "flow" and not r.get("rolled_back")]
    if flow_stages:
        for weights in sorted((out / "stages" / flow_stages[-1]).glob("raft_*.pt")):
            member = weights.stem.split("_")[1]
            name = "raft_finetuned.pt" if member == "0" else f"raft_finetuned_m{member}.pt"
            atomic_write_bytes(out / name, weights.read_bytes())
    device = torch.cuda.get_device_name() if accelerator == "cuda" else "cpu"
    summary = {
        "format": "lit-boot-bootstrap", "version": 1, **settings, "plan": plan.to_dict(), "device": device,
        "precision": precision,
        "stages": result.history, "before_after": {k: list(v) for k, v in result.before_after().items()},
        "speed": speed_summary(result), "drift_guard_events": guard_events,
        "decisions": decision_summary(result.history),
    }  # fmt: skip
    atomic_write_bytes(out / "summary.json", (json.dumps(summary, indent=2, default=str) + "\n").encode())
    plot_history(result.history, out / "metrics.png")
    if config.video:
        write_overlay_video(result, config.mode)
    write_report(out, result.initial_scene, ensembled=True)  # last: it reads the files above


def write_overlay_video(result: BootstrapResult, mode: str) -> None:
    """overlay.mp4: the mosaics of :func:`overlay_frames` (with the GT flow and the EPE change
    when the scene has GT flow, over pixels valid and not occluded, as the EPE metrics) at
    :func:`video_fps` (2 fps for up to 10 mosaics, else as fast as lasts 5 s, at most the scene's fps)."""
    before, keep0 = result.initial_scene.pose_points(mode)
    after, keep1 = result.scene.pose_points(mode)
    layout = result.scene.pose_layout(mode)
    nan = float("nan")
    before = torch.where(keep0[..., None], before, nan)
    after = torch.where(keep1[..., None], after, nan)
    gt = result.scene.gt
    gt_flow, valid = (gt.flow, gt.flow_mask()) if gt is not None else (None, None)
    mosaic = overlay_frames(result.scene.frames, result.initial_flows, result.flows, before, after, layout,
                            gt_flow=gt_flow, gt_valid=valid, decisions=result.decisions,
                            others=other_people(result.scene, mode))  # fmt: skip
    write_video(mosaic, result.run_dir / "overlay.mp4", fps=video_fps(len(mosaic), result.scene.fps))
