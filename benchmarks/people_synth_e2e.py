"""The product's own people, end to end, on synthetic scenes with several people: identity
switches and coverage against the true identities (issue 25's "zero identity switches" bar, with
a real detector and pose estimator instead of simulated ones).

Each scene's rendered frames go through ``estimate_poses(frames, people="all", detector=YOLOX-Nano)``
(the top-down estimator a user runs: YOLOX boxes, MediaPipe on each box's crop, the tracker on the
boxes and poses); every person it returns (a track with a pose) is matched in each frame to the
true people by the IoU of its box with each one's visible box (the extent of the pixels where that
person is seen, ``GroundTruth.truths``), an optimal assignment, pairs with IoU >= --min-iou. Per
true person: the frames it is visible in (at least --min-pixels pixels seen), the share of them
a returned person covers, and its identity switches (the covering person changes between two
covered frames, the MOT definition), also counted over its clear frames only (where the box
that covers it overlaps no other true person by --min-iou: the detector's one box around two
overlapping people is neither's); and the returned people that cover nobody (false tracks).
Also by the poses, what the method paints: per true person the frames where a returned person's
pose lies on it (median joint distance below --max-pose-dist of its size) and the switches of the
returned person whose pose that is.
Scenes: make_scene(people=N, frames=--frames, --height x --width, seed, motion by the seed's place
in --seeds, as benchmarks/people_synth_tracking.py).

Usage: OMP_NUM_THREADS=1 python benchmarks/people_synth_e2e.py [--people 2,3] [--seeds 30,31,32,33]
           [--frames 16] [--height 256] [--width 512] [--min-iou 0.3] [--min-pixels 50]
           [--detector ../shared/checkpoints/yolox_nano.onnx] [--det-score 0.25] [--det-iou 0.45]
           [--on-jump keep] [--max-jump 0.5] [--why] [--true-boxes] [--true-poses] [--pose-model M.onnx]
           [--json out.json]

With ``--true-boxes`` the detector is replaced by the true people's visible boxes (each person's
seen pixels' extent wherever at least --min-pixels are seen, score 1: a detector that never
merges two people nor misses one), so that what is left is the pose estimator's and the
tracker's; everything else as above. With ``--true-poses`` MediaPipe is replaced by a perfect
top-down pose estimator (:mod:`true_crop_poses`: each crop gives the true pose of the person most
seen in its box; --on-jump and --max-jump do not apply), so that what is left is the detector's and
the tracker's (with ``--true-boxes`` too, the tracker's alone). With ``--pose-model`` a top-down
SimCC model exported to ONNX (e.g. RTMPose's; ``estimate_poses(pose_model=...)``) takes MediaPipe's
place, to measure one's own model against these figures.

The first line names the installed versions of the packages the counts move with (another install
gave other counts for the same code: BENCHMARKS.md, "A borrowed pose"). The last line sums the
scenes: identity switches (over clear frames), the true people's mean covered share, the
returned people that cover nobody, and the frames with a pose on a true person and those poses' switches,
by kind (:func:`switch_kinds`; ``--why`` prints each one) and how many of them have a pose before or after
that fits two true people (:func:`on_two`: within --max-pose-dist of both), how many lie in the frames
the product marks to check (:func:`checked`), which are so many of the returned people's frames with a pose;
and the switches seen from the returned people's side (:func:`track_changes`).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import torch
from scipy.optimize import linear_sum_assignment

from lit_boot.estimate import PersonBoxDetector, PersonDetector, estimate_people, estimate_poses, frames_to_check
from lit_boot.estimate.track_cost import iou_matrix
from lit_boot.synth import make_scene
from people_synth_tracking import MOTIONS, scene_parser, true_people
from real_data import SHARED
from true_crop_poses import TrueCropPoses


def returned_people(scene, detector: PersonBoxDetector, true_poses: bool = False, **options) -> list:
    """The people ``estimate_poses(scene.frames, people="all", detector=detector, **options)``
    returns with a pose in some frame (Person, each with its boxes), as a user's run gives them;
    with ``true_poses``, ``estimate_people`` with :class:`true_crop_poses.TrueCropPoses` instead."""
    if true_poses:
        every = estimate_people(TrueCropPoses(scene), scene.frames, detector, "all")
    else:
        every = estimate_poses(scene.frames, people="all", detector=detector, **options)
    return [p for p in every.people() if p.person_boxes is not None and p.keypoints_conf.amax() > 0]


class TrueBoxes:
    """A detector that returns one scene's true visible boxes (:func:`visible_boxes`), for
    ``--true-boxes`` (a :class:`lit_boot.estimate.PersonBoxDetector`): ``detect_frames`` gives per
    frame the boxes (N_t, 5) of the people seen, in ``scene.people()`` order."""

    def __init__(self, boxes: torch.Tensor):  # boxes (P, T, 5); no model to load
        self.boxes, self.path = boxes, Path("true-boxes")

    def detect_frames(self, frames: torch.Tensor) -> list[torch.Tensor]:
        return [self.boxes[:, t][self.boxes[:, t, 4] > 0] for t in range(self.boxes.shape[1])]


def visible_boxes(scene, min_pixels: int) -> torch.Tensor:
    """(P, T, 5) each true person's visible box (x0, y0, x1, y1 px: the edges of its seen pixels, pixel
    centres at integer coordinates, as the detector's boxes) and 1 where at least
    ``min_pixels`` of it are seen, in ``scene.people()`` order."""
    truths = true_people(scene)
    out = torch.zeros(len(truths), scene.num_frames, 5)
    for p, truth in enumerate(truths):
        for t, mask in enumerate(truth.person_mask):
            if int(mask.sum()) < min_pixels:
                continue
            ys, xs = torch.nonzero(mask, as_tuple=True)
            edges = torch.tensor([xs.min() - 0.5, ys.min() - 0.5, xs.max() + 0.5, ys.max() + 0.5])
            out[p, t] = torch.cat([edges, torch.ones(1)])
    return out


def score(found: torch.Tensor, truth: torch.Tensor, min_iou: float) -> tuple[list[dict], int]:
    """Per true person (truth (P, T, 5)): visible frames, covered share, identity switches, and the
    switches counted over its clear frames only (where the box covering it overlaps no other true
    person by ``min_iou``: one box around two people is neither's); and how many of the returned
    people (found (Q, T, 5)) cover nobody in any frame."""
    P, T = truth.shape[:2]
    covering = [[None] * T for _ in range(P)]
    clear = [[False] * T for _ in range(P)]
    used = set()
    for t in range(T):
        here_q = [q for q in range(found.shape[0]) if found[q, t, 4] > 0]
        here_p = [p for p in range(P) if truth[p, t, 4] > 0]
        if not here_q or not here_p:
            continue
        overlap = iou_matrix(found[here_q, t, :4], truth[here_p, t, :4])
        rows, cols = linear_sum_assignment(-overlap.numpy())
        for r, c in zip(rows, cols):
            if overlap[r, c] >= min_iou:
                covering[here_p[c]][t] = here_q[r]
                clear[here_p[c]][t] = int((overlap[r] >= min_iou).sum()) == 1
                used.add(here_q[r])
    rows = []
    for p in range(P):
        seen = [q for q in covering[p] if q is not None]
        seen_clear = [q for q, c in zip(covering[p], clear[p]) if q is not None and c]
        visible = int((truth[p, :, 4] > 0).sum())
        rows.append({"person": p, "visible": visible, "covered": round(len(seen) / max(visible, 1), 3),
                     "switches": sum(a != b for a, b in zip(seen, seen[1:])),
                     "clear_switches": sum(a != b for a, b in zip(seen_clear, seen_clear[1:]))})  # fmt: skip
    return rows, found.shape[0] - len(used)


def pose_distances(est, truths: list, t: int) -> torch.Tensor:
    """(len(truths),) the median distance of ``est``'s confident joints (> 0.3) in frame t from each
    true person's (``truths``: keypoints2d (T, 17, 2)), in that person's size (its keypoints' larger
    extent); inf everywhere with fewer than 4 confident joints."""
    confident = est.keypoints_conf[t] > 0.3
    out = torch.full((len(truths),), float("inf"))
    if int(confident.sum()) < 4:
        return out
    for j, truth in enumerate(truths):
        true = truth.keypoints2d[t]
        size = float((true.amax(0) - true.amin(0)).max().clamp_min(1.0))
        out[j] = (est.keypoints2d[t, confident] - true[confident]).norm(dim=-1).median() / size
    return out


def pose_owners(people: list, truths: list, visible: torch.Tensor, max_dist: float) -> list[list[int | None]]:
    """Per true person and frame, the returned person whose pose lies on it (None: nobody). A pose
    (``people``: PoseEstimates, coco17) lies on a true person (``truths``: each one's keypoints2d
    (T, 17, 2)) where the median distance of its confident joints (> 0.3, at least
    4) from the true ones is below ``max_dist`` x the true keypoints' larger extent (an optimal
    assignment per frame, among the people visible (P, T))."""
    P, T = visible.shape
    covering = [[None] * T for _ in range(P)]
    for t in range(T):
        here_p = [p for p in range(P) if visible[p, t]]
        cost = torch.full((len(people), len(here_p)), float("inf"))
        for q, est in enumerate(people):
            cost[q] = pose_distances(est, [truths[p] for p in here_p], t)
        if not len(here_p) or not len(people):
            continue
        rows, cols = linear_sum_assignment(torch.nan_to_num(cost, posinf=1e6).numpy())
        for r, c in zip(rows, cols):
            if cost[r, c] < max_dist:
                covering[here_p[c]][t] = r
    return covering


def pose_switches(covering: list[list[int | None]]) -> list[dict]:
    """Per true person (``covering``: :func:`pose_owners`), the frames a returned person's pose lies
    on it and that pose's identity switches."""
    out = []
    for owners in covering:
        seen = [q for q in owners if q is not None]
        out.append({"pose_frames": len(seen), "pose_switches": sum(a != b for a, b in zip(seen, seen[1:]))})
    return out


