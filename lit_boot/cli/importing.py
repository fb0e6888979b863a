"""Data in: ``lit-boot import KIND ... --out DIR`` (a dataset scene or a video as a lit-boot scene
folder) and ``lit-boot estimate-pose VIDEO --out FILE`` (MediaPipe Pose to a pose file).

Kinds of ``import`` and their readers (every reader argument is a flag; positional ones come first):

- ``sintel ROOT SCENE``: :func:`lit_boot.data.readers.read_sintel` (frames + GT flow)
- ``3dpw ROOT SEQUENCE``: :func:`lit_boot.data.readers.read_3dpw` (frames, OpenPose keypoints, GT)
- ``h36m ROOT SUBJECT ACTION``: :func:`lit_boot.data.readers.read_h36m` (the paper's protocol)
- ``video PATH``: :func:`lit_boot.data.readers.read_video` (an mp4 or a folder of frames)

``--poses FILE`` attaches pose estimates to the scene (our npz/JSON, METRO, DCPose or COCO
JSON; see :func:`lit_boot.data.readers.read_estimates`); ``--estimate true`` runs MediaPipe
Pose on the frames instead (the ``mediapipe`` extra). The folder is what ``lit-boot bootstrap
--data.scene`` reads.

A kind's description is its reader's first docstring paragraph, read from the source file, so
``lit-boot import --help`` imports no reader (nor torch); only the chosen kind's reader is
imported, for its arguments.
"""

from __future__ import annotations

import ast
import importlib
from collections.abc import Iterable
from functools import cache
from pathlib import Path
from typing import Any, Callable

from .checks import check_input_paths, check_video_options
from .console import ArgumentParser, CliError, drop_native_noise, plain, refuse_to_overwrite, set_help

__all__ = ["import_scene", "import_parser", "estimate_pose", "estimate_pose_parser", "with_poses", "KINDS"]

#: Kind -> (module in lit_boot.data.readers, reader function).
KINDS = {"sintel": ("sintel", "read_sintel"), "3dpw": ("pw3d", "read_3dpw"), "h36m": ("h36m", "read_h36m"),
         "video": ("video", "read_video")}  # fmt: skip

_RANGE = "(inclusive; default: all)"
#: Help of the readers' arguments (their docstrings describe them in prose, not per argument).
ARG_HELP: dict[str, str] = {
    "root": "the dataset's root folder",
    "scene": "Sintel scene name (e.g. alley_1)",
    "pass_name": "Sintel pass: final or clean",
    "sequence": "3DPW sequence name (e.g. downtown_walking_00)",
    "person": "which person of the sequence (0-based), or all: every person (the others in the scene's others)",
    "split": "train, validation or test (default: search all three)",
    "invalid": "frames whose GT is not aligned to the image: drop them, keep them, or error",
    "subject": "Human3.6M subject (e.g. S9)",
    "action": 'action name (e.g. "Walking 1")',
    "camera": "camera id (default: the paper's evaluation camera)",
    "camera_params": "camera calibration (default: the built-in one for the subject and camera)",
    "video": "the video file or frame folder (default: the standard path under root)",
    "positions_3d": "3D joints npz (default: the standard path under root)",
    "positions_2d": "2D joints npz (default: the standard path under root)",
    "path": "a video file (mp4, anything OpenCV reads) or a folder of frames",
    "first": f"first frame, 0-based {_RANGE}",
    "last": f"last frame, 0-based {_RANGE}",
    "stride": "keep every N-th frame",
    "max_frames": "keep at most N frames",
    "size": "resize to [height, width] px",
    "resize": "resize: a height in px (int), a scale (float) or [height, width]",
    "fps": "the source's frame rate (default: the file's; 30 for a folder)",
}
ARG_HELP_BY_KIND = {
    "sintel": {"first": f"first frame number, from 1 {_RANGE}", "last": f"last frame number {_RANGE}"},
    "3dpw": {"joints_layout": "layout of the GT joints: lsp14 (the paper's 14) or smpl (24)"},
    "video": {"first": "first source frame, 0-based (the frames before are not decoded; default: 0)"},
    "h36m": {"joints_layout": "layout of the GT joints: lsp14 (the paper's 14) or h36m17"},
}


def _reader(kind: str) -> Callable[..., Any]:
    module, name = KINDS[kind]
    return getattr(importlib.import_module(f"lit_boot.data.readers.{module}"), name)


@cache
def describe(kind: str) -> str:
    """The first paragraph of ``kind``'s reader docstring, one line, without reST markup (read
    from the source, importing nothing)."""
    module, name = KINDS[kind]
    source = (Path(__file__).parents[1] / "data" / "readers" / f"{module}.py").read_text(encoding="utf-8")
    node = next(n for n in ast.walk(ast.parse(source)) if isinstance(n, ast.FunctionDef) and n.name == name)
    return plain(" ".join((ast.get_docstring(node) or "").split("\n\n", 1)[0].split()))


