"""A box without a pose beside a box with one is not tracked.

Where a detection's crop gives no pose (fewer than :data:`.track_cost.KEYPOINT_MIN_JOINTS` joints
confident above :data:`.track_cost.KEYPOINT_CONF`; a neighbour's pose already counts for none) and its
box overlaps a detection with a pose in the same frame by IoU :data:`OVERLAP` or more, the box is
mostly that of a person half hidden behind the posed one, or a second, looser box on the posed
person: its crop shows the person in front, so only the box could link it to a track, and that is
where the tracker's switches came from (synthetic scenes with people crossing: the poses' identity
switches 20 -> 17 and 18 -> 12 over 120 people; BENCHMARKS.md, "A box without a pose beside one with
a pose, held out of tracking"). :func:`poseless_beside_posed` finds such boxes so that they are
dropped before tracking; a hidden person's track is bridged across the frames it loses, as any gap.
A box that holds the posed box (at least :data:`HOLDS` of the posed box's area inside it) is kept:
it may be a person's own box with a smaller posed box inside it (the man walking beside the main
woman on the shared street clip). Boxes are x0, y0, x1, y1 px (:mod:`.detector`).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from .track_cost import KEYPOINT_CONF, KEYPOINT_MIN_JOINTS, box_areas, box_intersections, iou_matrix

__all__ = ["poseless_beside_posed", "inside_share", "OVERLAP", "HOLDS"]

#: A pose-less box overlapping a posed box by this IoU or more is dropped (the overlap at which
#: ``lit-boot ids`` lists a frame to check).
OVERLAP = 0.3
#: ... unless at least this share of the posed box's area lies inside it.
HOLDS = 0.9


def inside_share(outer: torch.Tensor, inner: torch.Tensor) -> torch.Tensor:
    """(N, M): the share of each ``inner`` box's area (M, 4) that lies inside each ``outer`` box (N, 4)."""
    return box_intersections(outer, inner) / box_areas(inner).clamp_min(1e-6)[None]


def poseless_beside_posed(detections: Sequence[torch.Tensor], keypoints: Sequence[torch.Tensor]) -> list[torch.Tensor]:
    """Per frame, the detections (N_t, 5) without a pose (their keypoints (N_t, K, 3): x, y px,
    confidence) whose box overlaps a detection with a pose by IoU >= OVERLAP and holds less than HOLDS
    of that box (module docstring). Returns per frame a (N_t,) bool."""
    out = []
    for dets, kps in zip(detections, keypoints):
        posed = (kps[..., 2] > KEYPOINT_CONF).sum(-1) >= KEYPOINT_MIN_JOINTS
        drop = torch.zeros(dets.shape[0], dtype=torch.bool)
        if bool(posed.any()) and not bool(posed.all()):
            boxes, with_pose = dets[:, :4], dets[posed, :4]
            beside = (iou_matrix(with_pose, boxes) >= OVERLAP) & (inside_share(boxes, with_pose).T < HOLDS)
            drop = beside.any(0) & ~posed
        out.append(drop)
    return out
