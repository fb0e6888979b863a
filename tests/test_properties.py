"""Property-based tests (hypothesis) of the readers: random valid inputs round-trip exactly;
random corruptions (truncation at any byte, flipped bytes, junk) are refused with lit-boot's own
errors naming the file (or, where the format has no check on those bytes, load unchanged) and
never surface as an error from deep inside numpy, zipfile, json or torch.

Seeds are fixed (derandomize) and examples few, so the suite is reproducible and quick.
"""

from __future__ import annotations

import json
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
import torch
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from lit_boot.core import Cameras, GroundTruth, Scene, SceneValidationError
from lit_boot.data import FloFormatError, SceneFormatError, load_scene, read_flo, save_scene, write_flo
from lit_boot.data.readers import PoseEstimates, read_estimates, save_poses

LIBRARY_ERRORS = (SceneFormatError, SceneValidationError, FloFormatError)  # DatasetFormatError: a SceneFormatError
EXAMPLES = settings(max_examples=30, deadline=None, derandomize=True)
FEW = settings(max_examples=15, deadline=None, derandomize=True)


@contextmanager
def folder() -> Iterator[Path]:
    with tempfile.TemporaryDirectory() as d:
        yield Path(d)


def refused_or(load: Callable[[], object], names: tuple[str, ...], same: Callable[[object], bool] | None) -> None:
    """``load()`` raises a lit-boot error whose message names one of ``names``, or returns a
    value for which ``same`` holds (no ``same``: it must raise). Any other exception fails."""
    try:
        value = load()
    except LIBRARY_ERRORS as err:
        assert any(n in str(err) for n in names), f"{type(err).__name__} names none of {names}: {err}"
        return
    assert same is not None, f"accepted: {names}"
    assert same(value), f"loaded something else from {names}"


def flipped(data: bytes, index: int, mask: int) -> bytes:
    return data[:index] + bytes([data[index] ^ mask]) + data[index + 1 :]


def tensors(shape: tuple[int, ...], dtype=np.float32, lo: float = -1e5, hi: float = 1e5):
    """Finite tensors of ``shape`` (bool and uint8 too)."""
    if dtype is bool:
        return hnp.arrays(np.bool_, shape).map(torch.from_numpy)
    if dtype is np.uint8:
        return hnp.arrays(np.uint8, shape).map(torch.from_numpy)
    width = 32 if dtype == np.float32 else 64
    return hnp.arrays(dtype, shape, elements=st.floats(lo, hi, width=width)).map(torch.from_numpy)


# --- .flo ------------------------------------------------------------------------------------------
flows = st.tuples(st.integers(1, 6), st.integers(1, 6)).flatmap(
    lambda hw: hnp.arrays(np.float32, (2, *hw), elements=st.floats(width=32, allow_nan=False, allow_infinity=False))
)


@EXAMPLES
@given(flow=flows)
def test_flo_round_trips_bit_exactly(flow: np.ndarray) -> None:
    with folder() as d:
        back = read_flo(write_flo(d / "f.flo", flow))
    assert back.numpy().tobytes() == flow.tobytes()


@EXAMPLES
@given(flow=flows, cut=st.floats(0, 1, exclude_max=True), index=st.integers(0, 11), mask=st.integers(1, 255))
def test_flo_truncated_or_header_flipped_is_refused(flow: np.ndarray, cut: float, index: int, mask: int) -> None:
    with folder() as d:
        data = write_flo(d / "f.flo", flow).read_bytes()
        (d / "cut.flo").write_bytes(data[: int(cut * len(data))])
        refused_or(lambda: read_flo(d / "cut.flo"), ("cut.flo",), None)
        (d / "flip.flo").write_bytes(flipped(data, index, mask))
        refused_or(lambda: read_flo(d / "flip.flo"), ("flip.flo",), None)


@EXAMPLES
@given(junk=st.binary(max_size=200))
def test_flo_junk_is_refused(junk: bytes) -> None:
    assume(not junk.startswith(b"PIEH"))
    with folder() as d:
        (d / "junk.flo").write_bytes(junk)
        refused_or(lambda: read_flo(d / "junk.flo"), ("junk.flo",), None)


# --- scene folders --------------------------------------------------------------------------------
@st.composite
def cameras(draw, T: int) -> Cameras:
    if draw(st.booleans()):
        return Cameras("pinhole", draw(tensors((T, 7))))
    return Cameras("weak_perspective", draw(tensors((T, 3))), draw(tensors((T, 3))), draw(st.floats(1.0, 1e3)))


