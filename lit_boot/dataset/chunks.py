"""Long scenes in chunks: plan overlapping chunk tasks, cut a scene to a chunk, stitch the
chunks' results back into whole sequences.

A chunk is a :class:`~lit_boot.dataset.tasks.Task` with ``frames`` [start, stop) and ``parent``
the whole scene's task name, named ``<parent>--<start>-<stop>`` (5 digits each). Consecutive
chunks share ``overlap`` frames. Per-frame results (poses, cameras) are stitched with a linear
cross-fade inside each overlap, so the sequence and its velocity stay continuous across chunk
borders; per-pair results (flows) switch hard from one chunk to the next at the overlap's middle.
"""

from __future__ import annotations

import dataclasses
import math
import re
from typing import TYPE_CHECKING, Any, TypeVar

import torch

from ..core.cameras import Cameras
from ..core.people import Person
from ..core.scene import GroundTruth, Scene

if TYPE_CHECKING:
    from ..data.readers.pose_file import PoseEstimates

#: A :class:`~lit_boot.dataset.tasks.Task` (not imported: tasks imports this module for slice_scene).
TaskT = TypeVar("TaskT")

__all__ = [
    "CHUNK_SEPARATOR",
    "chunk_name",
    "plan_chunks",
    "slice_scene",
    "stitch_estimates",
    "stitch_pairs",
    "stitch_sequences",
]

#: Between a chunk's parent name and its frames ('@' is no file-name character of safe_name).
CHUNK_SEPARATOR = "--"
_GT_FRAMES = ("joints3d", "joints2d", "person_mask", "keypoints2d")
_GT_PAIRS = ("flow", "flow_valid", "flow_occluded")
#: Metadata lists with one entry per frame (readers: frame_indices, files, frames, campose_valid).
_META_FRAMES = ("frame_indices", "files", "frames", "campose_valid")
_MASK_FILE = re.compile(r"frame_(\d+)\.png$")


def chunk_name(name: str, start: int, stop: int) -> str:
    """The name of the chunk [start, stop) of the task ``name``, e.g. "clip--00090-00190" (a
    safe name when ``name`` is one)."""
    return f"{name}{CHUNK_SEPARATOR}{start:05d}-{stop:05d}"


def plan_chunks(task: TaskT, num_frames: int, length: int, overlap: int) -> list[TaskT]:
    """The :class:`~lit_boot.dataset.tasks.Task` ``task`` (T = ``num_frames`` frames) as chunk
    tasks of at most ``length`` frames, consecutive ones sharing exactly ``overlap`` frames;
    ``[task]`` itself when T <= ``length``.

    n = ceil((T - overlap) / (length - overlap)) chunks of near-equal length (the first ones one
    frame longer), the first starting at 0 and the last ending at T; so there is no short tail:
    every chunk has more than (length + overlap) / 2 >= overlap + 2 frames. Requires
    2 <= overlap (the temporal terms see across the border) and overlap + 2 <= length.
    """
    for key, value in (("num_frames", num_frames), ("length", length), ("overlap", overlap)):
        if isinstance(value, bool) or not isinstance(value, int):
            raise TypeError(f"plan_chunks: {key} must be an int, got {value!r}")
    if task.frames is not None:
        raise ValueError(f"plan_chunks: task {task.name!r} is already a chunk (frames {task.frames})")
    if num_frames < 1:
        raise ValueError(f"plan_chunks: num_frames must be >= 1, got {num_frames}")
    if overlap < 2:
        raise ValueError(f"plan_chunks: overlap must be >= 2 frames (smoothness across the border), got {overlap}")
    if length < overlap + 2:
        raise ValueError(f"plan_chunks: length must be >= overlap + 2 = {overlap + 2}, got {length}")
    if num_frames <= length:
        return [task]
    n = math.ceil((num_frames - overlap) / (length - overlap))
    base, extra = divmod(num_frames + (n - 1) * overlap, n)
    chunks, start = [], 0
    for i in range(n):
        stop = start + base + (i < extra)
        chunks.append(dataclasses.replace(task, name=chunk_name(task.name, start, stop), frames=(start, stop),
                                          parent=task.name))  # fmt: skip
        start = stop - overlap
    assert chunks[-1].frames[1] == num_frames
    return chunks


