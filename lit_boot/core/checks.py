"""Field checks shared by the scene model's classes: shapes, dtypes, finiteness, layouts.

Every check raises :class:`SceneValidationError` naming the field (``owner.field``) and what was
expected.
"""

from __future__ import annotations

from typing import Any

import torch

from .cameras import Cameras
from .joints import get_layout

__all__ = ["SceneValidationError", "check_tensor", "check_cameras", "check_estimates"]


class SceneValidationError(ValueError):
    """A scene field has the wrong shape, dtype or values."""


def check_tensor(name: str, value: Any, shape: tuple, kind: str) -> None:
    """Check a tensor's shape (None in ``shape`` = any size), dtype kind and finiteness."""
    if not isinstance(value, torch.Tensor):
        raise SceneValidationError(f"{name}: expected a torch.Tensor, got {type(value).__name__}")
    want = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
    if value.ndim != len(shape) or any(s is not None and s != v for s, v in zip(shape, value.shape)):
        raise SceneValidationError(f"{name}: expected shape {want}, got {tuple(value.shape)}")
    if kind == "uint8" and value.dtype != torch.uint8:
        raise SceneValidationError(f"{name}: expected dtype uint8, got {value.dtype}")
    if kind == "bool" and value.dtype != torch.bool:
        raise SceneValidationError(f"{name}: expected dtype bool, got {value.dtype}")
    if kind == "float":
        if not value.is_floating_point():
            raise SceneValidationError(f"{name}: expected a floating-point dtype, got {value.dtype}")
        if not torch.isfinite(value).all():
            raise SceneValidationError(f"{name}: expected finite values, found NaN or inf")


def check_cameras(name: str, cameras: Any, T: int) -> None:
    if not isinstance(cameras, Cameras):
        raise SceneValidationError(f"{name}: expected a lit_boot Cameras, got {type(cameras).__name__}")
    check_tensor(f"{name}.params", cameras.params, (T, cameras.params.shape[1]), "float")
    if cameras.crops is not None:
        check_tensor(f"{name}.crops", cameras.crops, (T, 3), "float")


def check_estimates(owner: str, est: Any, T: int, layouts: Any = None) -> None:
    """Check the pose-estimate fields of ``est`` (a Scene or alike: joints3d, cameras,
    keypoints2d, keypoints_conf, person_boxes) for T frames, in the joint layouts of ``layouts``
    (an object with joints3d_layout and keypoints_layout; default ``est`` itself); errors name
    ``owner.field``."""
    layouts = est if layouts is None else layouts
    for key in ("joints3d_layout", "keypoints_layout"):
        try:
            get_layout(getattr(layouts, key))
        except ValueError as err:
            raise SceneValidationError(f"{owner}.{key}: {err}") from None
    if est.joints3d is not None:
        J = get_layout(layouts.joints3d_layout).num_joints
        check_tensor(f"{owner}.joints3d", est.joints3d, (T, J, 3), "float")
    if est.cameras is not None:
        check_cameras(f"{owner}.cameras", est.cameras, T)
    if (est.keypoints2d is None) != (est.keypoints_conf is None):
        raise SceneValidationError(f"{owner}.keypoints2d and {owner}.keypoints_conf: give both or neither")
    if est.keypoints2d is not None:
        K = get_layout(layouts.keypoints_layout).num_joints
        check_tensor(f"{owner}.keypoints2d", est.keypoints2d, (T, K, 2), "float")
        check_tensor(f"{owner}.keypoints_conf", est.keypoints_conf, (T, K), "float")
        if (est.keypoints_conf < 0).any() or (est.keypoints_conf > 1).any():
            raise SceneValidationError(f"{owner}.keypoints_conf: expected values in [0, 1]")
    boxes = getattr(est, "person_boxes", None)
    if boxes is not None:
        check_tensor(f"{owner}.person_boxes", boxes, (T, 5), "float")
        if (boxes[:, 4] < 0).any() or (boxes[:, 4] > 1).any():
            raise SceneValidationError(f"{owner}.person_boxes: expected scores (column 4) in [0, 1]")
        found = boxes[:, 4] > 0
        if ((boxes[found, 2:4] < boxes[found, 0:2])).any():
            raise SceneValidationError(f"{owner}.person_boxes: expected x0 <= x1 and y0 <= y1 where a person is found")