def track_changes(covering: list[list[int | None]], returned: int) -> int:
    """The switches seen from the returned people's side (``covering``: :func:`pose_owners`; ``returned``
    people): how often a returned person's poses go from one true person to another (a track that
    carries two people's poses in turn; MOT's per-true-person count misses it where the other has
    no track of its own)."""
    changes = 0
    for q in range(returned):
        seq = [p for t in range(len(covering[0]) if covering else 0) for p, owners in enumerate(covering)
               if owners[t] == q]  # fmt: skip
        changes += sum(a != b for a, b in zip(seq, seq[1:]))
    return changes


def switch_kinds(covering: list[list[int | None]]) -> list[tuple[int, int, int, str]]:
    """Each switch of the poses (``covering``: :func:`pose_owners`) as (true person, frame before,
    frame after, kind): "new after a gap" / "new, next frame" (the old track has no pose on anyone
    after, the new one none before: the person found again as a new track, after frames without
    a pose or in the very next one), "new takes over" (a new track, the old one goes on with someone
    else), "between tracks" (the new track had a pose on someone before)."""
    out = []
    for p, owners in enumerate(covering):
        seen = [(t, q) for t, q in enumerate(owners) if q is not None]
        for (t0, a), (t1, b) in zip(seen, seen[1:]):
            if a == b:
                continue
            b_before = any(owners_[t] == b for owners_ in covering for t in range(t1))
            a_after = any(owners_[t] == a for owners_ in covering for t in range(t0 + 1, len(owners)))
            if b_before:
                kind = "between tracks"
            elif a_after:
                kind = "new takes over"
            else:
                kind = "new, next frame" if t1 == t0 + 1 else "new after a gap"
            out.append((p, t0, t1, kind))
    return out


