"""Does the image evidence (lit_boot.flow.evidence) tell good flow from bad, without GT?

For seeded synthetic scenes (exact flow and occlusions) and the Sintel samples (final pass, the
pairs with a .flo): the mean census error (7x7 soft census, of 48) of the GT flow, of pretrained
RAFT's flow and of the zero flow, and the forward-backward occlusion estimate of RAFT (forward
and backward flows, UnFlow's alpha1 0.01, alpha2 0.5; targets leaving the image count as
occluded) against the GT occlusion mask: precision P and recall R, next to the occlusion rate
(a random mask's precision) and the flagged fraction (a random mask's recall).

Census means pool every selected pixel of every pair: "noc" = in bounds under the GT flow and
not occluded (synthetic: GT mask; Sintel: no occlusion masks in the samples, so every valid,
in-bounds pixel: occluded ones included), "person" = GT person mask too (synthetic only). The
Sintel samples carry no occlusion masks: their P/R column is against the pixels whose GT target
leaves the frame (certainly occluded; a lower bound on occlusions), marked "oof".

Usage:
  OMP_NUM_THREADS=1 python benchmarks/evidence_check.py [--updates 20] [--frames 5]
      [--size 256] [--sintel-size H,W (default: full 436x1024)] [--parts synth,sintel]
      [--weights ../shared/checkpoints/raft-small.pth]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import torch

from lit_boot.data.readers import list_sintel_scenes, read_sintel
from lit_boot.flow import load_raft, predict_flow
from lit_boot.flow.evidence import forward_backward_check, photometric_error, warp
from lit_boot.synth import make_scene

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
#: (motion, seed, extra make_scene options): static camera, pan, dolly, noise + blur.
SYNTH = [
    ("run", 1, {}),
    ("walk", 2, {"pan_deg_per_s": 20.0}),
    ("jump", 3, {}),
    ("wave", 4, {"amplitude": 1.5, "speed": 1.5}),
    ("turn", 5, {"dolly_mm_per_s": 400.0}),
    ("run", 6, {"noise_std": 2.0, "motion_blur": 3, "pan_deg_per_s": -15.0}),
]


class Sums:
    """Pixel-pooled sums of one group of pairs."""

    def __init__(self) -> None:
        self.values: dict[str, float] = {}

    def add(self, key: str, value: torch.Tensor | float) -> None:
        self.values[key] = self.values.get(key, 0.0) + float(value)

    def ratio(self, num: str, den: str) -> float:
        return self.values.get(num, 0.0) / self.values[den] if self.values.get(den) else float("nan")


def measure(sums: Sums, model, image1, image2, gt_flow, valid, occluded, person, updates: int) -> None:
    """Add one batch of pairs' census sums and occlusion counts to ``sums``."""
    with torch.no_grad():
        fw = predict_flow(model, image1, image2, num_flow_updates=updates)
        bw = predict_flow(model, image2, image1, num_flow_updates=updates)
    _, gt_inside = warp(image2, gt_flow)
    noc = valid & gt_inside & ~occluded
    flows = {"gt": gt_flow, "raft": fw, "zero": torch.zeros_like(gt_flow)}
    for name, flow in flows.items():
        error, inside = photometric_error(image1, image2, flow)
        for region, mask in (("noc", noc), ("person", None if person is None else noc & person)):
            if mask is not None:
                sums.add(f"{name}_{region}", error[mask & inside].sum())
                sums.add(f"{name}_{region}_n", (mask & inside).sum())
    _, flagged = forward_backward_check(fw, bw)
    sums.add("hits", (flagged & occluded & valid).sum())
    sums.add("flagged", (flagged & valid).sum())
    sums.add("occluded", (occluded & valid).sum())
    sums.add("pixels", valid.sum())
    sums.add("pairs", image1.shape[0])


