"""One person (a track) of a scene with several: the per-person pose estimates.

A :class:`~lit_boot.core.scene.Scene` holds its main person in its own fields (``joints3d``,
``cameras``, ``keypoints2d``, ``keypoints_conf``, ``person_boxes``, ``track_id``) and every
other person as a :class:`Person` in ``Scene.others``; a single-person scene has no others
(P = 1). Each person's fields are per frame, in the scene's joint layouts and pixels; a frame
where a person is absent has keypoint confidences 0 and a box score 0.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import torch

from .cameras import Cameras
from .checks import SceneValidationError, check_estimates

__all__ = ["Person", "PERSON_FIELDS", "check_people"]

#: The per-frame fields a person has (each may be None).
PERSON_FIELDS = ("joints3d", "cameras", "keypoints2d", "keypoints_conf", "person_boxes")


@dataclass
class Person:
    """One person's estimates over a scene's T frames (no pixels of its own).

    track_id: the person's id, unique in the scene (kept through crossings by the tracker).
    joints3d (T, J, 3) mm camera frame with ``cameras``; keypoints2d (T, K, 2) px with
    keypoints_conf (T, K) in [0, 1] (0 = not found); person_boxes (T, 5): the person's box
    (x0, y0, x1, y1 px) and score in [0, 1] (0 = absent). Layouts: the scene's.
    """

    track_id: int = 0
    joints3d: torch.Tensor | None = None
    cameras: Cameras | None = None
    keypoints2d: torch.Tensor | None = None
    keypoints_conf: torch.Tensor | None = None
    person_boxes: torch.Tensor | None = None

    @classmethod
    def of(cls, owner: Any) -> Person:
        """The main person of ``owner`` (a Scene or PoseEstimates): its own fields."""
        return cls(track_id=int(owner.track_id), **{key: getattr(owner, key) for key in PERSON_FIELDS})

    def fields(self) -> dict[str, Any]:
        """The per-frame fields as a dict (for ``dataclasses.replace`` of a scene)."""
        return {key: getattr(self, key) for key in PERSON_FIELDS}

    def present(self) -> tuple[str, ...]:
        """The names of the fields that are not None."""
        return tuple(key for key in PERSON_FIELDS if getattr(self, key) is not None)

    def map(self, fn: Any) -> Person:
        """A copy with ``fn`` applied to every present tensor (cameras: to params and crops)."""
        out = {}
        for key in ("joints3d", "keypoints2d", "keypoints_conf", "person_boxes"):
            value = getattr(self, key)
            out[key] = None if value is None else fn(value)
        cams = self.cameras
        if cams is not None:
            crops = None if cams.crops is None else fn(cams.crops)
            out["cameras"] = Cameras(cams.model, fn(cams.params), crops, cams.crop_size)
        return dataclasses.replace(self, **out)

    def posed(self) -> torch.Tensor:
        """(T,) bool: frames where the person's pose was estimated, a keypoint of confidence > 0
        (every frame when there are no confidences). Elsewhere an estimator's 3D joints and
        camera are a neighbour frame's, filled in: no evidence of the pose in that frame."""
        if self.keypoints_conf is not None:
            return (self.keypoints_conf > 0).any(-1)
        pose = self.joints3d if self.joints3d is not None else self.keypoints2d
        if pose is not None:
            return torch.ones(pose.shape[0], dtype=torch.bool)
        return torch.zeros(self.person_boxes.shape[0], dtype=torch.bool)  # a box and no pose

    def found(self) -> torch.Tensor:
        """(T,) bool: frames where the person has a keypoint of confidence > 0 or a box."""
        T = next(getattr(self, k).shape[0] for k in ("keypoints_conf", "person_boxes", "joints3d")
                 if getattr(self, k) is not None)  # fmt: skip
        found = torch.zeros(T, dtype=torch.bool)
        if self.keypoints_conf is not None:
            found |= (self.keypoints_conf > 0).any(-1)
        if self.person_boxes is not None:
            found |= self.person_boxes[:, 4] > 0
        return found


def check_people(owner: str, main: Any, others: Sequence[Any], T: int) -> None:
    """Check ``others`` (a sequence of :class:`Person`) beside the main person of ``main`` (a
    Scene or PoseEstimates, whose layouts they share): the same fields present as the main
    person's, each for T frames, track ids unique. Errors name ``owner.others[i].field``."""
    if not isinstance(others, tuple):
        raise SceneValidationError(f"{owner}.others: expected a tuple of Person, got {type(others).__name__}")
    if isinstance(main.track_id, bool) or not isinstance(main.track_id, int) or main.track_id < 0:
        raise SceneValidationError(f"{owner}.track_id: expected an int >= 0, got {main.track_id!r}")
    ids = [main.track_id]
    want = Person.of(main).present()
    for i, person in enumerate(others):
        name = f"{owner}.others[{i}]"
        if not isinstance(person, Person):
            raise SceneValidationError(f"{name}: expected a lit_boot Person, got {type(person).__name__}")
        if isinstance(person.track_id, bool) or not isinstance(person.track_id, int) or person.track_id < 0:
            raise SceneValidationError(f"{name}.track_id: expected an int >= 0, got {person.track_id!r}")
        if person.present() != want:
            raise SceneValidationError(f"{name}: expected the main person's fields {list(want)}, got "
                                       f"{list(person.present())}")  # fmt: skip
        check_estimates(name, person, T, layouts=main)
        if person.cameras is not None and (person.cameras.model, person.cameras.params.shape[1]) != (
                main.cameras.model, main.cameras.params.shape[1]):  # fmt: skip
            raise SceneValidationError(f"{name}.cameras: expected the main person's camera model "
                                       f"{main.cameras.model!r}, got {person.cameras.model!r}")  # fmt: skip
        ids.append(person.track_id)
    if len(set(ids)) != len(ids):
        raise SceneValidationError(f"{owner}.others: track ids must be unique, got {ids}")