# --- cutting a scene ------------------------------------------------------------------------------
def _cut(value: torch.Tensor | None, start: int, stop: int) -> torch.Tensor | None:
    return None if value is None else value[start:stop].clone()


def _cut_cameras(cameras: Cameras | None, start: int, stop: int) -> Cameras | None:
    if cameras is None:
        return None
    return Cameras(cameras.model, _cut(cameras.params, start, stop), _cut(cameras.crops, start, stop),
                   cameras.crop_size)  # fmt: skip


def _cut_gt(gt: GroundTruth | None, start: int, stop: int) -> GroundTruth | None:
    if gt is None:
        return None
    fields = {key: _cut(getattr(gt, key), start, stop) for key in _GT_FRAMES}
    fields |= {key: _cut(getattr(gt, key), start, stop - 1) for key in _GT_PAIRS}  # pairs t -> t+1
    others = tuple(dataclasses.replace(p, **{key: _cut(getattr(p, key), start, stop) for key in _GT_FRAMES})
                   for p in gt.others)  # fmt: skip
    return dataclasses.replace(gt, **fields, cameras=_cut_cameras(gt.cameras, start, stop), others=others)


def _cut_events(events: list[Any], start: int, stop: int) -> list[Any]:
    """Synthetic keypoint failures ({"frame": t} or {"frames": [...]}) inside the cut, shifted."""
    out = []
    for event in events:
        if isinstance(event, dict) and isinstance(event.get("frame"), int):
            if start <= event["frame"] < stop:
                out.append({**event, "frame": event["frame"] - start})
        elif isinstance(event, dict) and isinstance(event.get("frames"), list):
            frames = [t - start for t in event["frames"] if isinstance(t, int) and start <= t < stop]
            if frames:
                out.append({**event, "frames": frames})
        else:
            out.append(event)
    return out


def _cut_metadata(meta: dict[str, Any], start: int, stop: int, T: int) -> dict[str, Any]:
    """Metadata of the cut: per-frame lists cut, frame-numbered entries kept inside and shifted,
    ``chunk`` = {"start", "stop"} (composed with an earlier cut's)."""
    per_frame = lambda v: isinstance(v, list) and len(v) == T  # noqa: E731
    out = {key: value[start:stop] if key in _META_FRAMES and per_frame(value) else value for key, value in meta.items()}
    if isinstance(meta.get("camera"), dict):  # lit_boot.synth: the true camera per frame
        out["camera"] = {k: v[start:stop] if per_frame(v) else v for k, v in meta["camera"].items()}
    if isinstance(meta.get("keypoint_failures"), list):
        out["keypoint_failures"] = _cut_events(meta["keypoint_failures"], start, stop)
    if isinstance(meta.get("people"), list):  # lit_boot.synth with several people: each one's failures
        out["people"] = [{**person, "keypoint_failures": _cut_events(person["keypoint_failures"], start, stop)}
                         if isinstance(person, dict) and isinstance(person.get("keypoint_failures"), list) else person
                         for person in meta["people"]]  # fmt: skip
    if isinstance(meta.get("pose_estimates"), list):
        out["pose_estimates"] = [
            {**e, "frame_indices": e["frame_indices"][start:stop]}
            if isinstance(e, dict) and per_frame(e.get("frame_indices")) else e
            for e in meta["pose_estimates"]
        ]  # fmt: skip
    numbers = meta.get("frames")
    if per_frame(numbers):  # MPI-Sintel: GT pairs and missing masks by frame number
        kept = set(numbers[start:stop])
        if isinstance(meta.get("gt_pairs"), list):
            out["gt_pairs"] = [p for p in meta["gt_pairs"] if p[0] in kept and p[1] in kept]
        if isinstance(meta.get("missing_masks"), list):
            pairs = set(numbers[start : stop - 1])
            number = lambda f: int(m.group(1)) if (m := _MASK_FILE.search(str(f))) else None  # noqa: E731
            out["missing_masks"] = [f for f in meta["missing_masks"] if number(f) is None or number(f) in pairs]
    offset = meta.get("chunk", {}).get("start", 0) if isinstance(meta.get("chunk"), dict) else 0
    out["chunk"] = {"start": offset + start, "stop": offset + stop}
    return out


