"""A perfect top-down pose estimator for synthetic scenes: each crop gives the true pose of the person
most seen in its box. For ``people_synth_e2e.py --true-poses``: what the tracker and the detector
leave of the identity switches when the pose estimator makes no mistake of its own.

:class:`TrueCropPoses` is a :class:`lit_boot.estimate.MediaPipeCrops` whose crops are read from the
scene's ground truth instead of MediaPipe: in each frame with a box, the true person with the most
seen pixels (``PersonTruth.person_mask``) inside the box (x0, y0, x1, y1 px, pixel centres at integer
coordinates) gives its true COCO-17 keypoints, confident (1) where seen (inside the frame, a pixel
of that person's own mask within 1 px: ``people_synth_tracking.seen_keypoints``) and 0
elsewhere; nobody where that person has fewer than ``min_pixels`` seen pixels in the box or fewer
than 4 joints seen. As a top-down estimator on a box around two people, it gives the one more seen
(mostly the one in front). A track's poses are its boxes' (no video mode). The 3D (MediaPipe's
world landmarks) is a flat stand-in from the 2D keypoints: it is not scored.
"""

from __future__ import annotations

import torch

from lit_boot.core.joints import COCO17, MEDIAPIPE33
from lit_boot.estimate import MediaPipeCrops
from lit_boot.estimate.mediapipe_pose import poses_from_landmarks
from people_synth_tracking import seen_keypoints, true_people

#: Each COCO-17 joint's MediaPipe-33 landmark (the same names).
COCO_IN_MEDIAPIPE = [MEDIAPIPE33.names.index(name) for name in COCO17.names]


class TrueCropPoses(MediaPipeCrops):
    """The true pose of the person most seen in each box (module docstring), for one ``scene``."""

    def __init__(self, scene, min_pixels: int = 50):
        truths = true_people(scene)
        self.masks = torch.stack([t.person_mask for t in truths])  # (P, T, H, W)
        self.keypoints = torch.stack([t.keypoints2d for t in truths])  # (P, T, 17, 2)
        self.seen = seen_keypoints(scene)  # (P, T, 17)
        self.min_pixels = min_pixels
        size = tuple(scene.frames.shape[2:])
        super().__init__(None, lambda *raw: poses_from_landmarks(*raw, size, source="true-crop-poses"))

    def _crops(self, frames: torch.Tensor, boxes: torch.Tensor) -> dict[str, torch.Tensor]:
        """The arrays of :func:`lit_boot.estimate.crop_pose.crop_landmarks` for boxes (T, 5), from the truth."""
        T = boxes.shape[0]
        out = {"landmarks": torch.zeros(T, 33, 2), "visibility": torch.zeros(T, 33), "presence": torch.ones(T, 33),
               "world": torch.zeros(T, 33, 3), "found": torch.zeros(T, dtype=torch.bool)}  # fmt: skip
        for t in torch.nonzero(boxes[:, 4] > 0).flatten().tolist():
            x0, y0, x1, y1 = (int(max(float(v) + 0.5, 0)) for v in boxes[t, :4])
            counts = self.masks[:, t, y0:y1, x0:x1].flatten(1).sum(1)
            p = int(counts.argmax())
            if int(counts[p]) < self.min_pixels or int(self.seen[p, t].sum()) < 4:
                continue
            points = self.keypoints[p, t]
            flat = (points - points.mean(0)) / float((points.amax(0) - points.amin(0)).max().clamp_min(1.0)) * 1.7
            out["landmarks"][t, COCO_IN_MEDIAPIPE] = points
            out["visibility"][t, COCO_IN_MEDIAPIPE] = self.seen[p, t].float()
            out["world"][t, COCO_IN_MEDIAPIPE] = torch.cat([flat, torch.linspace(-0.05, 0.05, 17)[:, None]], -1)
            out["found"][t] = True
        return out

    def estimate_track(self, frames: torch.Tensor, boxes: torch.Tensor):
        return self.estimate_person(frames, boxes)
