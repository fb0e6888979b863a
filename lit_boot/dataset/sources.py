"""Discovery: the scenes of a dataset, a folder of videos or a user's list, as :class:`Task` s.

Every function returns tasks with unique names (:func:`~lit_boot.dataset.tasks.safe_name` of
the scene, sequence, action or file; a clash gets ``_2``, ``_3``, ...) and absolute paths in
their args. ``reader_args`` (JSON values) go to every task's reader (e.g. ``{"size": [218,
512]}`` for Sintel, ``{"resize": 360}`` for videos). A missing folder raises
FileNotFoundError, a folder with nothing of the expected kind ValueError, both naming the path
and what was expected. Only folder listings are read here (and, for 3DPW and Human3.6M, the
annotation files that list persons / actions); frames are read by :meth:`Task.load`.
"""

from __future__ import annotations

import dataclasses
import inspect
import json
import os
import re
import shlex
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from ..core.frame_runs import frame_runs
from .tasks import Task, safe_name

__all__ = [
    "SOURCES",
    "VIDEO_SUFFIXES",
    "discover",
    "h36m_tasks",
    "manifest_tasks",
    "pw3d_tasks",
    "scene_tasks",
    "sintel_tasks",
    "video_tasks",
    "with_pose_files",
]

#: Video file suffixes (OpenCV reads them), compared case-insensitively.
VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".webm")
#: Pose files found beside a video (same stem).
POSE_SUFFIXES = (".npz", ".json")
#: Sources of :func:`discover`; those whose functions take ``reader_args``.
SOURCES = ("sintel", "3dpw", "h36m", "videos", "list", "scenes")
READER_SOURCES = ("sintel", "3dpw", "h36m", "videos")
#: Task args that hold paths (made absolute, relative to a list file's folder).
PATH_ARGS = ("path", "root", "video", "positions_3d", "positions_2d")
_SINTEL_FRAME = re.compile(r"^frame_(\d+)\.png$")


def _absolute(path: str | os.PathLike) -> Path:
    """``path`` absolute and normalised ("a/../b" -> "b"), "~" expanded."""
    return Path(os.path.abspath(Path(path).expanduser()))


def _folder(path: str | os.PathLike, what: str) -> Path:
    path = _absolute(path)
    if not path.is_dir():
        raise FileNotFoundError(f"{path}: no such folder (expected {what})")
    return path


def _unique(names: Iterable[str]) -> list[str]:
    """Safe, unique names: the n-th repeat of a name gets ``_n``."""
    out: list[str] = []
    for name in names:
        base = safe_name(name)
        name, n = base, 1
        while name in out:
            n += 1
            name = f"{base}_{n}"
        out.append(name)
    return out


def _tasks(kind: str, items: list[tuple[str, dict[str, Any], str | None]], where: Path, what: str) -> list[Task]:
    """Tasks of ``kind`` from (name, args, poses); ValueError naming ``where`` when empty."""
    if not items:
        raise ValueError(f"{where}: found no {what}")
    names = _unique(name for name, _, _ in items)
    return [Task(name, kind, args, poses) for name, (_, args, poses) in zip(names, items)]


def _select(available: Sequence[str], wanted: Iterable[str] | None, where: Path, what: str) -> list[str]:
    """``wanted`` (all when None), each checked to be among ``available``."""
    if wanted is None:
        return list(available)
    wanted = [wanted] if isinstance(wanted, str) else list(wanted)
    missing = [w for w in wanted if w not in available]
    if missing:
        raise FileNotFoundError(f"{where}: no {what} {missing}; it holds {list(available)}")
    return wanted


