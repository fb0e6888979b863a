"""Camera models: differentiable projection of 3D joints (millimetres) to image pixels.

Pixel convention everywhere in lit-boot: pixel centres at integer coordinates, ``(x, y)`` with
x to the right and y down; flow at pixel (x, y) moves it to (x+u, y+v). Camera frame: x right,
y down, z forward (OpenCV).

Two models, each a functional projection plus a small per-frame container:

- ``"weak_perspective"``: METRO/HMR on a square crop (REFERENCE section 3). Parameters
  (s, tx, ty) per frame act on joints in *metres* (METRO's unit): ``x = s * (X/1000 + t)`` in
  [-1, 1] crop coordinates, then ``u_crop = (x + 1) / 2 * crop_size`` and
  ``u_img = (u_crop + start - crop_size / 2) / scale`` with the crop's (scale, start_x, start_y)
  (HMR's ``proc_param``: the image was resized by ``scale`` and cropped at ``start``).
- ``"pinhole"``: (fx, fy, cx, cy, tx, ty, tz) per frame; ``u = fx (X+tx)/(Z+tz) + cx``.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

__all__ = [
    "CAMERA_MODELS",
    "Cameras",
    "project_weak_perspective",
    "project_pinhole",
    "fit_weak_perspective",
    "inside_image",
]

CAMERA_MODELS = ("weak_perspective", "pinhole")
#: Number of per-frame parameters of each camera model.
CAMERA_NUM_PARAMS = {"weak_perspective": 3, "pinhole": 7}


def inside_image(points: torch.Tensor, height: int, width: int) -> torch.Tensor:
    """(...) bool: True where the point (..., 2) px (x, y; pixel centres at integer coordinates)
    lies within an image of ``height`` x ``width`` (NaN points: False)."""
    upper = points.new_tensor([width - 1, height - 1])
    return ((points >= 0) & (points <= upper)).all(dim=-1)


def project_weak_perspective(
    points: torch.Tensor, params: torch.Tensor, crops: torch.Tensor, crop_size: float = 224.0
) -> torch.Tensor:
    """METRO/HMR weak perspective to image pixels.

    points (..., J, 3) mm; params (..., 3) = (s, tx, ty), tx/ty in metres; crops (..., 3) =
    (scale, start_x, start_y). Returns (..., J, 2) pixels. Depth is ignored.
    """
    s = params[..., None, 0:1]
    t = params[..., None, 1:3]
    x = s * (points[..., :2] / 1000.0 + t)
    u_crop = (x + 1.0) * 0.5 * crop_size
    return (u_crop + crops[..., None, 1:3] - crop_size / 2.0) / crops[..., None, 0:1]


def project_pinhole(points: torch.Tensor, params: torch.Tensor) -> torch.Tensor:
    """Pinhole perspective. points (..., J, 3) mm; params (..., 7) = (fx, fy, cx, cy, tx, ty, tz)
    with the translation in mm. Returns (..., J, 2) pixels. Points must lie in front (z > 0)."""
    p = points + params[..., None, 4:7]
    z = p[..., 2:3].clamp_min(1e-6)
    return p[..., :2] / z * params[..., None, 0:2] + params[..., None, 2:4]


def fit_weak_perspective(
    points: torch.Tensor,
    pixels: torch.Tensor,
    crops: torch.Tensor,
    crop_size: float = 224.0,
    weights: torch.Tensor | None = None,
) -> torch.Tensor:
    """Least-squares (s, tx, ty) per frame so that the weak-perspective projection of
    ``points`` (T, J, 3) mm matches ``pixels`` (T, J, 2). Closed form (linear in s and s*t).
    ``weights`` (T, J) are per-joint weights (e.g. confidences). Returns (T, 3)."""
    half = crop_size / 2.0
    # u_img * scale - start = half * s * X_m + half * s * t  ->  y = a X + b
    y = pixels * crops[:, None, 0:1] - crops[:, None, 1:3]
    x = points[..., :2] / 1000.0
    w = torch.ones_like(x[..., 0]) if weights is None else weights.to(x)
    wsum = w.sum(-1, keepdim=True).clamp_min(1e-12)  # (T,1)
    xm = (w[..., None] * x).sum(-2) / wsum  # (T,2)
    ym = (w[..., None] * y).sum(-2) / wsum
    xc, yc = x - xm[:, None], y - ym[:, None]
    a = (w[..., None] * xc * yc).sum((-1, -2)) / (w[..., None] * xc * xc).sum((-1, -2)).clamp_min(1e-12)
    b = ym - a[:, None] * xm  # (T,2) = half * s * t
    s = a / half
    t = b / (half * s[:, None])
    return torch.cat([s[:, None], t], dim=-1)


@dataclass
class Cameras:
    """Per-frame cameras of one model.

    params (T, P): P = 3 for ``weak_perspective`` (s, tx, ty), 7 for ``pinhole``.
    crops (T, 3): (scale, start_x, start_y) for ``weak_perspective``; None for ``pinhole``.
    """

    model: str
    params: torch.Tensor
    crops: torch.Tensor | None = None
    crop_size: float = 224.0

    def __post_init__(self) -> None:
        if self.model not in CAMERA_MODELS:
            raise ValueError(f"Cameras.model: expected one of {CAMERA_MODELS}, got {self.model!r}")
        n = CAMERA_NUM_PARAMS[self.model]
        if self.params.ndim != 2 or self.params.shape[1] != n:
            raise ValueError(
                f"Cameras.params: expected shape (T, {n}) for model {self.model!r}, got {tuple(self.params.shape)}"
            )
        if self.model == "weak_perspective":
            if self.crops is None or tuple(self.crops.shape) != (self.params.shape[0], 3):
                got = None if self.crops is None else tuple(self.crops.shape)
                raise ValueError(
                    f"Cameras.crops: expected shape ({self.params.shape[0]}, 3) (scale, start_x, start_y) "
                    f"for weak_perspective, got {got}"
                )
        elif self.crops is not None:
            raise ValueError("Cameras.crops: only the weak_perspective model takes crops")

    def __len__(self) -> int:
        return self.params.shape[0]

    def project(self, points: torch.Tensor, params: torch.Tensor | None = None) -> torch.Tensor:
        """Project (T, J, 3) mm to (T, J, 2) px, optionally with replacement ``params`` (T, P)
        (e.g. parameters being optimised)."""
        params = self.params if params is None else params
        if self.model == "weak_perspective":
            return project_weak_perspective(points, params, self.crops.to(params), self.crop_size)
        return project_pinhole(points, params)

    def to(self, *args, **kwargs) -> Cameras:
        crops = None if self.crops is None else self.crops.to(*args, **kwargs)
        return Cameras(self.model, self.params.to(*args, **kwargs), crops, self.crop_size)
