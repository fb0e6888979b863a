"""Does the evidence gate (lit_boot.flow.gate) keep the good sketch pixels and drop the bad?

For seeded synthetic scenes (2D mode: the DCPose-like noisy keypoints2d) and, with
``--parts sintel``, the Sintel samples with MediaPipe keypoints (final pass, the pairs with a
.flo): FlowTTT's targets with the gate off and on (each variant below over the same RAFT base
flows, forward and backward), no training. Per variant, pooled over the pairs' valid
non-occluded pixels (Sintel: valid only):

- painted: fraction of pixels the sketch paints after the guards and the gate; kept: painted
  after / before the gate;
- sketch / base EPE on the painted pixels (px; the gate should drop pixels where the sketch is
  worse than the base);
- target EPE on the region the ungated sketch paints (px; "do no harm": at most the base's,
  which is the "base" column of the off row).

With ``--finetune N``: also the person EPE (synthetic) and the all-pixel EPE (valid pixels,
occluded ones included) after N epochs of FlowTTT on the "off" and the ``--finetune-variants``
targets (slow on CPU); each scene's line ends with pretrained RAFT's.

Usage:
  OMP_NUM_THREADS=1 python benchmarks/gate_check.py [--size 256] [--frames 5] [--scenes 4] [--updates 20]
      [--parts synth,sintel] [--sintel-size 218,512] [--margins=-1,0,1] [--search 3]
      [--finetune 0] [--finetune-variants photometric/bone+pixel/0]
      [--weights ../shared/checkpoints/raft-small.pth]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import lightning as L
import torch

from lit_boot.flow import FlowTTT, SceneFlowData, SketchConfig
from lit_boot.synth import make_scene

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
#: (motion, seed, extra make_scene options): static camera, pan, jump, noise + blur + pan.
SYNTH = [
    ("run", 0, {}),
    ("walk", 1, {"pan_deg_per_s": 20.0}),
    ("jump", 2, {}),
    ("run", 3, {"noise_std": 2.0, "motion_blur": 3, "pan_deg_per_s": -15.0}),
]
SINTEL = [("alley_1", 1, 4), ("market_5", 1, 4), ("temple_3", 21, 24)]


def variants(margins: list[float], search: int) -> dict[str, SketchConfig]:
    """The gate settings compared, named gate/level/margin[/search r]: off; the photometric
    gate per pixel at each margin; per bone and both at margin 0; the same with the fb
    check; and the bone search."""
    out = {"off": SketchConfig()}
    for m in margins:
        out[f"photometric/pixel/{m:g}"] = SketchConfig(gate="photometric", gate_level="pixel", gate_margin=m)
    for gate in ("photometric", "photometric+fb"):
        for level in ("pixel", "bone", "bone+pixel"):
            out.setdefault(f"{gate}/{level}/0", SketchConfig(gate=gate, gate_level=level, gate_margin=0.0))
    if search:
        for level in ("bone", "bone+pixel"):
            out[f"photometric/{level}/0/search{search}"] = SketchConfig(
                gate="photometric", gate_level=level, gate_margin=0.0, gate_search=search
            )
    return out


def region(dm: SceneFlowData) -> torch.Tensor:
    """(P, H, W) bool: valid, non-occluded GT pixels."""
    gt = dm.scene.gt
    ok = gt.flow_valid.clone() if gt.flow_valid is not None else torch.ones_like(gt.flow[:, 0], dtype=torch.bool)
    return ok & ~gt.flow_occluded if gt.flow_occluded is not None else ok


def sums(model: FlowTTT, dm: SceneFlowData, base: torch.Tensor, ungated: torch.Tensor) -> dict[str, float]:
    """Pixel-pooled sums of one variant's current targets on one scene."""
    gt, ok = dm.scene.gt.flow, region(dm)
    err = lambda f, m: float((f - gt).norm(dim=1)[m].sum())  # noqa: E731
    painted, before = model.sketch_masks & ok, ungated & ok
    return {"pixels": float(ok.sum()), "painted": float(painted.sum()), "before": float(before.sum()),
            "sketch": err(model.targets, painted), "base": err(base, painted),
            "target_region": err(model.targets, before), "base_region": err(base, before)}  # fmt: skip


def finetune(model: FlowTTT, dm: SceneFlowData, epochs: int) -> tuple[float, float]:
    """(person EPE (NaN without a person mask), all-pixel EPE) after ``epochs`` of FlowTTT on
    the set targets."""
    trainer = L.Trainer(max_epochs=epochs, logger=False, enable_checkpointing=False, enable_progress_bar=False,
                        enable_model_summary=False, num_sanity_val_steps=0, check_val_every_n_epoch=epochs)  # fmt: skip
    trainer.fit(model, datamodule=dm)
    m = trainer.callback_metrics
    return float(m.get("val/epe_person", float("nan"))), float(m["val/epe"])