def sintel_tasks(
    root: str | os.PathLike,
    scenes: str | Iterable[str] | None = None,
    pass_name: str = "final",
    reader_args: dict[str, Any] | None = None,
) -> list[Task]:
    """One "sintel" task per scene folder of ``root``/training/``pass_name``: all (None), the
    given names, or "human": the paper's human subset present
    (:data:`lit_boot.data.readers.SINTEL_HUMAN_SCENES`). A scene whose frame
    numbers have gaps (a partial copy) gives one task per run of consecutive frames (args
    first / last; named ``<scene>_<first>-<last>``)."""
    if pass_name not in ("clean", "final"):
        raise ValueError(f"pass_name: expected 'clean' or 'final', got {pass_name!r}")
    folder = _folder(Path(root) / "training" / pass_name, f"an MPI-Sintel root holding training/{pass_name}/<scene>/")
    available = sorted(p.name for p in folder.iterdir() if p.is_dir())
    if scenes == "human":
        from ..data.readers.sintel import SINTEL_HUMAN_SCENES

        chosen = [s for s in SINTEL_HUMAN_SCENES if s in available]
        if not chosen:
            raise ValueError(f"{folder}: none of the human scenes {list(SINTEL_HUMAN_SCENES)}; it holds {available}")
    else:
        chosen = _select(available, scenes, folder, "Sintel scene")
    items = []
    for scene in chosen:
        numbers = sorted(int(m.group(1)) for p in (folder / scene).iterdir() if (m := _SINTEL_FRAME.match(p.name)))
        args = {"root": str(_absolute(root)), "scene": scene, "pass_name": pass_name, **(reader_args or {})}
        runs = frame_runs(numbers)
        for first, last in runs:
            window = {} if len(runs) == 1 else {"first": first, "last": last}
            name = scene if len(runs) == 1 else f"{scene}_{first:04d}-{last:04d}"
            items.append((name, {**args, **window}, None))
    return _tasks("sintel", items, folder, "Sintel scene with frame_NNNN.png frames")


def pw3d_tasks(
    root: str | os.PathLike,
    split: str | None = "test",
    sequences: Iterable[str] | None = None,
    persons: str | int | Iterable[int] = "all",
    reader_args: dict[str, Any] | None = None,
) -> list[Task]:
    """One "3dpw" task per (sequence, person) of ``split`` (None: train, validation and test)
    under ``root``/sequenceFiles/<split>/<sequence>.pkl, named ``<sequence>_p<person>``.
    ``persons``: "all" (every person the sequence's pickle annotates: the standard test set's
    35K frames count them all), or the person numbers to take."""
    from ..data.readers.pw3d import PW3D_SPLITS, load_3dpw_pickle

    root = _folder(root, "a 3DPW root holding sequenceFiles/<split>/<sequence>.pkl")
    base = _folder(root / "sequenceFiles", "a 3DPW root holding sequenceFiles/<split>/<sequence>.pkl")
    if split is not None and split not in PW3D_SPLITS:
        raise ValueError(f"split: expected one of {PW3D_SPLITS} or None, got {split!r}")
    if isinstance(persons, str) and persons != "all":
        raise ValueError(f"persons: expected 'all', a person number or a list of them, got {persons!r}")
    files = {p.stem: p for s in (PW3D_SPLITS if split is None else (split,)) if (base / s).is_dir()
             for p in sorted((base / s).glob("*.pkl"))}  # fmt: skip
    items = []
    for sequence in _select(sorted(files), sequences, base, "3DPW sequence"):
        if persons == "all":
            chosen = range(len(load_3dpw_pickle(files[sequence])["jointPositions"]))
        else:
            chosen = [persons] if isinstance(persons, int) else list(persons)
        for person in chosen:
            args = {"root": str(root), "sequence": sequence, "split": files[sequence].parent.name,
                    "person": int(person), **(reader_args or {})}  # fmt: skip
            items.append((f"{sequence}_p{person}", args, None))
    return _tasks("3dpw", items, base / split if split else base, "3DPW sequence (<sequence>.pkl)")


def h36m_tasks(
    root: str | os.PathLike,
    subjects: Iterable[str] = ("S9", "S11"),
    actions: Iterable[str] | None = None,
    reader_args: dict[str, Any] | None = None,
) -> list[Task]:
    """One "h36m" task per (subject, action), the paper's protocol by default (subjects S9 and
    S11; the reader's camera 60457274, every 5th frame), named ``<subject>_<action>``.
    ``actions`` None: every action of the subject in ``root``/data_3d_h36m.npz (or
    ``reader_args["positions_3d"]``). The frames of each (``root``/<subject>/Videos/<action>.
    <camera>.mp4 or that folder without .mp4) must exist: FileNotFoundError lists those missing
    (choose ``actions`` to run on part of the dataset)."""
    from ..data.readers.h36m import H36M_EVAL_CAMERA, list_h36m_actions

    root = _folder(root, "a Human3.6M root holding data_3d_h36m.npz, data_2d_h36m_gt.npz and <subject>/Videos/")
    reader_args = dict(reader_args or {})
    camera = reader_args.get("camera", H36M_EVAL_CAMERA)
    items, missing = [], []
    for subject in [subjects] if isinstance(subjects, str) else subjects:
        have = list_h36m_actions(root, subject, positions_3d=reader_args.get("positions_3d"))
        for action in _select(have, actions, root / "data_3d_h36m.npz", f"{subject} action"):
            video = root / subject / "Videos" / f"{action}.{camera}.mp4"
            if "video" not in reader_args and not video.exists() and not video.with_suffix("").is_dir():
                missing.append(str(video))
            args = {"root": str(root), "subject": subject, "action": action, **reader_args}
            items.append((f"{subject}_{action}", args, None))
    if missing:
        more = f" and {len(missing) - 3} more" if len(missing) > 3 else ""
        raise FileNotFoundError(f"{root}: no frames for {missing[:3]}{more} (a video, or that folder without "
                                ".mp4); pass actions to choose those present")  # fmt: skip
    return _tasks("h36m", items, root, "Human3.6M action")


