"""What the product's own identity switches cost the method: the whole method on synthetic scenes
with several people, from the estimates a user's run makes (issue 25's synthetic bar).

Per scene: ``estimate_poses(frames, people="all", detector=YOLOX-Nano)`` (YOLOX boxes, MediaPipe on
each box's crop, the tracker), then the method (``bootstrap``, --mode) twice on the scene with
those estimates in place of its simulated ones: "own", the tracker's ids as they are; "true ids",
the same poses and boxes re-labelled frame by frame to the true person each pose lies on
(``people_synth_e2e.pose_owners``; a pose on nobody stays with its track). The two runs differ
only by the identity switches. Per run: the EPE change of the final flow against pretrained
RAFT's on each true person's pixels, the background and all pixels (``people_synth.masks``), and
the poses' switches on the true people (``people_synth_e2e.pose_switches``; 0 with true ids).
Scenes: make_scene(people=N, frames=--frames, --height x --width, seed, motion by the seed's place
in --seeds, as benchmarks/people_synth_e2e.py).

The first line names the installed versions the estimates move with (as people_synth_e2e.py's).

Usage: OMP_NUM_THREADS=1 python benchmarks/people_synth_own.py [--mode 2d|3d] [--people 2,3]
           [--seeds 30,31,32,33] [--frames 8] [--height 256] [--width 512]
           [--weights ../shared/checkpoints/raft-small.pth] [--out /tmp/people_synth_own] [--json out.json]
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import time
from pathlib import Path

import torch

from lit_boot.bootstrap import bootstrap
from lit_boot.core.cameras import Cameras
from lit_boot.core.people import Person
from lit_boot.estimate import PersonDetector, estimate_poses
from lit_boot.synth import make_scene
from people_synth import changes, masks
from people_synth_e2e import package_versions, pose_owners, pose_switches, visible_boxes
from people_synth_tracking import MOTIONS, scene_parser, true_people
from real_data import SHARED

FIELDS = ("joints3d", "keypoints2d", "keypoints_conf", "person_boxes")


def regrouped(people: list[Person], source: torch.Tensor, track_id: int) -> Person:
    """A person whose frame t is ``people[source[t]]``'s frame t (``source`` (T,) int, -1: absent,
    its confidences and box score 0)."""
    T = source.shape[0]
    filler = people[0]
    rows = [(people[int(q)] if q >= 0 else filler, t) for t, q in enumerate(source)]

    def gather(get) -> torch.Tensor:
        return torch.stack([get(person)[t] for person, t in rows])

    out = {}
    for key in FIELDS:
        if getattr(filler, key) is not None:
            out[key] = gather(lambda p, key=key: getattr(p, key)).clone()
            if key in ("keypoints_conf", "person_boxes"):
                out[key][source < 0] = 0
    cams = filler.cameras
    if cams is not None:
        crops = None if cams.crops is None else gather(lambda p: p.cameras.crops)
        out["cameras"] = Cameras(cams.model, gather(lambda p: p.cameras.params), crops, cams.crop_size)
    assert all(v.shape[0] == T for k, v in out.items() if k != "cameras")
    return Person(track_id=track_id, **out)


def true_ids(scene, people: list[Person], min_pixels: int, max_dist: float) -> tuple[list[Person], list[dict]]:
    """``people`` (the returned ones) re-labelled: one person per true person, each frame's pose the
    returned one lying on it; what lies on nobody stays with its own track (ids from 100). Also the
    poses' switches per true person under the tracker's ids."""
    posed = [i for i, p in enumerate(people) if p.keypoints_conf is not None and p.keypoints_conf.amax() > 0]
    truths = true_people(scene)
    visible = visible_boxes(scene, min_pixels)[..., 4] > 0
    covering = pose_owners([people[i] for i in posed], truths, visible, max_dist)
    T = scene.num_frames
    taken = torch.zeros(len(people), T, dtype=torch.bool)
    out = []
    for p, owners in enumerate(covering):
        source = torch.tensor([posed[q] if q is not None else -1 for q in owners])
        taken[source[source >= 0], torch.arange(T)[source >= 0]] = True
        if (source >= 0).any():
            out.append(regrouped(people, source, p))
    for i, person in enumerate(people):
        rest = torch.where(taken[i], -1, i)
        if not taken[i].all() and bool(person.found()[rest >= 0].any()):
            out.append(regrouped(people, rest, 100 + i))
    return out, pose_switches(covering)


def bare(scene):
    """``scene`` without its simulated estimates (the GT stays)."""
    return dataclasses.replace(scene, joints3d=None, cameras=None, keypoints2d=None, keypoints_conf=None,
                               person_boxes=None, others=())  # fmt: skip


def main() -> None:
    parser = scene_parser(__doc__.splitlines()[0])
    parser.set_defaults(frames=8)
    parser.add_argument("--mode", default="2d")
    parser.add_argument("--height", type=int, default=256)
    parser.add_argument("--width", type=int, default=512)
    parser.add_argument("--min-pixels", type=int, default=50)
    parser.add_argument("--max-pose-dist", type=float, default=0.15)
    parser.add_argument("--weights", default=str(SHARED / "checkpoints/raft-small.pth"))
    parser.add_argument("--detector", default=str(SHARED / "checkpoints/yolox_nano.onnx"))
    parser.add_argument("--out", default="/tmp/people_synth_own")
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    detector = PersonDetector(args.detector)
    print(f"packages: {package_versions()}")
    rows = []
    for n in (int(v) for v in args.people.split(",")):
        for i, seed in enumerate(int(v) for v in args.seeds.split(",")):
            scene = make_scene(frames=args.frames, height=args.height, width=args.width,
                               motion=MOTIONS[i % len(MOTIONS)], seed=seed, people=n)  # fmt: skip
            people_px, background = masks(scene)
            est = estimate_poses(scene.frames, people="all", detector=detector)
            relabelled, switches = true_ids(scene, est.people(), args.min_pixels, args.max_pose_dist)
            runs = {"own": est, "true ids": est.with_people(relabelled)}
            for variant, estimates in runs.items():
                out = Path(args.out) / f"p{n}_s{seed}_{variant.replace(' ', '_')}"
                shutil.rmtree(out, ignore_errors=True)
                start = time.perf_counter()
                result = bootstrap(estimates.apply_to(bare(scene)), out, mode=args.mode,
                                   flow={"weights": args.weights}, progress_bar=False, video=False)  # fmt: skip
                row = {"people": n, "seed": seed, "variant": variant, "seconds": round(time.perf_counter() - start, 1),
                       "pose_switches": int(sum(s["pose_switches"] for s in switches)) if variant == "own" else 0,
                       "pose_frames": [int(s["pose_frames"]) for s in switches],
                       **changes(result, scene, people_px, background)}  # fmt: skip
                rows.append(row)
                print(json.dumps(row), flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps({"settings": vars(args), "packages": package_versions(), "rows": rows},
                                              indent=1))


if __name__ == "__main__":
    main()
