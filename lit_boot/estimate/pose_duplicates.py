"""One pose, one person: where two tracks' crops give the same pose, it counts for one of them.

Where two people overlap, the detector often gives one box around both beside a box of one of
them, and the pose estimator finds the same person in both crops; painted twice under two track
ids, that person's motion would also be taught as the other's. :func:`duplicate_frames` finds,
in every frame, the pairs of people whose poses coincide (the median distance of the joints
confident in both, at least :data:`MIN_JOINTS`, below :data:`MAX_DISTANCE` x the pose's size)
and gives the pose to the person whose box fits it best (the IoU of the box with the extent of
the pose's confident keypoints), or, where one box is a detection and the other the tracker's
guess across a gap, to the detection's: the other person has no pose in that frame.
:func:`duplicate_detections` does the same among one frame's detections before tracking, so that
a box around two people does not start a second track on the one it shares a pose with. Keypoints are px;
boxes x0, y0, x1, y1 px with pixel centres at integer coordinates (:mod:`.detector`).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from .track_cost import KEYPOINT_CONF, KEYPOINT_MIN_JOINTS, iou_matrix

__all__ = ["duplicate_frames", "duplicate_detections", "keypoint_extent", "pose_apart", "MAX_DISTANCE", "MIN_JOINTS"]

#: Two poses are one where their shared joints' median distance is below this share of the pose's
#: size (the larger side of its confident keypoints' extent).
MAX_DISTANCE = 0.1
#: The joints (confident in both poses) that must be shared to compare two poses, and the
#: confidence above which a joint counts: the tracker's own (:mod:`.track_cost`).
MIN_JOINTS = KEYPOINT_MIN_JOINTS
CONF = KEYPOINT_CONF


def keypoint_extent(keypoints: torch.Tensor, confident: torch.Tensor) -> torch.Tensor:
    """(4,) x0, y0, x1, y1 of the confident keypoints (K, 2)."""
    points = keypoints[confident]
    return torch.cat([points.amin(0), points.amax(0)])


def pose_apart(keypoints_a: torch.Tensor, confident_a: torch.Tensor, keypoints_b: torch.Tensor,
               confident_b: torch.Tensor) -> float | None:  # fmt: skip
    """How far pose B (keypoints (K, 2) px, confident (K,) bool) lies from pose A: the median
    distance of the joints confident in both over A's size (the larger side of its confident
    keypoints' extent); None where they share fewer than MIN_JOINTS."""
    shared = confident_a & confident_b
    if int(shared.sum()) < MIN_JOINTS:
        return None
    extent = keypoint_extent(keypoints_a, confident_a)
    size = float((extent[2:] - extent[:2]).max().clamp_min(1.0))
    return float((keypoints_a[shared] - keypoints_b[shared]).norm(dim=-1).median()) / size


def duplicate_frames(
    keypoints: Sequence[torch.Tensor],
    confidence: Sequence[torch.Tensor],
    boxes: Sequence[torch.Tensor],
    bridged: Sequence[torch.Tensor] | None = None,
) -> list[torch.Tensor]:
    """For P people, each one's keypoints (T, K, 2) px, confidences (T, K) (0: not found) and
    boxes (T, 5): per person a (T,) bool of the frames where its pose is another person's too and
    that person's box fits it better (ties: the earlier person keeps it). With ``bridged`` (per
    person a (T,) bool: frames whose box is the tracker's guess across a gap, not a detection), a
    detection's box is preferred to a bridged one whatever their fit: a crop where nobody was
    detected shows whoever stands there, often the person in front."""
    P = len(keypoints)
    drop = [torch.zeros(c.shape[0], dtype=torch.bool) for c in confidence]
    for t in range(drop[0].shape[0] if P else 0):
        confident = [confidence[p][t] > CONF for p in range(P)]
        for a in range(P):
            for b in range(a + 1, P):
                if drop[a][t] or drop[b][t]:
                    continue
                apart = pose_apart(keypoints[a][t], confident[a], keypoints[b][t], confident[b])
                if apart is None or apart >= MAX_DISTANCE:
                    continue
                pose, other = (keypoint_extent(keypoints[p][t], confident[p]) for p in (a, b))
                fit_a, fit_b = (float(iou_matrix(extent[None], boxes[p][t, None, :4])[0, 0])
                                for p, extent in ((a, pose), (b, other)))  # fmt: skip
                if bridged is not None and bool(bridged[a][t]) != bool(bridged[b][t]):
                    fit_a, fit_b = float(not bridged[a][t]), float(not bridged[b][t])
                drop[b if fit_a >= fit_b else a][t] = True
    return drop


def duplicate_detections(detections: Sequence[torch.Tensor], keypoints: Sequence[torch.Tensor]) -> list[torch.Tensor]:
    """Per frame, the detections (N_t, 5) whose pose (their keypoints (N_t, K, 3): x, y px,
    confidence) is another detection's too and fits that one's box better (:func:`duplicate_frames`
    within the frame): a box around two people beside a box of one of them, which would otherwise
    start a second track on that person. Returns per frame a (N_t,) bool."""
    out = []
    for dets, kps in zip(detections, keypoints):
        one = [kps[i : i + 1] for i in range(dets.shape[0])]
        drop = duplicate_frames([k[..., :2] for k in one], [k[..., 2] for k in one],
                                [dets[i : i + 1] for i in range(dets.shape[0])])  # fmt: skip
        out.append(torch.cat(drop) if drop else torch.zeros(0, dtype=torch.bool))
    return out
