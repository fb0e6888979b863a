"""Cost of generating synthetic scenes (wall time, CPU).

Usage: python benchmarks/synth_speed.py [--repeats 3] [--threads N]
Prints a Markdown table: size, frames, motion, seconds (median of the repeats), ms per frame.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time
from pathlib import Path

import torch

from lit_boot.synth import make_scene

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
CASES = [
    dict(height=64, width=64, frames=4, motion="walk"),
    dict(height=256, width=256, frames=24, motion="run"),
    dict(height=436, width=1024, frames=50, motion="walk"),
    dict(height=436, width=1024, frames=50, motion="bvh", bvh=str(SHARED / "data/mocap/cmu_131/131_01.bvh"), bvh_start=2.0),
    dict(height=436, width=1024, frames=50, motion="run", pan_deg_per_s=10.0, motion_blur=3),
]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--threads", type=int, default=torch.get_num_threads())
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    print(f"CPU: {platform.processor() or platform.machine()}, torch {torch.__version__}, {args.threads} threads, seed 0")
    print("| size | frames | motion | extras | seconds | ms/frame |")
    print("| --- | --- | --- | --- | --- | --- |")
    for case in CASES:
        if case["motion"] == "bvh" and not Path(case["bvh"]).exists():
            print(f"| skipped: {case['bvh']} missing |")
            continue
        times = []
        for _ in range(args.repeats):
            start = time.perf_counter()
            make_scene(seed=0, **case)
            times.append(time.perf_counter() - start)
        t = statistics.median(times)
        extras = ", ".join(f"{k}={v}" for k, v in case.items() if k in ("pan_deg_per_s", "motion_blur", "bvh_start"))
        print(f"| {case['height']}x{case['width']} | {case['frames']} | {case['motion']} | {extras} | {t:.2f} | {1000 * t / case['frames']:.0f} |")


if __name__ == "__main__":
    main()
