"""The metrics lit-boot reports, under one naming scheme and one convention.

Names (the same everywhere: FlowTTT's and the refiners' validation, the orchestrator's stage
records, summary.json, :class:`~lit_boot.pose.PoseResult`):

- flow, px: ``epe`` (every valid, non-occluded pixel: :meth:`GroundTruth.flow_mask`; Sintel's
  "matched"), ``epe_unmatched`` (the valid pixels occluded in frame t+1) and ``epe_all_pixels``
  (every valid pixel, occluded or not: Sintel's "all"; both where the GT marks occlusions),
  ``epe_person`` / ``epe_background`` (the matched pixels on / off the GT person mask of frame t),
  ``epe_joints`` (the authors' convention: each GT joint's displacement t -> t+1 against the
  flow at the joint's rounded pixel, joints inside the image);
- 3D poses, mm: ``mpjpe_mm`` (root-aligned, the layout's root), ``pa_mpjpe_mm`` (Procrustes),
  ``accel_mm_per_frame2`` (3 frames or more); 2D points, px: ``proj2d_px`` (3D mode: the
  projected joints against the GT 2D joints), ``kp2d_px`` (2D mode: the keypoints against the
  GT keypoints).

With several people the bare pose names are the main person's, ``<name>_all`` pools every person
with ground truth, ``<name>_person<track id>`` is one other person's (:func:`people_metric_objects`);
the flow's ``epe_person`` is every person's pixels (pooled by nature), and each person's own are
``epe_person_person<track id>`` and ``epe_joints_person<track id>`` (:func:`scene_flow_metrics`).

Lightning modules log them as ``val/<name>``; the orchestrator's records and the pose results
hold the bare names. EPE-like means pool every selected pixel (or joint) of every pair.
``scene_flow_metric_objects`` / ``scene_pose_metric_objects`` give the updated ``Metric``
objects behind those numbers (their sum states: :mod:`lit_boot.metrics.states`).
"""

from __future__ import annotations

import re

import torch
import torch.nn.functional as F
from torch import Tensor
from torchmetrics import Metric

from ..core import GroundTruth, Person, PersonTruth, Scene, get_layout, inside_image
from .flow import EndPointError, PointEndPointError
from .pose import AccelerationError, MeanPerJointPositionError, Root

__all__ = [
    "FlowMetrics",
    "PoseMetrics",
    "scene_flow_metrics",
    "scene_pose_metrics",
    "scene_flow_metric_objects",
    "scene_pose_metric_objects",
    "people_metric_objects",
    "base_metric_name",
    "metric_person",
    "POOLED_SUFFIX",
    "PERSON_SUFFIX",
]

#: Name suffixes of the metrics of scenes with several people: ``kp2d_px_all`` pools every
#: person, ``kp2d_px_person3`` is track 3's; the bare name is the main person's.
POOLED_SUFFIX = "_all"
PERSON_SUFFIX = "_person"
#: The flow metrics reported for each person of a scene with several (the others are whole-frame).
FLOW_PEOPLE_METRICS = ("epe_person", "epe_joints")
_PERSON_NAME = re.compile(rf".+?{PERSON_SUFFIX}(\d+)")
_PEOPLE_NAME = re.compile(rf"(.+?)(?:{POOLED_SUFFIX}|{PERSON_SUFFIX}\d+)")


def _values(metrics: dict[str, Metric]) -> dict[str, float]:
    """{name: float(metric.compute())}."""
    return {name: float(metric.compute()) for name, metric in metrics.items()}


