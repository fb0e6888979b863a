"""Per-frame pose estimates of the people of a video (:class:`PoseEstimates`), no pixels.

Saved and read by :mod:`.pose_file` (lit-boot's pose file). Conventions: pixels with pixel
centres at integer coordinates, millimetres in the camera frame (:mod:`lit_boot.core.cameras`).
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from typing import Any

import torch

from ...core.cameras import Cameras
from ...core.joints import get_layout
from ...core.people import PERSON_FIELDS, Person, check_people
from ...core.scene import Scene, SceneValidationError, check_estimates
from ._common import scale_factors, scale_points

__all__ = ["PoseEstimates", "ANISOTROPY_TOLERANCE"]

#: Largest relative difference of the x and y resize factors weak-perspective cameras tolerate.
ANISOTROPY_TOLERANCE = 0.01


@dataclass
class PoseEstimates:
    """Per-frame pose estimates of the people in T frames (no pixels).

    keypoints2d (T, K, 2) px + keypoints_conf (T, K) in [0, 1] (0 = not found) in
    ``keypoints_layout``; joints3d (T, J, 3) mm in ``joints3d_layout`` with ``cameras``;
    either part may be absent, not both. frame_indices (T,) int64: the source-video frame of
    each row (default 0..T-1); image_size (H, W) of the frames the pixels refer to (None =
    unknown: taken to be the scene's); source: who made them; metadata: JSON-serialisable;
    person_boxes (T, 5): a person detector's box and score per frame (see
    :class:`~lit_boot.core.Scene`), or None. These are the main person's (track id
    ``track_id``); ``others``: the other people's (:class:`~lit_boot.core.people.Person`, the
    same fields, frames and layouts), as in a Scene. Checked on construction (:meth:`validate`).
    """

    keypoints2d: torch.Tensor | None = None
    keypoints_conf: torch.Tensor | None = None
    keypoints_layout: str = "coco17"
    joints3d: torch.Tensor | None = None
    joints3d_layout: str = "lsp14"
    cameras: Cameras | None = None
    frame_indices: torch.Tensor | None = None
    image_size: tuple[int, int] | None = None
    source: str = "unknown"
    metadata: dict[str, Any] = field(default_factory=dict)
    person_boxes: torch.Tensor | None = None
    track_id: int = 0
    others: tuple[Person, ...] = ()

    def __post_init__(self) -> None:
        if self.frame_indices is None and self.num_frames is not None:
            self.frame_indices = torch.arange(self.num_frames, dtype=torch.int64)
        if self.image_size is not None:
            self.image_size = tuple(int(v) for v in self.image_size)
        self.validate()

    @property
    def num_frames(self) -> int | None:
        """T (None while neither keypoints2d nor joints3d is set)."""
        present = self.keypoints2d if self.keypoints2d is not None else self.joints3d
        return None if present is None else int(present.shape[0])

    def validate(self) -> None:
        """Check every field; SceneValidationError names the field and what was expected."""
        T = self.num_frames
        if T is None:
            raise SceneValidationError("PoseEstimates: give keypoints2d (with keypoints_conf) or joints3d, or both")
        if self.cameras is not None and self.joints3d is None:
            raise SceneValidationError("PoseEstimates.cameras: cameras need joints3d")
        check_estimates("PoseEstimates", self, T)
        check_people("PoseEstimates", self, self.others, T)
        fi = self.frame_indices
        if not isinstance(fi, torch.Tensor) or fi.dtype != torch.int64 or tuple(fi.shape) != (T,):
            got = f"{fi.dtype} {tuple(fi.shape)}" if isinstance(fi, torch.Tensor) else type(fi).__name__
            raise SceneValidationError(f"PoseEstimates.frame_indices: expected int64 of shape ({T},), got {got}")
        if (fi < 0).any() or (fi[1:] <= fi[:-1]).any():
            raise SceneValidationError("PoseEstimates.frame_indices: expected non-negative, strictly increasing")
        if self.image_size is not None and (len(self.image_size) != 2 or min(self.image_size) < 1):
            raise SceneValidationError(f"PoseEstimates.image_size: expected (H, W) > 0 or None, got {self.image_size}")
        if not isinstance(self.source, str):
            raise SceneValidationError(f"PoseEstimates.source: expected a str, got {type(self.source).__name__}")
        try:
            json.dumps(self.metadata, allow_nan=False)
        except (TypeError, ValueError) as err:
            raise SceneValidationError(f"PoseEstimates.metadata: must be JSON-serialisable: {err}") from None

    @property
    def num_people(self) -> int:
        """P: the main person and the others."""
        return 1 + len(self.others)

    def people(self) -> list[Person]:
        """Every person, the main one first."""
        return [Person.of(self), *self.others]

    def with_people(self, people: list[Person], **changes: Any) -> PoseEstimates:
        """A copy with ``people`` (at least one; the first is the main person, the rest the
        others) and the other fields ``changes``."""
        main, *rest = people
        return dataclasses.replace(self, **main.fields(), track_id=main.track_id, others=tuple(rest), **changes)

    def found(self) -> torch.Tensor:
        """(T,) bool: rows where the main person has any keypoint of confidence > 0 (all True
        without keypoints)."""
        if self.keypoints_conf is None:
            return torch.ones(self.num_frames, dtype=torch.bool)
        return (self.keypoints_conf > 0).any(-1)

    def take(self, rows: torch.Tensor | list[int]) -> PoseEstimates:
        """The estimates of rows ``rows`` (0-based row numbers, increasing)."""
        rows = torch.as_tensor(rows, dtype=torch.int64)
        people = [person.map(lambda x: x[rows].clone()) for person in self.people()]
        return self.with_people(people, frame_indices=self.frame_indices[rows].clone())

    def rescaled(self, image_size: tuple[int, int]) -> PoseEstimates:
        """The estimates for the frames resized to ``image_size`` (H, W): pixels, pinhole
        intrinsics and weak-perspective crops move with the image (pixel centres at integer
        coordinates). Weak-perspective cameras need x and y factors within 1 %."""
        if self.image_size is None or tuple(self.image_size) == tuple(image_size):
            return dataclasses.replace(self, image_size=tuple(image_size))
        sx, sy = scale_factors(*self.image_size, image_size)
        people = [_rescale_person(person, sx, sy) for person in self.people()]
        return self.with_people(people, image_size=tuple(image_size))

    def apply_to(self, scene: Scene) -> Scene:
        """A copy of ``scene`` with these estimates (the fields present here replace the scene's).

        Rows are matched to the scene's frames by ``scene.metadata["frame_indices"]`` when the
        scene has them and all are among ``frame_indices``; otherwise row by row when T agrees
        and ``frame_indices`` is the default 0..T-1. Pixels are rescaled when ``image_size``
        (if None: ``scene.metadata["native_size"]``, which :func:`~.video.read_video` records,
        else the scene's size) differs from the scene's. ``metadata["pose_estimates"]`` lists the
        estimates applied so far (source, fields, frame_indices, metadata). The people here
        become the scene's people; another person whose track the scene has keeps that track's
        fields that are absent here (refined 3D joints keep their 2D keypoints). Raises
        SceneValidationError on a mismatch, or for a found keypoint (confidence > 0) more than
        one image size outside the frame (x outside [-W, 2W], y outside [-H, 2H]).
        """
        est = self.take(self._rows_for(scene))
        if est.image_size is None and scene.metadata.get("native_size"):
            est = dataclasses.replace(est, image_size=tuple(scene.metadata["native_size"]))
        est = est.rescaled((scene.height, scene.width))
        for person in est.people():
            _check_in_image(est, person, scene.height, scene.width)
        fields: dict[str, Any] = {"track_id": est.track_id, "others": _merged_others(scene, est.others)}
        if est.keypoints2d is not None:
            fields |= {"keypoints2d": est.keypoints2d, "keypoints_conf": est.keypoints_conf,
                       "keypoints_layout": est.keypoints_layout}  # fmt: skip
        if est.joints3d is not None:
            fields |= {"joints3d": est.joints3d, "joints3d_layout": est.joints3d_layout, "cameras": est.cameras}
        if est.person_boxes is not None:
            fields["person_boxes"] = est.person_boxes
        info = {"source": self.source, "fields": sorted(set(fields) - {"track_id", "others"}),
                "people": [p.track_id for p in est.people()], "frame_indices": est.frame_indices.tolist(),
                "metadata": self.metadata}  # fmt: skip
        history = [*scene.metadata.get("pose_estimates", []), info]
        return dataclasses.replace(scene, **fields, metadata={**scene.metadata, "pose_estimates": history})

    def _rows_for(self, scene: Scene) -> list[int]:
        T, mine = scene.num_frames, self.frame_indices.tolist()
        wanted = scene.metadata.get("frame_indices")
        if wanted is not None and set(wanted) <= set(mine):
            where = {f: r for r, f in enumerate(mine)}
            return [where[f] for f in wanted]
        if T == len(mine) and mine == list(range(T)):
            return mine
        raise SceneValidationError(
            f"PoseEstimates ({self.source}): {len(mine)} rows for video frames {_span(mine)} do not cover the "
            f"scene {scene.name!r}'s {T} frames" + (f" (video frames {_span(wanted)})" if wanted is not None else "")
        )


def _merged_others(scene: Scene, others: tuple[Person, ...]) -> tuple[Person, ...]:
    """``others``, each completed by the fields it lacks from the scene's person of its track."""
    by_id = {person.track_id: person for person in scene.people()}
    merged = []
    for person in others:
        old = by_id.get(person.track_id)
        missing = {} if old is None else {k: getattr(old, k) for k in PERSON_FIELDS if getattr(person, k) is None}
        merged.append(dataclasses.replace(person, **missing))
    return tuple(merged)


def _check_in_image(est: PoseEstimates, person: Person, height: int, width: int) -> None:
    """SceneValidationError for a person's found keypoints more than one image size outside the frame."""
    if person.keypoints2d is None:
        return
    x, y = person.keypoints2d[..., 0], person.keypoints2d[..., 1]
    far = (person.keypoints_conf > 0) & ((x < -width) | (x > 2 * width) | (y < -height) | (y > 2 * height))
    if not far.any():
        return
    t, k = (int(i) for i in far.nonzero()[0])
    name = get_layout(est.keypoints_layout).names[k]
    who = "" if person.track_id == est.track_id and not est.others else f" person {person.track_id}"
    raise SceneValidationError(
        f"PoseEstimates ({est.source}){who}.keypoints2d: {int(far.sum())} found keypoints in {int(far.any(1).sum())} "
        f"frames lie more than one image size outside the {width}x{height} px frames, first {name} of video frame "
        f"{int(est.frame_indices[t])} at ({float(x[t, k]):.0f}, {float(y[t, k]):.0f}) px (expected x in "
        f"[{-width}, {2 * width}], y in [{-height}, {2 * height}]; wrong image_size or units?)"
    )


def _span(values: list[int]) -> str:
    return f"{values[0]}..{values[-1]}" if values else "none"


def _rescale_person(person: Person, sx: float, sy: float) -> Person:
    """A person's estimates for frames resized by sx, sy (pixels, boxes and cameras)."""
    keypoints = None if person.keypoints2d is None else scale_points(person.keypoints2d, sx, sy)
    boxes = person.person_boxes
    if boxes is not None:
        corners = scale_points(boxes[:, :4].reshape(-1, 2, 2), sx, sy).reshape(-1, 4)
        boxes = torch.cat([corners, boxes[:, 4:]], dim=1)
    return dataclasses.replace(person, keypoints2d=keypoints, person_boxes=boxes,
                               cameras=_rescale_cameras(person.cameras, sx, sy))  # fmt: skip


def _rescale_cameras(cameras: Cameras | None, sx: float, sy: float) -> Cameras | None:
    if cameras is None:
        return None
    p = cameras.params.clone()
    if cameras.model == "pinhole":
        p[:, 0:2] *= torch.tensor([sx, sy], dtype=p.dtype)
        p[:, 2:4] = scale_points(p[:, 2:4], sx, sy)
        return Cameras("pinhole", p)
    if abs(sx / sy - 1.0) > ANISOTROPY_TOLERANCE:
        raise SceneValidationError(
            f"PoseEstimates.cameras: cannot rescale weak-perspective cameras by x {sx:.4f} / y {sy:.4f} "
            "(the aspect ratio changes)"
        )
    # u' = (u + 0.5) s - 0.5 with u = (u_crop + start - c/2) / scale  =>  scale' = scale / s,
    # start' = start + (s - 1) / 2 * scale'.
    crops = cameras.crops.clone()
    crops[:, 0] = crops[:, 0] / (sx * sy) ** 0.5
    crops[:, 1:3] = crops[:, 1:3] + (torch.tensor([sx, sy], dtype=crops.dtype) - 1.0) / 2.0 * crops[:, 0:1]
    return Cameras("weak_perspective", p, crops, cameras.crop_size)
