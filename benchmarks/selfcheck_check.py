"""How often the flow stage's self-check (lit_boot.bootstrap.selfcheck) picks the flow that the
ground truth says is better, per region, on seeded synthetic scenes with exact GT.

For each scene: pretrained RAFT's flow (initial) and flow_1 of a bootstrap run (self-check off: the
tuned flow; synthetic scenes in 3D mode, the Sintel samples in 2D mode with MediaPipe's keypoints,
as benchmarks/real_data.py); then the self-check at each margin and tile size. Per pair and region
(the self-check's own: tiles, each split into its person part, inside the dilated sketch, and its
background part), GT's better flow is the one with the lower EPE over valid, non-occluded pixels;
a region where the two differ by less than ``--tie`` px counts as a GT tie (keeping the initial
flow is then right). Agreement = regions where the self-check's choice is GT's better flow (ties:
initial kept), over regions with >= 16 GT pixels.
EPE all / person / background (GT person mask; Sintel: all only, over its GT pair) of initial,
tuned and checked flows, pooled over pixels per scene, then the mean over scenes.

Usage:
  OMP_NUM_THREADS=1 python benchmarks/selfcheck_check.py [--scenes 0,1,4,7] [--frames 8]
      [--height 128] [--width 256] [--epochs 4] [--margins 0,0.02,0.05] [--tiles 32,64]
      [--sintel alley_1,market_5] [--sintel-size 218,512] [--sintel-epochs 8] [--seed 0]
  OMP_NUM_THREADS=1 python benchmarks/selfcheck_check.py --suite [--scenes 0,1,4,7] [--suite-epochs 8]
      (the whole method with self_check photometric, the bootstrap suite's settings at --frames 8)
Scenes are benchmarks/bootstrap_suite.py's (index = its seed: run_s0, walk_s1, hop_bvh_s4, run_pan_s7).
"""

from __future__ import annotations

import argparse
import shutil
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bootstrap_suite import SCENES, SHARED  # noqa: E402

from lit_boot.bootstrap import Bootstrap  # noqa: E402
from lit_boot.bootstrap.evaluate import flow_metrics  # noqa: E402
from lit_boot.bootstrap.selfcheck import region_labels, region_names, self_check  # noqa: E402
from lit_boot.synth import make_scene  # noqa: E402


def gt_region_epe(flows: torch.Tensor, gt: torch.Tensor, valid: torch.Tensor, labels: torch.Tensor, count: int):
    """Per pair and region: (mean EPE (T-1, count), GT pixels (T-1, count))."""
    epe = torch.where(valid, (flows - gt).norm(dim=1), torch.zeros(()))
    sums = torch.zeros(flows.shape[0], count).scatter_add_(1, labels.flatten(1), epe.flatten(1))
    pixels = torch.zeros(flows.shape[0], count).scatter_add_(1, labels.flatten(1), valid.flatten(1).float())
    return sums / pixels.clamp(min=1), pixels


def agreement(scene, initial, tuned, person, record, tile: int, tie: float) -> dict[str, list[int]]:
    """Per region kind ("person", "background"): [agreeing regions, judged regions, GT ties,
    regions where GT says the tuned flow is better] for one self-check."""
    gt = scene.gt
    valid = gt.flow_valid & ~gt.flow_occluded if gt.flow_occluded is not None else gt.flow_valid
    labels = region_labels(person, tile)
    names = region_names(*initial.shape[-2:], tile)
    e_init, pixels = gt_region_epe(initial, gt.flow.float(), valid, labels, len(names))
    e_tuned, _ = gt_region_epe(tuned, gt.flow.float(), valid, labels, len(names))
    counts = {"person": [0, 0, 0, 0], "background": [0, 0, 0, 0]}
    for t, pair in enumerate(record["per_pair"]):
        for r, name in enumerate(names):
            if pixels[t, r] < 16 or name not in pair["regions"]:
                continue
            diff = float(e_init[t, r] - e_tuned[t, r])
            c = counts["person" if name.startswith("person") else "background"]
            c[0] += (diff >= tie) == (name in pair["tuned"])
            c[1] += 1
            c[2] += abs(diff) < tie
            c[3] += diff >= tie
    return counts


