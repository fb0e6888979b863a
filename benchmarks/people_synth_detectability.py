"""How often YOLOX-Nano finds a partly hidden person on synthetic scenes, by how many of the person's
keypoints are seen: the rate that `people_synth_tracking.py --min-visible K` stands in for (its
simulated detector fires on any person with K keypoints seen, and on nobody with fewer).

Each true person in each frame of make_scene(people=N, ...) (as benchmarks/people_synth_e2e.py:
--height x --width, 16 frames, motion by the seed's place in --seeds) counts as found where one of
the detector's boxes is matched to it (an optimal assignment of the frame's boxes to the true
people's visible boxes, the extent of their seen pixels, IoU >= --min-iou); its keypoints seen are
`people_synth_tracking.visible_keypoints` (inside the frame, its own pixels within 1 px).

Usage: OMP_NUM_THREADS=1 python benchmarks/people_synth_detectability.py [--people 2,3] [--seeds 30,31,32,33]
           [--height 256] [--width 512] [--min-iou 0.3] [--detector ../shared/checkpoints/yolox_nano.onnx]

Prints one row per count of keypoints seen (0..17): person-frames, found, rate.
"""

from __future__ import annotations

import torch
from scipy.optimize import linear_sum_assignment

from lit_boot.estimate import PersonDetector
from lit_boot.estimate.track_cost import iou_matrix
from lit_boot.synth import make_scene
from people_synth_e2e import visible_boxes
from people_synth_tracking import MOTIONS, scene_parser, visible_keypoints
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
    args = parser.parse_args()
    detector = PersonDetector(args.detector)
    total, hits = torch.zeros(18, dtype=torch.long), torch.zeros(18, dtype=torch.long)
    for n in (int(v) for v in args.people.split(",")):
        for i, seed in enumerate(int(v) for v in args.seeds.split(",")):
            scene = make_scene(frames=args.frames, height=args.height, width=args.width, seed=seed, people=n,
                               motion=MOTIONS[i % len(MOTIONS)])  # fmt: skip
            truth, seen = visible_boxes(scene, 1), visible_keypoints(scene)
            for t, detections in enumerate(detector.detect_frames(scene.frames)):
                found = found_people(detections, truth[:, t], args.min_iou)
                for p in range(n):
                    total[seen[p, t]] += 1
                    hits[seen[p, t]] += p in found
    print("| keypoints seen | person-frames | found by the detector | rate |")
    print("| --- | --- | --- | --- |")
    for k in range(18):
        if total[k]:
            print(f"| {k} | {int(total[k])} | {int(hits[k])} | {float(hits[k]) / float(total[k]):.0%} |")


if __name__ == "__main__":
    main()