@st.composite
def ground_truth(draw, T: int, H: int, W: int) -> GroundTruth | None:
    if not draw(st.booleans()):
        return None
    maybe = lambda strategy: draw(st.none() | strategy)  # noqa: E731
    return GroundTruth(
        flow=maybe(tensors((T - 1, 2, H, W))), flow_valid=maybe(tensors((T - 1, H, W), bool)),
        flow_occluded=maybe(tensors((T - 1, H, W), bool)), joints3d=maybe(tensors((T, 14, 3))),
        joints2d=maybe(tensors((T, 14, 2))), cameras=maybe(cameras(T)), person_mask=maybe(tensors((T, H, W), bool)),
        keypoints2d=maybe(tensors((T, 17, 2))),
    )  # fmt: skip


json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**40), 2**40) | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(max_size=6),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=4), inner, max_size=3),
    max_leaves=6,
)  # fmt: skip


@st.composite
def scenes(draw) -> Scene:
    T, H, W = draw(st.integers(1, 3)), draw(st.integers(1, 5)), draw(st.integers(1, 5))
    joints = draw(st.none() | tensors((T, 14, 3), draw(st.sampled_from([np.float32, np.float64]))))
    has_keypoints = draw(st.booleans())
    return Scene(
        frames=draw(tensors((T, 3, H, W), np.uint8)), fps=draw(st.floats(0.5, 240)), name=draw(st.text(max_size=8)),
        joints3d=joints, cameras=draw(cameras(T)) if joints is not None and draw(st.booleans()) else None,
        keypoints2d=draw(tensors((T, 17, 2))) if has_keypoints else None,
        keypoints_conf=draw(tensors((T, 17), lo=0.0, hi=1.0)) if has_keypoints else None,
        gt=draw(ground_truth(T, H, W)), metadata=draw(st.dictionaries(st.text(max_size=5), json_values, max_size=3)),
    )  # fmt: skip


def same_tensors(a: object, b: object) -> bool:
    if isinstance(a, torch.Tensor) or isinstance(b, torch.Tensor):
        return isinstance(a, torch.Tensor) and isinstance(b, torch.Tensor) and a.dtype == b.dtype and torch.equal(a, b)
    if isinstance(a, Cameras) or isinstance(b, Cameras):
        return (isinstance(a, Cameras) and isinstance(b, Cameras) and a.model == b.model and a.crop_size == b.crop_size
                and same_tensors(a.params, b.params) and (a.crops is b.crops is None or same_tensors(a.crops, b.crops)))
    if isinstance(a, GroundTruth) or isinstance(b, GroundTruth):
        keys = GroundTruth.__dataclass_fields__
        return isinstance(a, GroundTruth) and isinstance(b, GroundTruth) and all(
            same_tensors(getattr(a, k), getattr(b, k)) for k in keys)  # fmt: skip
    return a == b


def same_scene(a: Scene, b: Scene) -> bool:
    return all(same_tensors(getattr(a, k), getattr(b, k)) for k in Scene.__dataclass_fields__)


@EXAMPLES
@given(scene=scenes())
def test_scene_folder_round_trips_exactly(scene: Scene) -> None:
    with folder() as d:
        loaded = load_scene(save_scene(scene, d / "scene"))
    assert same_scene(loaded, scene)


@pytest.fixture(scope="module")
def saved() -> Iterator[tuple[Path, Scene]]:
    g = torch.Generator().manual_seed(0)
    scene = Scene(frames=torch.randint(0, 256, (2, 3, 4, 5), dtype=torch.uint8, generator=g),
                  joints3d=torch.randn(2, 14, 3, generator=g), metadata={"note": "x"},
                  gt=GroundTruth(flow=torch.randn(1, 2, 4, 5, generator=g)))  # fmt: skip
    with folder() as d:
        yield save_scene(scene, d / "scene"), scene


FILES = ("arrays.npz", "scene.json", "frames/000001.png")


@FEW
@given(which=st.sampled_from(FILES), cut=st.floats(0, 1, exclude_max=True))
def test_scene_file_truncated_is_refused(saved, which: str, cut: float) -> None:
    source, scene = saved
    with folder() as d:
        copy = _copy_with(source, d, which, lambda data: data[: int(cut * len(data))])
        # a PNG cut inside its last chunk (IEND) may still decode: then it must decode identically
        same = (lambda s: same_scene(s, scene)) if which.endswith("png") else None
        refused_or(lambda: load_scene(copy), (Path(which).name,), same)


