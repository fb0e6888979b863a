"""How often YOLOX-Nano finds a partly hidden person on synthetic scenes, by how many of the person's
keypoints are seen: the rate that `people_synth_tracking.py --min-visible K` stands in for (its
simulated detector fires on any person with K keypoints seen, and on nobody with fewer).

Each true person in each frame of make_scene(people=N, ...) (as benchmarks/people_synth_e2e.py:
--height x --width, 16 frames, motion by the seed's place in --seeds) counts as found where one of
the detector's boxes is matched to it (an optimal assignment of the frame's boxes to the true
people's visible boxes, the extent of their seen pixels, IoU >= --min-iou); its keypoints seen are
`people_synth_tracking.visible_keypoints` (inside the frame, its own pixels within 1 px).

With ``--poses`` also the product's poses (``estimate_poses(frames, people="all", detector=...)``,
YOLOX boxes, MediaPipe on each box's crop, tracked): of the person-frames the detector found, those
where a returned pose lies on the person (`people_synth_e2e.pose_owners`, its median joint within
15% of the person's size): how often the pose estimator misses a person it was given, by occlusion
(the rate that `people_synth_tracking.py --pose-miss` draws at random).

Usage: OMP_NUM_THREADS=1 python benchmarks/people_synth_detectability.py [--people 2,3] [--seeds 30,31,32,33]
           [--height 256] [--width 512] [--min-iou 0.3] [--detector ../shared/checkpoints/yolox_nano.onnx]
           [--poses]

Prints one row per count of keypoints seen (0..17): person-frames, found, rate (and with --poses,
the found ones with a pose on them, and their share).
"""

from __future__ import annotations

import torch
from scipy.optimize import linear_sum_assignment

from lit_boot.estimate import PersonDetector
from lit_boot.estimate.track_cost import iou_matrix
from lit_boot.synth import make_scene
from people_synth_e2e import pose_owners, returned_people, visible_boxes
from people_synth_tracking import MOTIONS, scene_parser, true_people, visible_keypoints
from real_data import SHARED


def found_people(detections: torch.Tensor, truth: torch.Tensor, min_iou: float) -> set[int]:
    """The true people (truth (P, 5) boxes, score 0: not seen) matched by one of ``detections``
    (N, 5): an optimal assignment by IoU, pairs with IoU >= ``min_iou``."""
    here = [p for p in range(truth.shape[0]) if truth[p, 4] > 0]
    if not here or not detections.shape[0]:
        return set()
    overlap = iou_matrix(detections[:, :4], truth[here, :4])
    rows, cols = linear_sum_assignment(-overlap.numpy())
    return {here[c] for r, c in zip(rows, cols) if overlap[r, c] >= min_iou}


def main() -> None:
    parser = scene_parser(__doc__.splitlines()[0])
    parser.add_argument("--height", type=int, default=256)
    parser.add_argument("--width", type=int, default=512)
    parser.add_argument("--min-iou", type=float, default=0.3)
    parser.add_argument("--detector", default=str(SHARED / "checkpoints" / "yolox_nano.onnx"))
    parser.add_argument("--poses", action="store_true", help="also the found people with a pose on them")
    args = parser.parse_args()
    detector = PersonDetector(args.detector)
    total, hits, posed = (torch.zeros(18, dtype=torch.long) for _ in range(3))
    for n in (int(v) for v in args.people.split(",")):
        for i, seed in enumerate(int(v) for v in args.seeds.split(",")):
            scene = make_scene(frames=args.frames, height=args.height, width=args.width, seed=seed, people=n,
                               motion=MOTIONS[i % len(MOTIONS)])  # fmt: skip
            truth, seen = visible_boxes(scene, 1), visible_keypoints(scene)
            owners = _pose_owners(scene, detector, truth) if args.poses else None
            for t, detections in enumerate(detector.detect_frames(scene.frames)):
                found = found_people(detections, truth[:, t], args.min_iou)
                for p in range(n):
                    total[seen[p, t]] += 1
                    hits[seen[p, t]] += p in found
                    posed[seen[p, t]] += p in found and owners is not None and owners[p][t] is not None
    extra = " found with a pose on them | share |" if args.poses else ""
    print(f"| keypoints seen | person-frames | found by the detector | rate |{extra}")
    print("| --- | --- | --- | --- |" + (" --- | --- |" if args.poses else ""))
    for k in range(18):
        if total[k]:
            row = f"| {k} | {int(total[k])} | {int(hits[k])} | {float(hits[k]) / float(total[k]):.0%} |"
            if args.poses:
                row += f" {int(posed[k])} | {float(posed[k]) / max(float(hits[k]), 1.0):.0%} |"
            print(row)


def _pose_owners(scene, detector: PersonDetector, truth: torch.Tensor) -> list[list[int | None]]:
    """Per true person and frame, the returned person whose pose lies on it (None: nobody), from
    ``estimate_poses(people="all")`` on the scene's frames."""
    return pose_owners(returned_people(scene, detector), true_people(scene), truth[..., 4] > 0, 0.15)


if __name__ == "__main__":
    main()
