"""BVH motion capture files: parsing, and sampling them as a :class:`Motion`.

A BVH file holds a joint hierarchy (OFFSETs in file units, CHANNELS per joint) and a table of
channel values per frame (positions in file units, rotations in degrees). Rotation channels of
one joint compose in their listed order: ``ZYX`` means ``R = Rz @ Ry @ Rx``. The CMU cgspeed
conversion is already in the body frame convention of :mod:`lit_boot.synth.skeleton`
(x = the body's left, y = up, z = forward) with identity rest rotations; its unit is about
5.6 cm, so :func:`bvh_motion` rescales the skeleton to a chosen height in millimetres.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import torch

from lit_boot.synth.skeleton import LANDMARKS, Motion, Skeleton, axis_angle_to_matrix, euler_to_matrix

__all__ = ["BvhData", "CMU_LANDMARKS", "read_bvh", "bvh_motion", "bvh_duration", "sample_channels", "rest_height"]

_CHANNELS = frozenset(f"{axis}{kind}" for axis in "XYZ" for kind in ("position", "rotation"))

#: Canonical landmark name -> joint name in the CMU cgspeed BVH conversion (e.g. 131_01.bvh).
CMU_LANDMARKS: dict[str, str] = {
    "pelvis": "Hips", "chest": "Chest2", "neck": "Neck", "head": "Head", "head_top": "Head_end",
    "left_hip": "LeftHip", "left_knee": "LeftKnee", "left_ankle": "LeftAnkle", "left_toe": "LeftToe_end",
    "right_hip": "RightHip", "right_knee": "RightKnee", "right_ankle": "RightAnkle", "right_toe": "RightToe_end",
    "left_shoulder": "LeftShoulder", "left_elbow": "LeftElbow", "left_wrist": "LeftWrist",
    "left_hand": "LFingers_end",
    "right_shoulder": "RightShoulder", "right_elbow": "RightElbow", "right_wrist": "RightWrist",
    "right_hand": "RFingers_end",
}  # fmt: skip


@dataclass
class BvhData:
    """The raw content of a BVH file.

    names (N,), parents (N,) with -1 for the root and parents before children (end sites are
    joints named ``f"{parent}_end"`` without channels), offsets (N, 3) float64 in file units,
    channels: per joint a tuple of channel names (e.g. ``("Zrotation", "Yrotation", "Xrotation")``)
    whose values are consecutive columns of ``values`` (F, C) float64, frame_time seconds,
    source: the file name used in error messages.
    """

    names: tuple[str, ...]
    parents: tuple[int, ...]
    offsets: torch.Tensor
    channels: tuple[tuple[str, ...], ...]
    frame_time: float
    values: torch.Tensor
    source: str = "<bvh>"

    @property
    def duration(self) -> float:
        """Seconds from the first to the last frame, ``(F - 1) * frame_time``."""
        return max(self.values.shape[0] - 1, 0) * self.frame_time

    def columns(self, joint: int) -> range:
        """The columns of ``values`` holding ``joint``'s channels."""
        start = sum(len(c) for c in self.channels[:joint])
        return range(start, start + len(self.channels[joint]))


class _Tokens:
    """Whitespace tokens of the HIERARCHY section with their 1-based line numbers."""

    def __init__(self, source: str, tokens: list[tuple[str, int]], end_line: int) -> None:
        self.source, self.tokens, self.end_line, self.pos = source, tokens, end_line, 0

    def fail(self, line: int, message: str) -> ValueError:
        return ValueError(f"{self.source}: line {line}: {message}")

    def next(self, expected: str) -> tuple[str, int]:
        if self.pos >= len(self.tokens):
            raise self.fail(self.end_line, f"unexpected end of hierarchy, expected {expected}")
        self.pos += 1
        return self.tokens[self.pos - 1]

    def expect(self, word: str) -> int:
        tok, line = self.next(repr(word))
        if tok != word:
            raise self.fail(line, f"expected {word!r}, found {tok!r}")
        return line

    def number(self, expected: str, kind: type = float) -> float:
        tok, line = self.next(expected)
        try:
            return kind(tok)
        except ValueError:
            raise self.fail(line, f"expected {expected}, found {tok!r}") from None


