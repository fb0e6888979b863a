"""What a scene's evidence lets a run do: the mode that runs, its stages, and one line that says
which and why (issue 57, "run what can run").

A scene may carry less than the requested mode works from. Each stage runs where its evidence
is:

- the zoom stage needs the person's box (a person detector's, or the box around a pose);
- the flow stages need a pose to draw the stick-man from, the pose stages one to refine: 3D
  joints with cameras in 3D mode, 2D keypoints in 2D mode. In 3D mode only the frames where
  the pose was estimated count (:meth:`~lit_boot.core.Person.posed`: elsewhere an estimator's
  joints are a neighbour frame's, filled in; the sketch does not draw them and the refiner does
  not hold them to the estimates).

So a 3D run on a scene with 2D keypoints and no 3D joints runs the 2D stages, and a scene whose
estimators found only the person's boxes runs the zoom stage alone. A run is refused only where
nothing can run: nobody found in any frame (:meth:`~lit_boot.core.Scene.require_pose`), or only
boxes with the zoom stage off.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

from ..core import Person, Scene
from .config import BootstrapConfig

__all__ = ["Plan", "plan_run"]


@dataclass(frozen=True)
class Plan:
    """What runs: ``mode`` ("3d" or "2d"), the stage names after the initial one, the mode the
    config asked for, and ``why``: one line for the console, summary.json and the report."""

    mode: str
    stages: tuple[str, ...]
    requested: str
    why: str

    def to_dict(self) -> dict[str, object]:
        return asdict(self)


def _frames(person: Person, what: str) -> int:
    """Frames with the pose (``what`` "pose") or with a box (``what`` "box")."""
    if what == "box":
        return int((person.person_boxes[:, 4] > 0).sum()) if person.person_boxes is not None else 0
    return int(person.posed().sum())


def plan_run(config: BootstrapConfig, scene: Scene) -> Plan:
    """The :class:`Plan` of ``config`` on ``scene`` (see the module doc). Raises ValueError naming
    the scene where nothing can run."""
    scene.require_pose("2d" if scene.keypoints2d is not None else config.mode)  # nobody at all: refused
    people = scene.people()
    T = scene.num_frames
    posed = max(_frames(p, "pose") for p in people)
    boxes = max(_frames(p, "box") for p in people)
    has_3d = scene.joints3d is not None and scene.cameras is not None and posed > 0
    has_2d = scene.keypoints2d is not None and posed > 0
    full = tuple(config.stages())
    if config.mode == "3d" and has_3d:
        filled = "" if posed == T else (f"; the other {T - posed} frames' joints are a neighbour's, filled in by the "
                                        "estimator: not drawn, not held to the estimates")  # fmt: skip
        return Plan("3d", full, "3d", f"3D mode: a 3D pose in {posed} of {T} frames{filled}")
    if has_2d:
        if config.mode == "2d":
            return Plan("2d", full, "2d", f"2D mode: 2D keypoints in {posed} of {T} frames")
        return Plan("2d", full, "3d", f"3D mode asked, but the scene has no 3D joints with cameras: the 2D stages run "
                                      f"on its 2D keypoints ({posed} of {T} frames)")  # fmt: skip
    if config.zooming == "off":
        raise ValueError(f"scene {scene.name!r}: no pose in any frame, only the person detector's boxes, and the zoom "
                         "stage (the one stage that works from boxes) is off: nothing can run")  # fmt: skip
    mode = "2d" if scene.keypoints2d is not None else config.mode
    return Plan(mode, ("zoom",), config.mode, f"no pose in any frame, only the person detector's boxes ({boxes} of "
                                              f"{T} frames): the zoom stage runs on them; the flow and pose stages "
                                              "need a pose")  # fmt: skip
