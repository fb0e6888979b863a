"""PoseRefiner speed: 1500 steps on a 300-frame, 14-joint video, Lightning's overhead included.

Rows (each the wall time of the whole ``trainer.fit`` plus the Trainer's construction, with the
scene and flows already in memory; CPU time of this process in brackets):

- lightning: the shipped structure: PoseData serves 1500 step indices as ONE epoch, the data
  lives on the module, loss terms logged every 50 steps, 1 torch thread;
- raw loop: the same loss and fused Adam in a plain PyTorch loop (no Lightning): the floor;
- raw loop, terms reduced separately: each term through its own SmoothL1 reduction (the pure
  functions of lit_boot.pose.losses) instead of the fused Objective;
- lightning, torch threads = default: the same, with torch's default intra-op threads;
- lightning, 1 step per epoch: the issue's first sketch, 1500 epochs of one step each
  (--compare only; measured on --epoch-steps epochs and scaled to 1500).

Early stopping is off so that every row runs exactly 1500 steps. The scene (synthetic walk, 300
frames, GT flow) is rendered once and cached under --cache.

With ``--people 1,2,4``: the shipped row for scenes of P people (the person and P-1 copies of its
estimates, each moved 3 px right per copy; one refinement of every person at once), beside P
single-person runs one after another.

Usage: python benchmarks/pose_refiner_speed.py [--frames 300] [--steps 1500] [--repeats 3] [--compare]
           [--people 1,2,4]
"""

from __future__ import annotations

import argparse
import logging
import os
import time
import warnings
from pathlib import Path

import torch

from lit_boot.core import Person
from lit_boot.data import load_scene, save_scene
from lit_boot.pose import PoseData, PoseRefiner, make_trainer
from lit_boot.synth import make_scene


def scene_for(args):
    folder = Path(args.cache) / f"speed_walk_{args.frames}f_{args.height}x{args.width}"
    if (folder / "scene.json").is_file():
        return load_scene(folder)
    scene = make_scene(motion="walk", frames=args.frames, height=args.height, width=args.width, seed=0)
    save_scene(scene, folder, overwrite=True)
    return scene


def crowd_of(scene, count: int):
    """``scene`` with ``count`` - 1 more people: copies of its estimates moved right 3 px each."""
    main = Person.of(scene)
    others = [Person(p, joints3d=main.joints3d, cameras=main.cameras, keypoints2d=main.keypoints2d + torch.tensor([3.0 * p, 0.0]),
                     keypoints_conf=main.keypoints_conf, person_boxes=main.person_boxes)
              for p in range(1, count)]  # fmt: skip
    return scene.with_people([main, *others])


def people_rows(scene, args) -> None:
    print("\n| people | every person at once: wall s (best of %d) | per person s | P single-person runs s |" % args.repeats)
    print("| --- | --- | --- | --- |")
    for count in [int(v) for v in args.people.split(",")]:
        crowd = crowd_of(scene, count)
        batched = min(timed(lambda: lightning_run(crowd, args.steps, 1))[0] for _ in range(args.repeats))
        single = min(timed(lambda: lightning_run(scene, args.steps, 1))[0] for _ in range(args.repeats)) * count
        print(f"| {count} | {batched:.2f} | {batched / count:.2f} | {single:.2f} |", flush=True)


def timed(fn) -> tuple[float, float]:
    wall, cpu = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - wall, time.process_time() - cpu


def lightning_run(scene, steps: int, num_threads: int | None) -> None:
    model = PoseRefiner(save=False, num_threads=num_threads, eval_every_n_steps=0)
    trainer = make_trainer(steps, early_stop=False, logger=False)
    trainer.fit(model, datamodule=PoseData(scene, scene.gt.flow, steps=steps))
    assert model.global_step == steps