class FlowMetrics(torch.nn.Module):
    """``epe``, ``epe_unmatched``, ``epe_all_pixels``, ``epe_person``, ``epe_background``,
    ``epe_joints`` (px), accumulated over batches of pairs (torchmetrics sum states);
    :meth:`compute` holds only those updated, each name prefixed by ``prefix`` (e.g. ``"val/"``)."""

    def __init__(self, prefix: str = ""):
        super().__init__()
        self.prefix = prefix
        self.epe = EndPointError()
        self.epe_unmatched = EndPointError()
        self.epe_all_pixels = EndPointError()
        self.epe_person = EndPointError()
        self.epe_background = EndPointError()
        self.epe_joints = PointEndPointError(mode="nearest")

    def update(
        self,
        flow: Tensor,
        gt_flow: Tensor | None = None,
        mask: Tensor | None = None,
        person: Tensor | None = None,
        joints: Tensor | None = None,
        joints_next: Tensor | None = None,
        unmatched: Tensor | None = None,
    ) -> None:
        """flow, gt_flow: (B, 2, H, W) px; mask: (B, H, W) bool, the pixels that count (valid and
        not occluded: matched); person: (B, H, W) bool; joints, joints_next: (B, K, 2) px, the GT
        joints in frames t and t+1; unmatched: (B, H, W) bool, the valid pixels occluded in frame
        t+1 (``epe_unmatched``, and with ``mask`` ``epe_all_pixels``). What is None is not scored."""
        if gt_flow is not None:
            self.epe.update(flow, gt_flow, mask)
        if gt_flow is not None and unmatched is not None:
            self.epe_unmatched.update(flow, gt_flow, unmatched)
            self.epe_all_pixels.update(flow, gt_flow, unmatched | mask if mask is not None else None)
        if gt_flow is not None and person is not None:
            self.epe_person.update(flow, gt_flow, mask & person)
            self.epe_background.update(flow, gt_flow, mask & ~person)
        if joints is not None:
            H, W = flow.shape[-2:]
            self.epe_joints.update(flow, joints, joints_next - joints, inside_image(joints, H, W))

    def updated(self) -> dict[str, Metric]:
        """{name: metric} of the metrics updated so far (no prefix)."""
        return {name: metric for name, metric in self.named_children() if metric.update_called}

    def compute(self) -> dict[str, Tensor]:
        return {self.prefix + name: metric.compute() for name, metric in self.updated().items()}

    def reset(self) -> None:
        for metric in self.children():
            metric.reset()


class PoseMetrics(torch.nn.Module):
    """Pose errors against ground truth, computed at once on whole videos: :meth:`joints3d`
    (``mpjpe_mm``, ``pa_mpjpe_mm``, ``accel_mm_per_frame2``) and :meth:`points2d` (a mean 2D
    distance in px under a given name). ``root``: the layout's root joint indices."""

    def __init__(self, root: Root = (0,)):
        super().__init__()
        self.mpjpe = MeanPerJointPositionError("root", root=root)
        self.pa_mpjpe = MeanPerJointPositionError("procrustes", root=root)
        self.accel = AccelerationError(root=root)
        self.points = MeanPerJointPositionError("none")

    @staticmethod
    def _once(metric: Metric, *args: Tensor) -> Metric:
        """A copy of ``metric`` updated with ``args`` alone (the states are the copy's own)."""
        metric = metric.clone()
        metric.reset()
        metric.update(*args)
        return metric

    @torch.no_grad()
    def joints3d_metrics(self, pred: Tensor, gt: Tensor) -> dict[str, Metric]:
        """The updated metrics behind :meth:`joints3d`, by name."""
        out = {"mpjpe_mm": self._once(self.mpjpe, pred, gt), "pa_mpjpe_mm": self._once(self.pa_mpjpe, pred, gt)}
        if pred.shape[0] >= 3:
            out["accel_mm_per_frame2"] = self._once(self.accel, pred, gt)
        return out

    @torch.no_grad()
    def points2d_metrics(self, name: str, pred: Tensor, gt: Tensor) -> dict[str, Metric]:
        """The updated metric behind :meth:`points2d`, {name: metric}."""
        return {name: self._once(self.points, F.pad(pred, (0, 1)), F.pad(gt, (0, 1)))}  # z = 0 on both sides

    def joints3d(self, pred: Tensor, gt: Tensor) -> dict[str, float]:
        """pred, gt: (T, J, 3) mm."""
        return _values(self.joints3d_metrics(pred, gt))

    def points2d(self, name: str, pred: Tensor, gt: Tensor) -> dict[str, float]:
        """{name: mean distance px} of pred, gt (T, K, 2) px over every point of every frame."""
        return _values(self.points2d_metrics(name, pred, gt))


def _flow_metric_objects(gt: GroundTruth, flows: Tensor, person: Tensor | None,
                         joints: Tensor | None) -> dict[str, Metric]:  # fmt: skip
    """The updated :class:`FlowMetrics` of ``flows`` with ``person`` (T, H, W) bool as the person
    mask and ``joints`` (T, J, 2) px as the GT joints (either may be None)."""
    metrics = FlowMetrics()
    joints = joints.float() if joints is not None else None
    metrics.update(flows.float(), gt.flow.float() if gt.flow is not None else None, gt.flow_mask(),
                   person[:-1] if person is not None else None,
                   joints[:-1] if joints is not None else None, joints[1:] if joints is not None else None,
                   gt.unmatched_mask())  # fmt: skip
    return metrics.updated()


