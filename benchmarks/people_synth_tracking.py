"""The person tracker on synthetic scenes with several people: identity switches and coverage
against the true identities (issue 25's "zero identity switches" bar).

Each person's true box per frame (its visible keypoints' extent, ``Scene.people()[p].person_boxes``)
becomes a detection with the edges jittered by ``--jitter`` of the box's larger side, missed with
probability ``--miss``, and each frame's detections shuffled; :func:`lit_boot.estimate.track_people`
links them (``--min-visible K``: a person is detected only where at least K of its 17 keypoints
are seen, as a real detector needs more than a sliver; `benchmarks/people_synth_detectability.py`
measures YOLOX-Nano's rate per count). Per true person: the frames it is visible in, the share of
them a track covers, and its identity switches (the covering track changes between two covered frames, the MOT
definition). Scenes: make_scene(people=N, frames=--frames, 128x256), seeds and motions below;
the other people walk across, crossing and occluding person 0.

Usage: python benchmarks/people_synth_tracking.py [--people 2,3] [--seeds 30,31,32,33]
           [--frames 16] [--jitter 0.05] [--miss 0.1] [--smoothing 0.5] [--keypoints]
           [--pose-miss 0.3|seen] [--keypoint-weight 1] [--no-stitch] [--beam 1] [--min-visible 8]
           [--looks] [--json out.json] [--grid [--seen-poses]]

``--grid`` prints one line instead of the table: the identity switches summed over the people of
the scenes, "noisy" (5% jitter, 10% missed), "exact" (none) and "harder" (10%/20%, 5%/20% and
10%/10%, summed) at pose-miss 0, then every condition's sum at pose-miss 0 / 0.3 / 0.6 and their
total (BENCHMARKS.md, "Keypoints in the tracker"); --jitter, --miss and --pose-miss are then unused.
``--pose-miss seen`` misses a detection's pose as the product's own estimator does on these scenes,
by how much of the person is seen (:data:`POSE_FOUND_BY_SEEN`), not at random; ``--grid
--seen-poses`` prints "noisy, exact, harder; total" with the poses missed that way. ``--looks``
gives the tracker each detection's look (:func:`lit_boot.estimate.looks.detection_looks`: the colours
of the rendered frame near its keypoints), as the product's estimator does.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import torch
import torch.nn.functional as F

from lit_boot.estimate import track_people
from lit_boot.estimate.looks import detection_looks
from lit_boot.synth import make_scene

MOTIONS = ("walk", "run", "wave")
#: (fewest keypoints seen, share of the detected people given a pose): MediaPipe on YOLOX-Nano's
#: crops of the rendered scenes, `people_synth_detectability.py --poses` on seeds 30-33 and 42-49
#: (BENCHMARKS.md, "A detector that needs more than a sliver"): none with 10 keypoints seen or
#: fewer, a quarter with 11-16, half of the fully seen.
POSE_FOUND_BY_SEEN = ((0, 0.0), (11, 0.26), (17, 0.50))


def true_people(scene) -> list:
    """The scene's true people (PersonTruth), in ``scene.people()`` order."""
    return scene.gt.truths([p.track_id for p in scene.people()])


def seen_keypoints(scene) -> torch.Tensor:
    """(P, T, 17) bool: each true person's COCO-17 keypoints seen: inside the frame, with a pixel of
    that person's own rendered mask within 1 px of the keypoint (the 3x3 around it)."""
    truths = true_people(scene)
    masks = torch.stack([t.person_mask for t in truths])  # (P, T, H, W)
    near = F.max_pool2d(masks.flatten(0, 1).float()[:, None], 3, 1, 1)[:, 0].view(masks.shape) > 0
    P, T, H, W = masks.shape
    px = torch.stack([t.keypoints2d for t in truths]).round().long()  # (P, T, 17, 2)
    inside = (px[..., 0] >= 0) & (px[..., 0] < W) & (px[..., 1] >= 0) & (px[..., 1] < H)
    x, y = px[..., 0].clamp(0, W - 1), px[..., 1].clamp(0, H - 1)
    return near[torch.arange(P)[:, None, None], torch.arange(T)[None, :, None], y, x] & inside


def visible_keypoints(scene) -> torch.Tensor:
    """(P, T) how many of each true person's COCO-17 keypoints are seen (:func:`seen_keypoints`)."""
    return seen_keypoints(scene).sum(-1)


