"""The whole method (flow -> pose -> flow) on seeded synthetic scenes with exact ground truth.

For each scene and preset: flow EPE (all / person / background / at joints) of pretrained RAFT,
after flow cycle 1 and after cycle 2; MPJPE / PA-MPJPE / acceleration error of the METRO-like
initial estimates and of the refined poses; the flow-pose agreement; and the speed (wall time
of the run / plain RAFT inference on the same frames, seconds per frame).

Usage:
  python benchmarks/bootstrap_suite.py [--presets default,paper] [--set tuning|validation] [--scenes 0,1,...]
      [--frames 12] [--height 128] [--width 256] [--weights ../shared/checkpoints/raft-small.pth]
      [--epochs 8] [--flow '{"sketch_weight": 10}'] [--mode 3d|2d] [--self-check off|photometric (default: the preset's)] [--gate] [--detector realistic|accurate]
      [--config '{"self_check": {"margin": 0}}'] [--out /tmp/bootstrap_suite] [--json out.json]

``--set validation`` runs the scenes no default was chosen on (VALIDATION; each with its own
simulated detector unless ``--detector`` is given); the defaults are chosen on ``tuning`` (SCENES).
``--mode 2d`` runs the 2D-only method on the DCPose-like keypoints (pose metric: kp2d_px);
``--self-check photometric`` turns the flow stages' self-check on; ``--gate`` makes the targets
with the evidence gate (:data:`GATE`); ``--detector accurate`` simulates the cleaner 2D
detector (lit_boot.synth.config.ACCURATE_DETECTOR) instead of the default measured from
MediaPipe on real clips (benchmarks/detector_noise.py). The last lines give, per preset, the issue-13 bars: the
mean over scenes of each EPE's relative change (RAFT -> the last flow stage), the worst scene's,
and whether the all-pixel EPE is better on every scene.

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
from lit_boot.synth import EstimateConfig, make_scene
from lit_boot.synth.config import ACCURATE_DETECTOR

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
    # where RAFT fails (raft-small, 128x256): fast limbs with motion blur (person EPE 8.5 px, motion
    # up to 36 px/frame) and large displacements (13.5 px, up to 50 px/frame)
    ("fast_blur_s8", dict(motion="run", seed=8, speed=2.0, motion_blur=5)),
    ("sprint_s9", dict(motion="run", seed=9, speed=2.5, fill=0.9)),
]
#: The validation set (issue 24, part 3): scenes no default was chosen on. Other seeds, every
#: procedural motion and all three BVH files, other sizes, speeds, headings, noise and camera
#: moves; each with the simulated detector it is run with (half "realistic", half "accurate").
VALIDATION = [
    ("walk_s11", dict(motion="walk", seed=11, heading_deg=60.0), "realistic"),
    ("run_s12", dict(motion="run", seed=12, speed=1.3, heading_deg=-30.0), "accurate"),
    ("jump_s13", dict(motion="jump", seed=13, fill=0.55), "realistic"),
    ("wave_s14", dict(motion="wave", seed=14, amplitude=1.2), "accurate"),
    ("turn_s15", dict(motion="turn", seed=15, girth=1.2), "realistic"),
    ("walk_bvh2_s16", dict(motion="bvh", seed=16, bvh=str(MOCAP / "131_02.bvh"), bvh_start=5.0), "accurate"),
    ("hop_bvh_s17", dict(motion="bvh", seed=17, bvh=str(MOCAP / "131_03.bvh"), bvh_start=6.0, pan_deg_per_s=5.0),
     "realistic"),
    ("walk_bvh_s18", dict(motion="bvh", seed=18, bvh=str(MOCAP / "131_01.bvh"), bvh_start=2.0, dolly_mm_per_s=300.0),
     "accurate"),
    ("run_small_s19", dict(motion="run", seed=19, fill=0.45, noise_std=3.0), "realistic"),
    ("walk_noise_s20", dict(motion="walk", seed=20, speed=1.4, noise_std=4.0, pan_deg_per_s=-8.0), "accurate"),
]
FLOW_KEYS = ("epe", "epe_person", "epe_background", "epe_joints")
#: The evidence gate of ``--gate``: bone+pixel with a 3 px search (benchmarks/gate_check.py's best).
GATE = {"gate": "photometric", "gate_level": "bone+pixel", "gate_search": 3}
POSE_KEYS = ("mpjpe_mm", "pa_mpjpe_mm", "accel_mm_per_frame2")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--presets", default="default,paper")
    p.add_argument("--set", default="tuning", choices=("tuning", "validation"),
                   help="tuning: SCENES, the scenes the defaults were chosen on; validation: VALIDATION")
    p.add_argument("--scenes", default=None, help="indices into the set (default: all of it)")
    p.add_argument("--frames", type=int, default=12)
    p.add_argument("--height", type=int, default=128)
    p.add_argument("--width", type=int, default=256)
    p.add_argument("--weights", default=str(SHARED / "checkpoints/raft-small.pth"))
    p.add_argument("--epochs", type=int, default=None, help="per flow stage (default: 8 in 3D mode, 50 in 2D)")
    p.add_argument("--flow", default="{}", help="FlowTTT options over the preset's, JSON")
    p.add_argument("--mode", default="3d", choices=("3d", "2d"))
    p.add_argument("--self-check", default=None, choices=("off", "photometric"), help="default: the preset's")
    p.add_argument("--gate", action="store_true", help="targets with the evidence gate (GATE)")
    p.add_argument("--detector", default=None, choices=("realistic", "accurate"),
                   help="the simulated 2D detector (default: realistic; a validation scene's own)")
    p.add_argument("--config", default="{}",
                   help="more BootstrapConfig options, JSON (e.g. '{\"self_check\": {\"margin\": 0}}')")  # fmt: skip
    p.add_argument("--out", default="/tmp/bootstrap_suite")
    p.add_argument("--json", default=None)
    args = p.parse_args()
    print(f"settings: {vars(args)}", flush=True)
    rows = []
    chosen = SCENES if args.set == "tuning" else VALIDATION
    indices = range(len(chosen)) if args.scenes is None else [int(s) for s in args.scenes.split(",")]
    for i in indices:
        name, spec, *own = chosen[i]
        detector = args.detector or (own[0] if own else "realistic")
        estimates = EstimateConfig(**(ACCURATE_DETECTOR if detector == "accurate" else {}))
        scene = make_scene(frames=args.frames, height=args.height, width=args.width, estimates=estimates, **spec)
        for preset in args.presets.split(","):
            out = Path(args.out) / f"{name}_{preset}"
            shutil.rmtree(out, ignore_errors=True)
            flow = {"weights": args.weights, **({"sketch": GATE} if args.gate else {}), **json.loads(args.flow)}
            config = json.loads(args.config)
            check = {**config.pop("self_check", {}), **({"method": args.self_check} if args.self_check else {})}
            result = bootstrap(scene, out, preset=preset, mode=args.mode, flow=flow, flow_epochs=args.epochs,
                               self_check=check, progress_bar=False, video=False, **config)  # fmt: skip
            by_stage = {r["stage"]: r for r in result.history}
            row = {"scene": name, "preset": preset, "detector": detector, "speed": speed_summary(result),
                   "stages": {k: {m: v for m, v in r.items() if isinstance(v, float)} for k, r in by_stage.items()}}  # fmt: skip
            rows.append(row)
            print(json.dumps(row), flush=True)
    print_table(rows, args.mode)
    for preset in args.presets.split(","):
        print_bars([r for r in rows if r["preset"] == preset], preset)
    if args.json:
        Path(args.json).write_text(json.dumps({"settings": vars(args), "rows": rows}, indent=1))


def print_table(rows: list[dict], mode: str) -> None:
    """The per-scene markdown table: EPEs per flow stage, the pose metrics, agreement, speed."""
    pose_keys = POSE_KEYS if mode == "3d" else ("kp2d_px",)
    print(f"\n| scene | preset | EPE all RAFT (-> zoom) -> c1 -> c2 | person | background | joints | "
          f"{' | '.join(k + ' init -> refined' for k in pose_keys)} | agreement px init -> end | x RAFT | s/frame |")
    print("| --- " * (9 + len(pose_keys)) + "|")
    for r in rows:
        s = r["stages"]
        stages = [st for st in ("initial", "zoom", "flow_1", "flow_2") if st in s]
        flow = [" -> ".join(f"{s[st].get(k, float('nan')):.3f}" for st in stages) for k in FLOW_KEYS]
        pose = [f"{s['initial'].get(k, float('nan')):.1f} -> {s['pose_1'].get(k, float('nan')):.1f}" for k in pose_keys]
        agree = f"{s['initial']['agreement_px']:.2f} -> {s['flow_2']['agreement_px']:.2f}"
        sp = r["speed"]
        print(f"| {r['scene']} | {r['preset']} | {' | '.join(flow)} | {' | '.join(pose)} | {agree} "
              f"| {sp['ratio_to_raft']:.1f} | {sp['s_per_frame']:.1f} |")  # fmt: skip


def print_bars(rows: list[dict], preset: str) -> None:
    """Mean and worst relative change (%) of EPE all / person / background, RAFT -> flow_2, of the
    pose metric (MPJPE in 3D, kp2d_px in 2D), estimates -> pose_1, and whether every scene's
    all-pixel EPE got better (the bars of issues 13 and 24)."""
    if not rows:
        return
    flow_keys = [k for k in ("epe_all_pixels", "epe", "epe_unmatched", "epe_person", "epe_background")
                 if k in rows[0]["stages"]["initial"]]  # fmt: skip
    rel = {k: [100 * (r["stages"]["flow_2"][k] / r["stages"]["initial"][k] - 1) for r in rows] for k in flow_keys}
    pose = next((k for k in ("mpjpe_mm", "kp2d_px") if k in rows[0]["stages"]["initial"]), None)
    if pose is not None:
        rel[pose] = [100 * (r["stages"]["pose_1"][pose] / r["stages"]["initial"][pose] - 1) for r in rows]
    parts = [f"{k} {sum(v) / len(v):+.1f}% (worst {max(v):+.1f}%)" for k, v in rel.items()]
    better = "; ".join(f"{k} better on {sum(v < 0 for v in rel[k])} of {len(rows)} scenes"
                       for k in ("epe_all_pixels", "epe") if k in rel)  # fmt: skip
    print(f"\n{preset}: mean over {len(rows)} scenes of the change RAFT -> flow_2 (epe_all_pixels: every valid "
          f"pixel, Sintel's all; epe: matched; epe_unmatched: occluded): {', '.join(parts)}; {better}")


if __name__ == "__main__":
    main()
