"""The poses without ground truth, before and after (issue 57, part 4), from finished runs.

For each run folder: the no-GT pose measures (lit_boot.bootstrap.evaluate.pose_evidence and the
census along the joints' tracks) of the input poses and of the refined ones (the last pose
stage's), in the mode that ran; with ground truth (the synthetic suites) MPJPE or the 2D
keypoint error beside them, and over the scenes how often each measure moved the way the GT error
did (a no-GT measure a reader can trust where it agrees in sign on most scenes).

Usage:
  python benchmarks/pose_evidence.py --synthetic /tmp/bootstrap_suite [--set validation] [--frames 8]
  python benchmarks/pose_evidence.py --sintel /tmp/real_data/3d [--sintel-size 218,512]   # real_data.py's runs
  python benchmarks/pose_evidence.py --runs RUN_DIR [RUN_DIR ...]   # runs of scene folders (clips; no GT)
The synthetic folder is bootstrap_suite.py's --out (one <scene>_default run per scene).
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from bootstrap_suite import SCENES, VALIDATION
from scipy.stats import spearmanr

from lit_boot.bootstrap.evaluate import pose_evidence, pose_track_error
from lit_boot.bootstrap.finished import read_run
from lit_boot.pose import load_pose_result
from lit_boot.synth import EstimateConfig, make_scene
from lit_boot.synth.config import ACCURATE_DETECTOR

GT_NAMES = ("mpjpe_mm", "kp2d_px")


def before_after(run_dir: Path, scene=None) -> dict:
    """{measure: [before, after]} of one run (the scene as the run started: ``scene`` or the run's)."""
    run = read_run(run_dir, scene)
    pose_stages = [r["stage"] for r in run.history if r.get("kind") == "pose" and not r.get("rolled_back")]
    if not pose_stages or run.scene is None:
        return {}
    start = run.scene
    refined = load_pose_result(run_dir / "stages" / pose_stages[-1]).apply_to(start)
    out = {}
    for name, scene_ in (("before", start), ("after", refined)):
        values = pose_evidence(scene_, run.mode)
        values["track_error"] = pose_track_error(scene_.frames, *scene_.pose_points(run.mode))
        for key, value in values.items():
            if "_person" not in key:
                out.setdefault(key, [math.nan, math.nan])[0 if name == "before" else 1] = value
    for key in GT_NAMES:
        first, last = run.history[0].get(key), next((r[key] for r in reversed(run.history) if key in r), None)
        if first is not None and last is not None:
            out[key] = [first, last]
    return out


def synthetic(folder: Path, which: str, frames: int) -> list[tuple[str, dict]]:
    rows = []
    for name, spec, *own in VALIDATION if which == "validation" else SCENES:
        detector = own[0] if own else "realistic"
        estimates = EstimateConfig(**(ACCURATE_DETECTOR if detector == "accurate" else {}))
        scene = make_scene(frames=frames, height=128, width=256, estimates=estimates, **spec)
        run = folder / f"{name}_default"
        if (run / "summary.json").is_file():
            rows.append((name, before_after(run, scene)))
    return rows


def sintel(folder: Path, size: str) -> list[tuple[str, dict]]:
    """The Sintel windows' runs under ``folder`` (real_data.py's --out/<mode>), each scene rebuilt
    as real_data.py built it (MediaPipe and YOLOX-Nano on the full-size frames)."""
    from real_data import SHARED, window_scene

    rows = []
    for run in sorted(p for p in folder.iterdir() if (p / "summary.json").is_file()):
        shape = None if size == "full" else tuple(int(v) for v in size.split(","))
        _, scene = window_scene(run.name, shape, str(SHARED / "checkpoints/yolox_nano.onnx"))
        rows.append((run.name, before_after(run, scene)))
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--synthetic", default=None, help="bootstrap_suite.py's --out folder")
    p.add_argument("--set", default="validation", choices=("tuning", "validation"))
    p.add_argument("--frames", type=int, default=8)
    p.add_argument("--runs", nargs="*", default=[])
    p.add_argument("--sintel", default=None, help="real_data.py's --out/<mode> folder of Sintel window runs")
    p.add_argument("--sintel-size", default="218,512")
    p.add_argument("--json", default=None)
    args = p.parse_args()
    rows = synthetic(Path(args.synthetic), args.set, args.frames) if args.synthetic else []
    rows += sintel(Path(args.sintel), args.sintel_size) if args.sintel else []
    rows += [(Path(r).name, before_after(Path(r))) for r in args.runs]
    rows = [(n, r) for n, r in rows if r]
    names = list(dict.fromkeys(k for _, r in rows for k in r))
    print("| run | " + " | ".join(names) + " |\n" + "| --- " * (len(names) + 1) + "|")
    for name, r in rows:
        cells = [f"{r[k][0]:.3g} -> {r[k][1]:.3g}" if k in r and math.isfinite(r[k][0]) else "" for k in names]
        print(f"| {name} | " + " | ".join(cells) + " |")
    change = {k: [100 * (r[k][1] / r[k][0] - 1) for _, r in rows
                  if k in r and r[k][0] and math.isfinite(r[k][0] + r[k][1])] for k in names}  # fmt: skip
    print("\nmean change: " + ", ".join(f"{k} {sum(v) / len(v):+.1f}%" for k, v in change.items() if v))
    gt = next((k for k in GT_NAMES if k in names), None)
    if gt is not None:
        for k in names:
            if k in GT_NAMES:
                continue
            pairs = [(r[k][1] / r[k][0] - 1, r[gt][1] / r[gt][0] - 1) for _, r in rows if k in r and gt in r]
            agree = sum((a < 0) == (b < 0) for a, b in pairs)
            rho = spearmanr(*zip(*pairs)).statistic if len(pairs) > 2 else math.nan
            print(f"{k}: moved the way {gt} did on {agree} of {len(pairs)} scenes; rank correlation of the "
                  f"relative changes across scenes {rho:+.2f}")
    if args.json:
        Path(args.json).write_text(json.dumps(dict(rows), indent=1))


if __name__ == "__main__":
    main()
