"""Throughput of dataset runs: scenes per hour with 1 and 2 local workers (or Ray), and what a
3DPW-size run would cost at the measured seconds per frame.

Usage:
  python benchmarks/dataset_throughput.py [--scenes 4] [--frames 8] [--height 128] [--width 256]
      [--workers 1,2] [--engine local|ray] [--weights ../shared/checkpoints/raft-small.pth]
      [--mode 3d] [--out /tmp/dataset_throughput] [--json out.json]

Synthetic scenes (motions run, walk, jump, wave, ..., seeds 0..N-1; exact GT) saved as scene
folders; one fresh dataset run per worker count (the default preset; the CPU's cores split
between the workers). Scenes per hour = scenes / wall time of the whole run (start-ups, the
summary and, for workers > 0, the worker processes' imports included). The 3DPW estimate: the
test split's 35,515 frames (24 sequences; the paper's 3DPW evaluation) at the measured wall
seconds per frame, at this benchmark's frame size.
"""

from __future__ import annotations

import argparse
import json
import shutil
import time
from pathlib import Path

from lit_boot.data import save_scene
from lit_boot.dataset import Task, run_dataset
from lit_boot.synth import make_scene

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
MOTIONS = ("run", "walk", "jump", "wave", "turn")
PW3D_TEST_FRAMES = 35515


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenes", type=int, default=4)
    p.add_argument("--frames", type=int, default=8)
    p.add_argument("--height", type=int, default=128)
    p.add_argument("--width", type=int, default=256)
    p.add_argument("--workers", default="1,2", help="comma-separated worker counts, one run each")
    p.add_argument("--engine", default="local", choices=("local", "ray"))
    p.add_argument("--weights", default=str(SHARED / "checkpoints/raft-small.pth"))
    p.add_argument("--mode", default="3d", choices=("3d", "2d"))
    p.add_argument("--out", default="/tmp/dataset_throughput")
    p.add_argument("--json", default=None)
    args = p.parse_args()
    root = Path(args.out)
    shutil.rmtree(root, ignore_errors=True)
    tasks = []
    for i in range(args.scenes):
        scene = make_scene(motion=MOTIONS[i % len(MOTIONS)], frames=args.frames, height=args.height,
                           width=args.width, seed=i)  # fmt: skip
        save_scene(scene, root / "scenes" / f"s{i}")
        tasks.append(Task(name=f"s{i}", kind="scene", args={"path": str(root / "scenes" / f"s{i}")}))
    config = {"mode": args.mode, "video": False, "flow": {"weights": args.weights}}
    rows = []
    for workers in (int(w) for w in args.workers.split(",")):
        start = time.perf_counter()
        result = run_dataset(tasks, root / f"run_w{workers}", config, engine=args.engine, workers=workers)
        wall = time.perf_counter() - start
        frames = args.scenes * args.frames
        row = {"engine": args.engine, "workers": workers, "scenes": args.scenes, "done": result.counts["done"],
               "wall_s": wall, "scenes_per_hour": 3600 * args.scenes / wall, "s_per_frame": wall / frames,
               "pw3d_test_hours": PW3D_TEST_FRAMES * wall / frames / 3600,
               "epe_change_pct": 100 * (result.metrics["final"]["epe"] / result.metrics["initial"]["epe"] - 1)}  # fmt: skip
        rows.append(row)
        print(json.dumps(row), flush=True)
    settings = {k: v for k, v in vars(args).items() if k != "json"}
    if args.json:
        Path(args.json).write_text(json.dumps({"settings": settings, "rows": rows}, indent=1) + "\n")


if __name__ == "__main__":
    main()