@torch.no_grad()
def scene_flow_metric_objects(gt: GroundTruth | None, flows: Tensor, track_id: int = 0) -> dict[str, Metric]:
    """The updated metrics behind :func:`scene_flow_metrics`, by name; {} without GT."""
    if gt is None:
        return {}
    out = _flow_metric_objects(gt, flows, gt.person_mask, gt.joints2d)
    if not gt.others:
        return out
    ids = [int(track_id), *(o.track_id for o in gt.others)]
    for person_id, truth in zip(ids, gt.truths(ids)):
        own = _flow_metric_objects(gt, flows, truth.person_mask, truth.joints2d)
        out.update({f"{name}{PERSON_SUFFIX}{person_id}": own[name] for name in FLOW_PEOPLE_METRICS if name in own})
    return out


def scene_flow_metrics(gt: GroundTruth | None, flows: Tensor, track_id: int = 0) -> dict[str, float]:
    """The flow metrics of ``flows`` (T-1, 2, H, W) px against a scene's ground truth (the GT
    flow's, and ``epe_joints`` with GT 2D joints); {} without either. With other people in the
    GT, ``epe_person`` stays every person's pixels and ``epe_joints`` the main person's joints,
    and each person's own are added as ``epe_person_person<id>`` / ``epe_joints_person<id>`` (the
    main person's under ``track_id``)."""
    return _values(scene_flow_metric_objects(gt, flows, track_id))


def _person_pose_metric_objects(scene: Scene, person: Person, truth: PersonTruth, mode: str) -> dict[str, Metric]:
    """One person's pose metrics against its truth (the layouts: the scene's and its GT's)."""
    if mode == "2d":
        if truth.keypoints2d is None or person.keypoints2d is None:
            return {}
        return PoseMetrics().points2d_metrics("kp2d_px", person.keypoints2d.float(), truth.keypoints2d.float())
    if person.joints3d is None or get_layout(scene.gt.joints_layout) != get_layout(scene.joints3d_layout):
        return {}
    metrics = PoseMetrics(root=get_layout(scene.joints3d_layout).root or (0,))
    joints = person.joints3d.float()
    out = metrics.joints3d_metrics(joints, truth.joints3d.float()) if truth.joints3d is not None else {}
    if truth.joints2d is not None and person.cameras is not None:
        out.update(metrics.points2d_metrics("proj2d_px", person.cameras.project(joints), truth.joints2d.float()))
    return out


def people_metric_objects(per_person: list[dict[str, Metric]], track_ids: list[int]) -> dict[str, Metric]:
    """Every person's metrics under one set of names: the main person's (the first) under the
    bare names; with several people also ``<name>_all`` (pooled over every person scored: their
    states merged) and ``<name>_person<track id>`` for each other person."""
    out = dict(per_person[0])
    if len(per_person) < 2:
        return out
    for name in dict.fromkeys(name for metrics in per_person for name in metrics):
        scored = [metrics[name] for metrics in per_person if name in metrics]
        pooled = scored[0].clone()
        for metric in scored[1:]:
            pooled.merge_state(metric)
        out[f"{name}{POOLED_SUFFIX}"] = pooled
    for track_id, metrics in zip(track_ids[1:], per_person[1:]):
        out.update({f"{name}{PERSON_SUFFIX}{track_id}": metric for name, metric in metrics.items()})
    return out


def base_metric_name(name: str) -> str:
    """The metric a (pooled or per-person) name reports: ``kp2d_px_person3`` -> ``kp2d_px``."""
    match = _PEOPLE_NAME.fullmatch(name)
    return match.group(1) if match else name


def metric_person(name: str) -> int | None:
    """The track id of a per-person metric name (``kp2d_px_person3`` -> 3), else None."""
    match = _PERSON_NAME.fullmatch(name)
    return int(match.group(1)) if match else None


@torch.no_grad()
def scene_pose_metric_objects(scene: Scene, mode: str) -> dict[str, Metric]:
    """The updated metrics behind :func:`scene_pose_metrics`, by name; {} without GT."""
    if scene.gt is None:
        return {}
    people = scene.people()
    ids = [person.track_id for person in people]
    truths = scene.gt.truths(ids)
    per_person = [{} if truth is None else _person_pose_metric_objects(scene, person, truth, mode)
                  for person, truth in zip(people, truths)]  # fmt: skip
    return people_metric_objects(per_person, ids)


def scene_pose_metrics(scene: Scene, mode: str) -> dict[str, float]:
    """The scene's current estimates against its ground truth: 3D mode, the 3D joints (GT in
    the same layout) and their projection (GT 2D joints); 2D mode, ``kp2d_px``; {} without GT.
    With several people: also pooled and per person (:func:`people_metric_objects`)."""
    return _values(scene_pose_metric_objects(scene, mode))
