"""Why a person of a multi-person synthetic scene gains less: each person's first target.

For each person of the scenes of ``people_synth.py`` (make_scene(people=N), 8 frames, 128x256):
visible pixels (valid, not occluded), height in px, the simulated detector's keypoint error on
the keypoints it found (px) and the share found, pretrained RAFT's EPE on the person's pixels,
the share of them painted by FlowTTT's first target (the default sketch, before any training)
and, on the painted pixels, RAFT's EPE against the target's. A target worse than RAFT there
has nothing good to teach.

Usage: OMP_NUM_THREADS=1 python benchmarks/people_targets.py [--mode 3d|2d]
           [--weights ../shared/checkpoints/raft-small.pth]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import torch

from lit_boot.flow import FlowTTT
from lit_boot.flow.data import SOURCE_OF_MODE, sketch_inputs
from lit_boot.synth import make_scene

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
SCENES = ((2, 30, "walk"), (2, 31, "run"), (3, 30, "walk"), (3, 31, "run"))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mode", default="3d")
    p.add_argument("--weights", default=str(SHARED / "checkpoints/raft-small.pth"))
    args = p.parse_args()
    print("| scene | person | pixels | height px | keypoint error px (found) | RAFT EPE | painted | on painted: RAFT / target EPE |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for n, seed, motion in SCENES:
        scene = make_scene(frames=8, height=128, width=256, motion=motion, seed=seed, people=n)
        gt = scene.gt
        model = FlowTTT(weights=args.weights).eval()
        model.prepare(scene, sketch_inputs(scene, SOURCE_OF_MODE[args.mode]))
        base, _ = model.base_flows(scene)
        raft = (base - gt.flow).norm(dim=1)
        target = (model.targets.cpu() - gt.flow).norm(dim=1)
        for person, truth in zip(scene.people(), gt.truths([q.track_id for q in scene.people()])):
            mask = truth.person_mask[:-1] & gt.flow_mask()
            painted = model.sketch_masks.cpu() & mask
            height = (truth.joints2d[..., 1].amax(-1) - truth.joints2d[..., 1].amin(-1)).mean()
            found = person.keypoints_conf > 0
            error = (person.keypoints2d - truth.keypoints2d).norm(dim=-1)[found].mean()
            print(f"| {n} people, s{seed} | {person.track_id} | {int(mask.sum())} | {float(height):.0f} | "
                  f"{float(error):.2f} ({float(found.float().mean()):.0%}) | {float(raft[mask].mean()):.2f} | "
                  f"{float(painted.sum() / mask.sum()):.0%} | {float(raft[painted].mean()):.2f} / "
                  f"{float(target[painted].mean()):.2f} |", flush=True)


if __name__ == "__main__":
    main()
