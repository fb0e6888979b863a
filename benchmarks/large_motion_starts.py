"""Where RAFT fails on large motion (issue 24, part 2): does a better start help? RAFT-small on
the GT pairs of the shared Sintel windows, no training, all-pixel EPE against the GT:

- ``base``: RAFT from zero (32 updates), the method's initial flow;
- ``coarseF``: RAFT on the pair resized by F (the motion F times smaller), scaled back;
- ``warmF``: RAFT at the pair's size started from ``coarseF`` (coarse to fine,
  lit_boot.flow.zoom.zoomed_flow with the whole frame as the crop and ``start``);
- ``warm_self``: RAFT started from its own flow (32 more updates).

Usage:
  OMP_NUM_THREADS=1 python benchmarks/large_motion_starts.py [--size 218,512|full]
      [--windows alley_1,market_5,market_5b,temple_3,bandage_1,ambush_4] [--factors 0.5,0.75]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import torch

from lit_boot.flow import load_raft, predict_flow
from lit_boot.flow.zoom import zoomed_flow
from real_data import HELDOUT_ROOT, SHARED, SINTEL, window_with_boxes


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", default="218,512")
    p.add_argument("--windows", default=",".join(w for w, *_ in SINTEL))
    p.add_argument("--factors", default="0.5,0.75")
    p.add_argument("--weights", default=str(SHARED / "checkpoints/raft-small.pth"))
    args = p.parse_args()
    torch.set_grad_enabled(False)
    model = load_raft("raft_small", args.weights).eval()
    size = None if args.size == "full" else tuple(int(v) for v in args.size.split(","))
    for window in args.windows.split(","):
        scene, _ = window_with_boxes(window, size, str(SHARED / "checkpoints/yolox_nano.onnx"), Path(HELDOUT_ROOT))
        height, width = scene.frames.shape[-2:]
        errors: dict[str, list[float]] = {}
        for t in (t for t in range(scene.num_frames - 1) if scene.gt.flow_valid[t].any()):
            a, b = scene.frames[t], scene.frames[t + 1]
            base = predict_flow(model, a[None], b[None])[0]
            whole = (0, height, 0, width)
            flows = {"base": base, "warm_self": zoomed_flow(model, a, b, whole, 1.0, 32, start=base)}
            for factor in (float(v) for v in args.factors.split(",")):
                coarse = zoomed_flow(model, a, b, whole, factor, 32)  # RAFT on the resized pair
                flows[f"coarse{factor}"] = coarse
                flows[f"warm{factor}"] = zoomed_flow(model, a, b, whole, 1.0, 32, start=coarse)
            valid = scene.gt.flow_valid[t]
            for name, flow in flows.items():
                errors.setdefault(name, []).append(float((flow - scene.gt.flow[t]).norm(dim=0)[valid].mean()))
        print(json.dumps({"window": window, **{k: round(sum(v) / len(v), 3) for k, v in errors.items()}}), flush=True)


if __name__ == "__main__":
    main()
