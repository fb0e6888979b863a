"""``lit-boot import KIND ... --out DIR``: a dataset scene or a video as a lit-boot scene folder.

Kinds and their readers (every reader argument is a flag; positional ones come first):

- ``sintel ROOT SCENE``: :func:`lit_boot.data.readers.read_sintel` (frames + GT flow)
- ``3dpw ROOT SEQUENCE``: :func:`lit_boot.data.readers.read_3dpw` (frames, OpenPose keypoints, GT)
- ``h36m ROOT SUBJECT ACTION``: :func:`lit_boot.data.readers.read_h36m` (the paper's protocol)
- ``video PATH``: :func:`lit_boot.data.readers.read_video` (an mp4 or a folder of frames)

``--poses FILE`` attaches pose estimates to the scene (our npz/JSON, METRO, DCPose or COCO
JSON; see :func:`lit_boot.data.readers.read_estimates`); ``--estimate true`` runs MediaPipe
Pose on the frames instead (the ``mediapipe`` extra). The folder is what ``lit-boot bootstrap
--data.scene`` reads.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

from jsonargparse import ArgumentParser

__all__ = ["import_scene", "import_parser"]


def _readers() -> dict[str, Callable[..., Any]]:
    from .data.readers import read_3dpw, read_h36m, read_sintel, read_video

    return {"sintel": read_sintel, "3dpw": read_3dpw, "h36m": read_h36m, "video": read_video}


def import_parser() -> ArgumentParser:
    """The parser of ``lit-boot import``: one subcommand per reader."""
    parser = ArgumentParser(prog="lit-boot import", description="Read a dataset scene or a video into a scene folder.")
    kinds = parser.add_subcommands(dest="kind")
    for kind, reader in _readers().items():
        sub = ArgumentParser(description=(reader.__doc__ or "").strip().splitlines()[0])
        sub.add_function_arguments(reader, nested_key=None, as_positional=True, skip={"poses"})
        sub.add_argument("--poses", type=Path | None, default=None, help="pose estimates to attach (file)")
        sub.add_argument("--estimate", type=bool, default=False, help="estimate poses with MediaPipe Pose")
        sub.add_argument("--out", type=Path, required=True, help="scene folder to write")
        sub.add_argument("--overwrite", type=bool, default=False, help="replace an existing scene folder")
        kinds.add_subcommand(kind, sub, help=sub.description)
    return parser


def with_poses(scene, poses: Path | None, estimate: bool):
    """``scene`` with estimates from the file ``poses`` or from MediaPipe (``estimate``)."""
    if poses is not None and estimate:
        raise ValueError("--poses and --estimate: give one of them, not both")
    if poses is not None:
        from .data.readers import read_estimates

        return read_estimates(poses).apply_to(scene)
    if estimate:
        from .estimate import estimate_poses

        return estimate_poses(scene.frames).apply_to(scene)
    return scene


def import_scene(argv: list[str]) -> int:
    """``lit-boot import``: read, attach poses, save the scene folder, print its summary."""
    from .data import save_scene

    args = import_parser().parse_args(argv)
    options = dict(vars(args[args.kind]))
    poses, estimate = options.pop("poses"), options.pop("estimate")
    out, overwrite = options.pop("out"), options.pop("overwrite")
    if out.exists() and not overwrite and (not out.is_dir() or any(out.iterdir())):
        raise FileExistsError(f"--out {out}: exists and is not empty (pass --overwrite true to replace it)")
    if args.kind == "video" and not estimate:  # read_video selects and checks the pose rows itself
        scene = _readers()["video"](**options, poses=poses)
    else:
        scene = with_poses(_readers()[args.kind](**options), poses, estimate)
    save_scene(scene, out, overwrite=overwrite)
    print(scene.summary())
    print(f"wrote {out}")
    return 0