def run_scene(name: str, dm: SceneFlowData, args, table: dict[str, dict[str, float]]) -> None:
    """Base flows once, then every variant's targets (and fine-tunes when asked)."""
    t0 = time.time()
    model = FlowTTT(weights=args.weights, train_updates=args.updates, predict_updates=args.updates,
                    sketch=SketchConfig(gate="photometric+fb"))  # fmt: skip
    state = {k: v.clone() for k, v in model.raft.state_dict().items()}
    inputs = dm.sketch_inputs()  # (loads the scene)
    base, bw = model.base_flows(dm.scene)
    model.sketch_config = SketchConfig()
    model.targets_from(dm.scene, base, inputs=inputs)
    ungated = model.sketch_masks.clone()
    for key, cfg in variants(args.margins, args.search).items():
        model.sketch_config = cfg
        report = model.targets_from(dm.scene, base, bw, inputs=inputs)
        s = sums(model, dm, base, ungated)
        s["kept"] = report.get("target/gate_kept_fraction", 1.0)
        if args.finetune and (key == "off" or key in args.finetune_variants):
            model.raft.load_state_dict(state)
            model.original = None
            (s["after"], s["after_all"]), s["runs"] = finetune(model, dm, args.finetune), 1.0
        for k, v in s.items():
            table.setdefault(key, {})[k] = table.get(key, {}).get(k, 0.0) + v
        print_row(f"{name} {key}", s)
    gt = dm.scene.gt
    valid = gt.flow_valid if gt.flow_valid is not None else torch.ones_like(gt.flow[:, 0], dtype=torch.bool)
    person = valid & gt.person_mask[:-1] if gt.person_mask is not None else valid
    epe = [float((base - gt.flow).norm(dim=1)[m].mean()) for m in (person, valid)]
    print(f"  ({name}: {time.time() - t0:.0f} s; pretrained RAFT's EPE person, all: {epe[0]:.3f} {epe[1]:.3f})")


def print_row(label: str, s: dict[str, float]) -> None:
    r = lambda a, b: s[a] / s[b] if s[b] else float("nan")  # noqa: E731
    after = f"  {s['after'] / s['runs']:.3f} {s['after_all'] / s['runs']:.3f}" if "after" in s else ""
    print(f"{label:<44} {r('painted', 'pixels'):7.4f} {r('painted', 'before'):6.3f} {r('sketch', 'painted'):7.3f} "
          f"{r('base', 'painted'):7.3f} {r('target_region', 'before'):7.3f} {r('base_region', 'before'):7.3f}{after}",
          flush=True)  # fmt: skip


def synth_scenes(args):
    for motion, seed, extra in SYNTH[: args.scenes]:
        scene = make_scene(motion=motion, seed=seed, frames=args.frames, height=args.size, width=args.size, **extra)
        yield f"synth {motion} seed={seed}", SceneFlowData(scene, pose_source="keypoints2d")


def sintel_scenes(args):
    from lit_boot.data.readers import read_sintel
    from lit_boot.estimate import estimate_poses

    size = tuple(int(v) for v in args.sintel_size.split(","))
    root = SHARED / "data/sintel_samples"
    for name, first, last in SINTEL:
        poses = estimate_poses(read_sintel(root, name, first=first, last=last))
        scene = poses.apply_to(read_sintel(root, name, first=first, last=last, size=size))
        yield f"sintel {name}", SceneFlowData(scene, pose_source="keypoints2d")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--size", type=int, default=256)
    p.add_argument("--frames", type=int, default=5)
    p.add_argument("--scenes", type=int, default=len(SYNTH), help="the first N synthetic scenes")
    p.add_argument("--updates", type=int, default=20)
    p.add_argument("--parts", default="synth")
    p.add_argument("--sintel-size", default="218,512")
    p.add_argument("--margins", type=lambda s: [float(v) for v in s.split(",")], default=[-1.0, 0.0, 1.0])
    p.add_argument("--search", type=int, default=3, help="gate_search radius of the search variants (0: none)")
    p.add_argument("--finetune", type=int, default=0, help="FlowTTT epochs per variant (0: targets only)")
    p.add_argument("--finetune-variants", type=lambda s: s.split(","), default=["photometric/bone+pixel/0"])
    p.add_argument("--weights", default=str(SHARED / "checkpoints/raft-small.pth"))
    args = p.parse_args()
    torch.manual_seed(0)
    print(f"settings: {vars(args)}")
    print(f"{'scene / variant':<44} painted   kept  sketch    base  target  base    (EPE px; last two: on the "
          "ungated sketch's pixels)" + ("  after: person, all" if args.finetune else ""))  # fmt: skip
    for part, scenes in (("synth", synth_scenes), ("sintel", sintel_scenes)):
        if part not in args.parts:
            continue
        table: dict[str, dict[str, float]] = {}
        for name, dm in scenes(args):
            run_scene(name, dm, args, table)
        for key, s in table.items():
            print_row(f"{part} pooled: {key}", s)


if __name__ == "__main__":
    main()