def import_parser(kinds: Iterable[str] | None = None) -> ArgumentParser:
    """The parser of ``lit-boot import``: one subcommand per reader; ``kinds`` (default: all)
    get their reader's arguments, the others are only listed (their readers not imported)."""
    full = set(KINDS if kinds is None else kinds)
    parser = ArgumentParser(prog="lit-boot import", description="Read a dataset scene or a video into a scene folder.")
    subcommands = parser.add_subcommands(dest="kind")
    for kind in KINDS:
        sub = ArgumentParser(description=describe(kind))
        if kind in full:
            _add_reader_arguments(sub, kind)
        sub.add_argument("--poses", type=Path | None, default=None, help="pose estimates to attach (file)")
        sub.add_argument("--estimate", type=bool, default=False, help="estimate poses with MediaPipe Pose")
        sub.add_argument("--detector", type=str | None, default=None,
                         help="with --estimate: a YOLOX person detector (yolox_nano, looked up in checkpoints/, or "
                              "an .onnx path) for the person's box in every frame, where the method zooms")  # fmt: skip
        sub.add_argument("--people", type=str | None, default=None,
                         help="with --estimate: all, largest or a number N: a pose for every person the detector "
                              "tracks (top-down; --detector defaults to yolox_nano); with --poses (COCO keypoints, "
                              "DCPose): every person of the file, linked by its track ids or the tracker; unset: one "
                              "person")  # fmt: skip
        sub.add_argument("--pose_model", type=str | None, default=None,
                         help="with --estimate: a top-down SimCC pose model exported to ONNX (RTMPose's; a local "
                              ".onnx path) in MediaPipe's place on each person's crops, 2D keypoints only")  # fmt: skip
        sub.add_argument("--out", type=Path, required=True, help="scene folder to write")
        sub.add_argument("--overwrite", type=bool, default=False, help="replace an existing scene folder")
        subcommands.add_subcommand(kind, sub, help=describe(kind))
    return parser


def _add_reader_arguments(parser: ArgumentParser, kind: str) -> None:
    parser.add_function_arguments(_reader(kind), nested_key=None, as_positional=True, as_group=False, skip={"poses"})
    set_help(parser, {**ARG_HELP, **ARG_HELP_BY_KIND.get(kind, {})})  # the readers' docstrings are prose, no "Args:"


def with_poses(scene, poses: Path | None, estimate: bool, detector: str | None = None, people: str | None = None,
               pose_model: str | None = None):  # fmt: skip
    """``scene`` with estimates from the file ``poses`` or from MediaPipe (``estimate``, with the
    person ``detector``'s boxes when given, for every tracked person with ``people``; with
    ``pose_model``, that ONNX model in MediaPipe's place; a scene in which nobody is found raises
    :class:`~lit_boot.estimate.NoPersonFound`)."""
    if message := estimate_options_error(poses, estimate, detector, people, pose_model):
        raise ValueError(message)
    _check_pose_model(pose_model)
    if poses is not None and estimate:
        raise ValueError("--poses and --estimate: give one of them, not both")
    if poses is not None:
        return read_pose_file(poses, people).apply_to(scene)
    if estimate:
        from ..estimate import estimate_poses, require_person

        with drop_native_noise():  # MediaPipe's native start-up lines
            est = estimate_poses(scene.frames, detector=detector, people=people, pose_model=pose_model)
        return require_person(est, f"scene {scene.name!r}").apply_to(scene)  # nobody: no pose to bootstrap
    return scene


def estimate_options_error(poses: Path | None, estimate: bool, detector: str | None, people: str | None,
                           pose_model: str | None) -> str | None:  # fmt: skip
    """What is wrong with options that need ``--estimate true`` given without it, else None."""
    if estimate:
        return None
    if pose_model is not None:
        return "--pose_model: needs --estimate true (it estimates the poses in MediaPipe's place)"
    if detector is not None:
        return "--detector: needs --estimate true (it adds the person's boxes to the estimated poses)"
    if people is not None and poses is None:
        return "--people: needs --estimate true or --poses (every person's pose comes from one of them)"
    return None


def read_pose_file(poses: Path, people: str | None):
    """The estimates of the file ``poses``: with ``people``, every person of a COCO keypoint or
    DCPose file (:func:`~lit_boot.estimate.read_tracked_estimates`), else one."""
    if people is None:
        from ..data.readers import read_estimates

        return read_estimates(poses)
    from ..estimate import read_tracked_estimates

    return read_tracked_estimates(poses, people=people)