def on_two(posed: list, truths: list, covering: list[list[int | None]], switches: list, max_dist: float) -> list[bool]:
    """Per switch of the poses (``switches``: :func:`switch_kinds` of ``covering``): whether the pose
    before or after it lies within ``max_dist`` of another true person (seen or hidden in that frame)
    as well as of its own (:func:`pose_distances`): the two stand where their joints nearly coincide,
    and the pose fits both. ``posed``: the returned people; ``truths``: every true person's PersonTruth."""
    out = []
    for p, t0, t1, _ in switches:
        near = [pose_distances(posed[covering[p][t]], truths, t) < max_dist for t in (t0, t1)]
        out.append(any(int(n.sum()) - int(n[p]) > 0 for n in near))
    return out


def checked(posed: list, owners: list[list[int | None]]) -> tuple[int, int, int]:
    """The switches of the poses (:func:`switch_kinds`) inside the frames the product marks to check
    (:func:`lit_boot.estimate.frames_to_check`: a frame from the last pose before the switch to the
    first after it, of either track), and the frames with a pose marked, of those with a pose:
    (switches caught, frames marked, frames with a pose)."""
    marks = frames_to_check(posed)
    caught = sum(bool(marks[owners[p][t0]][t0 : t1 + 1].any() or marks[owners[p][t1]][t0 : t1 + 1].any())
                 for p, t0, t1, _ in switch_kinds(owners))  # fmt: skip
    found = [(person.keypoints_conf > 0).any(-1) for person in posed]
    return caught, sum(int((m & f).sum()) for m, f in zip(marks, found)), sum(int(f.sum()) for f in found)