def slice_scene(scene: Scene, start: int, stop: int) -> Scene:
    """Frames [start, stop) of ``scene``: frames, estimates, cameras and every per-frame ground
    truth field cut to T' = stop - start frames, the flows and their masks to the T' - 1 pairs
    between them; per-frame metadata cut likewise (``metadata["chunk"]`` records [start, stop)
    in the source's frames). A copy; ValueError unless 0 <= start < stop <= T."""
    T = scene.num_frames
    if isinstance(start, bool) or isinstance(stop, bool) or not (isinstance(start, int) and isinstance(stop, int)):
        raise TypeError(f"slice_scene: start and stop must be ints, got {start!r}, {stop!r}")
    if not 0 <= start < stop <= T:
        raise ValueError(f"slice_scene: frames [{start}, {stop}) of scene {scene.name!r}: expected "
                         f"0 <= start < stop <= {T}")  # fmt: skip
    return dataclasses.replace(
        scene, frames=_cut(scene.frames, start, stop), joints3d=_cut(scene.joints3d, start, stop),
        cameras=_cut_cameras(scene.cameras, start, stop), keypoints2d=_cut(scene.keypoints2d, start, stop),
        keypoints_conf=_cut(scene.keypoints_conf, start, stop), gt=_cut_gt(scene.gt, start, stop),
        metadata=_cut_metadata(scene.metadata, start, stop, T), person_boxes=_cut(scene.person_boxes, start, stop),
        others=tuple(person.map(lambda x: x[start:stop].clone()) for person in scene.others),
    )  # fmt: skip


# --- stitching ------------------------------------------------------------------------------------
def _spans(chunks: list[tuple[int, torch.Tensor]], total: int, extra: int, what: str) -> list[tuple[int, int]]:
    """[start, stop) of each chunk (in chunk order) on an axis of ``total`` items, a chunk
    of n items covering n + ``extra`` frames; ValueError unless sorted, in range, covering all
    and no chunk inside another."""
    if not chunks:
        raise ValueError(f"{what}: no chunks given")
    spans = []
    for i, (start, value) in enumerate(chunks):
        if not isinstance(value, torch.Tensor) or value.ndim < 1 or len(value) < 1:
            raise ValueError(f"{what}: chunk {i} is not a tensor with at least one {('frame', 'pair')[extra]}")
        if value.shape[1:] != chunks[0][1].shape[1:]:
            raise ValueError(f"{what}: chunk {i} has shape {tuple(value.shape)}, chunk 0 {tuple(chunks[0][1].shape)}")
        spans.append((int(start), int(start) + len(value)))
    if spans[0][0] != 0 or spans[-1][1] != total:
        raise ValueError(f"{what}: chunks span [{spans[0][0]}, {spans[-1][1]}), expected [0, {total}) of all items")
    for i, ((a0, a1), (b0, b1)) in enumerate(zip(spans, spans[1:])):
        if not (a0 < b0 and a1 < b1 and b0 <= a1):
            raise ValueError(f"{what}: chunks {i} [{a0}, {a1}) and {i + 1} [{b0}, {b1}) must be in order, "
                             "overlapping or adjacent, neither inside the other")  # fmt: skip
    return spans