def epochs_run(scene, epochs: int) -> None:
    model = PoseRefiner(save=False, eval_every_n_steps=0)
    trainer = make_trainer(epochs, early_stop=False, logger=False, max_epochs=epochs)
    trainer.fit(model, datamodule=PoseData(scene, scene.gt.flow, steps=1))
    assert model.global_step == epochs


def raw_run(scene, steps: int) -> None:
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    model = PoseRefiner(save=False)
    model.prepare(scene, scene.gt.flow)
    optimizer = torch.optim.Adam(model.parameters(), lr=model.hparams.lr, fused=True)  # as configure_optimizers
    for _ in range(steps):
        optimizer.zero_grad()
        loss, _ = model.total_loss()
        loss.backward()
        optimizer.step()
    torch.set_num_threads(before)


def unfused_run(scene, steps: int) -> None:
    """The raw loop with every term reduced on its own (one SmoothL1 and one dot product per
    term, the Objective's weights split by term) instead of the fused single pass."""
    import torch.nn.functional as F

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    model = PoseRefiner(save=False)
    model.prepare(scene, scene.gt.flow)
    weights = model.objective.weights.split(model.objective.sizes)
    optimizer = torch.optim.Adam(model.parameters(), lr=model.hparams.lr, fused=True)
    for _ in range(steps):
        optimizer.zero_grad()
        loss = sum(torch.dot(F.smooth_l1_loss(r.reshape(-1), torch.zeros_like(w), reduction="none"), w)
                   for r, w in zip(model.residuals(), weights))  # fmt: skip
        loss.backward()
        optimizer.step()
    torch.set_num_threads(before)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--height", type=int, default=128)
    parser.add_argument("--width", type=int, default=256)
    parser.add_argument("--steps", type=int, default=1500)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--compare", action="store_true", help="also time 1-step epochs")
    parser.add_argument("--epoch-steps", type=int, default=300)
    parser.add_argument("--cache", default="/tmp/pose_bench")
    parser.add_argument("--people", default=None, help="e.g. 1,2,4: time scenes of that many people instead")
    args = parser.parse_args()
    warnings.filterwarnings("ignore")
    logging.getLogger("lightning.pytorch").setLevel(logging.ERROR)
    scene = scene_for(args)
    print(f"scene: {scene.num_frames} frames, {scene.joints3d.shape[1]} joints, {scene.width}x{scene.height} px; "
          f"{args.steps} steps; torch {torch.__version__}, {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.2f}")  # fmt: skip
    rows = {
        "lightning (shipped: 1 epoch of N steps, 1 thread)": lambda: lightning_run(scene, args.steps, 1),
        "raw PyTorch loop (no Lightning, 1 thread)": lambda: raw_run(scene, args.steps),
        "raw loop, each term reduced separately (no fused Objective)": lambda: unfused_run(scene, args.steps),
        "lightning, torch default threads": lambda: lightning_run(scene, args.steps, None),
    }
    if args.compare:
        scale = args.steps / args.epoch_steps
        rows[f"lightning, 1 step per epoch (x{scale:g} from {args.epoch_steps} epochs)"] = (
            lambda: epochs_run(scene, args.epoch_steps), scale)  # fmt: skip
    lightning_run(scene, 20, 1)  # warm-up (imports, first allocations)
    if args.people:
        people_rows(scene, args)
        return
    print("\n| variant | wall s (best / median of %d) | CPU s (best) | per step ms |" % args.repeats)
    print("| --- | --- | --- | --- |")
    for name, entry in rows.items():
        fn, scale = entry if isinstance(entry, tuple) else (entry, 1.0)
        times = sorted((timed(fn) for _ in range(args.repeats)), key=lambda t: t[0])
        walls = [t[0] * scale for t in times]
        median = walls[len(walls) // 2]
        print(f"| {name} | {walls[0]:.2f} / {median:.2f} | {min(t[1] for t in times) * scale:.2f} | "
              f"{walls[0] / args.steps * 1000:.2f} |", flush=True)  # fmt: skip
    print(f"\nload average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
