"""Every person of the shared no-GT videos before and after the method (issue 25's bar on the
videos): each tracked person's pose (estimate_poses(people="all"), top-down), the 2D default run
(every person painted), and per person the census error of frame t against frame t+1 warped by
the flow (0..48, lower is better; lit_boot.flow.evidence.photometric_error) inside that person's
box, for pretrained RAFT's flow and the final flow. Also the people's counts and the wall time.

Usage:
  OMP_NUM_THREADS=1 python benchmarks/people_real.py [--videos street,football,basketball]
      [--resize 360] [--max-frames 8] [--weights ../shared/checkpoints/raft-small.pth] [--config JSON]
      [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import shutil
import time
from pathlib import Path

import torch

from lit_boot.bootstrap import bootstrap
from lit_boot.data.readers.video import read_video
from lit_boot.estimate import estimate_poses
from lit_boot.flow.evidence import photometric_error
from people_tracking import VIDEOS
from real_data import SHARED


def box_census(frames: torch.Tensor, flows: torch.Tensor, boxes: torch.Tensor) -> float | None:
    """Mean census error (0..48) inside the person's box of frame t over the pairs with a box."""
    error, inside = photometric_error(frames[:-1], frames[1:], flows)
    values = []
    for t in range(flows.shape[0]):
        if boxes[t, 4] <= 0:
            continue
        x0, y0, x1, y1 = (int(round(float(v))) for v in boxes[t, :4])
        region = (slice(max(y0, 0), y1 + 1), slice(max(x0, 0), x1 + 1))
        keep = inside[t][region]
        if keep.any():
            values.append(error[t][region][keep])
    return float(torch.cat(values).float().mean()) if values else None


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--videos", default="street,football,basketball")
    p.add_argument("--resize", type=int, default=360)
    p.add_argument("--max-frames", type=int, default=8)
    p.add_argument("--weights", default=str(SHARED / "checkpoints/raft-small.pth"))
    p.add_argument("--out", default="/tmp/people_real")
    p.add_argument("--config", default="{}",
                   help='more BootstrapConfig options, JSON, e.g. \'{"zoom": {"small_scale": 4}}\'')
    p.add_argument("--json", default=None)
    args = p.parse_args()
    rows = []
    for name in args.videos.split(","):
        scene = read_video(SHARED / VIDEOS[name], max_frames=args.max_frames, resize=args.resize)
        start = time.perf_counter()
        est = estimate_poses(scene.frames, people="all", detector=SHARED / "checkpoints/yolox_nano.onnx")
        scene = est.apply_to(scene)
        estimate_s = time.perf_counter() - start
        out = Path(args.out) / name
        shutil.rmtree(out, ignore_errors=True)
        start = time.perf_counter()
        result = bootstrap(scene, out, mode="2d", flow={"weights": args.weights}, progress_bar=False, video=False,
                           **json.loads(args.config))
        run_s = time.perf_counter() - start
        people = []
        for person in scene.people():
            before = box_census(scene.frames, result.initial_flows, person.person_boxes)
            after = box_census(scene.frames, result.flows, person.person_boxes)
            people.append({"track_id": person.track_id, "pose_frames": int((person.keypoints_conf > 0).any(-1).sum()),
                           "census_before": before, "census_after": after,
                           "change_pct": None if before is None else round(100 * (after / before - 1), 2)})  # fmt: skip
        row = {"video": name, "frames": scene.num_frames, "size": [scene.height, scene.width],
               "people": scene.num_people, "estimate_s": round(estimate_s, 1), "run_s": round(run_s, 1),
               "per_person": people}  # fmt: skip
        rows.append(row)
        print(json.dumps(row), flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps({"settings": vars(args), "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