def stitch_sequences(chunks: list[tuple[int, torch.Tensor]], num_frames: int,
                     confidences: list[torch.Tensor] | None = None) -> torch.Tensor:
    """Per-frame tensors of chunks, (start, (T_c, ...)) in order of start, as one (num_frames,
    ...) sequence. Outside the overlaps a frame is its chunk's; inside the n frames shared by
    consecutive chunks the later one's weight ramps linearly (k + 1) / (n + 1), k = 0 .. n-1
    (0 and 1 fall just outside the overlap), the earlier one's is 1 minus that, so the sequence
    and its first differences stay continuous. (Weights are normalised where chunks overlap
    more than pairwise.) ``confidences``: per chunk, (T_c, ...) leading dims of its value (e.g.
    keypoint confidences (T_c, K) for keypoints (T_c, K, 2)), multiplied into the weights, so a
    chunk that did not find a keypoint lends it no position; where every chunk's confidence is
    0 the plain cross-fade is kept. Result dtype: the chunks' (floating point)."""
    spans = _spans(chunks, num_frames, 0, "stitch_sequences")
    if confidences is not None and len(confidences) != len(chunks):
        raise ValueError(f"stitch_sequences: {len(confidences)} confidences for {len(chunks)} chunks")
    dtype = chunks[0][1].dtype if chunks[0][1].is_floating_point() else torch.get_default_dtype()
    shape = chunks[0][1].shape[1:]
    plain, sure, sure_weight = [torch.zeros(num_frames, *shape, dtype=torch.float64) for _ in range(3)]
    plain_weight = torch.zeros(num_frames, *[1] * len(shape), dtype=torch.float64)
    for i, ((start, stop), (_, value)) in enumerate(zip(spans, chunks)):
        t = torch.arange(start, stop, dtype=torch.float64)
        w = torch.ones(stop - start, dtype=torch.float64)
        if i > 0 and (n := spans[i - 1][1] - start) > 0:
            w = torch.minimum(w, (t - start + 1) / (n + 1))
        if i + 1 < len(spans) and (n := stop - spans[i + 1][0]) > 0:
            w = torch.minimum(w, (stop - t) / (n + 1))
        w = w.view(-1, *[1] * len(shape))
        value = value.detach().to(torch.float64)
        plain[start:stop] += w * value
        plain_weight[start:stop] += w
        if confidences is not None:
            c = confidences[i].detach().to(torch.float64).clamp_min(0)
            if tuple(c.shape) != tuple(value.shape[: c.ndim]):
                raise ValueError(f"stitch_sequences: confidences {i} {tuple(c.shape)} do not lead value "
                                 f"{tuple(value.shape)}")  # fmt: skip
            wc = (w * c.reshape(*c.shape, *[1] * (value.ndim - c.ndim))).expand_as(value)
            sure[start:stop] += wc * value
            sure_weight[start:stop] += wc
    out = plain / plain_weight
    if confidences is not None:
        out = torch.where(sure_weight > 0, sure / sure_weight.clamp_min(1e-300), out)
    return out.to(dtype)


def stitch_pairs(chunks: list[tuple[int, torch.Tensor]], num_pairs: int) -> torch.Tensor:
    """Per-pair tensors of chunks, (start frame, (T_c - 1, ...)) in order of start (e.g. flows
    (T_c - 1, 2, H, W)), as one (num_pairs, ...): pair p (frame p -> p+1) comes from the chunk
    in which it lies farthest from a chunk end (for chunks of equal length, the one whose centre
    is nearest; the earlier on a tie), i.e. a hard switch at the middle of each overlap. No
    blending."""
    spans = _spans(chunks, num_pairs, 1, "stitch_pairs")
    margins = torch.full((len(spans), num_pairs), -1.0)
    for i, (start, stop) in enumerate(spans):  # stop: one past the chunk's last pair
        p = torch.arange(start, stop, dtype=torch.float32)
        margins[i, start:stop] = torch.minimum(p - start, stop - 1 - p)
    best = margins.argmax(0)  # the first maximum: the earlier chunk on a tie
    out = torch.empty(num_pairs, *chunks[0][1].shape[1:], dtype=chunks[0][1].dtype)
    for i, (start, stop) in enumerate(spans):
        take = (best == i).nonzero().flatten()
        out[take] = chunks[i][1][take - start].detach()
    return out


def _same(parts: list[tuple[int, PoseEstimates]], get, what: str) -> Any:
    values = [get(est) for _, est in parts]
    if any(v != values[0] for v in values):
        raise ValueError(f"stitch_estimates: the parts differ in {what}: {values}")
    return values[0]


