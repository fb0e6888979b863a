"""One scene's consecutive frame pairs, with what the target sketch needs (FlowTTT's data).

A :class:`SceneFlowData` reads a scene folder (or takes a :class:`~lit_boot.core.Scene`) and
serves pairs (t, t+1): both frames, the pair index, and, when the scene has them, the ground
truth used for evaluation only (flow, its valid mask, the person mask, GT 2D joints at t and
t+1). :meth:`SceneFlowData.sketch_inputs` gives the joints the stick-man is drawn from.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import lightning as L
import torch
from torch.utils.data import DataLoader, Dataset

from ..core import Scene, get_layout
from ..data import load_scene

__all__ = ["POSE_SOURCES", "MODE_OF_SOURCE", "SketchInputs", "ScenePairs", "SceneFlowData"]

#: Where the stick-man comes from: projected 3D joints (3D mode), 2D keypoints (2D-only mode),
#: or the ground-truth 2D joints (an oracle, for benchmarks).
POSE_SOURCES = ("auto", "joints3d", "keypoints2d", "gt")
#: The method's mode (:data:`lit_boot.core.POSE_MODES`) whose pose each estimate source is.
MODE_OF_SOURCE = {"joints3d": "3d", "keypoints2d": "2d"}
SOURCE_OF_MODE = {mode: source for source, mode in MODE_OF_SOURCE.items()}


@dataclass
class SketchInputs:
    """Joints per pair: joints_t, joints_t1 (T-1, K, 2) px; confidence_t/_t1 (T-1, K) or None;
    depths (T-1, K) mm at t or None; the joints' layout name. A scene with several people gives
    every person's, with a person axis: (T-1, P, K, 2) and (T-1, P, K), the main person first."""

    layout: str
    joints_t: torch.Tensor
    joints_t1: torch.Tensor
    confidence_t: torch.Tensor | None
    confidence_t1: torch.Tensor | None
    depths: torch.Tensor | None


def sketch_inputs(scene: Scene, source: str = "auto") -> SketchInputs:
    """The joints to draw for every pair of ``scene``: the pose of a mode
    (:meth:`Scene.pose_points`) or the GT 2D joints. ``auto`` uses projected 3D joints when the
    scene has joints and cameras, else 2D keypoints."""
    if source not in POSE_SOURCES:
        raise ValueError(f"pose_source: expected one of {POSE_SOURCES}, got {source!r}")
    if source == "auto":
        source = "joints3d" if scene.joints3d is not None and scene.cameras is not None else "keypoints2d"
    if scene.others and source in MODE_OF_SOURCE:
        return _people_inputs(scene, MODE_OF_SOURCE[source])
    conf = depths = None
    if source in MODE_OF_SOURCE:
        mode = MODE_OF_SOURCE[source]
        try:
            joints, keep = scene.pose_points(mode)
        except ValueError as err:
            raise ValueError(f"pose_source {source!r}: {err}") from None
        layout = scene.pose_layout(mode)
        if mode == "3d":  # the frames with a pose (a filled-in pose, drawn, would say the person stood still)
            depths, conf = scene.joints3d[..., 2].float(), keep.float()
        else:
            conf = scene.keypoints_conf
    else:
        if scene.gt is None or scene.gt.joints2d is None:
            raise ValueError(f"pose_source 'gt': scene {scene.name!r} has no ground-truth 2D joints")
        joints, layout = scene.gt.joints2d, scene.gt.joints_layout
        depths = scene.gt.joints3d[..., 2] if scene.gt.joints3d is not None else None
    joints = joints.float()
    return SketchInputs(
        layout=get_layout(layout).name,
        joints_t=joints[:-1],
        joints_t1=joints[1:],
        confidence_t=None if conf is None else conf[:-1].float(),
        confidence_t1=None if conf is None else conf[1:].float(),
        depths=None if depths is None else depths[:-1],
    )


