"""One task of a dataset run: one scene (or one chunk of a long one), as a JSON-ready spec.

A :class:`Task` names where its frames and poses come from (a scene folder, a video, or a scene
of a dataset a reader of :mod:`lit_boot.data.readers` knows) and, for a chunk, which frames;
:meth:`Task.load` reads it into a :class:`~lit_boot.core.Scene`. Tasks travel to worker
processes and Ray as plain dicts (:meth:`Task.to_dict`, :meth:`Task.from_dict`).
"""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass, field, replace
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ..core.scene import Scene

__all__ = ["Task", "KINDS", "READERS", "safe_name"]

#: Kinds of source -> what ``args`` holds: "scene" {"path"}; "video" {"path", and read_video's
#: options}; "sintel" / "3dpw" / "h36m": the reader's arguments (root, scene | sequence |
#: subject and action, ...).
KINDS = ("scene", "video", "sintel", "3dpw", "h36m")
#: Kind -> (module of lit_boot.data.readers, reader function) for the kinds a reader reads.
READERS = {"video": ("video", "read_video"), "sintel": ("sintel", "read_sintel"), "3dpw": ("pw3d", "read_3dpw"),
           "h36m": ("h36m", "read_h36m")}  # fmt: skip


def safe_name(text: str) -> str:
    """``text`` as a file name: runs of characters other than letters, digits, ``.``, ``-`` and
    ``_`` become ``_`` (e.g. "S9/Walking 1" -> "S9_Walking_1")."""
    name = re.sub(r"[^A-Za-z0-9._-]+", "_", text).strip("._")
    if not name:
        raise ValueError(f"{text!r}: gives an empty task name")
    return name


@dataclass(frozen=True)
class Task:
    """One scene of a dataset run.

    name: unique in the run, a file name (its run folder is ``<out>/scenes/<name>``); kind: one
    of :data:`KINDS`; args: the source's arguments (JSON values; paths as strings); poses: a
    pose file to attach (None: the source's own estimates, or MediaPipe Pose for a source
    without any); frames: [start, stop) of the source's frames for a chunk, None for all;
    parent: the whole scene's name when this task is a chunk of it.
    """

    name: str
    kind: str
    args: dict[str, Any] = field(default_factory=dict)
    poses: str | None = None
    frames: tuple[int, int] | None = None
    parent: str | None = None

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"task {self.name!r}: kind {self.kind!r} is not one of {', '.join(KINDS)}")
        if safe_name(self.name) != self.name:
            raise ValueError(f"task name {self.name!r}: use letters, digits, '.', '-' and '_' only")
        if self.frames is not None:
            start, stop = self.frames
            if not 0 <= start < stop:
                raise ValueError(f"task {self.name!r}: frames {self.frames} must be [start, stop) with 0 <= start < stop")

    @property
    def scene_name(self) -> str:
        """The whole scene's name (the parent's for a chunk)."""
        return self.parent or self.name

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (:meth:`from_dict` reads it back)."""
        out = asdict(self)
        out["frames"] = list(self.frames) if self.frames is not None else None
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Task:
        frames = data.get("frames")
        return cls(name=data["name"], kind=data["kind"], args=dict(data.get("args") or {}), poses=data.get("poses"),
                   frames=tuple(frames) if frames is not None else None, parent=data.get("parent"))  # fmt: skip

    def load(self, *, estimate: bool = True) -> Scene:
        """Read the task's scene: the source by kind ("scene": :func:`~lit_boot.data.load_scene`;
        the others: their reader with ``args``), then ``poses`` attached (any pose file
        :func:`~lit_boot.data.readers.read_estimates` reads; a scene with no pose file and no
        estimates of its own, e.g. a video or a Sintel scene, gets MediaPipe Pose, run on the
        task's frames only, unless ``estimate`` is False, e.g. to count the frames), then
        ``frames`` [start, stop) cut out
        (:func:`~lit_boot.dataset.chunks.slice_scene`). A video chunk decodes its own frames only
        (``read_video``'s ``first``); the other kinds read the whole scene, then cut.

        Raises ValueError naming the task for bad args or frames beyond the scene,
        :class:`~lit_boot.estimate.NoPersonFound` when MediaPipe finds nobody, and the readers'
        errors naming the file: FileNotFoundError (missing path), DatasetFormatError /
        SceneFormatError (unreadable or inconsistent file, bad video, poses not matching).
        """
        from .chunks import slice_scene

        scene = self._read()
        if self.frames is not None:
            start, stop = self.frames
            have = scene.num_frames + (start if self.kind == "video" else 0)  # a video chunk is read cut
            if stop > have:
                raise ValueError(f"task {self.name!r}: frames [{start}, {stop}) but the source has {have} frames")
            if self.kind == "video":
                scene = replace(scene, metadata={**scene.metadata, "chunk": {"start": start, "stop": stop}})
            else:
                scene = slice_scene(scene, start, stop)
        if estimate and self.poses is None and scene.keypoints2d is None and scene.joints3d is None:
            from ..estimate import estimate_poses, require_person

            est = require_person(estimate_poses(scene), f"task {self.name!r}")  # nobody: this task fails, named
            scene = est.apply_to(scene)  # rows matched by metadata["frame_indices"]
        return scene

    def num_frames(self) -> int:
        """The frames of the task's whole source scene (what :meth:`load` gives without
        ``frames``): a video's are counted without decoding them (see
        :func:`~lit_boot.data.readers.video.video_frame_count`); the other kinds are read."""
        if self.kind != "video":
            return self.load(estimate=False).num_frames
        from ..data.readers.video import video_frame_count

        return video_frame_count(**self.args)

    def _read(self) -> Scene:
        """The source's scene with ``poses`` attached (not cut; a video chunk: its own frames only)."""
        import importlib
        import inspect

        args = dict(self.args)
        if "poses" in args:
            raise ValueError(f"task {self.name!r}: give the pose file as Task.poses, not in args")
        if self.kind == "scene":
            if set(args) != {"path"}:
                raise ValueError(f"task {self.name!r}: kind 'scene' takes args {{'path'}}, got {sorted(args)}")
            from ..data.scene_io import load_scene

            return self._attach(load_scene(args["path"]))
        module, name = READERS[self.kind]
        reader = getattr(importlib.import_module(f"lit_boot.data.readers.{module}"), name)
        try:
            inspect.signature(reader).bind(**args)
        except TypeError as err:
            raise ValueError(f"task {self.name!r}: args {sorted(args)} do not fit {name}: {err}") from None
        if self.kind != "video":
            return self._attach(reader(**args))
        if self.frames is not None:  # decode the chunk's frames only
            start, stop = self.frames
            cap, first, stride = args.get("max_frames"), args.get("first", 0), args.get("stride", 1)
            args["first"] = first + start * stride  # a source frame
            args["max_frames"] = stop - start if cap is None else max(1, min(cap, stop) - start)
        return reader(**args, poses=self.poses)  # read_video selects and checks the pose rows itself

    def _attach(self, scene: Scene) -> Scene:
        """``scene`` with the pose file ``poses`` applied (unchanged without one)."""
        if self.poses is None:
            return scene
        from ..core.scene import SceneValidationError
        from ..data.readers import DatasetFormatError, read_estimates

        try:
            return read_estimates(self.poses).apply_to(scene)
        except SceneValidationError as err:
            raise DatasetFormatError(f"{self.poses}: {err}") from None