def _stitch_frame_indices(parts: list[tuple[int, PoseEstimates]], num_frames: int) -> torch.Tensor:
    """The parts' frame_indices on the whole: 0..T-1 when every part has its default
    0..T_c-1; otherwise the parts' values, which must agree where parts overlap."""
    if all(est.frame_indices.tolist() == list(range(est.num_frames)) for _, est in parts):
        return torch.arange(num_frames, dtype=torch.int64)
    out = torch.full((num_frames,), -1, dtype=torch.int64)
    for start, est in parts:
        seen = out[start : start + est.num_frames]
        if ((seen >= 0) & (seen != est.frame_indices)).any():
            raise ValueError(f"stitch_estimates: frame_indices of the part at frame {start} disagree with "
                             "the previous part's where they overlap")  # fmt: skip
        out[start : start + est.num_frames] = est.frame_indices
    return out


def _stitch_person(parts: list[tuple[int, Person]], num_frames: int, camera_model: tuple | None) -> Person:
    """One person's per-chunk fields, (start frame, Person) in order of start, cross-faded into
    ``num_frames`` rows (keypoints weighted by their confidences too)."""

    def stitch(get, confidences: list[torch.Tensor] | None = None) -> torch.Tensor | None:
        values = [get(person) for _, person in parts]
        if all(v is None for v in values):
            return None
        if any(v is None for v in values):
            raise ValueError("stitch_estimates: a field is present in some parts only")
        return stitch_sequences([(start, v) for (start, _), v in zip(parts, values)], num_frames, confidences)

    cameras = None
    if camera_model is not None:
        cameras = Cameras(camera_model[0], stitch(lambda p: p.cameras.params), stitch(lambda p: p.cameras.crops),
                          camera_model[1])  # fmt: skip
    has_conf = all(p.keypoints_conf is not None for _, p in parts)  # a keypoint not found lends no position
    conf = [p.keypoints_conf for _, p in parts] if has_conf and parts[0][1].keypoints2d is not None else None
    return Person(parts[0][1].track_id, joints3d=stitch(lambda p: p.joints3d), cameras=cameras,
                  keypoints2d=stitch(lambda p: p.keypoints2d, conf), keypoints_conf=stitch(lambda p: p.keypoints_conf),
                  person_boxes=stitch(lambda p: p.person_boxes))  # fmt: skip


def stitch_estimates(parts: list[tuple[int, PoseEstimates]], num_frames: int) -> PoseEstimates:
    """Per-chunk pose estimates, (start frame, PoseEstimates of T_c rows) in order of start, as
    one PoseEstimates of ``num_frames`` rows: every person's (the same tracks in every part)
    keypoints2d (weighted by their confidences too), keypoints_conf, joints3d, boxes and the
    cameras' params and crops by :func:`stitch_sequences` (the cross-fade); layouts, camera
    model, image_size must agree across parts. ``metadata``: {"chunks": [[start, stop], ...],
    "parts": [each part's metadata]}."""
    from ..data.readers.pose_file import PoseEstimates

    if not parts:
        raise ValueError("stitch_estimates: no parts given")
    first = parts[0][1]
    for key in ("keypoints_layout", "joints3d_layout", "image_size"):
        _same(parts, lambda e: getattr(e, key), key)
    model = None
    if any(e.cameras is not None for _, e in parts):
        model = _same(parts, lambda e: None if e.cameras is None else (e.cameras.model, e.cameras.crop_size),
                      "cameras (model, crop_size)")  # fmt: skip
    ids = _same(parts, lambda e: [p.track_id for p in e.people()], "people (track ids)")
    main, *others = [_stitch_person([(start, e.people()[i]) for start, e in parts], num_frames, model)
                     for i in range(len(ids))]  # fmt: skip
    sources = list(dict.fromkeys(est.source for _, est in parts))
    return PoseEstimates(
        **main.fields(), track_id=main.track_id, others=tuple(others), keypoints_layout=first.keypoints_layout,
        joints3d_layout=first.joints3d_layout, frame_indices=_stitch_frame_indices(parts, num_frames),
        image_size=first.image_size, source="+".join(sources),
        metadata={"chunks": [[s, s + e.num_frames] for s, e in parts], "parts": [e.metadata for _, e in parts]},
    )  # fmt: skip