def detections_of(scene, jitter: float, miss: float, g: torch.Generator,
                  min_visible: int = 1) -> tuple[list[torch.Tensor], list[list[int]], list[torch.Tensor]]:  # fmt: skip
    """Each frame's noisy, shuffled detections (N_t, 5), the true person of each, and each one's
    keypoints (N_t, K, 3): the person's simulated 2D estimates (x, y px, confidence). With
    ``min_visible`` > 1, a person is detected only where at least that many of its keypoints are
    seen (:func:`visible_keypoints`; 1: wherever its box is, any keypoint seen)."""
    boxes = torch.stack([p.person_boxes for p in scene.people()])  # (P, T, 5)
    # the random draws as with every box: the same misses and jitter for the boxes that stay
    seen = visible_keypoints(scene) >= min_visible if min_visible > 1 else torch.ones(boxes.shape[:2], dtype=bool)
    poses = torch.stack([torch.cat([p.keypoints2d, p.keypoints_conf[..., None]], -1) for p in scene.people()])
    dets, who, kps = [], [], []
    for t in range(boxes.shape[1]):
        rows, owners = [], []
        for p in range(boxes.shape[0]):
            box = boxes[p, t]
            if box[4] <= 0 or torch.rand(1, generator=g).item() < miss:
                continue
            side = float((box[2:4] - box[:2]).max().clamp_min(1.0))
            noisy = box[:4] + torch.randn(4, generator=g) * jitter * side
            rows.append(torch.cat([torch.minimum(noisy[:2], noisy[2:]), torch.maximum(noisy[:2], noisy[2:]),
                                   torch.tensor([0.9])]))  # fmt: skip
            owners.append(p)
        order = [i for i in torch.randperm(len(rows), generator=g).tolist() if seen[owners[i], t]]
        dets.append(torch.stack([rows[i] for i in order]) if order else torch.zeros(0, 5))
        who.append([owners[i] for i in order])
        kps.append(poses[[owners[i] for i in order], t].reshape(len(order), poses.shape[2], 3))
    return dets, who, kps


def pose_missed(seen: list[int], pose_miss: float | str, g: torch.Generator) -> torch.Tensor:
    """(N,) True where a detection's pose is not found: at random with probability ``pose_miss``, or,
    with ``"seen"``, by how many keypoints of its person are ``seen`` (:data:`POSE_FOUND_BY_SEEN`)."""
    draw = torch.rand(len(seen), generator=g)
    if pose_miss != "seen":
        return draw < float(pose_miss)
    found = torch.tensor([[rate for least, rate in POSE_FOUND_BY_SEEN if n >= least][-1] for n in seen])
    return draw >= found.reshape(-1)


def score(tracks: torch.Tensor, dets: list[torch.Tensor], who: list[list[int]], visible: torch.Tensor) -> list[dict]:
    """Per true person: visible frames, covered share, identity switches."""
    P, T = visible.shape
    covering = [[None] * T for _ in range(P)]
    for k, track in enumerate(tracks):
        for t in range(T):
            if track[t, 4] <= 0 or not len(dets[t]):
                continue
            same = (dets[t] == track[t]).all(-1).nonzero()
            if len(same):
                covering[who[t][int(same[0])]][t] = k
    rows = []
    for p in range(P):
        seen = [k for k in covering[p] if k is not None]
        switches = sum(a != b for a, b in zip(seen, seen[1:]))
        shown = int(visible[p].sum())
        covered = round(len(seen) / max(shown, 1), 3)
        rows.append({"person": p, "visible": shown, "covered": covered, "switches": switches})
    return rows


GRID = {"noisy": [(0.05, 0.1)], "exact": [(0.0, 0.0)], "harder": [(0.1, 0.2), (0.05, 0.2), (0.1, 0.1)]}