def package_versions() -> str:
    """The versions these counts move with (BENCHMARKS.md, "A borrowed pose": the crops are resized by
    OpenCV, and another install gave other counts for the same code)."""
    from importlib.metadata import PackageNotFoundError, version

    names = ("torch", "mediapipe", "onnxruntime", "opencv-python-headless", "opencv-contrib-python", "numpy")
    found = []
    for name in names:
        try:
            found.append(f"{name} {version(name)}")
        except PackageNotFoundError:
            found.append(f"{name} absent")
    return ", ".join(found) + f"; cpu: {cpu_name()}"


def cpu_name() -> str:
    """The CPU's model name and the vector extensions TFLite's and onnxruntime's kernels choose by
    (another machine gave other counts with the same versions: BENCHMARKS.md, "Ids fixed by hand")."""
    import platform

    try:
        info = open("/proc/cpuinfo").read()
    except OSError:
        return platform.processor() or "unknown"
    model = next((line.split(":", 1)[1].strip() for line in info.splitlines() if line.startswith("model name")), "?")
    flags = set(next((line.split(":", 1)[1].split() for line in info.splitlines() if line.startswith("flags")), []))
    return f"{model} ({', '.join(f for f in ('avx2', 'avx512f', 'amx_tile') if f in flags) or 'no avx2'})"


