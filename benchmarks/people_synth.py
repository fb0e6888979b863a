"""The whole method on synthetic scenes with several people (issue 25's synthetic bar): every
person painted (the scene as generated) against the main person alone (``scene.person(0)``,
today's single-person method on the same frames).

Per scene and variant: the change of the final flow's EPE against pretrained RAFT's on each
person's pixels (GT ``person_mask`` of person 0 and ``gt.others[i].person_mask``: where that
person is the visible surface in frame t, valid and not occluded), on the background (nobody's
pixels) and on all pixels; wall time. Scenes: lit_boot.synth.make_scene(people=N) with the seeds
and motions below, 8 frames, 128x256, the default preset (3D or ``--mode 2d``). The motion follows
the seed's place in ``--seeds`` (walk, run, wave): the tuning seeds 30,31 and the validation seeds
32,33 are each run as their own command (walk, run), as BENCHMARKS.md's tables were.

Usage:
  OMP_NUM_THREADS=1 python benchmarks/people_synth.py [--mode 3d|2d] [--people 2,3] [--seeds 30,31]
      [--variants every,main] [--flow '{"people_balance": true}'] [--config '{"zoom": {"confirm": "veto"}}']
      [--weights ../shared/checkpoints/raft-small.pth]
      [--out /tmp/people_synth] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import shutil
import time
from pathlib import Path

import torch

from lit_boot.bootstrap import bootstrap
from lit_boot.synth import make_scene

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
MOTIONS = ("walk", "run", "wave")


def masks(scene) -> tuple[list[torch.Tensor], torch.Tensor]:
    """Each person's scored pixels (T-1, H, W) bool, main first, and the background's."""
    gt = scene.gt
    scored = gt.flow_mask()
    others = [o.person_mask[:-1] for o in gt.others]
    union = gt.person_mask[:-1]
    main = union & ~torch.stack(others).any(0) if others else union
    return [m & scored for m in [main, *others]], ~union & scored


def change(initial: torch.Tensor, final: torch.Tensor, gt: torch.Tensor, where: torch.Tensor) -> float:
    """Relative EPE change (final vs initial) on ``where``, %."""
    before = (initial - gt).norm(dim=1)[where].mean()
    after = (final - gt).norm(dim=1)[where].mean()
    return float(100 * (after / before - 1))


def changes(result, scene, people: list[torch.Tensor], background: torch.Tensor) -> dict:
    """A run's EPE changes (%, one decimal) against pretrained RAFT's on each person's pixels
    (``people``, from :func:`masks`), the background and every scored pixel."""
    gt = scene.gt.flow
    return {"person": [round(change(result.initial_flows, result.flows, gt, m), 1) for m in people],
            "background": round(change(result.initial_flows, result.flows, gt, background), 1),
            "all": round(change(result.initial_flows, result.flows, gt, scene.gt.flow_mask()), 1)}  # fmt: skip


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mode", default="3d")
    p.add_argument("--people", default="2,3")
    p.add_argument("--seeds", default="30,31")
    p.add_argument("--weights", default=str(SHARED / "checkpoints/raft-small.pth"))
    p.add_argument("--out", default="/tmp/people_synth")
    p.add_argument("--variants", default="every,main", help="every (the scene as generated), main (person 0 alone)")
    p.add_argument("--flow", default="{}", help='extra FlowTTT options as JSON, e.g. \'{"people_balance": true}\'')
    p.add_argument("--config", default="{}",
                   help='more BootstrapConfig options, JSON, e.g. \'{"zoom": {"confirm": "veto"}}\'')
    p.add_argument("--json", default=None)
    args = p.parse_args()
    rows = []
    for n in [int(v) for v in args.people.split(",")]:
        for i, seed in enumerate(int(v) for v in args.seeds.split(",")):
            scene = make_scene(frames=8, height=128, width=256, motion=MOTIONS[i % len(MOTIONS)], seed=seed, people=n)
            people, background = masks(scene)
            variants = {"every": ("every person", scene), "main": ("main person only", scene.person(0))}
            for variant, run_scene in (variants[v] for v in args.variants.split(",")):
                out = Path(args.out) / f"p{n}_s{seed}_{variant.split()[0]}"
                shutil.rmtree(out, ignore_errors=True)
                start = time.perf_counter()
                flow = {"weights": args.weights, **json.loads(args.flow)}
                result = bootstrap(run_scene, out, mode=args.mode, flow=flow, progress_bar=False, video=False,
                                   **json.loads(args.config))
                seconds = time.perf_counter() - start
                row = {"people": n, "seed": seed, "variant": variant, "seconds": round(seconds, 1),
                       **changes(result, scene, people, background)}  # fmt: skip
                rows.append(row)
                print(json.dumps(row), flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps({"settings": vars(args), "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