def _people_inputs(scene: Scene, mode: str) -> SketchInputs:
    """Every person's joints of ``mode`` (a person axis after the pair's). In 3D a person counts
    in the frames where its pose was estimated (:meth:`~lit_boot.core.Scene.pose_points`)."""
    joints, conf, depths = [], [], []
    for p in range(scene.num_people):
        person = scene.person(p)
        try:
            points, keep = person.pose_points(mode)
        except ValueError as err:
            raise ValueError(f"pose_source {SOURCE_OF_MODE[mode]!r}, person {person.track_id}: {err}") from None
        joints.append(points.float())
        if mode == "2d":
            conf.append(person.keypoints_conf.float())
        else:
            conf.append(keep.float())
            depths.append(person.joints3d[..., 2].float())
    joints, conf = torch.stack(joints, 1), torch.stack(conf, 1)
    return SketchInputs(layout=get_layout(scene.pose_layout(mode)).name, joints_t=joints[:-1], joints_t1=joints[1:],
                        confidence_t=conf[:-1], confidence_t1=conf[1:],
                        depths=torch.stack(depths, 1)[:-1] if depths else None)  # fmt: skip


class ScenePairs(Dataset):
    """Pairs (t, t+1) of one scene as dicts: image1, image2 (3, H, W) uint8, index; and gt_flow
    (2, H, W), gt_valid (H, W: where the flow is scored, GroundTruth.flow_mask: Sintel's matched),
    gt_unmatched (H, W: the valid pixels occluded in frame t+1, GroundTruth.unmatched_mask), person
    (H, W), gt_joints (J, 2) at t and gt_joints_next at t+1 when the scene has them."""

    def __init__(self, scene: Scene):
        self.scene = scene
        self.flow_mask = scene.gt.flow_mask() if scene.gt is not None else None  # once, not per pair
        self.unmatched = scene.gt.unmatched_mask() if scene.gt is not None else None

    def __len__(self) -> int:
        return self.scene.num_frames - 1

    def __getitem__(self, i: int) -> dict[str, torch.Tensor]:
        s = self.scene
        item = {"image1": s.frames[i], "image2": s.frames[i + 1], "index": torch.tensor(i)}
        gt = s.gt
        if gt is not None and gt.flow is not None:
            item["gt_flow"] = gt.flow[i].float()
            item["gt_valid"] = self.flow_mask[i]  # valid and not occluded, as the orchestrator scores
            if self.unmatched is not None:
                item["gt_unmatched"] = self.unmatched[i]
        if gt is not None and gt.person_mask is not None:
            item["person"] = gt.person_mask[i]
        if gt is not None and gt.joints2d is not None:
            item["gt_joints"] = gt.joints2d[i].float()
            item["gt_joints_next"] = gt.joints2d[i + 1].float()
        return item


class SceneFlowData(L.LightningDataModule):
    """One scene's pairs for FlowTTT.

    Args:
        scene: a scene folder (see ``lit-boot synth``), or a Scene object from Python.
        pose_source: where the stick-man comes from: auto, joints3d, keypoints2d, or gt (oracle).
        batch_size: pairs per step (the paper: 1).
        shuffle: visit the pairs in random order each epoch.
        num_workers: DataLoader workers.
    """

    def __init__(
        self,
        scene: str | Path | Scene,
        pose_source: str = "auto",
        batch_size: int = 1,
        shuffle: bool = True,
        num_workers: int = 0,
    ):
        super().__init__()
        if pose_source not in POSE_SOURCES:
            raise ValueError(f"pose_source: expected one of {POSE_SOURCES}, got {pose_source!r}")
        self.scene_arg = scene
        self.pose_source = pose_source
        self.batch_size = batch_size
        self.shuffle = shuffle
        self.num_workers = num_workers
        self.scene: Scene | None = scene if isinstance(scene, Scene) else None

    @property
    def name(self) -> str:
        """The scene's name (its folder name before it is loaded)."""
        return self.scene.name if self.scene is not None else Path(self.scene_arg).name

    def setup(self, stage: str | None = None) -> None:
        if self.scene is None:
            self.scene = load_scene(self.scene_arg)
        if self.scene.num_frames < 2:
            raise ValueError(f"scene {self.scene.name!r}: needs at least 2 frames for flow, has 1")

    def sketch_inputs(self) -> SketchInputs:
        self.setup()
        return sketch_inputs(self.scene, self.pose_source)

    def _loader(self, shuffle: bool) -> DataLoader:
        self.setup()
        return DataLoader(
            ScenePairs(self.scene), batch_size=self.batch_size, shuffle=shuffle, num_workers=self.num_workers
        )

    def train_dataloader(self) -> DataLoader:
        return self._loader(self.shuffle)

    def val_dataloader(self) -> DataLoader:
        return self._loader(False)

    def predict_dataloader(self) -> DataLoader:
        return self._loader(False)