def main() -> None:
    parser = scene_parser(__doc__.splitlines()[0])
    parser.add_argument("--height", type=int, default=256)
    parser.add_argument("--width", type=int, default=512)
    parser.add_argument("--min-iou", type=float, default=0.3)
    parser.add_argument("--min-pixels", type=int, default=50)
    parser.add_argument("--detector", default=str(SHARED / "checkpoints" / "yolox_nano.onnx"))
    parser.add_argument("--max-pose-dist", type=float, default=0.15,
                        help="a pose lies on a true person within this share of its size (median joint)")
    parser.add_argument("--on-jump", default="keep", help="estimate_poses' on_jump (keep, drop)")
    parser.add_argument("--max-jump", type=float, default=0.5, help="estimate_poses' max_jump")
    parser.add_argument("--det-score", type=float, default=0.25, help="PersonDetector's score threshold")
    parser.add_argument("--det-iou", type=float, default=0.45, help="PersonDetector's NMS IoU threshold")
    parser.add_argument("--why", action="store_true", help="print each switch of the poses and its kind")
    parser.add_argument("--true-boxes", action="store_true",
                        help="the true people's visible boxes in place of the detector (module docstring)")
    parser.add_argument("--pose-model", default=None,
                        help="a top-down SimCC pose model exported to ONNX (RTMPose's) in MediaPipe's place")
    parser.add_argument("--true-poses", action="store_true",
                        help="a perfect top-down pose estimator in place of MediaPipe (module docstring)")
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    detector = PersonDetector(args.detector, score=args.det_score, iou=args.det_iou)
    print(f"packages: {package_versions()}")
    print("| scene | true person: visible frames, covered, identity switches (pose: frames, switches) "
          "| people returned (false) | s |")  # fmt: skip
    print("| --- | --- | --- | --- |")
    out, total, clear, covered, false_total, poses, pose_frames, kinds, carried = [], 0, 0, [], 0, 0, 0, {}, 0
    fitting_two = 0  # switches whose pose fits two true people (:func:`on_two`)
    marked = [0, 0, 0]  # switches caught, frames marked, frames with a pose (:func:`checked`)
    for n in (int(v) for v in args.people.split(",")):
        for i, seed in enumerate(int(v) for v in args.seeds.split(",")):
            scene = make_scene(frames=args.frames, height=args.height, width=args.width, seed=seed, people=n,
                               motion=MOTIONS[i % len(MOTIONS)])  # fmt: skip
            truth = visible_boxes(scene, args.min_pixels)
            start = time.perf_counter()
            posed = returned_people(scene, TrueBoxes(truth) if args.true_boxes else detector, args.true_poses,
                                    on_jump=args.on_jump, max_jump=args.max_jump,
                                    pose_model=args.pose_model)  # fmt: skip
            seconds = time.perf_counter() - start
            found = torch.stack([p.person_boxes for p in posed]) if posed else torch.zeros(0, args.frames, 5)
            rows, false = score(found, truth, args.min_iou)
            truths = true_people(scene)
            owners = pose_owners(posed, truths, truth[..., 4] > 0, args.max_pose_dist)
            for row, on_pose in zip(rows, pose_switches(owners)):
                row.update(on_pose)
            marked = [a + b for a, b in zip(marked, checked(posed, owners))]
            switches = switch_kinds(owners)
            for (p, t0, t1, kind), both in zip(switches, on_two(posed, truths, owners, switches, args.max_pose_dist)):
                kinds[kind] = kinds.get(kind, 0) + 1
                fitting_two += both
                if args.why:
                    print(f"  {n} people, s{seed}, true person {p}: frames {t0} -> {t1}, {kind}"
                          f"{', the pose fits two people' if both else ''}")
            poses += sum(r["pose_switches"] for r in rows)
            carried += track_changes(owners, len(posed))
            pose_frames += sum(r["pose_frames"] for r in rows)
            total += sum(r["switches"] for r in rows)
            clear += sum(r["clear_switches"] for r in rows)
            covered += [r["covered"] for r in rows]
            false_total += false
            cells = "; ".join(f"{r['person']}: {r['visible']}, {r['covered']:.0%}, {r['switches']} "
                              f"(pose {r['pose_frames']}, {r['pose_switches']})" for r in rows)  # fmt: skip
            print(f"| {n} people, s{seed} | {cells} | {found.shape[0]} ({false}) | {seconds:.1f} |", flush=True)
            out.append({"people": n, "seed": seed, "returned": int(found.shape[0]), "false": false, "rows": rows,
                        "seconds": seconds})  # fmt: skip
    print(f"identity switches {total} ({clear} over clear frames), covered {sum(covered) / max(len(covered), 1):.0%}, "
          f"false people {false_total}; poses on a true person {pose_frames} frames, their switches {poses} "
          f"({', '.join([f'{k} {v}' for k, v in sorted(kinds.items())] + [f'fitting two people {fitting_two}'])}); "
          f"in the frames marked to check "
          f"{marked[0]}, marked {marked[1]} of {marked[2]} frames with a pose; a returned person's poses going "
          f"from one true person to another {carried}")
    if args.json:
        Path(args.json).write_text(json.dumps({"settings": vars(args), "packages": package_versions(), "scenes": out},
                                              indent=1))


if __name__ == "__main__":
    main()
