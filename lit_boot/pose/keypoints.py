"""The detector's 2D keypoints as the refiners use them: mapped to the 3D joints' layout,
restricted to chosen joints, with binary or real-valued confidence weights.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from ..core import Scene, get_layout, map_joints

__all__ = ["AUTHORS_KEYPOINT_JOINTS", "CONFIDENCE_MODES", "confidence_weights", "keypoints_for_layout"]

#: The joints the authors' 2D term uses (no face, hips, neck or head).
AUTHORS_KEYPOINT_JOINTS: tuple[str, ...] = (
    "right_shoulder", "left_shoulder", "right_elbow", "left_elbow", "right_wrist", "left_wrist",
    "right_knee", "left_knee", "right_ankle", "left_ankle",
)  # fmt: skip

#: binary: 1 where confidence > threshold (the authors, threshold 0 = detected); real: the
#: confidence itself where > threshold; none: 1 everywhere.
CONFIDENCE_MODES = ("binary", "real", "none")


def confidence_weights(confidence: torch.Tensor, mode: str = "binary", threshold: float = 0.0) -> torch.Tensor:
    """Per-keypoint weights (T, K) from confidences (T, K) in [0, 1] (see CONFIDENCE_MODES)."""
    if mode not in CONFIDENCE_MODES:
        raise ValueError(f"confidence: expected one of {CONFIDENCE_MODES}, got {mode!r}")
    confidence = confidence.float()
    if mode == "none":
        return torch.ones_like(confidence)
    detected = confidence > threshold
    return detected.float() if mode == "binary" else confidence * detected


def keypoints_for_layout(
    scene: Scene,
    layout: str,
    joints: Sequence[str] | None = None,
    mode: str = "binary",
    threshold: float = 0.0,
) -> tuple[torch.Tensor, torch.Tensor]:
    """The scene's keypoints mapped to ``layout``: positions (T, J, 2) px and weights (T, J).

    ``joints`` names the joints that get a weight (default: the authors' 10); every other
    joint weighs 0. A named joint the keypoint layout cannot provide (e.g. LSP's head top from
    COCO-17) raises ValueError.
    """
    if scene.keypoints2d is None:
        raise ValueError(f"scene {scene.name!r} has no 2D keypoints")
    dst = get_layout(layout)
    names = AUTHORS_KEYPOINT_JOINTS if joints is None else tuple(joints)
    weights = confidence_weights(scene.keypoints_conf, mode, threshold)
    points, defined, weights = map_joints(scene.keypoints2d.float(), scene.keypoints_layout, dst, weights)
    selected = torch.zeros(dst.num_joints, dtype=torch.bool)
    for name in names:
        if name not in dst.names:
            raise ValueError(f"keypoint_joints: layout {dst.name!r} has no joint {name!r}; expected names from {dst.names}")
        index = dst.names.index(name)
        if not defined[index]:
            raise ValueError(
                f"keypoint_joints: joint {name!r} cannot be made from {scene.keypoints_layout} keypoints"
            )
        selected[index] = True
    return points, weights * selected.to(weights)
