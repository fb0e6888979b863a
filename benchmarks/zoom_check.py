"""What tells a good zoomed flow from a bad one (issue 24, part 1), on real Sintel windows with GT.

For every GT pair of each window: pretrained RAFT's flow (32 updates), the person's box (the YOLOX
person detector, followed over the window: lit_boot.estimate.person_boxes, on the full-size
frames), and RAFT on the crop around the box zoomed 2x and 1.5x (lit_boot.flow.zoom.zoom_pair with
a fixed scale). Then each rule for what to keep of the zoomed flow, and the all-pixel EPE it gives
(every valid pixel, occluded ones included: Sintel's convention), as a change against RAFT's:

- zoom: the zoomed flow on its whole pasted region;
- census: where the frames say it is better (the self-check's person rule: 5x5 mean census error
  2% lower and the pixel's own lower; lit_boot.bootstrap.selfcheck.choose_pixels);
- refine<D: where it moves RAFT's flow by less than D px (lit_boot.flow.zoom.refines);
- census&refine<D: both (the zoom stage's rule);
- R<N: the scale is chosen from the motion (s = min(2, N / the 95th percentile of RAFT's flow on
  the box), 1.5x when 2x is out of reach, no zoom below that), then census&refine<8.

Usage:
  python benchmarks/zoom_check.py [--windows alley_1,...,h_cave_2a,...] [--size 218,512|full]
      [--updates 32] [--weights ../shared/checkpoints/raft-small.pth] [--json out.json]
The windows are benchmarks/real_data.py's SINTEL (../shared) and HELDOUT (--heldout-root).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import torch

from lit_boot.bootstrap.config import ZoomConfig
from lit_boot.bootstrap.zoom import keep_pixels
from lit_boot.flow import load_raft, predict_flow
from lit_boot.flow.zoom import pair_boxes, refines, zoom_pair
from real_data import HELDOUT, HELDOUT_ROOT, SHARED, SINTEL, window_with_boxes

SCALES = (2.0, 1.5)


def rules(pair: dict) -> dict[str, tuple[torch.Tensor, float] | None]:
    """Rule -> (the zoomed flow's pixels kept (H, W) bool, the scale whose zoomed flow they take),
    or None (not zoomed)."""
    base, out = pair["base"], {}
    for scale in SCALES:
        cand = pair.get(scale)
        if cand is None:
            continue
        census, region, tag = pair[f"census{scale}"], pair[f"region{scale}"], "" if scale == 2.0 else "@1.5"
        out["zoom" + tag] = (region, scale)
        out["census" + tag] = (census, scale)
        for d in (4.0, 8.0, 16.0):
            out[f"refine<{d:g}{tag}"] = (refines(base, cand, d) & region, scale)
            out[f"census&refine<{d:g}{tag}"] = (census & refines(base, cand, d), scale)
    for reach in (40.0, 60.0, 80.0):
        pick = next((s for s in SCALES if s * pair["motion"] <= reach and pair.get(s) is not None), None)
        out[f"R<{reach:g}"] = None if pick is None else (pair[f"census{pick}"] & refines(base, pair[pick], 8.0), pick)
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--windows", default=",".join([w for w, *_ in SINTEL] + [w for w, *_ in HELDOUT]))
    p.add_argument("--heldout-root", default=str(HELDOUT_ROOT))
    p.add_argument("--size", default="218,512", help="H,W or full (436x1024)")
    p.add_argument("--updates", type=int, default=32, help="RAFT iterations, also on the zoomed crop")
    p.add_argument("--weights", default=str(SHARED / "checkpoints/raft-small.pth"))
    p.add_argument("--detector", default=str(SHARED / "checkpoints/yolox_nano.onnx"))
    p.add_argument("--json", default=None)
    args = p.parse_args()
    print(f"settings: {vars(args)}", flush=True)
    size = None if args.size == "full" else tuple(int(v) for v in args.size.split(","))
    model = load_raft("raft_small", args.weights).eval()
    config = ZoomConfig()
    table = {}
    for window in args.windows.split(","):
        scene, boxes = window_with_boxes(window, size, args.detector, Path(args.heldout_root))
        sums = {}
        for t, box in enumerate(pair_boxes(boxes)):
            if not scene.gt.flow_valid[t].any():
                continue
            frames, gt, valid = scene.frames[t : t + 2], scene.gt.flow[t], scene.gt.flow_valid[t]
            start = time.perf_counter()
            base = predict_flow(model, frames[:1], frames[1:], args.updates)[0].float()
            pair = {"base": base, "motion": 0.0, "seconds_raft": time.perf_counter() - start}
            for scale in SCALES if box is not None else ():
                zoomed = zoom_pair(model, frames[0], frames[1], base, box, max_scale=scale, min_scale=scale,
                                   reach_px=1e9, context=config.context, min_context_px=config.min_context_px,
                                   border_px=config.border_px, min_updates=args.updates,
                                   max_updates=args.updates)  # fmt: skip
                if zoomed.region is None:
                    continue
                y0, y1, x0, x1 = zoomed.region
                region = torch.zeros_like(valid)
                region[y0:y1, x0:x1] = True
                pair |= {scale: zoomed.candidate, f"region{scale}": region, "motion": zoomed.motion_px,
                         f"census{scale}": keep_pixels(frames, base, zoomed.candidate, zoomed.region,
                                                 ZoomConfig(max_change_px=1e9))}  # fmt: skip
            err_base = (base - gt).norm(dim=0)
            sums.setdefault("raft", [0.0, 0.0])
            sums["raft"][0] += float(err_base[valid].sum())
            sums["raft"][1] += float(valid.sum())
            for name, rule in rules(pair).items():
                err = err_base
                if rule is not None:
                    keep, scale = rule
                    err = torch.where(keep, (pair[scale] - gt).norm(dim=0), err_base)
                acc = sums.setdefault(name, [0.0, 0.0])
                acc[0] += float(err[valid].sum())
                acc[1] += float(valid.sum())
        raft = sums["raft"][0] / sums["raft"][1]
        table[window] = {name: 100 * (s[0] / s[1] / raft - 1) for name, s in sums.items() if name != "raft"}
        table[window]["raft_epe"] = raft
        print(json.dumps({window: {k: round(v, 2) for k, v in table[window].items()}}), flush=True)
    names = sorted({n for row in table.values() for n in row if n != "raft_epe"})
    print("\n| rule | " + " | ".join(table) + " | mean shared | worst shared | mean held-out | worst held-out |")
    print("| --- " * (5 + len(table)) + "|")
    for name in names:
        vals = {w: row.get(name, 0.0) for w, row in table.items()}
        shared = [v for w, v in vals.items() if not w.startswith("h_")]
        held = [v for w, v in vals.items() if w.startswith("h_")]
        agg = [f"{sum(x) / len(x):+.1f}%" if x else "-" for x in (shared,)] + [f"{max(shared):+.1f}%" if shared else "-"]
        agg += [f"{sum(held) / len(held):+.1f}%" if held else "-", f"{max(held):+.1f}%" if held else "-"]
        print(f"| {name} | " + " | ".join(f"{v:+.1f}%" for v in vals.values()) + " | " + " | ".join(agg) + " |")
    if args.json:
        Path(args.json).write_text(json.dumps({"settings": vars(args), "table": table}, indent=1))


if __name__ == "__main__":
    main()
