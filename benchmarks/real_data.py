"""The method on real data, with MediaPipe Pose as the only pose source (the mediapipe extra).

- The Sintel windows (final pass; the held-out ones with --heldout-root), MediaPipe's keypoints
  and 3D joints and the YOLOX boxes: each window in each ``--mode`` (2D and 3D by default; a run
  does what the scene's evidence allows: lit_boot.bootstrap.plan); EPE of the pairs with GT,
  before (pretrained RAFT) and after, as Sintel reports it: "all" = every valid pixel, "noc"
  (matched) = valid and not occluded (lit-boot's ``epe``), "occ" (unmatched) = valid and occluded
  in frame t+1. Run folders: ``--out``/<mode>/<window>; keypoints_gt_pair.png in each shows
  MediaPipe's keypoints on the GT pair's first frame.
- The basketball clip (no GT): the whole 3D method on its first frames; the football clip (no GT,
  10 frames): the 2D-only method. For both, the flow-pose agreement (L_opt residual, px) before and
  after, the overlay video in the run folder, and the image evidence (no GT needed): the census
  error (0..48) of the frames warped by RAFT's and by the final flow, on the person (the last flow
  stage's target dilated by 16 px) and on all pixels, with what the target painted and the
  self-check kept (issue 13).

Usage:
  python benchmarks/real_data.py [--parts sintel,basketball,football] [--scenes alley_1,market_5,...]
      [--mode 2d,3d] [--sintel-size 218,512] [--flow '{"sketch": {"max_disagreement_px": 3}}']
      [--epochs N (default: the mode's)] [--pose-steps 1500] [--basketball-frames 16]
      [--basketball-resize 270] [--weights ../shared/checkpoints/raft-small.pth]
      [--self-check off|photometric] [--gate] [--config JSON] [--detector PATH|none] [--estimate JSON]
      [--heldout-root ROOT] [--out /tmp/real_data] [--json out.json]
The Sintel windows are every sample in ../shared (SINTEL); market_5's two windows are market_5
and market_5b.
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

import torch

from lit_boot.bootstrap import bootstrap
from lit_boot.bootstrap.outputs import speed_summary
from lit_boot.data.readers import read_sintel, read_video
from lit_boot.data.visualize import scene_preview, write_png
from lit_boot.estimate import estimate_poses
from lit_boot.metrics import flow_errors

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
#: Held-out Sintel windows (not in ../shared; BENCHMARKS.md, "Held-out Sintel windows", says where
#: they come from): the official layout under --heldout-root, as benchmarks/heldout_sintel.py writes it.
HELDOUT_ROOT = Path(__file__).resolve().parents[1].parent / "heldout/sintel"
SINTEL = [("alley_1", 1, 4), ("market_5", 1, 4), ("market_5b", 8, 11), ("temple_3", 21, 24), ("bandage_1", 34, 37),
          ("ambush_4", 3, 8)]  # fmt: skip
#: (window, scene, first, last, pass) of the held-out windows.
HELDOUT = [("h_cave_2a", "cave_2", 1, 4, "final"), ("h_cave_2b", "cave_2", 10, 13, "final"),
           ("h_cave_4", "cave_4", 40, 43, "final"), ("h_ambush_2", "ambush_2", 20, 21, "final"),
           ("h_ambush_x", "unidentified_ambush", 2, 5, "final"), ("h_shaman_x", "unidentified_shaman", 41, 44, "final"),
           ("h_alley_2c", "alley_2", 1, 4, "clean")]  # fmt: skip
GATE = {"gate": "photometric", "gate_level": "bone+pixel", "gate_search": 3}


def windows(heldout_root: Path = HELDOUT_ROOT) -> dict[str, tuple]:
    """Window name -> (Sintel root, scene, first, last, pass) of SINTEL and HELDOUT."""
    out = {w: (SHARED / "data/sintel_samples", w.rstrip("b"), a, b, "final") for w, a, b in SINTEL}
    return out | {w: (Path(heldout_root), *rest) for w, *rest in HELDOUT}


def window_with_boxes(window: str, size, detector: str, heldout_root: Path = HELDOUT_ROOT):
    """A Sintel window at ``size`` (H, W or None: full) and the person's boxes (T, 5) from the
    YOLOX ``detector`` on its full-size frames (lit_boot.estimate.person_boxes), rescaled."""
    from lit_boot.estimate import person_boxes

    root, name, first, last, pass_name = windows(heldout_root)[window]
    full = read_sintel(root, name, first=first, last=last, pass_name=pass_name)
    scene = read_sintel(root, name, first=first, last=last, pass_name=pass_name, size=size)
    boxes = person_boxes(full.frames, detector)
    sx, sy = scene.width / full.width, scene.height / full.height
    boxes[:, :4] = (boxes[:, :4] + 0.5) * torch.tensor([sx, sy, sx, sy]) - 0.5
    return scene, boxes


def window_scene(window: str, size, detector: str | None, estimate: dict | None = None,
                 heldout_root: Path = HELDOUT_ROOT):
    """A Sintel window at ``size`` (H, W or None: full) with MediaPipe's poses (and the YOLOX
    ``detector``'s boxes) estimated on its full-size frames (they miss small people), rescaled."""
    root, name, first, last, pass_name = windows(heldout_root)[window]
    poses = estimate_poses(read_sintel(root, name, first=first, last=last, pass_name=pass_name),
                           detector=detector, **(estimate or {}))  # fmt: skip
    return poses, poses.apply_to(read_sintel(root, name, first=first, last=last, size=size, pass_name=pass_name))


