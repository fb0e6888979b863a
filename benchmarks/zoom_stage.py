"""The zoom stage alone, with variants of its settings (issue 24, part 1): what it gains and costs.

For every pair: pretrained RAFT's flow (32 updates), then the zoom stage
(lit_boot.bootstrap.zoom.zoom_flows) with each variant of ZoomConfig; the EPE change against
RAFT's and the zoom's seconds against RAFT's.

- ``--source sintel``: the Sintel windows of benchmarks/real_data.py (SINTEL in ../shared, HELDOUT
  under --heldout-root), the person's boxes from the YOLOX detector on the full-size frames
  (lit_boot.estimate.person_boxes), the GT pairs only; EPE over every valid pixel (Sintel's "all").
- ``--source synthetic``: the suite scenes of benchmarks/bootstrap_suite.py (``--set tuning``:
  SCENES, ``validation``: VALIDATION; 8 frames, 128x256), the boxes around the pose of ``--mode``
  (3d: the projected METRO-like joints, 2d: the DCPose-like keypoints); EPE over valid
  non-occluded pixels, all / person / background, mean over scenes. ``--set small`` and
  ``small_validation``: SMALL and SMALL_VALIDATION, small people at 256x512, 4 frames.

A variant's ``max_cost`` "auto" (the default) is the mode's (ZoomConfig.for_mode): 2D's for the
Sintel windows (as real_data.py runs them), ``--mode``'s for the synthetic scenes.

Usage:
  python benchmarks/zoom_stage.py --source sintel|synthetic [--windows alley_1,...] [--size 218,512|full]
      [--set tuning|validation|small|small_validation] [--mode 3d|2d]
      [--variants '{"default": {}, "wide": {"context": 0.5}}']
      [--weights ../shared/checkpoints/raft-small.pth] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import torch

from bootstrap_suite import SCENES, VALIDATION
from lit_boot.bootstrap.config import ZoomConfig
from lit_boot.bootstrap.zoom import person_boxes as pose_boxes
from lit_boot.bootstrap.zoom import zoom_flows
from lit_boot.core import Scene
from lit_boot.flow import load_raft, predict_flow
from lit_boot.synth import EstimateConfig, make_scene
from lit_boot.synth.config import ACCURATE_DETECTOR
from real_data import HELDOUT_ROOT, SHARED, SINTEL, window_with_boxes


@torch.no_grad()
def raft_flows(model, scene: Scene, pairs: list[int]) -> torch.Tensor:
    return torch.stack([predict_flow(model, scene.frames[t : t + 1], scene.frames[t + 1 : t + 2])[0].float()
                        for t in pairs])  # fmt: skip


def epe(flows: torch.Tensor, gt: torch.Tensor, mask: torch.Tensor) -> float:
    return float((flows - gt).norm(dim=1)[mask].mean())


def sintel_cases(args, model):
    """(name, scene, pairs, boxes (T, 5), masks {"all": (P, H, W)}) per window."""
    size = None if args.size == "full" else tuple(int(v) for v in args.size.split(","))
    for window in args.windows.split(","):
        scene, boxes = window_with_boxes(window, size, args.detector, Path(args.heldout_root))
        pairs = [t for t in range(scene.num_frames - 1) if scene.gt.flow_valid[t].any()]
        yield window, scene, pairs, boxes, {"all": scene.gt.flow_valid[pairs]}


#: Small people (issue 24: resolution where the person is, chosen from the person's size): a
#: tuning set and a validation set, 256x512, 4 frames, the person filling 25-35% of the height.
SMALL = [("small_walk_s50", dict(motion="walk", seed=50, fill=0.3)),
         ("small_run_s51", dict(motion="run", seed=51, fill=0.3)),
         ("small_jump_s52", dict(motion="jump", seed=52, fill=0.3)),
         ("small_walk_s53", dict(motion="walk", seed=53, fill=0.3))]
SMALL_VALIDATION = [("small_run_s54", dict(motion="run", seed=54, fill=0.25), "realistic"),
                    ("small_wave_s55", dict(motion="wave", seed=55, fill=0.35), "accurate"),
                    ("small_turn_s56", dict(motion="turn", seed=56, fill=0.3), "realistic"),
                    ("small_walk_s57", dict(motion="walk", seed=57, fill=0.25, heading_deg=40.0), "accurate")]
SETS = {"tuning": SCENES, "validation": VALIDATION, "small": SMALL, "small_validation": SMALL_VALIDATION}


def synthetic_cases(args, model):
    small = args.set.startswith("small")
    size = dict(frames=4, height=256, width=512) if small else dict(frames=8, height=128, width=256)
    for name, spec, *own in SETS[args.set]:
        estimates = EstimateConfig(**(ACCURATE_DETECTOR if own and own[0] == "accurate" else {}))
        scene = make_scene(**size, estimates=estimates, **spec)
        valid, person = scene.gt.flow_mask(), scene.gt.person_mask[:-1]
        pairs = list(range(scene.num_frames - 1))
        yield name, scene, pairs, pose_boxes(scene, args.mode), {"all": valid, "person": valid & person,
                                                                    "background": valid & ~person}  # fmt: skip


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--source", required=True, choices=("sintel", "synthetic"))
    p.add_argument("--windows", default=",".join(w for w, *_ in SINTEL))
    p.add_argument("--heldout-root", default=str(HELDOUT_ROOT))
    p.add_argument("--size", default="218,512")
    p.add_argument("--set", default="tuning", choices=tuple(SETS))
    p.add_argument("--mode", default="3d", choices=("3d", "2d"))
    p.add_argument("--variants", default='{"default": {}}', help="name -> ZoomConfig fields, JSON")
    p.add_argument("--weights", default=str(SHARED / "checkpoints/raft-small.pth"))
    p.add_argument("--detector", default=str(SHARED / "checkpoints/yolox_nano.onnx"))
    p.add_argument("--json", default=None)
    args = p.parse_args()
    print(f"settings: {vars(args)}", flush=True)
    torch.manual_seed(0)
    model = load_raft("raft_small", args.weights).eval()
    mode = "2d" if args.source == "sintel" else args.mode  # the Sintel runs are 2D (real_data.py)
    variants = {name: ZoomConfig(**fields).for_mode(mode) for name, fields in json.loads(args.variants).items()}
    rows, seconds = [], {"raft": 0.0, **dict.fromkeys(variants, 0.0)}
    cases = sintel_cases(args, model) if args.source == "sintel" else synthetic_cases(args, model)
    for name, scene, pairs, boxes, masks in cases:
        start = time.perf_counter()
        base = raft_flows(model, scene, pairs)
        seconds["raft"] += time.perf_counter() - start
        gt = scene.gt.flow[pairs]
        row = {"case": name, "raft": {k: epe(base, gt, m) for k, m in masks.items()}}
        for variant, config in variants.items():
            start = time.perf_counter()
            flows = torch.cat([zoom_flows(model, Scene(frames=scene.frames[t : t + 2]), base[i : i + 1],
                                          boxes[t : t + 2], config)[0] for i, t in enumerate(pairs)])  # fmt: skip
            seconds[variant] += time.perf_counter() - start
            row[variant] = {k: 100 * (epe(flows, gt, m) / row["raft"][k] - 1) for k, m in masks.items()}
        rows.append(row)
        print(json.dumps(row), flush=True)
    keys = list(rows[0]["raft"])
    print(f"\n| variant | {' | '.join(f'{k} mean (worst)' for k in keys)} | seconds / RAFT's |")
    print("| --- " * (2 + len(keys)) + "|")
    for variant in variants:
        cells = [f"{sum(r[variant][k] for r in rows) / len(rows):+.1f}% ({max(r[variant][k] for r in rows):+.1f}%)"
                 for k in keys]  # fmt: skip
        print(f"| {variant} | {' | '.join(cells)} | {seconds[variant] / seconds['raft']:.2f} |")
    if args.json:
        Path(args.json).write_text(json.dumps({"settings": vars(args), "rows": rows, "seconds": seconds}, indent=1))


if __name__ == "__main__":
    main()
