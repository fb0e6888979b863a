"""How usable a finished run's flow is beyond EPE (issue 57, part 5; no ground truth needed).

For each run folder: where the final flow differs from RAFT's (|final - RAFT| > 0.05 px), the
share of those pixels that disagree with most of their 8 neighbours on whether they changed
(speckle; lit_boot.metrics.coherence), and the same for each flow-making stage's own change; inside
the zoom stage's regions (the person's crop), the mean gradient magnitude of RAFT's flow, of the
zoom stage's flow and of the final flow (roughness); along each region's border, the mean step of
RAFT's flow and of the final flow (a seam where the crop ended). Bars: speckle at most 1%, the
final flow no rougher inside the regions than the rougher of its candidates, no step along the
border larger than RAFT's own.

Usage:
  python benchmarks/coherence.py RUN_DIR [RUN_DIR ...] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import torch

from lit_boot.bootstrap.finished import read_run
from lit_boot.data.flows import read_flows
from lit_boot.metrics.coherence import border_step, changed_pixels, roughness, speckle


def regions(run_dir: Path) -> list[tuple[int, int, int, int] | None]:
    """The zoom stage's pasted region per pair (None: not zoomed), or [] without a zoom stage."""
    path = run_dir / "stages" / "zoom" / "stage.json"
    if not path.is_file():
        return []
    pairs = json.loads(path.read_text())["info"]["zoom"]["per_pair"]
    return [tuple(p["region"]) if p.get("region") else None for p in pairs]


def measure(run_dir: Path) -> dict:
    """The coherence figures of one finished run (module doc)."""
    run = read_run(run_dir)
    initial, final = run.initial_flows.float(), run.flows.float()
    row = {"run": str(run_dir), "speckle": speckle(changed_pixels(final, initial)),
           "changed": float(changed_pixels(final, initial).float().mean()), "stages": {}}  # fmt: skip
    before = initial
    for record in run.history[1:]:
        if record.get("kind") not in ("zoom", "flow") or record.get("rolled_back"):
            continue
        flows = read_flows(run_dir / "stages" / record["stage"] / "flows.npz").float()
        row["stages"][record["stage"]] = speckle(changed_pixels(flows, before))
        before = flows
    zoom = run_dir / "stages" / "zoom" / "flows.npz"
    zoomed = read_flows(zoom).float() if zoom.is_file() else None
    rough, steps = {"raft": [], "zoom": [], "final": []}, {"raft": [], "final": []}
    for t, box in enumerate(regions(run_dir)[: final.shape[0]]):
        if box is None:
            continue
        y0, y1, x0, x1 = box
        inside = torch.zeros(1, *final.shape[-2:], dtype=torch.bool)
        inside[0, y0:y1, x0:x1] = True
        for name, flows in (("raft", initial), ("zoom", zoomed), ("final", final)):
            if flows is not None:
                rough[name].append(roughness(flows[t : t + 1], inside))
        steps["raft"].append(border_step(initial[t], box))
        steps["final"].append(border_step(final[t], box))
    mean = lambda v: sum(x for x in v if math.isfinite(x)) / max(1, sum(math.isfinite(x) for x in v))  # noqa: E731
    row["roughness"] = {k: mean(v) for k, v in rough.items() if v}
    row["border_step"] = {k: mean(v) for k, v in steps.items() if v}
    return row


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("runs", nargs="+")
    p.add_argument("--json", default=None)
    args = p.parse_args()
    rows = [measure(Path(r)) for r in args.runs]
    print("| run | changed | speckle (final vs RAFT) | per stage | roughness in the regions RAFT / zoom / final "
          "| border step RAFT / final |\n| --- | --- | --- | --- | --- | --- |")
    for r in rows:
        stages = ", ".join(f"{k} {100 * v:.1f}%" for k, v in r["stages"].items())
        rough = " / ".join(f"{v:.3f}" for v in r["roughness"].values())
        step = " / ".join(f"{v:.3f}" for v in r["border_step"].values())
        print(f"| {r['run']} | {100 * r['changed']:.1f}% | {100 * r['speckle']:.1f}% | {stages} | {rough} | {step} |")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