def _parse_hierarchy(tok: _Tokens) -> tuple[list[str], list[int], list[list[float]], list[tuple[str, ...]]]:
    """Joints (names, parents, offsets, channels) in file order, end sites included."""
    names: list[str] = []
    parents: list[int] = []
    offsets: list[list[float]] = []
    channels: list[tuple[str, ...]] = []

    def offset() -> list[float]:
        return [tok.number("an OFFSET number") for _ in range(3)]

    def add(name: str, parent: int) -> int:
        names.append(name)
        parents.append(parent)
        offsets.append([])
        channels.append(())
        return len(names) - 1

    def joint(name: str, parent: int) -> None:
        index = add(name, parent)
        line = tok.expect("{")
        while True:
            word, line = tok.next("OFFSET, CHANNELS, JOINT, End Site or '}'")
            if word == "OFFSET":
                offsets[index] = offset()
            elif word == "CHANNELS":
                count = int(tok.number("a channel count", int))
                chans = tuple(tok.next("a channel name")[0] for _ in range(count))
                bad = [c for c in chans if c not in _CHANNELS]
                if bad:
                    raise tok.fail(line, f"unknown channels {bad}, expected names like 'Xposition', 'Zrotation'")
                channels[index] = chans
            elif word == "JOINT":
                joint(tok.next("a joint name")[0], index)
            elif word == "End":
                tok.expect("Site")
                end = add(f"{name}_end", index)
                tok.expect("{")
                tok.expect("OFFSET")
                offsets[end] = offset()
                tok.expect("}")
            elif word == "}":
                break
            else:
                raise tok.fail(line, f"unknown keyword {word!r}, expected OFFSET, CHANNELS, JOINT, End Site or '}}'")
        if not offsets[index]:
            raise tok.fail(line, f"joint {name!r} has no OFFSET")

    tok.expect("HIERARCHY")
    tok.expect("ROOT")
    joint(tok.next("the root's name")[0], -1)
    if tok.pos < len(tok.tokens):
        word, line = tok.tokens[tok.pos]
        raise tok.fail(line, f"unknown keyword {word!r} after the root joint, expected MOTION")
    return names, parents, offsets, channels


def _header(source: str, lines: list[tuple[int, str]], i: int, key: str, kind: type, end_line: int) -> float:
    """The number after ``key`` on the i-th non-blank line of the MOTION section."""
    if i >= len(lines):
        raise ValueError(f"{source}: line {end_line}: unexpected end of file, expected '{key}'")
    number, text = lines[i]
    try:
        if not text.startswith(key):
            raise ValueError
        value = kind(text[len(key) :].strip())
    except ValueError:
        raise ValueError(f"{source}: line {number}: expected '{key} <number>', found {text[:40]!r}") from None
    if value <= 0:
        raise ValueError(f"{source}: line {number}: expected a positive '{key}', found {value}")
    return value


def _parse_motion(
    source: str, lines: list[tuple[int, str]], n_channels: int, end_line: int
) -> tuple[float, torch.Tensor]:
    """(frame_time, values (F, C)) from the non-blank lines after MOTION."""
    frames = int(_header(source, lines, 0, "Frames:", int, end_line))
    frame_time = _header(source, lines, 1, "Frame Time:", float, end_line)
    rows = lines[2:]
    if len(rows) < frames:
        raise ValueError(f"{source}: line {end_line}: file ends after {len(rows)} of {frames} motion rows (truncated)")
    if len(rows) > frames:
        raise ValueError(f"{source}: line {rows[frames][0]}: more motion rows than 'Frames: {frames}'")
    values: list[list[float]] = []
    for number, text in rows:
        parts = text.split()
        if len(parts) != n_channels:
            raise ValueError(f"{source}: line {number}: expected {n_channels} values, found {len(parts)}")
        try:
            values.append([float(p) for p in parts])
        except ValueError:
            raise ValueError(f"{source}: line {number}: expected {n_channels} numbers, found text") from None
    return frame_time, torch.tensor(values, dtype=torch.float64).reshape(frames, n_channels)


