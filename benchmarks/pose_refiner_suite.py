"""PoseRefiner on seeded synthetic scenes with exact ground truth: before/after and ablation.

For each scene (METRO-like 3D joints with weak-perspective cameras, DCPose-like keypoints):
MPJPE, PA-MPJPE (mm) and acceleration error (mm/frame^2) of the initial estimates and after
refinement with (a) the ground-truth flow (an oracle) and (b) pretrained RAFT's flow
(torchvision raft_small with the original raft-small.pth weights, 32 updates). Then the loss
ablation of the paper's supplementary: L_3D; + L_2D; + L_temp without bones; + L_temp; + L_opt.
With --mode2d, also the 2D-only mode's keypoint error before and after.

Scenes and RAFT flows are cached under --cache (default /tmp/pose_bench) so reruns are fast.

Usage:
  python benchmarks/pose_refiner_suite.py [--frames 16] [--height 128] [--width 256]
      [--steps 1500] [--no-early-stop] [--flows gt,raft] [--ablation] [--weights KEY=VALUE ...]
      [--pixel-scale 1] [--scenes run_s0,...] [--mode2d]
      [--json out.json]

Conventions: MPJPE on the 14 LSP joints, pelvis (mean of the hips) subtracted, no Procrustes;
PA-MPJPE after a similarity Procrustes alignment per frame; acceleration error = norm of the
difference of second differences (mm/frame^2, not scaled by fps), root-aligned. Means pool
all joints of all frames of a scene; "mean" rows average the five scenes.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch

from lit_boot.data import load_scene, save_scene
from lit_boot.pose import PoseLossWeights, load_flows, refine_poses
from lit_boot.synth import make_scene

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
SCENES = {
    "run_s0": dict(motion="run", seed=0),
    "walk_s1": dict(motion="walk", seed=1, speed=1.6),
    "jump_s2": dict(motion="jump", seed=2),
    "wave_s3": dict(motion="wave", seed=3, amplitude=1.5),
    "hop_bvh_s4": dict(motion="bvh", seed=4, bvh=str(SHARED / "data/mocap/cmu_131/131_03.bvh"), bvh_start=3.0),
}
METRICS = ("mpjpe_mm", "pa_mpjpe_mm", "accel_mm_per_frame2")
SHORT = {"mpjpe_mm": "MPJPE", "pa_mpjpe_mm": "PA-MPJPE", "accel_mm_per_frame2": "Accel"}
FULL = PoseLossWeights()
ABLATION = {
    "L_3D": PoseLossWeights(opt=0, keypoints2d=0, pos=0, cam=0, bone=0),
    "+ L_2D": PoseLossWeights(opt=0, pos=0, cam=0, bone=0),
    "+ L_temp without bones": PoseLossWeights(opt=0, bone=0),
    "+ L_temp": PoseLossWeights(opt=0),
    "+ L_opt (full)": PoseLossWeights(),
}


def scene_for(name: str, args) -> object:
    """The synthetic scene ``name``, rendered once and cached as a scene folder."""
    folder = Path(args.cache) / f"{name}_{args.frames}f_{args.height}x{args.width}"
    if (folder / "scene.json").is_file():
        return load_scene(folder)
    scene = make_scene(frames=args.frames, height=args.height, width=args.width, **SCENES[name])
    save_scene(scene, folder, overwrite=True)
    return scene


def raft_flows(name: str, scene, args) -> Path:
    """Pretrained RAFT's flows for every pair, cached as a flows.npz (key flow, index)."""
    path = Path(args.cache) / f"raft_{name}_{args.frames}f_{args.height}x{args.width}_{args.updates}u.npz"
    if not path.is_file():
        from lit_boot.flow import load_raft, predict_flow  # benchmarks only: lit_boot.pose never imports it

        model = load_raft("raft_small", args.raft_weights).eval()
        with torch.no_grad():
            flows = [predict_flow(model, scene.frames[t], scene.frames[t + 1], args.updates)[0].float()
                     for t in range(scene.num_frames - 1)]  # fmt: skip
        np.savez(path, flow=torch.stack(flows).numpy(), index=np.arange(len(flows)))
    return path


def joint_epe(flows: torch.Tensor, scene) -> float:
    """EPE (px) of a flow at the GT 2D joints, nearest pixel (the authors' convention)."""
    from lit_boot.metrics import epe_at_points

    j = scene.gt.joints2d
    return float(epe_at_points(flows, j[:-1], j[1:] - j[:-1], mode="nearest").mean())


def run(scene, flows, weights: PoseLossWeights, args) -> dict:
    result = refine_poses(scene, flows, steps=args.steps, early_stop=not args.no_early_stop, loss_weights=weights,
                          pixel_scale=args.pixel_scale)  # fmt: skip
    return {"before": result.metrics_before, "after": result.metrics_after, "steps": result.steps,
            "seconds": result.seconds, "loss": result.loss}  # fmt: skip


