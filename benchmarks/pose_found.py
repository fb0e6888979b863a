"""Frames with a person's pose on the shared Sintel windows (issue 25's first bar): MediaPipe Pose
alone (video mode, the full-size frames) against MediaPipe with the person detector's crops where
it missed (lit_boot.estimate.estimate_poses(detector=..., crops=True); lit_boot.estimate.crop_pose),
and the top-down estimator of every person (estimate_poses(detector=..., people="all"): the
detector's tracks, MediaPipe on each one's crops; "top-down": frames where any person has a pose).

A frame counts when any keypoint has a confidence above 0. The windows are
benchmarks/real_data.py's SINTEL (every window in ../shared) and, with --heldout-root, HELDOUT.
Each result's keypoints are drawn on its frames into --out (judge them by eye: a crop may find a
non-human figure).

Usage:
  python benchmarks/pose_found.py [--windows alley_1,...] [--detector ../shared/checkpoints/yolox_nano.onnx]
      [--out /tmp/pose_found] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import torch

from lit_boot.data.readers import read_sintel
from lit_boot.data.visualize import write_png
from lit_boot.estimate import estimate_poses
from real_data import HELDOUT_ROOT, SHARED, SINTEL, windows


def draw(frames: torch.Tensor, est) -> torch.Tensor:
    """The frames (T, 3, H, W) with the keypoints that count (every person's; the main one's lime,
    the others' magenta), side by side, downscaled 2x."""
    from torchvision.utils import draw_keypoints

    out = []
    for t in range(frames.shape[0]):
        image = frames[t]
        for p, person in enumerate(est.people()):
            keep = person.keypoints_conf[t] > 0
            if keep.any():
                colour = "lime" if p == 0 else "magenta"
                image = draw_keypoints(image, person.keypoints2d[t][keep][None], colors=colour, radius=4)
        out.append(image[:, ::2, ::2])
    return torch.cat(out, dim=2)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--windows", default=",".join(w for w, *_ in SINTEL))
    p.add_argument("--heldout-root", default=str(HELDOUT_ROOT))
    p.add_argument("--detector", default=str(SHARED / "checkpoints/yolox_nano.onnx"))
    p.add_argument("--out", default="/tmp/pose_found")
    p.add_argument("--json", default=None)
    args = p.parse_args()
    rows, all_windows = [], windows(Path(args.heldout_root))
    Path(args.out).mkdir(parents=True, exist_ok=True)
    for window in args.windows.split(","):
        root, name, first, last, pass_name = all_windows[window]
        frames = read_sintel(root, name, first=first, last=last, pass_name=pass_name).frames
        alone = estimate_poses(frames)
        crops = estimate_poses(frames, detector=args.detector, crops=True)
        every = estimate_poses(frames, detector=args.detector, people="all")
        anyone = torch.stack([p.found() for p in every.people()]).any(0)
        row = {"window": window, "frames": frames.shape[0], "mediapipe": int(alone.found().sum()),
               "boxes": int((crops.person_boxes[:, 4] > 0).sum()), "with_crops": int(crops.found().sum()),
               "top_down": int(anyone.sum()), "top_down_people": every.num_people}  # fmt: skip
        rows.append(row)
        print(json.dumps(row), flush=True)
        for tag, est in (("mediapipe", alone), ("crops", crops), ("top_down", every)):
            write_png(Path(args.out) / f"{window}_{tag}.png", draw(frames, est))
    total = {k: sum(r[k] for r in rows) for k in ("frames", "mediapipe", "boxes", "with_crops", "top_down")}
    print("\n| window | frames | MediaPipe alone | person boxes | MediaPipe + crops | top-down, every person |")
    print("| --- | --- | --- | --- | --- | --- |")
    for r in [*rows, {"window": "all", **total}]:
        cells = (r[k] for k in ("window", "frames", "mediapipe", "boxes", "with_crops", "top_down"))
        print("| " + " | ".join(str(c) for c in cells) + " |")
    if args.json:
        Path(args.json).write_text(json.dumps({"settings": vars(args), "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
