"""How often the flow stage's self-check (lit_boot.bootstrap.selfcheck) picks the flow that the
ground truth says is better, per region, on seeded synthetic scenes with exact GT.

For each scene: pretrained RAFT's flow (initial) and flow_1 of a bootstrap run (3D mode, self-check
off: the tuned flow); then the self-check at each margin and tile size. Per pair and region (the
self-check's own regions: the dilated sketch, and background tiles), GT's better flow is the one
with the lower EPE over valid, non-occluded pixels; a region where the two differ by less than
``--tie`` px counts as a GT tie (keeping the initial flow is then right). Agreement = regions where
the self-check's choice is GT's better flow (ties: initial kept), over regions with GT pixels.
EPE all / person / background (GT person mask) of initial, tuned and checked flows, pooled.

Usage:
  OMP_NUM_THREADS=1 python benchmarks/selfcheck_check.py [--scenes 0,1,4,7] [--frames 8]
      [--height 128] [--width 256] [--epochs 4] [--margins 0,0.02,0.05] [--tiles 32,64]
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


def agreement(scene, initial, tuned, person, record, tile: int, tie: float) -> tuple[int, int, int, int]:
    """(agreeing regions, judged regions, GT ties, GT says tuned is better) for one self-check."""
    gt = scene.gt
    valid = gt.flow_valid & ~gt.flow_occluded if gt.flow_occluded is not None else gt.flow_valid
    labels = region_labels(person, tile)
    names = region_names(*initial.shape[-2:], tile)
    e_init, pixels = gt_region_epe(initial, gt.flow.float(), valid, labels, len(names))
    e_tuned, _ = gt_region_epe(tuned, gt.flow.float(), valid, labels, len(names))
    agree = judged = ties = tuned_better = 0
    for t, pair in enumerate(record["per_pair"]):
        for r, name in enumerate(names):
            if pixels[t, r] < 16 or name not in pair["regions"]:
                continue
            judged += 1
            diff = float(e_init[t, r] - e_tuned[t, r])
            gt_tuned = diff >= tie
            ties += abs(diff) < tie
            tuned_better += gt_tuned
            agree += gt_tuned == (name in pair["tuned"])
    return agree, judged, ties, tuned_better


def run_scene(name: str, spec: dict, args) -> tuple:
    """Scene, initial and tuned flows and the person region of one bootstrap run (flow_1 only)."""
    scene = make_scene(frames=args.frames, height=args.height, width=args.width, **spec)
    out = Path(args.out) / name
    shutil.rmtree(out, ignore_errors=True)
    boot = Bootstrap(scene, out, flow={"weights": args.weights}, flow_epochs=args.epochs, cycles=0, video=False,
                     progress_bar=False, seed=args.seed)  # fmt: skip
    result = boot.run()
    person = boot.models[0].person_region(boot.models[0].sketch_masks)
    return scene, result.initial_flows, result.flows, person


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
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--weights", default=str(SHARED / "checkpoints/raft-small.pth"))
    p.add_argument("--out", default="/tmp/selfcheck_check")
    args = p.parse_args()
    print(f"settings: {vars(args)}", flush=True)
    runs = {}
    for i in [int(s) for s in args.scenes.split(",")]:
        name, spec = SCENES[i]
        start = time.perf_counter()
        runs[name] = run_scene(name, spec, args)
        print(f"{name} ({spec}): flow_1 in {time.perf_counter() - start:.0f} s", flush=True)
    keys = ("epe", "epe_person", "epe_background")
    print("\nscene        tile margin  agree/judged  ties  gt:tuned  kept tuned  EPE all init/tuned/checked"
          "    person init/tuned/checked    background init/tuned/checked")  # fmt: skip
    totals = {}
    for name, (scene, initial, tuned, person) in runs.items():
        m_i, m_t = flow_metrics(scene, initial), flow_metrics(scene, tuned)
        for tile in [int(s) for s in args.tiles.split(",")]:
            for margin in [float(s) for s in args.margins.split(",")]:
                checked, record = self_check(scene.frames, initial, tuned, person, margin, tile, args.blend)
                m_c = flow_metrics(scene, checked)
                a, j, ties, better = agreement(scene, initial, tuned, person, record, tile, args.tie)
                tot = totals.setdefault((tile, margin), [0, 0, {k: [0.0, 0.0, 0.0] for k in keys}])
                tot[0] += a
                tot[1] += j
                for k in keys:
                    for s, m in enumerate((m_i, m_t, m_c)):
                        tot[2][k][s] += m[k] / len(runs)
                epes = "  ".join(f"{m_i[k]:.3f}/{m_t[k]:.3f}/{m_c[k]:.3f}" for k in keys)
                print(f"{name:12s} {tile:4d} {margin:6.2f}  {a:3d}/{j:3d} {100 * a / j:5.1f}%  {ties:4d}  {better:8d}"
                      f"  {record['kept_tuned_fraction']:10.3f}  {epes}", flush=True)  # fmt: skip
    print("\nmean over scenes (EPE) and pooled agreement:")
    for (tile, margin), (a, j, epes) in totals.items():
        e = "  ".join(f"{k}: {v[0]:.4f} / {v[1]:.4f} / {v[2]:.4f}" for k, v in epes.items())
        print(f"tile {tile:3d} margin {margin:.2f}: agreement {a}/{j} = {100 * a / j:.1f}%  init / tuned / checked  {e}")


if __name__ == "__main__":
    main()
