"""Pictures: flow colour images, stick-man overlays, PNG files and scene previews.

Images are uint8 tensors (3, H, W) in RGB order; keypoints are (x, y) pixels with pixel
centres at integer coordinates.
"""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np
import torch
from PIL import ImageColor

from ..core.joints import JointLayout, get_layout
from ..core.scene import Scene
from .atomic import atomic_write_bytes

__all__ = ["draw_skeleton", "flow_image", "read_png", "scene_preview", "write_png", "OTHER_COLOURS", "OTHER_RGB"]

Color = str | tuple[int, int, int]

#: The other people's skeleton colours, one per track in the scene's order of people (the main
#: person is drawn in lime), as names and RGB (the overlay video's, the id sheet's).
OTHER_COLOURS = ("deepskyblue", "orange", "magenta", "yellow", "cyan", "white")
OTHER_RGB = ((0, 191, 255), (255, 165, 0), (255, 0, 255), (255, 255, 0), (0, 255, 255), (255, 255, 255))


def flow_image(flow: torch.Tensor, max_magnitude: float | None = None) -> torch.Tensor:
    """Colour-code flow (2, H, W) or (B, 2, H, W) px with ``torchvision.utils.flow_to_image``.

    Returns uint8 (3, H, W) or (B, 3, H, W). Hue = direction, saturation = magnitude.
    Without ``max_magnitude`` each flow is normalised by its own largest magnitude (also within
    a batch). With ``max_magnitude`` every flow is normalised by that common value: the flow
    is divided by it, vectors longer than it are clipped to length 1 (full saturation), and a
    one-pixel unit vector is appended as a reference so that flow_to_image's own
    normalisation by the maximum is the identity; that column is cropped away again.
    """
    if flow.ndim == 4:
        return torch.stack([flow_image(f, max_magnitude) for f in flow])
    if flow.ndim != 3 or flow.shape[0] != 2:
        raise ValueError(f"flow_image: expected flow of shape (2, H, W) or (B, 2, H, W), got {tuple(flow.shape)}")
    from torchvision.utils import flow_to_image  # here, not at import: the CLI's help stays light

    flow = flow.detach().float()
    if max_magnitude is None:
        return flow_to_image(flow)
    if not max_magnitude > 0:
        raise ValueError(f"flow_image: max_magnitude must be positive, got {max_magnitude}")
    scaled = flow / max_magnitude
    scaled = scaled / scaled.norm(dim=0, keepdim=True).clamp_min(1.0)
    reference = torch.zeros_like(scaled[:, :, :1])
    reference[0] = 1.0
    return flow_to_image(torch.cat([scaled, reference], dim=2))[:, :, :-1]


def _rgb(color: Color) -> tuple[int, int, int]:
    if isinstance(color, str):
        return tuple(ImageColor.getrgb(color)[:3])
    return tuple(int(c) for c in color)


def _check_image(image: torch.Tensor, who: str) -> None:
    if not isinstance(image, torch.Tensor) or image.dtype != torch.uint8 or image.ndim != 3 or image.shape[0] != 3:
        got = f"{image.dtype} {tuple(image.shape)}" if isinstance(image, torch.Tensor) else type(image).__name__
        raise ValueError(f"{who}: expected a uint8 RGB image of shape (3, H, W), got {got}")


def draw_skeleton(
    image: torch.Tensor,
    keypoints: torch.Tensor,
    layout: str | JointLayout,
    confidence: torch.Tensor | None = None,
    threshold: float = 0.0,
    color: Color = "lime",
    radius: int = 2,
    width: int = 2,
) -> torch.Tensor:
    """Draw the stick-man of ``layout`` (its ``sketch_bones``) on a copy of ``image``.

    image uint8 (3, H, W) RGB; keypoints (K, 2) px in ``layout``; confidence (K,) or None.
    Virtual joints are appended with ``layout.with_virtual`` (their confidence is the minimum
    of their parts'). A joint is drawn iff its confidence > ``threshold`` (all if None) and it
    is finite; a bone iff both its ends are. Coordinates are rounded to the nearest pixel.
    ``torchvision.utils.draw_keypoints`` rasterises points and bones; since it draws bones
    in white whatever its ``colors``, it draws on a blank canvas and the marked pixels are
    painted in ``color`` (a PIL colour name, "#rrggbb" or an RGB tuple). Returns uint8 (3, H, W).
    """
    _check_image(image, "draw_skeleton")
    layout = get_layout(layout)
    if keypoints.ndim != 2 or keypoints.shape != (layout.num_joints, 2):
        raise ValueError(
            f"draw_skeleton: expected keypoints of shape ({layout.num_joints}, 2) for layout "
            f"{layout.name!r}, got {tuple(keypoints.shape)}"
        )
    if confidence is not None and confidence.shape != (layout.num_joints,):
        raise ValueError(
            f"draw_skeleton: expected confidence of shape ({layout.num_joints},), got {tuple(confidence.shape)}"
        )
    conf = None if confidence is None else confidence.detach().cpu().float()
    points, conf = layout.with_virtual(keypoints.detach().cpu().float(), conf)
    finite = torch.isfinite(points).all(-1)
    visible = finite if conf is None else finite & (conf > threshold)
    points = torch.where(finite[:, None], points, torch.zeros_like(points)).round()
    from torchvision.utils import draw_keypoints

    canvas = torch.zeros(image.shape, dtype=torch.uint8)
    marks = draw_keypoints(
        canvas, points[None], connectivity=list(layout.sketch_bones), colors="white",
        radius=radius, width=width, visibility=visible[None],
    )  # fmt: skip
    mask = (marks != 0).any(0).to(image.device)
    rgb = torch.tensor(_rgb(color), dtype=torch.uint8, device=image.device)
    return torch.where(mask, rgb[:, None, None], image)


