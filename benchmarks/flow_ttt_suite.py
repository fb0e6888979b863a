"""FlowTTT on seeded synthetic scenes with exact ground truth.

For each scene: pretrained RAFT's EPE (all pixels / person / background / at joints), then
FlowTTT fine-tuned with targets from (a) the ground-truth poses (an oracle), (b) the simulated
METRO-like 3D joints projected by their weak-perspective cameras (3D mode), and (c) the
simulated DCPose-like 2D keypoints with their failures (2D-only mode). Every condition starts
from the same pretrained weights.

Usage:
  python benchmarks/flow_ttt_suite.py [--weights ../shared/checkpoints/raft-small.pth]
      [--epochs 8] [--lr 1e-5] [--sketch-weight 1] [--loss-beta 1] [--target-updates N]
      [--freeze-batchnorm] [--size 3] [--conditions gt,joints3d,keypoints2d]
      [--frames 12] [--height 128] [--width 256] [--json out.json]

Conventions: EPE = mean over pixels of all pairs (torchvision's convention), over valid,
non-occluded pixels; "person" = GT person mask, "background" = the rest; "joints" = the GT 2D
joints' displacement vs the flow at the rounded joint pixel (the authors' convention).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import lightning as L
import torch

from lit_boot.flow import FlowTTT, SceneFlowData, SketchConfig, load_raft, person_region, predict_flow
from lit_boot.metrics import EndPointError, PointEndPointError
from lit_boot.synth import make_scene

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
SCENES = [
    dict(motion="run", seed=0),
    dict(motion="walk", seed=1, speed=1.6),
    dict(motion="jump", seed=2),
    dict(motion="wave", seed=3, amplitude=1.5, speed=1.5),
    dict(motion="bvh", seed=4, bvh=str(SHARED / "data/mocap/cmu_131/131_03.bvh"), bvh_start=3.0),
]


@torch.no_grad()
def predict_all(model: torch.nn.Module, scene, updates: int = 32) -> torch.Tensor:
    """The flow of every pair of ``scene`` (T-1, 2, H, W) px."""
    model.eval()
    return torch.stack([predict_flow(model, scene.frames[t], scene.frames[t + 1], updates).float()[0]
                        for t in range(scene.num_frames - 1)])  # fmt: skip


def score(flows: torch.Tensor, scene) -> dict[str, float]:
    """EPE all / person / background / at joints over every pair of ``scene``."""
    m = {k: EndPointError() for k in ("all", "person", "background")}
    joints = PointEndPointError(mode="nearest")
    gt = scene.gt
    for t, flow in enumerate(flows[:, None]):
        valid = (gt.flow_valid[t] & ~gt.flow_occluded[t])[None]
        person = gt.person_mask[t][None]
        m["all"].update(flow, gt.flow[t][None], valid)
        m["person"].update(flow, gt.flow[t][None], valid & person)
        m["background"].update(flow, gt.flow[t][None], valid & ~person)
        j = gt.joints2d[t][None]
        joints.update(flow, j, gt.joints2d[t + 1][None] - j)
    out = {k: v.compute().item() for k, v in m.items()}
    out["joints"] = joints.compute().item()
    return out


def evaluate(model: torch.nn.Module, scene) -> dict[str, float]:
    return score(predict_all(model, scene), scene)


def fine_tune(scene, source: str, args) -> tuple[dict[str, float], dict[str, float], float]:
    """FlowTTT on one scene with targets from ``source``; returns (EPEs, target report, seconds)."""
    torch.manual_seed(0)
    model = FlowTTT(
        weights=args.weights, lr=args.lr, train_updates=args.train_updates, sketch_weight=args.sketch_weight,
        crop_margin=args.crop_margin, train_parts=args.train_parts, loss_beta=args.loss_beta,
        target_updates=args.target_updates, freeze_batchnorm=args.freeze_batchnorm,
        sketch=SketchConfig(footprint=args.footprint, size=args.size, guard=not args.no_guard),
    )  # fmt: skip
    data = SceneFlowData(scene, pose_source=source)
    trainer = L.Trainer(
        max_epochs=args.epochs if source != "keypoints2d" else args.epochs_2d, logger=False,
        enable_checkpointing=False, enable_progress_bar=False, enable_model_summary=False, limit_val_batches=0,
    )  # fmt: skip
    start = time.perf_counter()
    trainer.fit(model, datamodule=data)
    seconds = time.perf_counter() - start
    tuned = predict_all(model.raft, scene)
    epe = score(tuned, scene)
    if args.composite_margins:  # the tuned flow near the sketch only, pretrained RAFT's elsewhere
        original = predict_all(load_raft("raft_small", args.weights), scene)
        for margin in [int(m) for m in args.composite_margins.split(",")]:
            region = person_region(model.sketch_masks, margin)[:, None]
            epe[f"composite_{margin}"] = score(torch.where(region, tuned, original), scene)
    return epe, model.target_report, seconds


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--weights", default=str(SHARED / "checkpoints/raft-small.pth"))
    p.add_argument("--epochs", type=int, default=8)
    p.add_argument("--epochs-2d", type=int, default=8, help="epochs in 2D mode (the paper: 50)")
    p.add_argument("--lr", type=float, default=1e-5)
    p.add_argument("--train-updates", type=int, default=20)
    p.add_argument("--sketch-weight", type=float, default=1.0)
    p.add_argument("--footprint", default="cross")
    p.add_argument("--size", type=int, default=3, help="footprint size, px (cross radius 15 at ~450 px tall people)")
    p.add_argument("--crop-margin", type=int, default=None)
    p.add_argument("--train-parts", default="all")
    p.add_argument("--loss-beta", type=float, default=1.0, help="SmoothL1 beta, px (the authors: 1)")
    p.add_argument("--target-updates", type=int, default=None, help="updates of the base flow (default: train updates)")
    p.add_argument("--freeze-batchnorm", action="store_true")
    p.add_argument("--composite-margins", default="", help="e.g. 4,8: also score tuned-near-the-sketch flows")
    p.add_argument("--no-guard", action="store_true")
    p.add_argument("--conditions", default="gt,joints3d,keypoints2d")
    p.add_argument("--scenes", default=",".join(str(i) for i in range(len(SCENES))))
    p.add_argument("--frames", type=int, default=12)
    p.add_argument("--height", type=int, default=128)
    p.add_argument("--width", type=int, default=256)
    p.add_argument("--json", default=None)
    args = p.parse_args()
    torch.set_num_threads(torch.get_num_threads())
    rows, results = [], []
    print(f"settings: {vars(args)}")
    for i in [int(s) for s in args.scenes.split(",")]:
        spec = SCENES[i]
        scene = make_scene(frames=args.frames, height=args.height, width=args.width, **spec)
        base = evaluate(load_raft("raft_small", args.weights), scene)
        entry = {"scene": scene.name, "raft": base}
        rows.append((scene.name, "RAFT", base, None, None))
        for source in args.conditions.split(","):
            epe, report, seconds = fine_tune(scene, source, args)
            entry[source] = {"epe": epe, "target": report, "seconds": seconds}
            rows.append((scene.name, f"FlowTTT<-{source}", epe, report, seconds))
            print(f"{scene.name} {source}: {epe} target {report} {seconds:.0f}s", flush=True)
        results.append(entry)
    print("\n| scene | flow | EPE all | person | background | joints | target EPE on painted px (sketch / RAFT) | s |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for name, label, e, rep, sec in rows:
        tgt = f"{rep.get('target/epe_sketch_painted', float('nan')):.2f} / {rep.get('target/epe_base_painted', float('nan')):.2f}" if rep else ""
        print(f"| {name} | {label} | {e['all']:.3f} | {e['person']:.3f} | {e['background']:.3f} | {e['joints']:.3f} | {tgt} | {'' if sec is None else f'{sec:.0f}'} |")
    if args.json:
        Path(args.json).write_text(json.dumps({"settings": vars(args), "results": results}, indent=1))


if __name__ == "__main__":
    main()
