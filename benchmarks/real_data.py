"""The method on real data, with MediaPipe Pose as the only pose source (the mediapipe extra).

- Sintel samples where MediaPipe finds the person (alley_1, market_5, temple_3; final pass):
  2D-only bootstrapping (KeypointRefiner, 50 flow epochs by default); EPE of the pairs with GT,
  before (pretrained RAFT) and after. "all" = every valid pixel, occluded ones included (Sintel's
  convention); "noc" = valid and not occluded (lit-boot's run metrics). keypoints_gt_pair.png in
  each run folder shows MediaPipe's keypoints on the GT pair's first frame.
- The basketball clip (no GT): the whole 3D method on its first frames; the flow-pose agreement
  (L_opt residual, px) before and after, and the overlay video in the run folder.

Usage:
  python benchmarks/real_data.py [--parts sintel,basketball] [--scenes alley_1,market_5,temple_3]
      [--sintel-size 218,512] [--flow '{"sketch": {"max_disagreement_px": 3}}']
      [--epochs N (default: the mode's)] [--pose-steps 1500] [--basketball-frames 16]
      [--basketball-resize 270] [--weights ../shared/checkpoints/raft-small.pth]
      [--out /tmp/real_data] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

import torch

from lit_boot.bootstrap import bootstrap
from lit_boot.bootstrap.outputs import speed_summary
from lit_boot.data.readers import read_sintel, read_video
from lit_boot.data.visualize import scene_preview, write_png
from lit_boot.estimate import estimate_poses
from lit_boot.metrics import flow_errors

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
SINTEL = [("alley_1", 1, 4), ("market_5", 1, 4), ("temple_3", 21, 24)]


def gt_pair_epe(flows: torch.Tensor, scene) -> dict[str, float]:
    """EPE over the pairs with GT: all valid pixels, and valid non-occluded ones."""
    gt = scene.gt
    valid = gt.flow_valid
    noc = valid & ~gt.flow_occluded if gt.flow_occluded is not None else valid
    return {"all": float(flow_errors(flows, gt.flow, valid)["epe"]), "noc": float(flow_errors(flows, gt.flow, noc)["epe"])}


def run(scene, out: Path, mode: str, args, video: bool) -> tuple[dict, object]:
    shutil.rmtree(out, ignore_errors=True)
    flow = {"weights": args.weights, **json.loads(args.flow)}
    result = bootstrap(scene, out, mode=mode, flow=flow, flow_epochs=args.epochs,
                       pose_steps=args.pose_steps, progress_bar=False, video=video)  # fmt: skip
    return speed_summary(result), result


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--parts", default="sintel,basketball")
    p.add_argument("--scenes", default=",".join(name for name, _, _ in SINTEL), help="Sintel samples to run")
    p.add_argument("--flow", default="{}", help='FlowTTT options over the preset\'s, JSON: {"sketch": {"max_disagreement_px": 3}}')
    p.add_argument("--sintel-size", default="218,512", help="H,W (the samples are 436,1024)")
    p.add_argument("--epochs", type=int, default=None, help="flow epochs per stage (default: 50 in 2D, 8 in 3D)")
    p.add_argument("--pose-steps", type=int, default=1500)
    p.add_argument("--basketball-frames", type=int, default=16)
    p.add_argument("--basketball-resize", type=int, default=270, help="frame height, px")
    p.add_argument("--weights", default=str(SHARED / "checkpoints/raft-small.pth"))
    p.add_argument("--out", default="/tmp/real_data")
    p.add_argument("--json", default=None)
    args = p.parse_args()
    print(f"settings: {vars(args)}", flush=True)
    rows = []
    if "sintel" in args.parts:
        size = tuple(int(v) for v in args.sintel_size.split(","))
        for name, first, last in (s for s in SINTEL if s[0] in args.scenes.split(",")):
            root = SHARED / "data/sintel_samples"
            # MediaPipe on the full-size frames (it misses small people), poses rescaled to `size`
            poses = estimate_poses(read_sintel(root, name, first=first, last=last))
            scene = poses.apply_to(read_sintel(root, name, first=first, last=last, size=size))
            speed, result = run(scene, Path(args.out) / name, "2d", args, video=False)
            # the detections on the GT pair's first frame, to judge them by eye (frame | GT flow | keypoints)
            first_gt = scene.metadata["frames"].index(scene.metadata["gt_pairs"][0][0])
            write_png(Path(args.out) / name / "keypoints_gt_pair.png", scene_preview(scene, first_gt))
            row = {"scene": name, "found": int(poses.found().sum()), "frames": scene.num_frames,
                   "before": gt_pair_epe(result.initial_flows, scene), "after": gt_pair_epe(result.flows, scene),
                   "agreement": [result.history[0]["agreement_px"], result.history[-1]["agreement_px"]], "speed": speed}  # fmt: skip
            rows.append(row)
            print(json.dumps(row), flush=True)
    if "basketball" in args.parts:
        path = SHARED / "data/videos/basketball_1080p_89f.mp4"
        scene = read_video(path, max_frames=args.basketball_frames, resize=args.basketball_resize)
        poses = estimate_poses(scene)
        scene = poses.apply_to(scene)
        speed, result = run(scene, Path(args.out) / "basketball", "3d", args, video=True)
        row = {"scene": "basketball", "found": int(poses.found().sum()), "frames": scene.num_frames,
               "agreement": [result.history[0]["agreement_px"], result.history[-1]["agreement_px"]],
               "overlay": str(result.run_dir / "overlay.mp4"), "speed": speed}  # fmt: skip
        rows.append(row)
        print(json.dumps(row), flush=True)
    print("\n| scene | frames (person found) | EPE all before -> after | EPE noc before -> after | agreement px | x RAFT |")
    print("| --- | --- | --- | --- | --- | --- |")
    for r in rows:
        epe = [f"{r['before'][k]:.3f} -> {r['after'][k]:.3f}" if "before" in r else "no GT" for k in ("all", "noc")]
        a = r["agreement"]
        print(f"| {r['scene']} | {r['frames']} ({r['found']}) | {epe[0]} | {epe[1]} | {a[0]:.2f} -> {a[1]:.2f} "
              f"| {r['speed']['ratio_to_raft']:.1f} |")  # fmt: skip
    if args.json:
        Path(args.json).write_text(json.dumps({"settings": vars(args), "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