@EXAMPLES
@given(which=st.sampled_from(FILES), where=st.floats(0, 1, exclude_max=True), mask=st.integers(1, 255))
def test_scene_file_flipped_is_refused_or_unchanged(saved, which: str, where: float, mask: int) -> None:
    """arrays.npz (zip CRC-32) and the PNGs (chunk CRCs) never load other values; scene.json
    has no checksum: a flip may load other metadata, but never crashes."""
    source, scene = saved
    with folder() as d:
        copy = _copy_with(source, d, which, lambda data: flipped(data, int(where * len(data)), mask))
        same = (lambda s: True) if which == "scene.json" else (lambda s: same_scene(s, scene))
        refused_or(lambda: load_scene(copy), (Path(which).name, str(copy)), same)


@FEW
@given(which=st.sampled_from(FILES), junk=st.binary(max_size=300))
def test_scene_file_junk_is_refused(saved, which: str, junk: bytes) -> None:
    source, _ = saved
    with folder() as d:
        copy = _copy_with(source, d, which, lambda data: junk)
        refused_or(lambda: load_scene(copy), (Path(which).name, str(copy)), None)


def _copy_with(source: Path, dest: Path, which: str, change: Callable[[bytes], bytes]) -> Path:
    """A copy of the scene folder ``source`` in ``dest`` with file ``which`` changed."""
    copy = dest / "scene"
    for file in source.rglob("*"):
        if file.is_file():
            (copy / file.relative_to(source)).parent.mkdir(parents=True, exist_ok=True)
            (copy / file.relative_to(source)).write_bytes(file.read_bytes())
    (copy / which).write_bytes(change((copy / which).read_bytes()))
    return copy


# --- pose files -----------------------------------------------------------------------------------
@st.composite
def pose_estimates(draw) -> PoseEstimates:
    T = draw(st.integers(1, 4))
    keypoints, joints = draw(st.booleans()), draw(st.booleans())
    assume(keypoints or joints)
    starts = draw(st.lists(st.integers(1, 5), min_size=T, max_size=T))
    return PoseEstimates(
        keypoints2d=draw(tensors((T, 17, 2))) if keypoints else None,
        keypoints_conf=draw(tensors((T, 17), lo=0.0, hi=1.0)) if keypoints else None,
        joints3d=draw(tensors((T, 14, 3))) if joints else None,
        cameras=draw(cameras(T)) if joints and draw(st.booleans()) else None,
        frame_indices=torch.tensor(np.cumsum(starts) - 1, dtype=torch.int64),
        image_size=draw(st.none() | st.tuples(st.integers(1, 2000), st.integers(1, 2000))),
        source=draw(st.text(max_size=6)), metadata=draw(st.dictionaries(st.text(max_size=5), json_values, max_size=3)),
    )  # fmt: skip


def same_poses(a: PoseEstimates, b: PoseEstimates) -> bool:
    return all(same_tensors(getattr(a, k), getattr(b, k)) for k in PoseEstimates.__dataclass_fields__)


@EXAMPLES
@given(poses=pose_estimates(), suffix=st.sampled_from([".npz", ".json"]))
def test_pose_file_round_trips_exactly(poses: PoseEstimates, suffix: str) -> None:
    with folder() as d:
        loaded = read_estimates(save_poses(poses, d / f"poses{suffix}"))
    assert same_poses(loaded, poses)


@EXAMPLES
@given(poses=pose_estimates(), suffix=st.sampled_from([".npz", ".json"]), cut=st.floats(0, 1, exclude_max=True),
       where=st.floats(0, 1, exclude_max=True), mask=st.integers(1, 255))  # fmt: skip
def test_pose_file_corrupted_is_refused(poses: PoseEstimates, suffix: str, cut: float, where: float, mask: int) -> None:
    """Truncated: always refused. Flipped: refused, or (.npz: CRC-checked) loads the same, or
    (.json: no checksum) loads something valid."""
    with folder() as d:
        data = save_poses(poses, d / f"poses{suffix}").read_bytes()
        (d / f"cut{suffix}").write_bytes(data[: int(cut * len(data))])
        refused_or(lambda: read_estimates(d / f"cut{suffix}"), (f"cut{suffix}",), None)
        (d / f"flip{suffix}").write_bytes(flipped(data, int(where * len(data)), mask))
        same = (lambda p: same_poses(p, poses)) if suffix == ".npz" else (lambda p: isinstance(p, PoseEstimates))
        refused_or(lambda: read_estimates(d / f"flip{suffix}"), (f"flip{suffix}",), same)


@EXAMPLES
@given(junk=st.binary(max_size=300) | st.builds(lambda v: json.dumps(v).encode(), json_values),
       suffix=st.sampled_from([".npz", ".json"]))  # fmt: skip
def test_pose_file_junk_is_refused(junk: bytes, suffix: str) -> None:
    with folder() as d:
        (d / f"junk{suffix}").write_bytes(junk)
        refused_or(lambda: read_estimates(d / f"junk{suffix}"), (f"junk{suffix}",), None)
