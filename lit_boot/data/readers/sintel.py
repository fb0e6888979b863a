"""MPI-Sintel: the frames of one training scene with its ground-truth forward flow.

The official training layout under ``root``::

    training/{clean,final}/<scene>/frame_NNNN.png   frames (RGB, NNNN from 0001)
    training/flow/<scene>/frame_NNNN.flo             flow NNNN -> NNNN+1 (Middlebury .flo, px)
    training/occlusions/<scene>/frame_NNNN.png       white = occluded (hidden in NNNN+1)
    training/invalid/<scene>/frame_NNNN.png          white = flow invalid

Partial copies work: a pair whose .flo is missing gets flow 0 and ``flow_valid`` False on
every pixel, so it counts in no flow metric; ``metadata["gt_pairs"]`` lists the pairs with
GT. A pair with a .flo but no occlusion / invalid mask counts every pixel as visible / valid
(listed in ``metadata["missing_masks"]``). NaN / inf or unknown (>= 1e9) flow pixels are invalid; a
.flo with no finite value at all is refused as corrupted. Sintel has no poses: the scene has none.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
import torch

from ...core.scene import GroundTruth, Scene
from ..flo import read_flo
from ._common import DatasetFormatError, Size, make_scene, read_image, read_images, require_dir, resize_array
from ._common import scale_factors, select_frames

__all__ = [
    "SINTEL_FPS",
    "SINTEL_HUMAN_PASS",
    "SINTEL_HUMAN_SCENES",
    "SINTEL_PASSES",
    "list_sintel_scenes",
    "read_sintel",
]

SINTEL_PASSES = ("clean", "final")
SINTEL_FPS = 24.0
#: The paper's human subset (REFERENCE section 3): these scenes, final pass, 49 pairs each.
SINTEL_HUMAN_SCENES = ("alley_2", "bamboo_2", "cave_2", "cave_4")
SINTEL_HUMAN_PASS = "final"

_FRAME = re.compile(r"^frame_(\d+)\.png$")
_BAD_FLOW = 1e9  # Middlebury's "unknown" values are around 1e9


def _training(root: str | os.PathLike, pass_name: str) -> Path:
    if pass_name not in SINTEL_PASSES:
        raise ValueError(f"pass_name: expected one of {SINTEL_PASSES}, got {pass_name!r}")
    root = require_dir(Path(root), "MPI-Sintel root")
    return require_dir(root / "training", f"an MPI-Sintel root holds training/{pass_name}/<scene>/frame_NNNN.png")


def list_sintel_scenes(root: str | os.PathLike, pass_name: str = "final") -> list[str]:
    """Sorted names of the scenes under ``root``/training/``pass_name``."""
    folder = require_dir(_training(root, pass_name) / pass_name, f"the {pass_name} pass of MPI-Sintel")
    return sorted(p.name for p in folder.iterdir() if p.is_dir())


def _frame_numbers(folder: Path) -> list[int]:
    return sorted(int(m.group(1)) for p in folder.iterdir() if (m := _FRAME.match(p.name)))


def _name(number: int) -> str:
    return f"frame_{number:04d}"


def _mask(path: Path, height: int, width: int, size: Size | None) -> torch.Tensor | None:
    """A white-means-true PNG mask as bool (H, W) (resized, nearest), None when missing."""
    if not path.is_file():
        return None
    image = read_image(path)
    if tuple(image.shape[1:]) != (height, width):
        raise DatasetFormatError(
            f"{path}: mask of {image.shape[2]}x{image.shape[1]} px, expected {width}x{height} like the frames"
        )
    return _resize_mask(image[0] > 127, size)


def _resize_mask(mask: torch.Tensor, size: Size | None) -> torch.Tensor:
    return torch.from_numpy(resize_array(mask.numpy().astype(np.uint8), size, nearest=True) > 0)


def _pair_gt(
    training: Path, scene: str, number: int, height: int, width: int, size: Size | None, missing: list[str]
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor] | None:
    """(flow (2, H, W), valid (H, W), occluded (H, W)) of pair number -> number+1 at ``size``;
    None without a .flo. Appends the masks it lacks to ``missing``."""
    file = training / "flow" / scene / f"{_name(number)}.flo"
    if not file.is_file():
        return None
    try:
        flow = read_flo(file, allow_nonfinite=True)  # a few NaN pixels: invalid there
    except ValueError as err:
        raise DatasetFormatError(str(err)) from None
    if not torch.isfinite(flow).any():
        raise DatasetFormatError(f"{file}: corrupted: every value is NaN or infinite (expected flow in px)")
    if tuple(flow.shape[1:]) != (height, width):
        raise DatasetFormatError(f"{file}: flow of {flow.shape[2]}x{flow.shape[1]} px, expected {width}x{height}")
    bad = ~torch.isfinite(flow).all(0) | (flow.abs() >= _BAD_FLOW).any(0)
    flow = torch.where(bad, torch.zeros_like(flow), flow)
    sx, sy = scale_factors(height, width, size)
    flow = torch.from_numpy(resize_array(flow.permute(1, 2, 0).numpy(), size, nearest=True)).permute(2, 0, 1)
    flow = flow * torch.tensor([sx, sy], dtype=flow.dtype)[:, None, None]
    bad = _resize_mask(bad, size)
    masks = {}
    for kind in ("invalid", "occlusions"):
        path = training / kind / scene / f"{_name(number)}.png"
        masks[kind] = _mask(path, height, width, size)
        if masks[kind] is None:
            missing.append(f"{kind}/{scene}/{path.name}")
            masks[kind] = torch.zeros_like(bad)
    return flow.contiguous(), ~(masks["invalid"] | bad), masks["occlusions"]


def read_sintel(
    root: str | os.PathLike,
    scene: str,
    *,
    pass_name: str = "final",
    first: int | None = None,
    last: int | None = None,
    size: Size | None = None,
) -> Scene:
    """Read frames ``first``..``last`` (inclusive, Sintel's numbering from 1; default: all) of
    one scene as a :class:`Scene` at 24 fps.

    GroundTruth: flow (T-1, 2, H, W) px forward t -> t+1, flow_valid (T-1, H, W) (False where
    invalid and on every pixel of a pair without a .flo), flow_occluded (T-1, H, W); gt is None
    when no pair has a .flo. ``size`` = (height, width) resizes frames (area / bilinear) and
    GT (nearest neighbour, flow scaled by the resize factors). Metadata: dataset, scene, pass,
    frames (numbers), gt_pairs ([n, n+1] with GT), missing_masks.

    Raises FileNotFoundError for a missing root, scene or frame folder, ValueError for bad
    arguments, :class:`DatasetFormatError` naming the file for a malformed or inconsistent one.
    """
    training = _training(root, pass_name)
    folder = training / pass_name / scene
    if not folder.is_dir():
        have = list_sintel_scenes(root, pass_name)
        raise FileNotFoundError(f"{folder}: no such Sintel scene; {training / pass_name} holds {have}")
    numbers = select_frames(_frame_numbers(folder), first, last, where=f"{folder} (frame_NNNN.png)")
    frames, (height, width) = read_images([folder / f"{_name(n)}.png" for n in numbers], size)
    missing: list[str] = []
    pairs = [_pair_gt(training, scene, n, height, width, size, missing) for n in numbers[:-1]]
    gt_pairs = [[n, n + 1] for n, pair in zip(numbers, pairs) if pair is not None]
    gt = None
    if gt_pairs:
        H, W = frames.shape[-2:]
        empty = (torch.zeros(2, H, W), torch.zeros(H, W, dtype=torch.bool), torch.zeros(H, W, dtype=torch.bool))
        flow, valid, occluded = (torch.stack(f) for f in zip(*(p if p is not None else empty for p in pairs)))
        gt = GroundTruth(flow=flow, flow_valid=valid, flow_occluded=occluded)
    metadata = {"dataset": "mpi-sintel", "scene": scene, "pass": pass_name, "frames": numbers,
                "gt_pairs": gt_pairs, "missing_masks": missing}  # fmt: skip
    name = f"sintel_{scene}_{pass_name}"
    return make_scene(folder, frames=frames, fps=SINTEL_FPS, name=name, gt=gt, metadata=metadata)