def _pose_file(path: Path) -> str | None:
    """The pose file beside ``path`` with its stem (a folder: its name) and suffix .npz or
    .json, None without one."""
    stem = path.stem if path.is_file() else path.name
    found = [path.with_name(stem + s) for s in POSE_SUFFIXES if path.with_name(stem + s).is_file()]
    if len(found) > 1:
        raise ValueError(f"{path}: two pose files beside it, {[str(f) for f in found]}; keep one")
    return str(found[0]) if found else None


def video_tasks(folder: str | os.PathLike, reader_args: dict[str, Any] | None = None) -> list[Task]:
    """One "video" task per video file of ``folder`` (:data:`VIDEO_SUFFIXES`, any case) and per
    sub-folder holding image frames, named after its stem; a pose file with the same stem beside
    it (``clip.npz`` or ``clip.json`` for ``clip.mp4`` or ``clip/``) becomes its ``poses``."""
    from ..data.readers.video import IMAGE_SUFFIXES

    folder = _folder(folder, "a folder of videos (" + ", ".join(VIDEO_SUFFIXES) + ") or of frame folders")
    items = []
    for path in sorted(folder.iterdir()):
        if path.name.startswith("."):
            continue
        is_video = path.is_file() and path.suffix.lower() in VIDEO_SUFFIXES
        is_frames = path.is_dir() and any(p.suffix.lower() in IMAGE_SUFFIXES for p in path.iterdir() if p.is_file())
        if is_video or is_frames:
            name = path.stem if is_video else path.name
            items.append((name, {"path": str(path), **(reader_args or {})}, _pose_file(path)))
    return _tasks("video", items, folder, "video file (" + ", ".join(VIDEO_SUFFIXES) + ") or folder of frames")


def scene_tasks(folder: str | os.PathLike) -> list[Task]:
    """One "scene" task per sub-folder of ``folder`` that is a saved lit-boot scene (holds a
    scene.json, :func:`~lit_boot.data.save_scene`), named after it; other entries are skipped."""
    folder = _folder(folder, "a folder of lit-boot scene folders")
    items = [(p.name, {"path": str(p)}, None) for p in sorted(folder.iterdir())
             if p.is_dir() and not p.name.startswith(".") and (p / "scene.json").is_file()]  # fmt: skip
    return _tasks("scene", items, folder, "scene folder (a sub-folder holding scene.json)")


def _resolve(value: Any, base: Path) -> Any:
    return str(_absolute(base / Path(value).expanduser())) if isinstance(value, (str, os.PathLike)) else value


def _source_task(path: Path, poses: str | None) -> tuple[str, dict[str, Any], str | None, str]:
    """(name, args, poses, kind) of a scene folder, a video file or a folder of frames."""
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such scene folder, video or folder of frames")
    if path.is_dir() and (path / "scene.json").is_file():
        return path.name, {"path": str(path)}, poses, "scene"
    return (path.stem if path.is_file() else path.name), {"path": str(path)}, poses, "video"


def _text_manifest(path: Path) -> list[Task]:
    items = []
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        try:
            columns = shlex.split(re.sub(r"(^|\s)#.*$", "", line))  # '#' starts a comment after a space
        except ValueError as err:
            raise ValueError(f"{path}:{number}: {err}") from None
        if not columns:
            continue
        if len(columns) > 2:
            raise ValueError(f"{path}:{number}: expected 'PATH [POSE_FILE]', got {len(columns)} columns")
        poses = _resolve(columns[1], path.parent) if len(columns) == 2 else None
        if poses is not None and not Path(poses).exists():
            raise FileNotFoundError(f"{path}:{number}: no such pose file {poses}")
        try:
            items.append(_source_task(Path(_resolve(columns[0], path.parent)), poses))
        except FileNotFoundError as err:
            raise FileNotFoundError(f"{path}:{number}: {err}") from None
    if not items:
        raise ValueError(f"{path}: lists no scene (expected lines 'PATH [POSE_FILE]')")
    names = _unique(name for name, _, _, _ in items)
    return [Task(name, kind, args, poses) for name, (_, args, poses, kind) in zip(names, items)]


