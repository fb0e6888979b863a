"""Option checks the command line makes before any heavy import, so that a bad value is one line
naming its option within a second, not after torch and Lightning have loaded.

- :func:`check_video_options`, :func:`check_input_paths`: the video reader's values and the input
  paths, by option name;
- :func:`name_option`: a settings error ("flow_epochs: expected ...") as its option's
  ("--flow_epochs: expected ...").

Cheap to import: no torch, no Lightning.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from .console import CliError

__all__ = ["check_video_options", "check_input_paths", "name_option", "VIDEO_SUFFIXES"]

#: Files a user may mean as a video (for ``--data.scene clip.mp4``).
VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".webm", ".m4v", ".mpg", ".mpeg", ".gif")


def check_video_options(prefix: str, stride: int, max_frames: int | None, resize: Any) -> None:
    """The video reader's values: ``stride`` >= 1, ``max_frames`` None or >= 1, ``resize`` None,
    a height > 0 px (int), a scale > 0 (float) or [height, width] > 0; a :class:`CliError`
    naming ``prefix`` + the option."""
    if stride < 1:
        raise CliError(f"--{prefix}stride: expected an integer >= 1 (every N-th frame), got {stride}")
    if max_frames is not None and max_frames < 1:
        raise CliError(f"--{prefix}max_frames: expected an integer >= 1 (at most N frames), got {max_frames}")
    sizes = resize if isinstance(resize, (list, tuple)) else [resize]
    if resize is not None and not all(isinstance(v, (int, float)) and v > 0 for v in sizes):
        raise CliError(f"--{prefix}resize: expected a height in px > 0 (an integer, e.g. 360) or a scale > 0 "
                       f"(a float, e.g. 0.5), got {resize}")  # fmt: skip


def check_input_paths(scene: Path | None, video: Path | None, poses: Path | None = None, prefix: str = "data.") -> None:
    """``--data.scene`` a folder (a video file there points to ``--data.video``), ``--data.video``
    and ``--data.poses`` existing; a :class:`CliError` naming the option otherwise."""
    if scene is not None:
        if scene.is_file():
            hint = f"; for a video use --{prefix}video {scene}" if scene.suffix.lower() in VIDEO_SUFFIXES else ""
            raise CliError(f"--{prefix}scene {scene}: is a file, not a scene folder{hint}")
        if not scene.is_dir():
            raise CliError(f"--{prefix}scene {scene}: no such scene folder")
    if video is not None and not video.exists():
        raise CliError(f"--{prefix}video {video}: no such video file or folder of frames")
    if poses is not None and not poses.is_file():
        raise CliError(f"--{prefix}poses {poses}: no such pose file")


def name_option(err: Exception, options: Iterable[str], aliases: dict[str, str] | None = None) -> Exception:
    """A settings error whose message starts with a field name ("flow_epochs: expected >= 1, got
    0", "self_check.tile: ...", "SynthConfig.frames: ...") as a :class:`CliError` naming the
    option ("--flow_epochs: ...") when ``--<name>`` is one of ``options``, or ``aliases`` maps the
    name to an option ({"arch": "--flow.arch"}); ``err`` itself otherwise."""
    match = re.match(r"(?:[A-Z]\w*\.)?([a-z_][\w.]*): (.*)$", str(err), re.S)
    if match is None:
        return err
    name, reason = match.groups()
    option = f"--{name}" if f"--{name}" in set(options) else (aliases or {}).get(name)
    return CliError(f"{option}: {reason}") if option else err