def gt_pair_epe(flows: torch.Tensor, scene) -> dict[str, float]:
    """EPE over the pairs with GT, as Sintel reports it: "all" valid pixels, the "noc" (matched:
    valid, not occluded) and the "occ" (unmatched: valid, occluded in frame t+1)."""
    gt = scene.gt
    valid = gt.flow_valid
    occluded = gt.flow_occluded if gt.flow_occluded is not None else torch.zeros_like(valid)
    masks = {"all": valid, "noc": valid & ~occluded, "occ": valid & occluded}
    return {k: float(flow_errors(flows, gt.flow, m)["epe"]) for k, m in masks.items() if m.any()}


def run(scene, out: Path, mode: str, args, video: bool) -> tuple[dict, object]:
    shutil.rmtree(out, ignore_errors=True)
    flow = {"weights": args.weights, **({"sketch": GATE} if args.gate else {}), **json.loads(args.flow)}
    config = json.loads(args.config)
    check = {**config.pop("self_check", {}), **({"method": args.self_check} if args.self_check else {})}
    result = bootstrap(scene, out, mode=mode, flow=flow, flow_epochs=args.epochs, self_check=check,
                       pose_steps=args.pose_steps, progress_bar=False, video=video, **config)  # fmt: skip
    return speed_summary(result), result


def evidence(result) -> dict:
    """Census error (0..48) of RAFT's and the final flow, on the person and on all pixels, and
    what each flow stage decided (lit_boot.bootstrap.decisions)."""
    import kornia

    from lit_boot.bootstrap.decisions import decision_summary
    from lit_boot.flow.evidence import photometric_error

    frames = result.scene.frames
    painted = result.decisions["painted"] if result.decisions is not None else torch.zeros(frames.shape[0] - 1, 1, 1)
    person = kornia.morphology.dilation(painted[:, None].float(), torch.ones(33, 33))[:, 0] > 0
    out = {}
    for name, flows in (("raft", result.initial_flows), ("final", result.flows)):
        sums = torch.zeros(4)
        for t in range(flows.shape[0]):
            err, ok = photometric_error(frames[t : t + 1], frames[t + 1 : t + 2], flows[t : t + 1].float())
            sel = ok[0] & person[t].expand_as(ok[0])
            sums += torch.tensor([float(err[0][sel].sum()), float(sel.sum()), float(err[ok].sum()), float(ok.sum())])
        out[name] = {"person": float(sums[0] / sums[1]) if sums[1] else float("nan"), "all": float(sums[2] / sums[3])}
    out["decisions"] = decision_summary(result.history)
    return out


def _change(r: dict, k: str) -> str:
    before, after = r["before"].get(k), r["after"].get(k)
    return "" if before is None else f"{before:.3f} -> {after:.3f} ({100 * (after / before - 1):+.1f}%)"


