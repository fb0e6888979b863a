"""The whole method (flow -> pose -> flow) on seeded synthetic scenes with exact ground truth.

For each scene and preset: flow EPE (all / person / background / at joints) of pretrained RAFT,
after flow cycle 1 and after cycle 2; MPJPE / PA-MPJPE / acceleration error of the METRO-like
initial estimates and of the refined poses; the flow-pose agreement; and the speed (wall time
of the run / plain RAFT inference on the same frames, seconds per frame).

Usage:
  python benchmarks/bootstrap_suite.py [--presets default,paper] [--scenes 0,1,...]
      [--frames 12] [--height 128] [--width 256] [--weights ../shared/checkpoints/raft-small.pth]
      [--epochs 8] [--out /tmp/bootstrap_suite] [--json out.json]

Conventions as in benchmarks/flow_ttt_suite.py (EPE pooled over valid non-occluded pixels of all
pairs; joints: GT joint displacement vs the flow at the rounded pixel) and
benchmarks/pose_refiner_suite.py (MPJPE on LSP-14, pelvis subtracted; Accel mm/frame^2).
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

from lit_boot.bootstrap import bootstrap
from lit_boot.bootstrap.outputs import speed_summary
from lit_boot.synth import make_scene

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
MOCAP = SHARED / "data/mocap/cmu_131"
SCENES = [
    ("run_s0", dict(motion="run", seed=0)),
    ("walk_s1", dict(motion="walk", seed=1, speed=1.6)),
    ("jump_s2", dict(motion="jump", seed=2)),
    ("wave_s3", dict(motion="wave", seed=3, amplitude=1.5, speed=1.5)),
    ("hop_bvh_s4", dict(motion="bvh", seed=4, bvh=str(MOCAP / "131_03.bvh"), bvh_start=3.0)),
    ("walk_bvh_s5", dict(motion="bvh", seed=5, bvh=str(MOCAP / "131_01.bvh"), bvh_start=4.6, pan_deg_per_s=5.0)),
    ("turn_s6", dict(motion="turn", seed=6)),
    ("run_pan_s7", dict(motion="run", seed=7, pan_deg_per_s=10.0, noise_std=2.0)),
]
FLOW_KEYS = ("epe", "epe_person", "epe_background", "epe_joints")
POSE_KEYS = ("mpjpe_mm", "pa_mpjpe_mm", "accel_mm_per_frame2")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--presets", default="default,paper")
    p.add_argument("--scenes", default=",".join(str(i) for i in range(len(SCENES))))
    p.add_argument("--frames", type=int, default=12)
    p.add_argument("--height", type=int, default=128)
    p.add_argument("--width", type=int, default=256)
    p.add_argument("--weights", default=str(SHARED / "checkpoints/raft-small.pth"))
    p.add_argument("--epochs", type=int, default=8)
    p.add_argument("--out", default="/tmp/bootstrap_suite")
    p.add_argument("--json", default=None)
    args = p.parse_args()
    print(f"settings: {vars(args)}", flush=True)
    rows = []
    for i in [int(s) for s in args.scenes.split(",")]:
        name, spec = SCENES[i]
        scene = make_scene(frames=args.frames, height=args.height, width=args.width, **spec)
        for preset in args.presets.split(","):
            out = Path(args.out) / f"{name}_{preset}"
            shutil.rmtree(out, ignore_errors=True)
            result = bootstrap(scene, out, preset=preset, flow={"weights": args.weights}, flow_epochs=args.epochs,
                               progress_bar=False, video=False)  # fmt: skip
            by_stage = {r["stage"]: r for r in result.history}
            row = {"scene": name, "preset": preset, "speed": speed_summary(result),
                   "stages": {k: {m: v for m, v in r.items() if isinstance(v, float)} for k, r in by_stage.items()}}  # fmt: skip
            rows.append(row)
            print(json.dumps(row), flush=True)
    print("\n| scene | preset | EPE all RAFT -> c1 -> c2 | person | background | joints | MPJPE init -> refined "
          "| PA-MPJPE | Accel | agreement px init -> end | x RAFT | s/frame |")  # fmt: skip
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        s = r["stages"]
        flow = [" -> ".join(f"{s[st].get(k, float('nan')):.3f}" for st in ("initial", "flow_1", "flow_2")) for k in FLOW_KEYS]
        pose = [f"{s['initial'].get(k, float('nan')):.1f} -> {s['pose_1'].get(k, float('nan')):.1f}" for k in POSE_KEYS]
        agree = f"{s['initial']['agreement_px']:.2f} -> {s['flow_2']['agreement_px']:.2f}"
        sp = r["speed"]
        print(f"| {r['scene']} | {r['preset']} | {' | '.join(flow)} | {' | '.join(pose)} | {agree} "
              f"| {sp['ratio_to_raft']:.1f} | {sp['s_per_frame']:.1f} |")  # fmt: skip
    for preset in args.presets.split(","):
        sel = [r["stages"] for r in rows if r["preset"] == preset]
        if not sel:
            continue
        mean = lambda st, k: sum(x[st][k] for x in sel) / len(sel)  # noqa: E731
        change = lambda a, b: 100 * (b - a) / a  # noqa: E731
        print(f"\n{preset}: mean over {len(sel)} scenes: person EPE {mean('initial', 'epe_person'):.3f} -> "
              f"{mean('flow_2', 'epe_person'):.3f} ({change(mean('initial', 'epe_person'), mean('flow_2', 'epe_person')):+.1f}%), "
              f"background {mean('initial', 'epe_background'):.3f} -> {mean('flow_2', 'epe_background'):.3f} "
              f"({change(mean('initial', 'epe_background'), mean('flow_2', 'epe_background')):+.1f}%), "
              f"all {mean('initial', 'epe'):.3f} -> {mean('flow_2', 'epe'):.3f}, "
              f"MPJPE {mean('initial', 'mpjpe_mm'):.1f} -> {mean('pose_1', 'mpjpe_mm'):.1f} "
              f"({change(mean('initial', 'mpjpe_mm'), mean('pose_1', 'mpjpe_mm')):+.1f}%)")  # fmt: skip
    if args.json:
        Path(args.json).write_text(json.dumps({"settings": vars(args), "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