def read_bvh(path: str | Path) -> BvhData:
    """Parse a BVH file (any indentation and line endings); ValueError names file and line."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as err:
        raise ValueError(f"{path}: cannot read the BVH file ({err.strerror or err})") from None
    lines = [(i + 1, s.strip()) for i, s in enumerate(text.splitlines()) if s.strip()]
    end_line = max(len(text.splitlines()), 1)  # where a truncated file ends
    split = next((k for k, (_, s) in enumerate(lines) if s == "MOTION"), len(lines))
    motion_line = lines[split][0] if split < len(lines) else end_line
    tokens = [(t, n) for n, s in lines[:split] for t in s.split()]
    names, parents, offsets, channels = _parse_hierarchy(_Tokens(str(path), tokens, motion_line))
    if split == len(lines):
        raise ValueError(f"{path}: line {end_line}: unexpected end of file, expected MOTION")
    frame_time, values = _parse_motion(str(path), lines[split + 1 :], sum(map(len, channels)), end_line)
    return BvhData(
        tuple(names), tuple(parents), torch.tensor(offsets, dtype=torch.float64), tuple(channels),
        frame_time, values, str(path),
    )  # fmt: skip


def _as_data(source: str | Path | BvhData) -> BvhData:
    return source if isinstance(source, BvhData) else read_bvh(source)


def bvh_duration(source: str | Path | BvhData) -> float:
    """Seconds from the first to the last frame of a BVH clip."""
    return _as_data(source).duration


def _unwrap_degrees(values: torch.Tensor) -> torch.Tensor:
    """(F, K) angles in degrees made continuous over frames (jumps > 180 deg removed)."""
    steps = values.diff(dim=0)
    steps = steps - 360.0 * torch.round(steps / 360.0)
    return torch.cat([values[:1], values[:1] + steps.cumsum(0)])


def sample_channels(data: BvhData, times: torch.Tensor) -> torch.Tensor:
    """Channel values (T, C) float64 at ``times`` (T,) seconds from the clip's first frame.

    Linear interpolation between frames; rotation channels are unwrapped first, so a sampled
    angle may leave [-180, 180]. Times outside [0, duration] raise ValueError.
    """
    t = times.detach().to(torch.float64).reshape(-1)
    frames, dt = data.values.shape[0], data.frame_time
    tol = max(1e-3 * dt, 1e-6 * data.duration)  # float32 times may overshoot the last frame
    if t.numel() and (t.min() < -tol or t.max() > data.duration + tol):
        raise ValueError(
            f"{data.source}: times {t.min().item():.4f}..{t.max().item():.4f} s outside the clip "
            f"(duration {data.duration:.4f} s: {frames} frames of {dt:.6g} s)"
        )
    rot = [k for k, name in enumerate(c for chans in data.channels for c in chans) if name.endswith("rotation")]
    values = data.values.clone()
    values[:, rot] = _unwrap_degrees(values[:, rot])
    if frames == 1:
        return values.expand(t.shape[0], -1).clone()
    f = (t / dt).clamp(0, frames - 1)
    i0 = f.floor().long().clamp(max=frames - 2)
    w = (f - i0).unsqueeze(1)
    return values[i0] * (1 - w) + values[i0 + 1] * w


def _local_rotations(data: BvhData, values: torch.Tensor) -> torch.Tensor:
    """(T, N, 3, 3) local rotations from the rotation channels, composed in file order."""
    T, N = values.shape[0], len(data.names)
    rotations = torch.eye(3, dtype=values.dtype).expand(T, N, 3, 3).clone()
    for j, chans in enumerate(data.channels):
        cols = [c for c, name in zip(data.columns(j), chans) if name.endswith("rotation")]
        order = "".join(name[0] for name in chans if name.endswith("rotation"))
        if len(cols) == 3:
            rotations[:, j] = euler_to_matrix(values[:, cols], order)
        else:
            for c, axis in zip(cols, order):
                rotations[:, j] = rotations[:, j] @ axis_angle_to_matrix(axis.lower(), values[:, c].deg2rad())
    return rotations


def _landmark_indices(data: BvhData, landmarks: dict[str, str]) -> dict[str, int]:
    """Canonical name -> joint index; ValueError naming the file and every missing joint."""
    missing = [f"{key} (no mapping)" for key in LANDMARKS if key not in landmarks]
    missing += [f"{key} -> {name!r}" for key, name in landmarks.items() if name not in data.names]
    if missing:
        raise ValueError(f"{data.source}: landmark joints not found: {', '.join(missing)}")
    return {key: data.names.index(name) for key, name in landmarks.items()}


def rest_height(skeleton: Skeleton) -> float:
    """Rest-pose height: head_top's y minus the lowest y of the toes and ankles (skeleton units)."""
    pos = skeleton.rest_positions()
    feet = [skeleton.landmarks[k] for k in ("left_toe", "right_toe", "left_ankle", "right_ankle")]
    return float(pos[skeleton.landmarks["head_top"], 1] - pos[feet, 1].min())


def bvh_motion(
    source: str | Path | BvhData,
    times: torch.Tensor,
    *,
    start: float = 0.0,
    height_mm: float | None = 1700.0,
    landmarks: dict[str, str] | None = None,
) -> Motion:
    """A BVH clip sampled at ``start + times`` (T,) seconds as a :class:`Motion` in millimetres.

    Offsets and root positions are scaled so that :func:`rest_height` equals ``height_mm``
    (None: file units are taken as mm). ``landmarks`` maps canonical names to file joint names
    (default :data:`CMU_LANDMARKS`). Position channels of non-root joints are ignored (rest
    offsets are used). ``Motion.times`` is ``times`` as given; dtype: ``times``' if floating, else
    the default dtype.
    """
    data = _as_data(source)
    index = _landmark_indices(data, CMU_LANDMARKS if landmarks is None else landmarks)
    values = sample_channels(data, start + times.detach().to(torch.float64))
    skeleton = Skeleton(data.names, data.parents, data.offsets.clone(), index)
    scale = 1.0
    if height_mm is not None:
        height = rest_height(skeleton)
        if height <= 0:
            raise ValueError(f"{data.source}: rest pose has non-positive height {height:.4g} (head_top below feet)")
        scale = height_mm / height
    root = data.offsets[0].expand(values.shape[0], 3).clone()
    for c, name in zip(data.columns(0), data.channels[0]):
        if name.endswith("position"):
            root[:, "XYZ".index(name[0])] += values[:, c]
    dtype = times.dtype if times.is_floating_point() else torch.get_default_dtype()
    skeleton = skeleton.scaled(scale)
    skeleton.offsets = skeleton.offsets.to(dtype)
    return Motion(skeleton, times, _local_rotations(data, values).to(dtype), (root * scale).to(dtype))
