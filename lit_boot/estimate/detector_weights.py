"""Where the person detector's ONNX file is: a path, or a known model name in the checkpoint folders.

Lookup order for :func:`resolve_detector_weights`, as for RAFT's weights (:mod:`lit_boot.flow.weights`):

1. an explicit file path (anything ending in ``.onnx``, or any existing file);
2. a known name (:data:`DETECTOR_MODELS`, e.g. ``"yolox_nano"``) as its file in the local checkpoint
   folders: ``$LIT_BOOT_CHECKPOINTS``, then ``./checkpoints`` and the project's ``checkpoints/``;
3. a download of that file from the YOLOX release into the first of those folders.

Offline with nothing local, the error names the file to place and where. No hash is enforced: the
public copies of ``yolox_nano.onnx`` differ in their bytes (checkpoints/README.md).
The folder list repeats :func:`lit_boot.flow.weights.checkpoint_dirs`, which this layer cannot import.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

__all__ = ["DETECTOR_MODELS", "detector_checkpoint_dirs", "download_file", "resolve_detector_weights"]

log = logging.getLogger(__name__)

_RELEASE = "https://github.com/Megvii-BaseDetection/YOLOX/releases/download/0.1.1rc0"
#: Known detector names -> (file name, download URL). Other YOLOX ONNX exports load by path.
DETECTOR_MODELS = {"yolox_nano": ("yolox_nano.onnx", f"{_RELEASE}/yolox_nano.onnx")}

_PROJECT_CHECKPOINTS = Path(__file__).resolve().parents[2] / "checkpoints"


def _default_dirs() -> list[Path]:
    """The folders searched after ``$LIT_BOOT_CHECKPOINTS``: ``./checkpoints``, then the project's."""
    return [Path.cwd() / "checkpoints", _PROJECT_CHECKPOINTS]


def detector_checkpoint_dirs() -> list[Path]:
    """Local folders searched for detector files, in order, without repeats."""
    dirs = [Path(os.environ["LIT_BOOT_CHECKPOINTS"])] if os.environ.get("LIT_BOOT_CHECKPOINTS") else []
    seen: list[Path] = []
    for d in dirs + _default_dirs():
        if d.resolve() not in [s.resolve() for s in seen]:
            seen.append(d)
    return seen


def download_file(url: str, target: Path) -> None:
    """Download ``url`` to ``target`` (through a temporary file, so a broken download leaves nothing)."""
    from torch.hub import download_url_to_file

    target.parent.mkdir(parents=True, exist_ok=True)
    download_url_to_file(url, str(target), hash_prefix=None, progress=False)


def resolve_detector_weights(model: str | os.PathLike = "yolox_nano") -> Path:
    """The local ONNX file for ``model``: a path, or a name of :data:`DETECTOR_MODELS` (see the
    module docstring for the order); downloads the named file when it is nowhere local."""
    as_path = Path(model)
    if as_path.suffix == ".onnx" or as_path.is_file():
        if not as_path.is_file():
            raise FileNotFoundError(f"detector model file {as_path} does not exist")
        return as_path
    name = str(model)
    if name not in DETECTOR_MODELS:
        raise ValueError(
            f"model: {name!r} is neither an ONNX file nor a known detector name ({', '.join(DETECTOR_MODELS)})"
        )
    file, url = DETECTOR_MODELS[name]
    for folder in detector_checkpoint_dirs():
        if (folder / file).is_file():
            return folder / file
    target = detector_checkpoint_dirs()[0] / file
    log.info("downloading %s from %s into %s", file, url, target.parent)
    try:
        download_file(url, target)
    except Exception as err:  # noqa: BLE001 - offline, refused, interrupted: all end the same way
        where = " or ".join(str(d) for d in detector_checkpoint_dirs())
        raise FileNotFoundError(
            f"detector {name}: {file} is not available locally and could not be downloaded from {url} "
            f"({type(err).__name__}: {err}). Place {file} in {where} (or set LIT_BOOT_CHECKPOINTS), "
            "or pass the file path."
        ) from None
    return target