def print_table(rows: list[dict]) -> None:
    """One markdown table per mode (EPE all / matched / unmatched, Sintel's, before -> after), the
    mean change of each over the windows with GT; then the no-GT clips."""
    for mode in dict.fromkeys(r.get("mode", "") for r in rows):
        mine = [r for r in rows if r.get("mode", "") == mode]
        print(f"\n{mode or 'clips'}:\n\n| window | ran | frames (pose, boxes) | EPE all | EPE matched | EPE unmatched "
              "| census person RAFT -> final | painted, kept tuned per flow stage | x RAFT |")
        print("| --- " * 9 + "|")
        for r in mine:
            ev = r["evidence"]
            census = f"{ev['raft']['person']:.2f} -> {ev['final']['person']:.2f}"
            decided = "; ".join(f"{d['painted_fraction'] or 0:.3f}, {d['kept_tuned_fraction']:.2f}"
                                for d in ev["decisions"])  # fmt: skip
            epe = [_change(r, k) if "before" in r else "no GT" for k in ("all", "noc", "occ")]
            ran = f"{r.get('ran', '')} {'+'.join(r.get('stages', []))}"
            print(f"| {r['scene']} | {ran} | {r['frames']} ({r['found']}, {r.get('boxes', '')}) | {' | '.join(epe)} "
                  f"| {census} | {decided} | {r['speed']['ratio_to_raft']:.1f} |")  # fmt: skip
        scored = [r for r in mine if "before" in r]
        if scored:
            means = {k: sum(100 * (r["after"][k] / r["before"][k] - 1) for r in scored) / len(scored)
                     for k in ("all", "noc", "occ") if all(k in r["before"] for r in scored)}  # fmt: skip
            worst = max(100 * (r["after"]["all"] / r["before"]["all"] - 1) for r in scored)
            print(f"\nmean change over {len(scored)} windows: " + ", ".join(f"{k} {v:+.1f}%" for k, v in means.items())
                  + f"; worst window (all) {worst:+.1f}%")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--parts", default="sintel,basketball,football")
    p.add_argument("--self-check", default=None, choices=("off", "photometric"), help="default: the preset's")
    p.add_argument("--gate", action="store_true", help="targets with the evidence gate (GATE)")
    p.add_argument("--scenes", default=",".join(name for name, _, _ in SINTEL),
                   help="Sintel windows to run: of SINTEL (../shared) and HELDOUT (--heldout-root)")
    p.add_argument("--heldout-root", default=str(HELDOUT_ROOT),
                   help="the held-out windows' Sintel root (benchmarks/heldout_sintel.py writes it)")
    p.add_argument("--detector", default=str(SHARED / "checkpoints/yolox_nano.onnx"),
                   help="YOLOX person detector for the person's boxes ('none': MediaPipe's keypoints only)")
    p.add_argument("--flow", default="{}", help='FlowTTT options over the preset\'s, JSON: {"sketch": {"max_disagreement_px": 3}}')
    p.add_argument("--config", default="{}", help="more BootstrapConfig options, JSON (e.g. '{\"zoom\": {\"method\": \"off\"}}')")
    p.add_argument("--estimate", default="{}",
                   help='more estimate_poses options for the Sintel windows, JSON (e.g. \'{"crops": true}\')')
    p.add_argument("--mode", default="2d,3d", help="the Sintel windows' modes, comma-separated (each window in each)")
    p.add_argument("--sintel-size", default="218,512", help="H,W (the samples are 436,1024) or full")
    p.add_argument("--epochs", type=int, default=None, help="flow epochs per stage (default: 50 in 2D, 8 in 3D)")
    p.add_argument("--pose-steps", type=int, default=1500)
    p.add_argument("--basketball-frames", type=int, default=16)
    p.add_argument("--basketball-resize", type=int, default=270, help="frame height, px")
    p.add_argument("--weights", default=str(SHARED / "checkpoints/raft-small.pth"))
    p.add_argument("--out", default="/tmp/real_data")
    p.add_argument("--json", default=None)
    args = p.parse_args()
    print(f"settings: {vars(args)}", flush=True)
    rows = []
    detector = None if args.detector == "none" else args.detector
    if "sintel" in args.parts:
        size = None if args.sintel_size == "full" else tuple(int(v) for v in args.sintel_size.split(","))
        for window in (w for w in windows(Path(args.heldout_root)) if w in args.scenes.split(",")):
            poses, scene = window_scene(window, size, detector, json.loads(args.estimate), Path(args.heldout_root))
            for mode in args.mode.split(","):
                speed, result = run(scene, Path(args.out) / mode / window, mode, args, video=False)
                # the detections on the GT pair's first frame, to judge them by eye (frame | GT flow | keypoints)
                first_gt = scene.metadata["frames"].index(scene.metadata["gt_pairs"][0][0])
                write_png(Path(args.out) / mode / window / "keypoints_gt_pair.png", scene_preview(scene, first_gt))
                boxes = 0 if poses.person_boxes is None else int((poses.person_boxes[:, 4] > 0).sum())
                plan = json.loads((result.run_dir / "summary.json").read_text())["plan"]
                row = {"scene": window, "mode": mode, "ran": plan["mode"], "stages": plan["stages"],
                       "found": int(poses.found().sum()), "boxes": boxes, "frames": scene.num_frames,
                       "before": gt_pair_epe(result.initial_flows, scene), "after": gt_pair_epe(result.flows, scene),
                       "agreement": [result.history[0]["agreement_px"], result.history[-1]["agreement_px"]],
                       "speed": speed, "evidence": evidence(result)}  # fmt: skip
                rows.append(row)
                print(json.dumps(row), flush=True)
    clips = {"basketball": ("basketball_1080p_89f.mp4", "3d", args.basketball_frames, args.basketball_resize),
             "football": ("football_720p_10f", "2d", None, args.basketball_resize)}  # fmt: skip
    for clip, (file, mode, frames, resize) in clips.items():
        if clip not in args.parts:
            continue
        scene = read_video(SHARED / "data/videos" / file, max_frames=frames, resize=resize)
        poses = estimate_poses(scene, detector=detector)
        scene = poses.apply_to(scene)
        speed, result = run(scene, Path(args.out) / clip, mode, args, video=True)
        row = {"scene": clip, "mode": mode, "found": int(poses.found().sum()), "frames": scene.num_frames,
               "agreement": [result.history[0]["agreement_px"], result.history[-1]["agreement_px"]],
               "overlay": str(result.run_dir / "overlay.mp4"), "speed": speed, "evidence": evidence(result)}  # fmt: skip
        rows.append(row)
        print(json.dumps(row), flush=True)
    print_table(rows)
    if args.json:
        Path(args.json).write_text(json.dumps({"settings": vars(args), "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