def fmt_row(cells: list) -> str:
    return "| " + " | ".join(str(c) for c in cells) + " |"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=16)
    parser.add_argument("--height", type=int, default=128)
    parser.add_argument("--width", type=int, default=256)
    parser.add_argument("--steps", type=int, default=1500)
    parser.add_argument("--no-early-stop", action="store_true")
    parser.add_argument("--flows", default="gt,raft")
    parser.add_argument("--scenes", default=",".join(SCENES))
    parser.add_argument("--ablation", action="store_true", help="also run the loss ablation")
    parser.add_argument("--mode2d", action="store_true", help="also run the 2D-only mode (KeypointRefiner)")
    parser.add_argument("--weights", nargs="*", default=[], help="override lambdas, e.g. opt=0.1")
    parser.add_argument("--pixel-scale", type=float, default=1.0, help="PoseRefiner.pixel_scale (1: the paper)")
    parser.add_argument("--cache", default="/tmp/pose_bench")
    parser.add_argument("--raft-weights", default=str(SHARED / "checkpoints/raft-small.pth"))
    parser.add_argument("--updates", type=int, default=32)
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    torch.set_num_threads(1)
    Path(args.cache).mkdir(parents=True, exist_ok=True)
    overrides = {k: float(v) for k, v in (w.split("=") for w in args.weights)}
    weights = PoseLossWeights(**{**vars(FULL), **overrides})
    kinds = args.flows.split(",")
    report: dict = {"args": vars(args), "scenes": {}}
    start = time.perf_counter()
    for name in args.scenes.split(","):
        scene = scene_for(name, args)
        entry: dict = {}
        for kind in kinds:
            flows = "gt" if kind == "gt" else str(raft_flows(name, scene, args))
            entry[f"epe_joints_{kind}"] = joint_epe(load_flows(flows, scene), scene)
            entry[kind] = run(scene, flows, weights, args)
            if args.mode2d:
                r2 = refine_poses(scene, flows, mode="2d", steps=args.steps, early_stop=not args.no_early_stop)
                entry[f"2d_{kind}"] = {"before": r2.metrics_before, "after": r2.metrics_after, "steps": r2.steps}
            if args.ablation:
                entry[f"ablation_{kind}"] = {label: run(scene, flows, w, args)["after"] for label, w in ABLATION.items()
                                             if kind == "gt" or "L_opt" in label}  # fmt: skip
        report["scenes"][name] = entry
        print(name, {k: (round(entry[k]["before"]["mpjpe_mm"], 2), round(entry[k]["after"]["mpjpe_mm"], 2))
                     for k in kinds}, flush=True)  # fmt: skip
    report["seconds"] = time.perf_counter() - start
    print_tables(report, kinds, args.ablation)
    if args.mode2d:
        print_2d_table(report, kinds)
    if args.json:
        Path(args.json).write_text(json.dumps(report, indent=2))


def print_tables(report: dict, kinds: list[str], ablation: bool) -> None:
    scenes = report["scenes"]
    print("\n### Before / after (mm; Accel in mm/frame^2)\n")
    header = ["scene", "joint EPE GT / RAFT (px)"] + [f"{SHORT[m]} init" for m in METRICS]
    header += [f"{SHORT[m]} {k}" for k in kinds for m in METRICS] + [f"steps {k}" for k in kinds]
    print(fmt_row(header))
    print(fmt_row(["---"] * len(header)))
    rows = []
    for name, e in scenes.items():
        first = e[kinds[0]]["before"]
        vals = [first[m] for m in METRICS] + [e[k]["after"][m] for k in kinds for m in METRICS]
        rows.append(vals)
        epe = " / ".join(f"{e[f'epe_joints_{k}']:.2f}" for k in kinds)
        print(fmt_row([name, epe] + [f"{v:.2f}" for v in vals] + [e[k]["steps"] for k in kinds]))
    mean = np.mean(np.array(rows), axis=0)
    print(fmt_row(["**mean**", ""] + [f"**{v:.2f}**" for v in mean] + [""] * len(kinds)))
    if not ablation:
        return
    print("\n### Loss ablation (MPJPE mm, mean over scenes; per scene in brackets)\n")
    print(fmt_row(["terms", "flow", "MPJPE", "PA-MPJPE", "Accel", "per scene MPJPE"]))
    print(fmt_row(["---"] * 6))
    init = [e[kinds[0]]["before"] for e in scenes.values()]
    print(fmt_row(["initial (METRO-like)", "-"] + [f"{np.mean([i[m] for i in init]):.2f}" for m in METRICS]
                  + [" ".join(f"{i['mpjpe_mm']:.1f}" for i in init)]))  # fmt: skip
    for kind in kinds:
        for label in ABLATION:
            res = [e[f"ablation_{kind}"][label] for e in scenes.values() if label in e[f"ablation_{kind}"]]
            if not res:
                continue
            flow = kind if "L_opt" in label else "-"
            print(fmt_row([label, flow] + [f"{np.mean([r[m] for r in res]):.2f}" for m in METRICS]
                          + [" ".join(f"{r['mpjpe_mm']:.1f}" for r in res)]))  # fmt: skip


def print_2d_table(report: dict, kinds: list[str]) -> None:
    print("\n### 2D-only mode: COCO-17 keypoint error (px, mean over all keypoints and frames)\n")
    header = ["scene", "initial (DCPose-like)"] + [f"refined, {k} flow" for k in kinds]
    print(fmt_row(header))
    print(fmt_row(["---"] * len(header)))
    rows = []
    for name, e in report["scenes"].items():
        vals = [e[f"2d_{kinds[0]}"]["before"]["kp2d_px"]] + [e[f"2d_{k}"]["after"]["kp2d_px"] for k in kinds]
        rows.append(vals)
        print(fmt_row([name] + [f"{v:.2f}" for v in vals]))
    print(fmt_row(["**mean**"] + [f"**{v:.2f}**" for v in np.mean(np.array(rows), axis=0)]))


if __name__ == "__main__":
    main()
