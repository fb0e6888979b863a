"""RAFT tuned on its own confirmed flow, no sketch (issue 24, part 2: pseudo-labels).

For each scene: pretrained RAFT's flow (32 updates) forward and backward; the pseudo-labels are
its forward flow where it passes the forward-backward check (``fb``; lit_boot.flow.evidence.
forward_backward_check), and also has a 7x7 census error below 8 of 48 (``census``), or every
pixel (``all``). RAFT (every weight, Adam lr 1e-5, 20 updates from zero, SmoothL1 on the final
prediction, the authors' fine-tune) is trained on them, each pair mirrored left-right half of the
time (a view whose labels are known: RAFT's prediction and its training target differ only
there), for ``--epochs`` epochs; then predicted again with 32 updates. Reported: the all-pixel
EPE (valid GT pixels) and the mean census error against RAFT's, after half and all the epochs.

Usage:
  OMP_NUM_THREADS=1 python benchmarks/pseudo_labels.py --variant fb|census|all
      [--scenes sprint_s9,fast_blur_s8,market_5b,ambush_4,alley_1] [--epochs 10] [--lr 1e-5]
Synthetic scenes are bootstrap_suite.py's (8 frames, 128x256); Sintel windows real_data.py's at 218x512.
"""

from __future__ import annotations

import argparse
import json
import time

import torch
import torch.nn.functional as F

from bootstrap_suite import SCENES
from lit_boot.data.readers import read_sintel
from lit_boot.flow import load_raft, predict_flow
from lit_boot.flow.evidence import forward_backward_check, photometric_error
from lit_boot.synth.generator import make_scene
from real_data import SHARED, windows

MIRROR = torch.tensor([-1.0, 1.0])[:, None, None]  # a left-right flip negates u


def load(name: str):
    if name in dict(SCENES):
        return make_scene(frames=8, height=128, width=256, **dict(SCENES)[name])
    root, scene, first, last, pass_name = windows()[name]
    return read_sintel(root, scene, first=first, last=last, pass_name=pass_name, size=(218, 512))


def flows(model, frames: torch.Tensor, backward: bool = False) -> torch.Tensor:
    """(T-1, 2, H, W) px, 32 updates, t -> t+1 (t+1 -> t with ``backward``)."""
    with torch.no_grad():
        pairs = [(frames[t + 1 : t + 2], frames[t : t + 1]) if backward else (frames[t : t + 1], frames[t + 1 : t + 2])
                 for t in range(frames.shape[0] - 1)]  # fmt: skip
        return torch.cat([predict_flow(model, a, b, 32).float() for a, b in pairs])


def labels(frames: torch.Tensor, base: torch.Tensor, backward: torch.Tensor, variant: str) -> torch.Tensor:
    """(T-1, H, W) bool: the pixels whose base flow is a pseudo-label."""
    if variant == "all":
        return torch.ones(base.shape[0], *base.shape[-2:], dtype=torch.bool)
    keep = ~forward_backward_check(base, backward)[1]
    if variant == "census":
        error, inside = photometric_error(frames[:-1], frames[1:], base)
        keep &= (error < 8) & inside
    return keep


def run_scene(name: str, args) -> dict:
    scene = load(name)
    frames, gt = scene.frames, scene.gt
    epe = lambda f: float((f - gt.flow).norm(dim=1)[gt.flow_valid].mean())  # noqa: E731
    model = load_raft("raft_small", args.weights).eval()
    base = flows(model, frames)
    held = labels(frames, base, flows(model, frames, backward=True), args.variant)
    census0, epe0 = float(photometric_error(frames[:-1], frames[1:], base)[0].mean()), epe(base)
    row = {"scene": name, "variant": args.variant, "raft_epe": round(epe0, 3), "held": round(float(held.float().mean()), 3)}
    optimizer = torch.optim.Adam(model.parameters(), lr=args.lr)
    start = time.perf_counter()
    for epoch in range(1, args.epochs + 1):
        model.train()
        for t in torch.randperm(base.shape[0]).tolist():
            i1, i2, target, weight = frames[t : t + 1], frames[t + 1 : t + 2], base[t : t + 1], held[t : t + 1].float()
            if torch.rand(()) < 0.5:
                i1, i2, target, weight = i1.flip(-1), i2.flip(-1), target.flip(-1) * MIRROR, weight.flip(-1)
            pred = predict_flow(model, i1, i2, 20).float()
            loss = (F.smooth_l1_loss(pred, target, reduction="none").sum(1) * weight).sum() / weight.sum().clamp(min=1)
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
        if epoch in (args.epochs // 2, args.epochs):
            tuned = flows(model.eval(), frames)
            row[f"epe_ep{epoch}_pct"] = round(100 * (epe(tuned) / epe0 - 1), 1)
            row[f"census_ep{epoch}_pct"] = round(100 * (float(photometric_error(frames[:-1], frames[1:], tuned)[0].mean())
                                                       / census0 - 1), 1)  # fmt: skip
    row["train_s"] = round(time.perf_counter() - start)
    return row


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--variant", default="fb", choices=("fb", "census", "all"))
    p.add_argument("--scenes", default="sprint_s9,fast_blur_s8,market_5b,ambush_4,alley_1")
    p.add_argument("--epochs", type=int, default=10)
    p.add_argument("--lr", type=float, default=1e-5)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--weights", default=str(SHARED / "checkpoints/raft-small.pth"))
    args = p.parse_args()
    print(f"settings: {vars(args)}", flush=True)
    torch.manual_seed(args.seed)
    for name in args.scenes.split(","):
        print(json.dumps(run_scene(name, args)), flush=True)


if __name__ == "__main__":
    main()
