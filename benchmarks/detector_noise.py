"""How bad is a real 2D pose detector? MediaPipe Pose on the real clips and Sintel samples in
../shared, measured the same way as the synthetic DCPose-like keypoints (lit_boot.synth), so the
simulated detector can be set from it (issue 13, part 4).

Per clip, over COCO-17 keypoints (MediaPipe's, converted by lit_boot.estimate):
- found: frames where the detector returned a person;
- confident: keypoints with confidence > 0.5, over found frames;
- height: median vertical extent (px) of the confident keypoints (the synthetic model's unit:
  its pixel settings are for a person 256 px tall);
- jitter: per-axis noise from second differences of each confident keypoint track,
  d = p(t+1) - 2 p(t) + p(t-1). For white noise of per-axis std s, |d| is Rayleigh with median
  1.1774 sqrt(6) s, so s = median|d| / 2.884 (robust to jumps); true motion adds to it, so it is
  an upper bound. Given in px and at 256 px tall (``s x 256 / height``: comparable with
  EstimateConfig.keypoint_noise_px);
- jumps: share of second differences above 6x their median (single-frame outliers: the
  simulated ``jump_prob`` shows up here about 3x, once per frame of the triplet it touches).
The same numbers for the synthetic scenes of benchmarks/bootstrap_suite.py: the GT keypoints
(what motion alone contributes) and the simulated DCPose-like keypoints (EstimateConfig defaults).

Usage:
  OMP_NUM_THREADS=1 python benchmarks/detector_noise.py [--frames 8] [--basketball-resize 540]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bootstrap_suite import SCENES, SHARED  # noqa: E402

from lit_boot.data.readers import read_sintel, read_video  # noqa: E402
from lit_boot.synth import make_scene  # noqa: E402

SINTEL = [("alley_1", 1, 4), ("ambush_4", 3, 8), ("bandage_1", 34, 37), ("market_5", 1, 4), ("market_5", 8, 11),
          ("temple_3", 21, 24)]  # fmt: skip
RAYLEIGH_MEDIAN = 1.1774 * 6**0.5  # median |second difference| / per-axis std of white noise


def stats(points: torch.Tensor, conf: torch.Tensor, threshold: float = 0.5) -> dict[str, float]:
    """The module docstring's numbers for keypoints (T, K, 2) px and confidences (T, K)."""
    found = conf.amax(1) > 0
    ok = conf > threshold
    heights = [float(p[k, 1].max() - p[k, 1].min()) for p, k in zip(points, ok) if k.sum() >= 2]
    height = float(torch.tensor(heights).median()) if heights else float("nan")
    d = points[2:] - 2 * points[1:-1] + points[:-2]
    both = ok[2:] & ok[1:-1] & ok[:-2]
    size = d.norm(dim=-1)[both]
    jitter = float(size.median()) / RAYLEIGH_MEDIAN if size.numel() else float("nan")
    jumps = float((size > 6 * size.median()).float().mean()) if size.numel() else float("nan")
    return {"frames": points.shape[0], "found": float(found.float().mean()),
            "confident": float(ok[found].float().mean()) if found.any() else 0.0, "height_px": height,
            "jitter_px": jitter, "jitter_at_256": jitter * 256 / height if heights else float("nan"),
            "jumps": jumps, "triplets": int(size.numel())}  # fmt: skip


def real_clips(args) -> list[tuple[str, torch.Tensor]]:
    """(name, frames (T, 3, H, W) uint8) of every real clip."""
    clips = []
    root = SHARED / "data/sintel_samples"
    for name, first, last in SINTEL:
        clips.append((f"sintel {name} {first}-{last}", read_sintel(root, name, first=first, last=last).frames))
    videos = SHARED / "data/videos"
    resize = args.basketball_resize or None
    clips.append(("basketball 89f", read_video(videos / "basketball_1080p_89f.mp4", resize=resize)))
    clips.append(("football 10f", read_video(videos / "football_720p_10f")))
    clips.append(("street 5f (5 fps)", read_video(videos / "street_540p_5f.mp4")))
    return clips


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--frames", type=int, default=8, help="frames of each synthetic scene")
    p.add_argument("--height", type=int, default=128)
    p.add_argument("--width", type=int, default=256)
    p.add_argument("--basketball-resize", type=int, default=540, help="frame height MediaPipe sees (0: 1080)")
    args = p.parse_args()
    from lit_boot.estimate import estimate_poses

    rows = []
    for name, frames in real_clips(args):
        est = estimate_poses(frames)
        rows.append((f"MediaPipe: {name}", stats(est.keypoints2d.float(), est.keypoints_conf.float())))
        print(rows[-1], flush=True)
    for name, spec in SCENES:
        scene = make_scene(frames=args.frames, height=args.height, width=args.width, **spec)
        gt = scene.gt.keypoints2d.float()
        rows.append((f"synthetic GT: {name}", stats(gt, torch.ones(gt.shape[:2]))))
        rows.append((f"synthetic DCPose-like: {name}", stats(scene.keypoints2d.float(), scene.keypoints_conf.float())))
    print("\n| clip | frames | found | confident | height px | jitter px | jitter at 256 px tall | jumps | triplets |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for name, s in rows:
        print(f"| {name} | {s['frames']} | {s['found']:.2f} | {s['confident']:.2f} | {s['height_px']:.0f} | "
              f"{s['jitter_px']:.2f} | {s['jitter_at_256']:.2f} | {s['jumps']:.3f} | {s['triplets']} |")  # fmt: skip


if __name__ == "__main__":
    main()
