"""The people tracker's own time (lit_boot.estimate.track_people, boxes alone) on synthetic
detections: P people walking at constant speeds across a 1900x900 frame (boxes 60x160 px, so
many cross), each box missed with probability 0.1, each frame's boxes shuffled; seed 0. Prints
seconds per frame for each beam (1: frame by frame).

Usage: OMP_NUM_THREADS=1 python benchmarks/tracker_speed.py [--people 5,10,20] [--frames 200] [--beams 1,16]
"""

from __future__ import annotations

import argparse
import time

import torch

from lit_boot.estimate import track_people


def detections(people: int, frames: int, g: torch.Generator) -> list[torch.Tensor]:
    """Per frame (N_t, 5) boxes x0, y0, x1, y1 px, score of ``people`` walkers."""
    x0, y0 = torch.rand(people, generator=g) * 1800, torch.rand(people, generator=g) * 900
    vx = (torch.rand(people, generator=g) - 0.5) * 20
    out = []
    for t in range(frames):
        rows = []
        for p in range(people):
            if torch.rand(1, generator=g).item() < 0.1:
                continue
            cx, cy = float(x0[p] + vx[p] * t) % 1900, float(y0[p])
            rows.append([cx - 30, cy - 80, cx + 30, cy + 80, 0.9])
        out.append(torch.tensor(rows).reshape(-1, 5)[torch.randperm(len(rows), generator=g)])
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--people", default="5,10,20")
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--beams", default="1,16")
    args = parser.parse_args()
    track_people(detections(2, 3, torch.Generator().manual_seed(1)))  # imports and first calls
    print("| people | " + " | ".join(f"beam {b}: ms per frame" for b in args.beams.split(",")) + " |")
    print("| --- |" + " --- |" * len(args.beams.split(",")))
    for people in (int(v) for v in args.people.split(",")):
        dets = detections(people, args.frames, torch.Generator().manual_seed(0))
        cells = []
        for beam in (int(v) for v in args.beams.split(",")):
            start = time.perf_counter()
            tracks = track_people(dets, beam=beam)
            cells.append(f"{1000 * (time.perf_counter() - start) / args.frames:.1f} ({tracks.shape[0]} tracks)")
        print(f"| {people} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