def switches(args: argparse.Namespace, jitter: float, miss: float, pose_miss: float | str) -> tuple[int, list[dict]]:
    """The identity switches summed over every scene's people, and the scenes' rows."""
    total, out = 0, []
    for n in (int(v) for v in args.people.split(",")):
        for i, seed in enumerate(int(v) for v in args.seeds.split(",")):
            scene = make_scene(frames=args.frames, height=128, width=256, motion=MOTIONS[i % len(MOTIONS)], seed=seed,
                               people=n)  # fmt: skip
            g = torch.Generator().manual_seed(seed)
            dets, who, kps = detections_of(scene, jitter, miss, g, args.min_visible)
            seen = visible_keypoints(scene)
            kps = [k * ~pose_missed([int(seen[p, t]) for p in who[t]], pose_miss, g)[:, None, None]
                   for t, k in enumerate(kps)]  # fmt: skip
            options = {"smoothing": args.smoothing, "keypoint_weight": args.keypoint_weight, "beam": args.beam}
            looks = detection_looks(scene.frames, dets, kps) if args.looks and args.keypoints else None
            tracks = track_people(dets, keypoints=kps if args.keypoints else None, stitch=not args.no_stitch,
                                  looks=looks, **{k: v for k, v in options.items() if v is not None})  # fmt: skip
            visible = torch.stack([p.person_boxes[:, 4] > 0 for p in scene.people()])
            rows = score(tracks, dets, who, visible)
            total += sum(r["switches"] for r in rows)
            out.append({"people": n, "seed": seed, "tracks": int(tracks.shape[0]), "rows": rows})
    return total, out


def grid(args: argparse.Namespace) -> str:
    if args.seen_poses:
        cells = [sum(switches(args, j, m, "seen")[0] for j, m in runs) for runs in GRID.values()]
        return f"{cells[0]}, {cells[1]}, {cells[2]}; {sum(cells)}"
    cells = {(pm, name): sum(switches(args, j, m, pm)[0] for j, m in runs)
             for pm in (0.0, 0.3, 0.6) for name, runs in GRID.items()}  # fmt: skip
    per_miss = [sum(cells[(pm, name)] for name in GRID) for pm in (0.0, 0.3, 0.6)]
    return (f"{cells[(0.0, 'noisy')]}, {cells[(0.0, 'exact')]}, {cells[(0.0, 'harder')]}; "
            f"{per_miss[0]} / {per_miss[1]} / {per_miss[2]}, {sum(per_miss)}")  # fmt: skip


def scene_parser(description: str) -> argparse.ArgumentParser:
    """A parser with the scenes' own options: --people, --seeds, --frames."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--people", default="2,3", help="people per scene, comma-separated")
    parser.add_argument("--seeds", default="30,31,32,33", help="the motion follows a seed's place here")
    parser.add_argument("--frames", type=int, default=16)
    return parser


def main() -> None:
    parser = scene_parser(__doc__.splitlines()[0])
    parser.add_argument("--jitter", type=float, default=0.05)
    parser.add_argument("--miss", type=float, default=0.1)
    parser.add_argument("--smoothing", type=float, default=None, help="track_people's smoothing (default: its own)")
    parser.add_argument("--keypoints", action="store_true", help="give the tracker each detection's keypoints")
    parser.add_argument("--pose-miss", default="0",
                        help="with --keypoints: the share of detections whose pose is not found (confidence 0), "
                        "or 'seen': by how much of the person is seen, as the product's estimator")
    parser.add_argument("--keypoint-weight", type=float, default=None, help="track_people's keypoint_weight")
    parser.add_argument("--no-stitch", action="store_true", help="track_people(stitch=False)")
    parser.add_argument("--beam", type=int, default=None, help="track_people's beam (1: frame by frame)")
    parser.add_argument("--looks", action="store_true",
                        help="with --keypoints: give the tracker each detection's look (the colours near its joints "
                        "in the rendered frame), as the product's estimator does")
    parser.add_argument("--min-visible", type=int, default=1,
                        help="detect a person only where this many of its keypoints are seen (1: any)")
    parser.add_argument("--json", default=None)
    parser.add_argument("--grid", action="store_true", help="the switches over the grid of conditions, one line")
    parser.add_argument("--seen-poses", action="store_true", help="with --grid: the poses missed as --pose-miss seen")
    args = parser.parse_args()
    if args.grid:
        print(grid(args))
        return
    print("| scene | person: visible frames, covered, identity switches | tracks |")
    print("| --- | --- | --- |")
    _, out = switches(args, args.jitter, args.miss, args.pose_miss)
    for scene in out:
        cells = "; ".join(f"{r['person']}: {r['visible']}, {r['covered']:.0%}, {r['switches']}" for r in scene["rows"])
        print(f"| {scene['people']} people, s{scene['seed']} | {cells} | {scene['tracks']} |", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps({"settings": vars(args), "scenes": out}, indent=1))


if __name__ == "__main__":
    main()