def row(name: str, sums: Sums, seconds: float, oof: bool = False) -> str:
    census = [f"{sums.ratio(f'{flow}_{region}', f'{flow}_{region}_n'):5.2f}" for region in ("noc", "person")
              for flow in ("gt", "raft", "zero")]  # fmt: skip
    cells = [
        f"{name:52s} {int(sums.values.get('pairs', 0)):2d}",
        f"{' / '.join(census[:3])}  ",
        f"{' / '.join(census[3:]):21s}",
        f"{sums.ratio('occluded', 'pixels'):.4f}{'*' if oof else ' '}",
        f"{sums.ratio('flagged', 'pixels'):.4f}",
        f"{sums.ratio('hits', 'flagged'):.3f}",
        f"{sums.ratio('hits', 'occluded'):.3f}",
        f"{seconds:5.1f}",
    ]
    return "  ".join(cells)


HEADER = "  ".join([f"{'scene':52s} {'n':>2s}", f"{'census noc: gt / raft / zero':23s}", f"{'census person':21s}",
                    "occ rate", "flagged", "P    ", "R    ", "    s"])  # fmt: skip


def synth_part(model, args, total: Sums) -> None:
    for motion, seed, extra in SYNTH:
        start = time.perf_counter()
        scene = make_scene(motion=motion, seed=seed, frames=args.frames, height=args.size, width=args.size, **extra)
        gt, sums = scene.gt, Sums()
        valid = torch.ones_like(gt.flow_occluded)
        frames = scene.frames
        person = gt.person_mask[:-1]
        measure(sums, model, frames[:-1], frames[1:], gt.flow, valid, gt.flow_occluded, person, args.updates)
        for key, value in sums.values.items():
            total.add(key, value)
        label = f"synth {motion} seed={seed}" + "".join(f" {k}={v:g}" for k, v in extra.items())
        print(row(label, sums, time.perf_counter() - start), flush=True)


def sintel_part(model, args, total: Sums) -> None:
    root = Path(args.sintel)
    size = tuple(int(v) for v in args.sintel_size.split(",")) if args.sintel_size else None
    for name in list_sintel_scenes(root):
        start, sums = time.perf_counter(), Sums()
        numbers = sorted(int(f.stem.split("_")[1]) for f in (root / "training/flow" / name).glob("frame_*.flo"))
        for first in numbers:  # one pair at a time: a sample's frames may have gaps
            scene = read_sintel(root, name, first=first, last=first + 1, size=size)
            frames, gt = scene.frames, scene.gt
            _, inside = warp(frames[1:], gt.flow)
            measure(sums, model, frames[:1], frames[1:], gt.flow, gt.flow_valid, ~inside, None, args.updates)
        for key, value in sums.values.items():
            total.add(key, value)
        label = f"sintel {name} {frames.shape[-1]}x{frames.shape[-2]} pairs from {numbers}"
        print(row(label, sums, time.perf_counter() - start, oof=True), flush=True)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--parts", default="synth,sintel")
    p.add_argument("--updates", type=int, default=20, help="RAFT updates, forward and backward")
    p.add_argument("--frames", type=int, default=5, help="frames per synthetic scene")
    p.add_argument("--size", type=int, default=256, help="synthetic frame height and width, px")
    p.add_argument("--sintel", default=str(SHARED / "data/sintel_samples"))
    p.add_argument("--sintel-size", default=None, help="H,W (default: full size, 436,1024)")
    p.add_argument("--weights", default=str(SHARED / "checkpoints/raft-small.pth"))
    args = p.parse_args()
    print(f"settings: {vars(args)}, torch threads {torch.get_num_threads()}", flush=True)
    model = load_raft("raft_small", args.weights).eval()
    print(HEADER, flush=True)
    for part, fn in (("synth", synth_part), ("sintel", sintel_part)):
        if part in args.parts:
            total = Sums()
            fn(model, args, total)
            print(row(f"{part}: all pairs pooled", total, 0.0, oof=part == "sintel"), flush=True)
    print("census: mean 7x7 soft-census error (of 48), lower is better; P/R: fb occlusion estimate "
          "vs GT occlusions (* Sintel: vs GT targets leaving the frame, no occlusion masks)")  # fmt: skip


if __name__ == "__main__":
    main()
