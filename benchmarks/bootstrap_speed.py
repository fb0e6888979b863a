"""Speed of the whole method: wall time / plain RAFT inference on the same frames, s/frame, peak memory.

Usage:
  python benchmarks/bootstrap_speed.py [--height 436 --width 1024 --frames 12] [--arch raft_small]
      [--weights ../shared/checkpoints/raft-small.pth] [--precision 16-mixed] [--train-updates 20]
      [--grad-updates 5] [--crop-margin 48] [--warm-start] [--lr 3e-5] [--flow JSON] [--mode 2d]
      [--epochs 8] [--pose-steps 1500] [--repeats 3] [--config JSON]

The preset's FlowTTT options hold unless given. ``--repeats N`` runs the method N times in this
process and reports the run with the median ratio, with every run's ratio in "ratios": the RAFT
stage of a small scene takes only seconds, so one run's ratio is noisy.

One synthetic scene (run s0), one bootstrap run (flow -> pose -> flow, default preset) in this
process. "RAFT" = the run's own initial stage: plain inference of every pair with 32 updates, so
the ratio compares like with like in the same run. Peak memory: CUDA max allocated, or the
process's peak resident set size on CPU. The levers: --precision (bf16-mixed / 16-mixed on
CUDA), --train-updates (RAFT iterations per training step), --grad-updates (backpropagate through
the last N of them only), --crop-margin (train on a crop around the person), --epochs.
"""

from __future__ import annotations

import argparse
import json
import resource
import tempfile
from pathlib import Path

import torch

from lit_boot.bootstrap import bootstrap
from lit_boot.bootstrap.outputs import speed_summary
from lit_boot.synth import make_scene

SHARED = Path(__file__).resolve().parents[1].parent / "shared"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--height", type=int, default=436)
    p.add_argument("--width", type=int, default=1024)
    p.add_argument("--frames", type=int, default=12)
    p.add_argument("--arch", default="raft_small")
    p.add_argument("--weights", default=str(SHARED / "checkpoints/raft-small.pth"))
    p.add_argument("--precision", default=None, help="Lightning precision of the flow stages (default: the preset's)")
    p.add_argument("--train-updates", type=int, default=None)
    p.add_argument("--grad-updates", type=int, default=None, help="backpropagate through the last N updates only")
    p.add_argument("--crop-margin", type=int, default=None)
    p.add_argument("--warm-start", action="store_true", help="frozen cached encoders, warm start (train_parts update_block)")
    p.add_argument("--lr", type=float, default=None)
    p.add_argument("--flow", default="{}", help="more FlowTTT options over the preset's, JSON")
    p.add_argument("--mode", default="3d", choices=("3d", "2d"))
    p.add_argument("--epochs", type=int, default=None, help="per flow stage (default: the mode's, 8 in 3D, 50 in 2D)")
    p.add_argument("--pose-steps", type=int, default=1500)
    p.add_argument("--repeats", type=int, default=1, help="runs; the one with the median ratio is reported")
    p.add_argument("--config", default="{}", help="more BootstrapConfig options, JSON (e.g. '{\"zoom\": {\"method\": \"off\"}}')")
    args = p.parse_args()
    scene = make_scene(motion="run", frames=args.frames, height=args.height, width=args.width, seed=0)
    flow = {"arch": args.arch, "weights": args.weights}
    given = {"train_updates": args.train_updates, "grad_updates": args.grad_updates, "crop_margin": args.crop_margin,
             "lr": args.lr}  # fmt: skip
    flow.update({k: v for k, v in given.items() if v is not None})
    flow.update(json.loads(args.flow))
    if args.warm_start:
        flow.update(warm_start=True, train_parts="update_block")
    runs = []
    for _ in range(args.repeats):
        with tempfile.TemporaryDirectory() as tmp:
            result = bootstrap(scene, Path(tmp) / "run", flow=flow, mode=args.mode, flow_epochs=args.epochs,
                               pose_steps=args.pose_steps, precision=args.precision, progress_bar=False, video=False,
                               **json.loads(args.config))  # fmt: skip
        runs.append((speed_summary(result), result))
    runs.sort(key=lambda run: run[0]["ratio_to_raft"])
    speed, result = runs[len(runs) // 2]
    speed["ratios"] = [round(run[0]["ratio_to_raft"], 2) for run in runs]
    cuda = torch.cuda.is_available()
    speed["peak_mib"] = (torch.cuda.max_memory_allocated() if cuda else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024) / 2**20
    speed["device"] = torch.cuda.get_device_name() if cuda else f"cpu ({torch.get_num_threads()} threads)"
    speed["stages_s"] = result.seconds
    speed["settings"] = vars(args)
    print(json.dumps(speed, indent=1))


if __name__ == "__main__":
    main()