def write_png(path: str | os.PathLike, image: torch.Tensor) -> Path:
    """Write a uint8 (3, H, W) RGB image as a lossless PNG (via cv2), atomically."""
    path = Path(path)
    _check_image(image, f"write_png({path})")
    bgr = cv2.cvtColor(image.detach().cpu().permute(1, 2, 0).numpy(), cv2.COLOR_RGB2BGR)
    ok, encoded = cv2.imencode(".png", bgr)
    if not ok:
        raise ValueError(f"write_png({path}): cv2 could not encode the image as PNG")
    return atomic_write_bytes(path, encoded.tobytes())


def read_png(path: str | os.PathLike) -> torch.Tensor:
    """Read an 8-bit PNG (or any image cv2 decodes) into uint8 (3, H, W) RGB.

    Grey images are replicated to three channels and an alpha channel is dropped. Raises
    FileNotFoundError for a missing file, ValueError naming the file for an undecodable one
    or a bit depth other than 8.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such image file")
    buffer = np.fromfile(path, dtype=np.uint8)
    image = cv2.imdecode(buffer, cv2.IMREAD_UNCHANGED) if buffer.size else None
    if image is None:
        raise ValueError(f"{path}: unreadable image (cv2 could not decode it; corrupted or not an image)")
    if image.dtype != np.uint8:
        raise ValueError(f"{path}: expected an 8-bit image, got dtype {image.dtype}")
    conversions = {2: cv2.COLOR_GRAY2RGB, 3: cv2.COLOR_BGR2RGB, 4: cv2.COLOR_BGRA2RGB}
    channels = 2 if image.ndim == 2 else image.shape[2]
    if channels not in conversions:
        raise ValueError(f"{path}: expected a grey, RGB or RGBA image, got {channels} channels")
    return torch.from_numpy(cv2.cvtColor(image, conversions[channels])).permute(2, 0, 1).contiguous()


def scene_preview(scene: Scene, index: int = 0) -> torch.Tensor:
    """Three panels side by side, uint8 (3, H, 3W), for frame ``index``.

    Left: the frame. Middle: the colour-coded GT flow from frame ``index`` to ``index + 1``
    (white where it is not valid), or the frame in grey when that pair has no valid GT flow.
    Right: the frame with the 2D keypoints (confidence > 0.5) in lime and, if present, the GT
    2D joints in red.
    """
    T = scene.num_frames
    if not -T <= index < T:
        raise IndexError(f"scene_preview: frame index {index} out of range for {T} frames")
    index %= T
    frame = scene.frames[index]
    gt = scene.gt
    valid = None if gt is None or gt.flow_valid is None or index >= T - 1 else gt.flow_valid[index]
    if gt is not None and gt.flow is not None and index < T - 1 and (valid is None or valid.any()):
        flow = gt.flow[index] if valid is None else gt.flow[index] * valid  # invalid pixels: white (no motion)
        middle = flow_image(flow).to(frame.device)
    else:
        from torchvision.transforms.functional import rgb_to_grayscale

        middle = rgb_to_grayscale(frame, num_output_channels=3)
    right = frame
    if scene.keypoints2d is not None:
        right = draw_skeleton(
            right, scene.keypoints2d[index], scene.keypoints_layout, scene.keypoints_conf[index], threshold=0.5
        )
    if gt is not None and gt.joints2d is not None:
        right = draw_skeleton(right, gt.joints2d[index], gt.joints_layout, color="red")
    return torch.cat([frame, middle, right], dim=2)
