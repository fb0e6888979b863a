"""How often the flow stage's self-check (lit_boot.bootstrap.selfcheck) picks the flow that the
ground truth says is better, and what the checked flow's EPE is, on seeded synthetic scenes with
exact GT and on the Sintel samples.

For each scene: pretrained RAFT's flow (initial) and flow_1 of a bootstrap run (self-check off: the
tuned flow; synthetic scenes in 3D mode, the Sintel samples in 2D mode with MediaPipe's keypoints,
as benchmarks/real_data.py), then the self-check at each margin and window. The runs are cached
in ``--out`` (``<scene>.pt``; ``--fresh`` runs them again).

Agreement with GT: on the background, per pair and tile, GT's better flow is the one with the
lower EPE over valid, non-occluded pixels, and a tile where the two differ by less than ``--tie``
px is a GT tie (keeping the initial flow is then right); on the person (the dilated sketch), the
same per pixel. Agreement = tiles (pixels) where the self-check's choice is GT's better flow, over
tiles with >= 16 GT pixels (over person pixels with GT).
EPE all / person / background (GT person mask; Sintel: all only, over its GT pair) of initial,
tuned and checked flows, pooled over pixels per scene; then the mean relative change over scenes.

Usage:
  OMP_NUM_THREADS=1 python benchmarks/selfcheck_check.py [--scenes 0,1,2,3,4,5,6,7] [--frames 8]
      [--height 128] [--width 256] [--mode 3d|2d] [--epochs 8 (3d) / 50 (2d)] [--margins 0,0.02,0.05] [--windows 3,5,9]
      [--tile 32] [--blend 0] [--own 1] [--gate] [--flow JSON] [--sintel alley_1,market_5] [--sintel-size 218,512]
      [--sintel-epochs 8] [--seed 0] [--out /tmp/selfcheck_check] [--fresh]
Scenes are benchmarks/bootstrap_suite.py's (index = its seed). ``--gate`` makes the targets with
the evidence gate (bone+pixel, search 3). The whole method with the self-check on is
benchmarks/bootstrap_suite.py with ``--self-check photometric``.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bootstrap_suite import GATE, SCENES, SHARED  # noqa: E402

from lit_boot.bootstrap import Bootstrap  # noqa: E402
from lit_boot.metrics import scene_flow_metrics  # noqa: E402
from lit_boot.bootstrap.selfcheck import SelfCheckConfig, region_labels, region_names, self_check  # noqa: E402
from lit_boot.flow import person_region  # noqa: E402
from lit_boot.synth import make_scene  # noqa: E402

KEYS = ("epe", "epe_person", "epe_background")


def gt_region_epe(flows: torch.Tensor, gt: torch.Tensor, valid: torch.Tensor, labels: torch.Tensor, count: int):
    """Per pair and region: (mean EPE (T-1, count), GT pixels (T-1, count))."""
    epe = torch.where(valid, (flows - gt).norm(dim=1), torch.zeros(()))
    sums = torch.zeros(flows.shape[0], count).scatter_add_(1, labels.flatten(1), epe.flatten(1))
    pixels = torch.zeros(flows.shape[0], count).scatter_add_(1, labels.flatten(1), valid.flatten(1).float())
    return sums / pixels.clamp(min=1), pixels


def agreement(scene, initial, tuned, person, record, weight, tie: float) -> dict[str, list[int]]:
    """[agreeing, judged, GT ties, GT says tuned] for "background" (tiles) and "person" (pixels)."""
    gt = scene.gt
    valid = gt.flow_valid & ~gt.flow_occluded if gt.flow_occluded is not None else gt.flow_valid
    tile = record["tile"]
    labels = region_labels(person, tile)
    names = region_names(*initial.shape[-2:], tile)
    e_init, pixels = gt_region_epe(initial, gt.flow.float(), valid & ~person, labels, len(names))
    e_tuned, _ = gt_region_epe(tuned, gt.flow.float(), valid & ~person, labels, len(names))
    counts = {"person": [0, 0, 0, 0], "background": [0, 0, 0, 0]}
    c = counts["background"]
    for t, pair in enumerate(record["per_pair"]):
        for r, name in enumerate(names):
            if pixels[t, r] < 16 or name not in pair["regions"]:
                continue
            diff = float(e_init[t, r] - e_tuned[t, r])
            c[0] += (diff >= tie) == (name in pair["tuned"])
            c[1], c[2], c[3] = c[1] + 1, c[2] + (abs(diff) < tie), c[3] + (diff >= tie)
    diff = (initial - gt.flow.float()).norm(dim=1) - (tuned - gt.flow.float()).norm(dim=1)
    judged = valid & person
    better, chose = (diff >= tie)[judged], (weight > 0.5)[judged]
    counts["person"] = [int((better == chose).sum()), int(judged.sum()), int((diff.abs() < tie)[judged].sum()),
                        int(better.sum())]  # fmt: skip
    return counts


def run_scene(name: str, scene, mode: str, epochs: int, args) -> dict:
    """Initial and tuned flows and the person region of one bootstrap run (flow_1 only), cached."""
    tag = ("_gate" if args.gate else "") + ("_2d" if mode == "2d" and scene.gt.person_mask is not None else "") + ("_" + args.flow.replace(" ", "").replace('"', "") if args.flow != "{}" else "")
    cache = Path(args.out) / f"{name}{tag}.pt"
    if cache.is_file() and not args.fresh:
        return torch.load(cache)
    out = Path(args.out) / name
    shutil.rmtree(out, ignore_errors=True)
    flow = {"weights": args.weights, **({"sketch": GATE} if args.gate else {}), **json.loads(args.flow)}
    boot = Bootstrap(scene, out, mode=mode, flow=flow, flow_epochs=epochs, cycles=0, video=False, progress_bar=False,
                     self_check={"method": "off"}, seed=args.seed)  # fmt: skip
    start = time.perf_counter()
    result = boot.run()
    print(f"{name}: flow_1 in {time.perf_counter() - start:.0f} s", flush=True)
    run = {"initial": result.initial_flows, "tuned": result.flows,
           "person": person_region(boot.models[0].sketch_masks)}  # fmt: skip
    torch.save(run, cache)
    return run


def sintel_scene(name: str, size: tuple[int, int]):
    """A Sintel sample (final pass) at ``size`` with MediaPipe's keypoints (found at full size),
    as benchmarks/real_data.py builds it."""
    from real_data import SINTEL

    from lit_boot.data.readers import read_sintel
    from lit_boot.estimate import estimate_poses

    first, last = next((f, la) for n, f, la in SINTEL if n == name)
    root = SHARED / "data/sintel_samples"
    poses = estimate_poses(read_sintel(root, name, first=first, last=last))
    return poses.apply_to(read_sintel(root, name, first=first, last=last, size=size))


def report(runs: dict, args) -> None:
    """Per scene, margin and window: agreement (person pixels, background tiles), the tuned
    fraction kept, EPE all / person / background of initial, tuned and checked flows; then pooled."""
    print("\nscene        margin win  agree person px       agree bg tiles (ties, gt:tuned)  kept"
          "  EPE all init/tuned/checked  person  background")  # fmt: skip
    totals = {}
    for name, (scene, run) in runs.items():
        group = "sintel" if scene.gt.person_mask is None else "synthetic"
        initial, tuned, person = run["initial"].float(), run["tuned"].float(), run["person"]
        m_i, m_t = scene_flow_metrics(scene.gt, initial), scene_flow_metrics(scene.gt, tuned)
        for margin in [float(s) for s in args.margins.split(",")]:
            for window in [int(s) for s in args.windows.split(",")]:
                config = SelfCheckConfig(margin=margin, tile=args.tile, blend=args.blend, window=window,
                                         own=bool(args.own))  # fmt: skip
                checked, record, weight = self_check(scene.frames, initial, tuned, person, config=config)
                metrics = (m_i, m_t, scene_flow_metrics(scene.gt, checked))
                counts = agreement(scene, initial, tuned, person, record, weight, args.tie)
                tot = totals.setdefault((group, margin, window), {"person": [0] * 4, "background": [0] * 4, "rel": []})
                for kind in ("person", "background"):
                    tot[kind] = [a + b for a, b in zip(tot[kind], counts[kind])]
                tot["rel"].append([[m.get(k, float("nan")) / m_i.get(k, float("nan")) - 1 for m in metrics[1:]]
                                   for k in KEYS])  # fmt: skip
                epes = "  ".join("/".join(f"{m.get(k, float('nan')):.3f}" for m in metrics) for k in KEYS)
                (pa, pj, _, pb), (ba, bj, bt, bb) = counts["person"], counts["background"]
                print(f"{name:12s} {margin:6.2f} {window:3d}  {pa:6d}/{pj:6d} (gt:tuned {pb:5d})  {ba:4d}/{bj:4d} "
                      f"({bt:3d}, {bb:3d})  {record['kept_tuned_fraction']:10.3f}  {epes}", flush=True)  # fmt: skip
    print("\npooled agreement; mean relative EPE change vs initial over scenes (tuned -> checked), worst scene:")
    for (group, margin, window), tot in totals.items():
        rel = 100 * torch.tensor(tot["rel"])  # (scenes, keys, [tuned, checked])
        mean = rel.nanmean(0) if hasattr(rel, "nanmean") else rel.mean(0)
        change = "  ".join(f"{k} {mean[i, 0]:+.1f}% -> {mean[i, 1]:+.1f}% (worst {rel[:, i, 1].max():+.1f}%)"
                           for i, k in enumerate(KEYS) if torch.isfinite(mean[i]).all())  # fmt: skip
        agree = "  ".join(f"{kind} {tot[kind][0]}/{tot[kind][1]} = {100 * tot[kind][0] / max(tot[kind][1], 1):.1f}%"
                          for kind in ("person", "background"))  # fmt: skip
        print(f"{group:9s} margin {margin:.2f} window {window}: {agree}  {change}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenes", default="0,1,2,3,4,5,6,7")
    p.add_argument("--frames", type=int, default=8)
    p.add_argument("--height", type=int, default=128)
    p.add_argument("--width", type=int, default=256)
    p.add_argument("--epochs", type=int, default=None, help="flow_1's epochs (default: 8 in 3D mode, 50 in 2D)")
    p.add_argument("--mode", default="3d", choices=("3d", "2d"), help="the synthetic scenes' mode")
    p.add_argument("--margins", default="0,0.02,0.05")
    p.add_argument("--windows", default="3,5,9")
    p.add_argument("--tile", type=int, default=32)
    p.add_argument("--blend", type=int, default=0)
    p.add_argument("--own", type=int, default=1, choices=(0, 1), help="a person pixel's own error must be lower too")
    p.add_argument("--gate", action="store_true", help="targets with the evidence gate (bone+pixel, search 3)")
    p.add_argument("--flow", default="{}", help="FlowTTT options over the preset's, JSON")
    p.add_argument("--tie", type=float, default=0.005, help="px: GT EPE differences below this are ties")
    p.add_argument("--sintel", default="alley_1,market_5", help="Sintel samples (2D mode, MediaPipe); '' for none")
    p.add_argument("--sintel-size", default="218,512", help="H,W")
    p.add_argument("--sintel-epochs", type=int, default=8)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--weights", default=str(SHARED / "checkpoints/raft-small.pth"))
    p.add_argument("--out", default="/tmp/selfcheck_check")
    p.add_argument("--fresh", action="store_true", help="run the bootstrap runs again even when cached")
    args = p.parse_args()
    print(f"settings: {vars(args)}", flush=True)
    runs = {}
    for i in [int(s) for s in args.scenes.split(",") if s]:
        name, spec = SCENES[i]
        scene = make_scene(frames=args.frames, height=args.height, width=args.width, **spec)
        runs[name] = scene, run_scene(name, scene, args.mode, args.epochs, args)
    size = tuple(int(v) for v in args.sintel_size.split(","))
    for name in [s for s in args.sintel.split(",") if s]:
        scene = sintel_scene(name, size)
        runs[name] = scene, run_scene(name, scene, "2d", args.sintel_epochs, args)
    report(runs, args)


if __name__ == "__main__":
    main()