def run_scene(name: str, scene, mode: str, epochs: int, args) -> tuple:
    """Scene, initial and tuned flows and the person region of one bootstrap run (flow_1 only)."""
    out = Path(args.out) / name
    shutil.rmtree(out, ignore_errors=True)
    boot = Bootstrap(scene, out, mode=mode, flow={"weights": args.weights}, flow_epochs=epochs, cycles=0,
                     video=False, progress_bar=False, seed=args.seed)  # fmt: skip
    start = time.perf_counter()
    result = boot.run()
    print(f"{name}: flow_1 in {time.perf_counter() - start:.0f} s", flush=True)
    person = boot.models[0].person_region(boot.models[0].sketch_masks)
    return scene, result.initial_flows, result.flows, person


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
    """Print per scene, tile and margin: agreement (person, background), the tuned fraction kept
    and EPE all / person / background of initial, tuned and checked flows; then pooled per group."""
    keys = ("epe", "epe_person", "epe_background")
    print("\nscene        tile margin  agree person  agree background (ties, gt:tuned)  kept tuned"
          "  EPE all init/tuned/checked  person  background")  # fmt: skip
    totals = {}
    for name, (scene, initial, tuned, person) in runs.items():
        group = "sintel" if scene.gt.person_mask is None else "synthetic"
        m_i, m_t = flow_metrics(scene, initial), flow_metrics(scene, tuned)
        for tile in [int(s) for s in args.tiles.split(",")]:
            for margin in [float(s) for s in args.margins.split(",")]:
                checked, record = self_check(scene.frames, initial, tuned, person, margin, tile, args.blend)
                metrics = (m_i, m_t, flow_metrics(scene, checked))
                counts = agreement(scene, initial, tuned, person, record, tile, args.tie)
                tot = totals.setdefault((group, tile, margin), {"person": [0] * 4, "background": [0] * 4, "epe": []})
                for kind in ("person", "background"):
                    tot[kind] = [a + b for a, b in zip(tot[kind], counts[kind])]
                tot["epe"].append([[m.get(k, float("nan")) for m in metrics] for k in keys])
                epes = "  ".join("/".join(f"{m.get(k, float('nan')):.3f}" for m in metrics) for k in keys)
                (pa, pj, _, pb), (ba, bj, bt, bb) = counts["person"], counts["background"]
                print(f"{name:12s} {tile:4d} {margin:6.2f}  {pa:3d}/{pj:3d} (gt:tuned {pb:2d})  {ba:4d}/{bj:4d} "
                      f"({bt:3d}, {bb:3d})  {record['kept_tuned_fraction']:10.3f}  {epes}", flush=True)  # fmt: skip
    print("\npooled agreement and mean EPE over scenes (init / tuned / checked):")
    for (group, tile, margin), tot in totals.items():
        mean = torch.tensor(tot["epe"]).mean(0)
        e = "  ".join(f"{k} {v[0]:.4f} / {v[1]:.4f} / {v[2]:.4f}" for k, v in zip(keys, mean.tolist()))
        agree = "  ".join(f"{kind} {tot[kind][0]}/{tot[kind][1]} = {100 * tot[kind][0] / max(tot[kind][1], 1):.1f}%"
                          for kind in ("person", "background"))  # fmt: skip
        print(f"{group:9s} tile {tile:3d} margin {margin:.2f}: {agree}  {e}")


def suite(args) -> None:
    """The whole method (flow -> pose -> flow, the suite's settings) with the self-check on: EPE
    and MPJPE per stage, to set against BENCHMARKS.md's bootstrap suite table (self-check off)."""
    keys = ("epe", "epe_person", "epe_background", "mpjpe_mm")
    print("\n| scene | EPE all RAFT -> c1 -> c2 | person | background | MPJPE init -> refined | kept tuned c1, c2 |")
    print("| --- | --- | --- | --- | --- | --- |")
    for i in [int(s) for s in args.scenes.split(",") if s]:
        name, spec = SCENES[i]
        scene = make_scene(frames=args.frames, height=args.height, width=args.width, **spec)
        out = Path(args.out) / f"{name}_suite"
        shutil.rmtree(out, ignore_errors=True)
        result = Bootstrap(scene, out, flow={"weights": args.weights}, flow_epochs=args.suite_epochs, video=False,
                           progress_bar=False, self_check="photometric").run()  # fmt: skip
        st = {r["stage"]: r for r in result.history}
        stages = ("initial", "flow_1", "flow_2")
        cells = [" -> ".join(f"{st[s].get(k, float('nan')):.3f}" for s in stages) for k in keys[:3]]
        mpjpe = f"{st['initial'].get(keys[3], float('nan')):.1f} -> {st['pose_1'].get(keys[3], float('nan')):.1f}"
        kept = ", ".join(f"{st[s]['info']['self_check']['kept_tuned_fraction']:.2f}" for s in ("flow_1", "flow_2"))
        print(f"| {name} | {' | '.join(cells)} | {mpjpe} | {kept} |", flush=True)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenes", default="0,1,4,7")
    p.add_argument("--frames", type=int, default=8)
    p.add_argument("--height", type=int, default=128)
    p.add_argument("--width", type=int, default=256)
    p.add_argument("--epochs", type=int, default=4)
    p.add_argument("--margins", default="0,0.02,0.05")
    p.add_argument("--tiles", default="32,64")
    p.add_argument("--blend", type=int, default=4)
    p.add_argument("--tie", type=float, default=0.005, help="px: GT EPE differences below this are ties")
    p.add_argument("--sintel", default="alley_1,market_5", help="Sintel samples (2D mode, MediaPipe); '' for none")
    p.add_argument("--sintel-size", default="218,512", help="H,W")
    p.add_argument("--sintel-epochs", type=int, default=8)
    p.add_argument("--suite", action="store_true", help="instead: the whole method with the self-check on")
    p.add_argument("--suite-epochs", type=int, default=8)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--weights", default=str(SHARED / "checkpoints/raft-small.pth"))
    p.add_argument("--out", default="/tmp/selfcheck_check")
    args = p.parse_args()
    print(f"settings: {vars(args)}", flush=True)
    if args.suite:
        return suite(args)
    runs = {}
    for i in [int(s) for s in args.scenes.split(",") if s]:
        name, spec = SCENES[i]
        scene = make_scene(frames=args.frames, height=args.height, width=args.width, **spec)
        runs[name] = run_scene(name, scene, "3d", args.epochs, args)
    size = tuple(int(v) for v in args.sintel_size.split(","))
    for name in [s for s in args.sintel.split(",") if s]:
        runs[name] = run_scene(name, sintel_scene(name, size), "2d", args.sintel_epochs, args)
    report(runs, args)


if __name__ == "__main__":
    main()
