"""A YOLOX person detector through onnxruntime: frames -> person boxes (x0, y0, x1, y1, score).

Any YOLOX ONNX export with the raw head (Megvii's export script without ``--decode_in_inference``)
works, ``yolox_nano`` by default (:mod:`.detector_weights`):

- input: one float32 image (1, 3, h, w), BGR, 0..255, no normalisation; the frame is resized
  keeping its aspect ratio into the top-left corner, the rest is 114 (:func:`letterbox`). h and w
  are read from the model (416 x 416 for YOLOX-Nano);
- output: (1, A, 5 + C): per anchor point of the strides 8, 16, 32 (grids of h/s x w/s cells, rows
  of x, finest stride first), the x and y offsets from the cell and the log width and height, in
  stride units, the objectness and C class scores (both after a sigmoid; COCO: C = 80, person 0).
  Decoding (:func:`decode_yolox`): centre = (offset + cell) x stride, size = exp(log size) x stride,
  score = objectness x class score; then a score threshold and non-maximum suppression.

Boxes are in the original frame's pixels with pixel centres at integer coordinates, as elsewhere
in lit-boot: a box covering the pixel columns a..b has x0 = a - 0.5 and x1 = b + 0.5 (x1 - x0 is
its width in pixels), and boxes are clipped to the frame, [-0.5, W - 0.5] x [-0.5, H - 0.5].
onnxruntime is part of the ``mediapipe`` extra and is imported only when a detector is built.
Another person detector plugs in through :class:`PersonBoxDetector` (one method); :func:`as_detector`
takes either, or a YOLOX model path or name.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Protocol

import cv2
import numpy as np
import torch

from .detector_weights import resolve_detector_weights

__all__ = [
    "ORT_INSTALL_HINT",
    "PERSON_CLASS",
    "YOLOX_STRIDES",
    "OnnxRuntimeUnavailable",
    "PersonDetector",
    "PersonBoxDetector",
    "as_detector",
    "detector_name",
    "decode_yolox",
    "import_onnxruntime",
    "letterbox",
    "select_boxes",
    "to_frame",
    "yolox_grids",
]

log = logging.getLogger(__name__)

#: The COCO class index of a person.
PERSON_CLASS = 0
#: YOLOX's head strides, finest first, in the order of the output's anchor points.
YOLOX_STRIDES = (8, 16, 32)
#: The letterbox's padding value (YOLOX's training preprocessing).
PAD_VALUE = 114
ORT_INSTALL_HINT = 'pip install "lit-boot[mediapipe]"  (installs onnxruntime with MediaPipe)'


class OnnxRuntimeUnavailable(ImportError):
    """onnxruntime is not installed; the message names the extra that installs it."""


def import_onnxruntime() -> Any:
    """Import and return ``onnxruntime``, or raise :class:`OnnxRuntimeUnavailable`."""
    try:
        import onnxruntime
    except ImportError as err:
        raise OnnxRuntimeUnavailable(
            f"the person detector needs onnxruntime ({err}); install it with: {ORT_INSTALL_HINT}"
        ) from err
    return onnxruntime


def open_session(path: Path, threads: int | None, providers: Sequence[str]) -> Any:
    """An onnxruntime session of the model file ``path``: ``threads`` intra-op threads (None:
    ``torch.get_num_threads()``, which follows ``OMP_NUM_THREADS``), ``providers`` in order of
    preference; onnxruntime's own warnings silenced. A file onnxruntime cannot load raises a
    ValueError naming it."""
    ort = import_onnxruntime()
    options = ort.SessionOptions()
    options.intra_op_num_threads = threads or torch.get_num_threads()
    options.inter_op_num_threads = 1
    options.log_severity_level = 3  # errors only: onnxruntime's warnings are not lit-boot's output
    missing = [p for p in providers if p not in ort.get_available_providers()]
    if missing or not providers:
        raise ValueError(f"providers: expected some of {ort.get_available_providers()}, got {list(providers)}")
    try:
        return ort.InferenceSession(str(path), sess_options=options, providers=list(providers))
    except Exception as err:  # noqa: BLE001 - onnxruntime raises its own types for a bad file
        first = str(err).strip().splitlines()[0] if str(err).strip() else ""
        raise ValueError(f"{path}: not an ONNX model onnxruntime can load ({type(err).__name__}: {first})") from None


def yolox_grids(height: int, width: int, strides: Sequence[int] = YOLOX_STRIDES) -> tuple[torch.Tensor, torch.Tensor]:
    """The anchor points of a ``height`` x ``width`` input, in YOLOX's output order: cells (A, 2)
    as (x, y) cell indices, and their strides (A, 1) px; A = sum over strides of (h//s) x (w//s)."""
    cells, sizes = [], []
    for s in strides:
        ys, xs = torch.meshgrid(torch.arange(height // s), torch.arange(width // s), indexing="ij")
        cells.append(torch.stack([xs, ys], -1).reshape(-1, 2))
        sizes.append(torch.full((cells[-1].shape[0], 1), float(s)))
    return torch.cat(cells).float(), torch.cat(sizes)


def decode_yolox(raw: torch.Tensor | np.ndarray, input_size: tuple[int, int]) -> tuple[torch.Tensor, torch.Tensor]:
    """Decode YOLOX's raw head output (1, A, 5 + C) or (A, 5 + C) for an input of ``input_size``
    = (h, w) px. Returns boxes (A, 4) as x0, y0, x1, y1 in the letterboxed input's pixels (its
    left/top edge at 0, as YOLOX's labels) and scores (A, C) = objectness x class score."""
    raw = torch.as_tensor(raw, dtype=torch.float32)
    raw = raw[0] if raw.ndim == 3 and raw.shape[0] == 1 else raw
    cells, strides = yolox_grids(*input_size)
    if raw.ndim != 2 or raw.shape[0] != cells.shape[0] or raw.shape[1] < 6:
        raise ValueError(
            f"raw: expected shape (1, {cells.shape[0]}, 5 + classes) for a {input_size[0]}x{input_size[1]} input "
            f"(strides {', '.join(map(str, YOLOX_STRIDES))}), got {tuple(raw.shape)}"
        )
    centre = (raw[:, :2] + cells) * strides
    size = raw[:, 2:4].exp() * strides
    boxes = torch.cat([centre - size / 2, centre + size / 2], 1)
    return boxes, raw[:, 4:5] * raw[:, 5:]


def letterbox(frame: torch.Tensor, input_size: tuple[int, int]) -> tuple[torch.Tensor, tuple[float, float]]:
    """A uint8 RGB frame (3, H, W) as YOLOX's input (3, h, w) float32 BGR 0..255: resized
    (bilinear) keeping its aspect ratio into the top-left corner, padded with 114. Also returns
    the scales (sy, sx) actually applied (the resized size over the frame's, per axis)."""
    _, H, W = frame.shape
    h, w = input_size
    r = min(h / H, w / W)
    new_h, new_w = min(h, max(1, round(H * r))), min(w, max(1, round(W * r)))
    bgr = np.ascontiguousarray(frame.flip(0).permute(1, 2, 0).numpy())
    resized = cv2.resize(bgr, (new_w, new_h), interpolation=cv2.INTER_LINEAR)
    out = torch.full((3, h, w), float(PAD_VALUE))
    out[:, :new_h, :new_w] = torch.from_numpy(resized).permute(2, 0, 1).float()
    return out, (new_h / H, new_w / W)


def select_boxes(
    boxes: torch.Tensor, scores: torch.Tensor, *, class_id: int = PERSON_CLASS, score: float = 0.25, iou: float = 0.45
) -> torch.Tensor:
    """The detections of class ``class_id``: boxes (A, 4) with class scores (A, C) whose score is
    above ``score``, after non-maximum suppression at IoU ``iou`` (torchvision's). Returns (N, 5)
    x0, y0, x1, y1, score, best score first."""
    from torchvision.ops import nms

    if not 0 <= class_id < scores.shape[1]:
        raise ValueError(f"class_id: expected a class index below {scores.shape[1]}, got {class_id!r}")
    s = scores[:, class_id]
    keep = s > score
    b, s = boxes[keep], s[keep]
    kept = nms(b, s, iou)  # sorted by score, best first
    return torch.cat([b[kept], s[kept, None]], 1)


def to_frame(detections: torch.Tensor, scale: tuple[float, float], frame_size: tuple[int, int]) -> torch.Tensor:
    """Detections (N, 5) in letterboxed pixels (edges at 0) -> the frame's pixels (pixel centres at
    integer coordinates), clipped to the frame of ``frame_size`` = (H, W); boxes left with no area
    are dropped. ``scale`` = (sy, sx) from :func:`letterbox`."""
    sy, sx = scale
    H, W = frame_size
    out = detections.clone()
    out[:, [0, 2]] = (out[:, [0, 2]] / sx - 0.5).clamp(-0.5, W - 0.5)
    out[:, [1, 3]] = (out[:, [1, 3]] / sy - 0.5).clamp(-0.5, H - 0.5)
    return out[(out[:, 2] > out[:, 0]) & (out[:, 3] > out[:, 1])]


class PersonDetector:
    """YOLOX through onnxruntime, for people (or any class of the model: ``class_id``).

    Args:
        model: an ONNX file path, or a known name (``"yolox_nano"``; :mod:`.detector_weights`).
        score: keep detections with objectness x class score above this (0..1).
        iou: non-maximum suppression's IoU threshold (0..1).
        class_id: the class to keep (COCO person = 0).
        threads: onnxruntime's intra-op threads (None: ``torch.get_num_threads()``, which follows
            ``OMP_NUM_THREADS``).
        providers: onnxruntime execution providers, in order of preference.
        input_size: (h, w) px for a model whose input size is not fixed; must match a fixed one.

    ``detect(frame)`` and ``detect_frames(frames)`` take torch uint8 RGB frames as lit-boot's
    scenes hold them and give (N, 5) float32 boxes x0, y0, x1, y1, score (module docstring).
    A missing or unreadable model file, or one whose input or output is not YOLOX's, raises an
    error naming the file and what was expected.
    """

    def __init__(
        self,
        model: str | os.PathLike = "yolox_nano",
        *,
        score: float = 0.25,
        iou: float = 0.45,
        class_id: int = PERSON_CLASS,
        threads: int | None = None,
        providers: Sequence[str] = ("CPUExecutionProvider",),
        input_size: tuple[int, int] | None = None,
    ) -> None:
        for name, value in (("score", score), ("iou", iou)):
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"{name}: expected a value in [0, 1], got {value!r}")
        if threads is not None and threads < 1:
            raise ValueError(f"threads: expected None or at least 1, got {threads!r}")
        import_onnxruntime()  # before the weights: a missing extra is named first
        self.path = resolve_detector_weights(model)
        self.score, self.iou, self.class_id = float(score), float(iou), int(class_id)
        self.session = open_session(self.path, threads, providers)
        self.input_name, self.input_size = self._check_input(input_size)
        self.output_name, self.num_classes = self._check_output()
        log.debug("person detector %s: input %dx%d, %s classes", self.path.name, *self.input_size, self.num_classes)

    def __repr__(self) -> str:
        h, w = self.input_size
        return f"PersonDetector({str(self.path)!r}, input {h}x{w}, score={self.score}, iou={self.iou})"

    def _check_input(self, input_size: tuple[int, int] | None) -> tuple[str, tuple[int, int]]:
        inputs = self.session.get_inputs()
        shape = list(inputs[0].shape) if len(inputs) == 1 else []
        if len(shape) != 4 or (shape[1] != 3 and not isinstance(shape[1], str | None)):
            raise ValueError(
                f"{self.path}: expected one input of shape [1, 3, h, w] (YOLOX's 'images'), got "
                + ", ".join(f"{i.name} {i.shape}" for i in inputs)
            )
        fixed = tuple(shape[2:]) if all(isinstance(d, int) for d in shape[2:]) else None
        if input_size is not None and fixed is not None and tuple(input_size) != fixed:
            raise ValueError(f"input_size: the model {self.path.name} takes {fixed[0]}x{fixed[1]}, got {input_size!r}")
        size = tuple(int(d) for d in (fixed or input_size or ()))
        if len(size) != 2:
            raise ValueError(f"input_size: {self.path.name}'s input size is not fixed ({shape}); pass (h, w)")
        if any(d <= 0 or d % max(YOLOX_STRIDES) for d in size):
            raise ValueError(f"{self.path}: expected an input size in multiples of 32 px, got {size[0]}x{size[1]}")
        return inputs[0].name, size  # type: ignore[return-value]

    def _expected(self) -> str:
        anchors = yolox_grids(*self.input_size)[0].shape[0]
        h, w = self.input_size
        return f"[1, {anchors}, 5 + classes] (YOLOX's raw head for a {h}x{w} input, strides 8, 16, 32)"

    def _check_output(self) -> tuple[str, int | None]:
        out = self.session.get_outputs()[0]
        shape = list(out.shape)
        anchors = yolox_grids(*self.input_size)[0].shape[0]
        known = [d if isinstance(d, int) else None for d in shape]
        if len(shape) != 3 or known[1] not in (anchors, None) or (known[2] is not None and known[2] < 6):
            raise ValueError(f"{self.path}: expected an output of shape {self._expected()}, got {out.name} {shape}")
        classes = known[2] - 5 if known[2] is not None else None
        if classes is not None and not 0 <= self.class_id < classes:
            raise ValueError(f"class_id: {self.path.name} has {classes} classes, got {self.class_id!r}")
        return out.name, classes

    def _raw(self, image: torch.Tensor) -> np.ndarray:
        (raw,) = self.session.run([self.output_name], {self.input_name: image[None].numpy()})
        anchors = yolox_grids(*self.input_size)[0].shape[0]
        if raw.ndim != 3 or raw.shape[:2] != (1, anchors) or raw.shape[2] < 6 + self.class_id:
            raise ValueError(f"{self.path}: expected an output of shape {self._expected()}, got {list(raw.shape)}")
        if float(np.median(raw[0, :, 2:4])) > 8:  # the raw head's log sizes stay near 2; e^8 x 8 px is absurd
            raise ValueError(
                f"{self.path}: the output's box sizes look like pixels, not log sizes in stride units: an export "
                "with --decode_in_inference? expected YOLOX's raw head (export it without that option)"
            )
        return raw

    def detect(self, frame: torch.Tensor) -> torch.Tensor:
        """The people in one frame, uint8 RGB (3, H, W): (N, 5) float32 x0, y0, x1, y1 px (pixel
        centres at integer coordinates, clipped to the frame), score; best score first."""
        if not isinstance(frame, torch.Tensor) or frame.dtype != torch.uint8 or frame.ndim != 3 or frame.shape[0] != 3:
            got = f"{frame.dtype} {tuple(frame.shape)}" if isinstance(frame, torch.Tensor) else type(frame).__name__
            raise ValueError(f"frame: expected a uint8 RGB tensor of shape (3, H, W), got {got}")
        image, scale = letterbox(frame.cpu(), self.input_size)
        boxes, scores = decode_yolox(self._raw(image), self.input_size)
        found = select_boxes(boxes, scores, class_id=self.class_id, score=self.score, iou=self.iou)
        return to_frame(found, scale, tuple(frame.shape[1:]))

    def detect_frames(self, frames: torch.Tensor) -> list[torch.Tensor]:
        """:meth:`detect` on each of frames (T, 3, H, W) uint8 RGB: T tensors (N_t, 5)."""
        if not isinstance(frames, torch.Tensor) or frames.ndim != 4:
            got = tuple(frames.shape) if isinstance(frames, torch.Tensor) else type(frames).__name__
            raise ValueError(f"frames: expected a uint8 RGB tensor of shape (T, 3, H, W), got {got}")
        start = time.perf_counter()
        out = [self.detect(f) for f in frames]
        seconds = time.perf_counter() - start
        log.debug("detected people in %d frames (%.3f s per frame)", len(out), seconds / max(1, len(out)))
        return out


class PersonBoxDetector(Protocol):
    """What lit-boot needs of a person detector (the protocol another detector implements to plug
    in; :class:`PersonDetector` is the built-in one): ``detect_frames(frames)``, frames (T, 3, H, W)
    uint8 RGB, gives one tensor (N_t, 5) per frame, x0, y0, x1, y1 px (pixel centres at integer
    coordinates, module docstring) and a score in 0..1; (0, 5) where nobody is found."""

    def detect_frames(self, frames: torch.Tensor) -> list[torch.Tensor]: ...


def as_detector(detector: Any, default: str | os.PathLike = "yolox_nano") -> PersonBoxDetector:
    """``detector`` itself where it has a ``detect_frames`` method (a :class:`PersonBoxDetector`),
    else a :class:`PersonDetector` of that YOLOX model path or name (``default`` where None)."""
    if callable(getattr(detector, "detect_frames", None)):
        return detector
    return PersonDetector(default if detector is None else detector)


def detector_name(detector: PersonBoxDetector) -> str:
    """What a run's metadata records of a detector: its model file, else its class name."""
    path = getattr(detector, "path", None)
    return str(path) if path is not None else type(detector).__name__