def import_scene(argv: list[str]) -> int:
    """``lit-boot import``: read, attach poses, save the scene folder, print its summary."""
    args = import_parser([argv[0]] if argv[:1] and argv[0] in KINDS else []).parse_args(argv)
    options = dict(vars(args[args.kind]))
    if args.kind == "video":  # before torch is imported
        check_video_options("", options["stride"], options["max_frames"], options["resize"])
        if not Path(options["path"]).exists():
            raise CliError(f"PATH {options['path']}: no such video file or folder of frames")
        check_input_paths(None, None, options["poses"], prefix="")
    from ..data import save_scene

    poses, estimate, detector = options.pop("poses"), options.pop("estimate"), options.pop("detector")
    people, pose_model = options.pop("people"), options.pop("pose_model")
    if people is not None:
        _check_people(people)
    out, overwrite = options.pop("out"), options.pop("overwrite")
    refuse_to_overwrite(out, overwrite)
    if args.kind == "video" and not estimate:  # read_video selects and checks the pose rows itself
        if message := estimate_options_error(poses, estimate, detector, people, pose_model):
            raise CliError(message)
        if people is not None:  # every person of the file; else read_video reads it (its errors name the file)
            poses = read_pose_file(poses, people)
        scene = _reader("video")(**options, poses=poses)
    else:
        scene = with_poses(_reader(args.kind)(**options), poses, estimate, detector, people, pose_model)
    save_scene(scene, out, overwrite=overwrite)
    print(scene.summary())
    from ..estimate import checks_line, scene_checks

    if line := checks_line(scene_checks(scene)):
        print(f"  {line}")
    print(f"wrote {out}")
    return 0


def estimate_pose_parser() -> ArgumentParser:
    """The parser of ``lit-boot estimate-pose``. Its options are written out here, not read from
    :func:`lit_boot.estimate.estimate_poses`'s signature: that module imports torch, and the
    help must not."""
    parser = ArgumentParser(prog="lit-boot estimate-pose", description=(
        "Estimate the pose of one person (with --people: of every person) in every frame of a video with "
        'MediaPipe Pose (pip install "lit-boot[mediapipe]"): COCO-17 keypoints, LSP-14 3D joints and '
        "weak-perspective cameras."))  # fmt: skip
    parser.add_argument("video", type=Path, help="a video file (e.g. .mp4) or a folder of frames")
    parser.add_argument("--out", type=Path, required=True, help="pose file to write (.npz or .json)")
    parser.add_argument("--stride", type=int, default=1, help="use every N-th frame")
    parser.add_argument("--max_frames", type=int | None, default=None, help="use at most N frames")
    parser.add_argument("--resize", type=int | float | None, default=None,
                        help="resize frames first: a height in px (int, e.g. 360) or a scale (float, e.g. 0.5)")  # fmt: skip
    parser.add_argument("--model_complexity", type=int, default=1,
                        help="0, 1 or 2 (only 1 ships with mediapipe; 0 and 2 are downloaded on first use)")  # fmt: skip
    parser.add_argument("--min_detection_confidence", type=float, default=0.5,
                        help="MediaPipe's person detector threshold")  # fmt: skip
    parser.add_argument("--on_jump", type=str, default="keep", help="keep or drop detections that jump")
    parser.add_argument("--detector", type=str | None, default=None,
                        help="a YOLOX person detector (yolox_nano, looked up in checkpoints/, or an .onnx path): "
                             "adds the person's box in every frame, where the method zooms (needs no keypoints)")  # fmt: skip
    parser.add_argument("--people", type=str | None, default=None,
                        help="all, largest or a number N: a pose for every person the detector tracks (top-down: "
                             "MediaPipe on each person's crops; --detector defaults to yolox_nano), the most "
                             "prominent first; unset: one person, MediaPipe on the whole frames")  # fmt: skip
    parser.add_argument("--pose_model", type=str | None, default=None,
                        help="a top-down pose model exported to ONNX with a SimCC head (RTMPose's; a local .onnx "
                             "path) in MediaPipe's place on each person's crops: 2D keypoints only (bootstrap with "
                             "--mode 2d); --people defaults to largest")  # fmt: skip
    parser.add_argument("--overwrite", type=bool, nargs="?", const=True, default=False, help="replace --out")
    return parser


def estimate_pose(argv: list[str]) -> int:
    """``lit-boot estimate-pose``: MediaPipe Pose on a video -> pose file; one summary line."""
    args = estimate_pose_parser().parse_args(argv)
    check_video_options("", args.stride, args.max_frames, args.resize)  # before torch is imported
    if not args.video.exists():
        raise CliError(f"VIDEO {args.video}: no such video file or folder of frames")
    if args.people is not None:
        _check_people(args.people)
    _check_pose_model(args.pose_model)
    from ..estimate import MediaPipeUnavailable, OnnxRuntimeUnavailable, estimate_pose_file

    options = {k: v for k, v in vars(args).items() if k not in ("video", "out", "overwrite")}
    try:
        with drop_native_noise():
            _, summary = estimate_pose_file(args.video, args.out, overwrite=args.overwrite, **options)
    except (MediaPipeUnavailable, OnnxRuntimeUnavailable) as err:
        raise CliError(str(err)) from None
    print(f"{summary}; wrote {args.out}")
    return 0


def _check_pose_model(pose_model: str | None) -> None:
    """CliError unless --pose_model is unset or an existing file (checked before torch is imported)."""
    if pose_model is not None and not Path(pose_model).is_file():
        raise CliError(f"--pose_model {pose_model}: no such file (a SimCC pose model exported to ONNX)")


def _check_people(people: str) -> None:
    """CliError unless --people is all, largest or a number >= 1 (checked before torch is imported)."""
    if people not in ("all", "largest") and not (people.isdigit() and int(people) >= 1):
        raise CliError(f"--people: expected all, largest or a number of people >= 1, got {people!r}")