def _dict_manifest(path: Path) -> list[Task]:
    try:
        if path.suffix.lower() == ".json":
            data = json.loads(path.read_text(encoding="utf-8"))
        else:
            import yaml

            data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except Exception as err:  # json / yaml raise many kinds of errors
        raise ValueError(f"{path}: unreadable {path.suffix[1:].upper()}: {err}") from None
    if not isinstance(data, list) or not all(isinstance(d, dict) for d in data):
        raise ValueError(f"{path}: expected a list of task dicts (name, kind, args, poses, frames)")
    tasks = []
    for i, entry in enumerate(data):
        try:
            task = Task.from_dict(entry)
        except (KeyError, TypeError, ValueError) as err:
            raise ValueError(f"{path}: task {i}: {type(err).__name__}: {err}") from None
        args = {k: _resolve(v, path.parent) if k in PATH_ARGS else v for k, v in task.args.items()}
        poses = None if task.poses is None else _resolve(task.poses, path.parent)
        tasks.append(Task(task.name, task.kind, args, poses, task.frames, task.parent))
    names = [t.name for t in tasks]
    if len(set(names)) != len(names):
        raise ValueError(f"{path}: task names repeat: {sorted({n for n in names if names.count(n) > 1})}")
    if not tasks:
        raise ValueError(f"{path}: lists no task")
    return tasks


def manifest_tasks(path: str | os.PathLike) -> list[Task]:
    """Tasks from a user's list. A text file: one scene a line, ``PATH [POSE_FILE]``
    (whitespace-separated, shell quoting for spaces; ``#`` starts a comment at a line's start or
    after a space), PATH a lit-boot scene folder ("scene") or a video file / folder of frames
    ("video"). A .json / .yaml / .yml file: a list of :meth:`Task.to_dict` dicts. Relative paths
    are relative to the list file's folder."""
    path = _absolute(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such list file (expected a text, JSON or YAML list of scenes)")
    if path.suffix.lower() in (".json", ".yaml", ".yml"):
        return _dict_manifest(path)
    return _text_manifest(path)


def discover(source: str, path: str | os.PathLike, poses: str | os.PathLike | None = None, **options: Any) -> list[Task]:
    """The tasks of ``source`` at ``path``: "sintel" (:func:`sintel_tasks`), "3dpw"
    (:func:`pw3d_tasks`), "h36m" (:func:`h36m_tasks`), "videos" (:func:`video_tasks`), "list"
    (:func:`manifest_tasks`) or "scenes" (:func:`scene_tasks`); ``options`` go to that function.
    ``poses``: a folder of pose files named after the tasks (see :func:`with_pose_files`)."""
    functions = {"sintel": sintel_tasks, "3dpw": pw3d_tasks, "h36m": h36m_tasks, "videos": video_tasks,
                 "list": manifest_tasks, "scenes": scene_tasks}  # fmt: skip
    if source not in functions:
        raise ValueError(f"source: expected one of {SOURCES}, got {source!r}")
    try:
        inspect.signature(functions[source]).bind(path, **options)
    except TypeError as err:
        raise ValueError(f"discover {source!r}: bad options {sorted(options)}: {err}") from None
    tasks = functions[source](path, **options)
    return with_pose_files(tasks, poses) if poses is not None else tasks


def with_pose_files(tasks: list[Task], folder: str | os.PathLike) -> list[Task]:
    """``tasks`` with the pose file ``<folder>/<task name>.npz`` or ``.json`` (or a folder
    ``<folder>/<task name>/`` of per-frame files, e.g. METRO's) as their ``poses``, where one
    exists; the others unchanged. FileNotFoundError if ``folder`` is missing, ValueError if it
    holds no pose file of any task."""
    folder = _folder(folder, "a folder of pose files named after the scenes")
    out, found = [], 0
    for task in tasks:
        candidates = [folder / f"{task.name}{suffix}" for suffix in POSE_SUFFIXES] + [folder / task.name]
        match = next((c for c in candidates if c.exists()), None)
        found += match is not None
        out.append(dataclasses.replace(task, poses=str(match)) if match is not None else task)
    if tasks and not found:
        names = ", ".join(t.name for t in tasks[:3]) + (", ..." if len(tasks) > 3 else "")
        raise ValueError(f"{folder}: no pose file named after any scene (expected e.g. {tasks[0].name}.npz; scenes: {names})")
    return out
