"""The YOLOX person detector on the Sintel samples in ../shared: frames with a person, and speed.

For each window of ../shared/data/sintel_samples/training/final/* (its frames, full size): the
frames where :class:`lit_boot.estimate.PersonDetector` finds a person (score above ``--score``),
the best score per frame, the frames the main-person track covers (:func:`main_person_boxes`), and
the detector's seconds per frame (letterbox + onnxruntime + decoding, after one warm-up frame).

Usage:
  OMP_NUM_THREADS=1 python benchmarks/detector_check.py [--model PATH] [--threads 1] [--score 0.25]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import torch

from lit_boot.data import read_png
from lit_boot.estimate import PersonDetector, main_person_boxes

SHARED = Path(__file__).resolve().parents[2] / "shared"


def windows(root: Path) -> list[tuple[str, list[Path]]]:
    """Each scene's runs of consecutive frames (market_5 holds two: 0001-0004 and 0008-0011)."""
    out = []
    for scene in sorted(p for p in root.iterdir() if p.is_dir()):
        paths = sorted(scene.glob("frame_*.png"))
        numbers = [int(p.stem.split("_")[1]) for p in paths]
        cuts = [0] + [i for i in range(1, len(paths)) if numbers[i] != numbers[i - 1] + 1] + [len(paths)]
        many = len(cuts) > 2
        for a, b in zip(cuts, cuts[1:]):
            out.append((f"{scene.name}_{numbers[a]:04d}-{numbers[b - 1]:04d}" if many else scene.name, paths[a:b]))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default=str(SHARED / "checkpoints/yolox_nano.onnx"))
    parser.add_argument("--frames", default=str(SHARED / "data/sintel_samples/training/final"))
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--score", type=float, default=0.25)
    args = parser.parse_args()
    det = PersonDetector(args.model, score=args.score, threads=args.threads)
    print(f"{det}, {args.threads} thread(s), torch threads {torch.get_num_threads()}")
    rows, seconds, total, with_person = [], [], 0, 0
    for name, paths in windows(Path(args.frames)):
        frames = torch.stack([read_png(p) for p in paths])
        det.detect(frames[0])  # warm-up (not timed)
        found = []
        for frame in frames:
            start = time.perf_counter()
            found.append(det.detect(frame))
            seconds.append(time.perf_counter() - start)
        _, tracked = main_person_boxes(found)
        hits = sum(len(f) > 0 for f in found)
        best = " ".join(f"{float(f[0, 4]):.2f}" if len(f) else "-" for f in found)
        rows.append(f"| {name} | {frames.shape[-1]}x{frames.shape[-2]} | {hits} of {len(found)} | "
                    f"{int(tracked.sum())} of {len(found)} | {best} |")  # fmt: skip
        total, with_person = total + len(found), with_person + hits
    print("| window | size | frames with a person | main-person track | best score per frame |")
    print("| --- | --- | --- | --- | --- |")
    print("\n".join(rows))
    s = torch.tensor(seconds)
    print(f"\nframes with a person: {with_person} of {total}; seconds per frame: mean {float(s.mean()):.3f}, "
          f"median {float(s.median()):.3f}, max {float(s.max()):.3f}")  # fmt: skip


if __name__ == "__main__":
    main()
