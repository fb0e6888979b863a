"""The typed parts of :class:`~lit_boot.bootstrap.BootstrapConfig`: what ``flow``, ``pose`` and
``flow_ensemble`` may hold.

Each is a ``TypedDict`` of the constructor arguments it overrides (FlowTTT with its
SketchConfig, the refiners with their loss lambdas), every key optional: a key that is absent
keeps the preset's value, which is why these are dicts and not dataclasses (None is a value of
its own for several arguments: ``weights=None`` is a random initialisation). Type checkers and
the command line (jsonargparse) check them by these annotations; :func:`check_options` refuses
an unknown key from Python before anything runs. The keys are tested against the classes'
signatures. Imports nothing heavy (the CLI's help reads this module).
"""

from __future__ import annotations

from typing import Any, TypedDict

__all__ = ["SketchOptions", "FlowOptions", "LossWeightOptions", "PoseOptions", "check_options"]


class SketchOptions(TypedDict, total=False):
    """:class:`lit_boot.flow.SketchConfig`'s fields: how the stick-man is drawn and guarded."""

    footprint: str
    size: int
    points_per_bone: int | None
    confidence_threshold: float
    guard: bool
    max_disagreement_px: float
    point_disagreement_factor: float
    max_joint_jump: float
    gate: str
    gate_margin: float
    gate_level: str
    gate_core: float
    gate_search: int


class FlowOptions(TypedDict, total=False):
    """:class:`lit_boot.flow.FlowTTT`'s arguments."""

    arch: str
    weights: str | None
    train_updates: int
    grad_updates: int | None
    predict_updates: int
    lr: float
    loss: str
    gamma: float
    loss_beta: float
    target_updates: int | None
    sketch_weight: float
    sketch_gap: float
    train_parts: str
    freeze_batchnorm: bool
    crop_margin: int | None
    hold_weight: float
    hold: str
    people_balance: bool
    warm_start: bool
    paste_crop: bool
    plateau_patience: int | None
    plateau_delta: float
    sketch: SketchOptions


class LossWeightOptions(TypedDict, total=False):
    """The refiners' lambdas: PoseLossWeights' (3D) and KeypointLossWeights' (2D) fields."""

    opt: float
    joints3d: float
    keypoints2d: float
    pos: float
    cam: float
    bone: float
    proj_smooth: float
    init: float
    smooth: float


class PoseOptions(TypedDict, total=False):
    """:class:`lit_boot.pose.PoseRefiner`'s (3D) and :class:`lit_boot.pose.KeypointRefiner`'s
    (2D) arguments; the orchestrator saves the poses itself (no ``save``, ``output_dir``)."""

    lr: float
    loss_weights: LossWeightOptions
    keypoint_joints: list[str] | None
    confidence: str
    confidence_threshold: float
    flow_inside_only: bool
    pixel_scale: float
    eval_every_n_steps: int
    num_threads: int | None
    people: str


def check_options(name: str, options: Any, kind: type) -> None:
    """ValueError naming ``name`` and the key unless ``options`` is a dict whose keys (and
    nested keys) are ``kind``'s (a TypedDict above)."""
    if not isinstance(options, dict):
        raise ValueError(f"{name}: expected a dict of {kind.__name__} keys, got {type(options).__name__}")
    known = kind.__annotations__
    for key, value in options.items():
        if key not in known:
            raise ValueError(f"{name}: unknown key {key!r}; expected some of {sorted(known)}")
        nested = {"sketch": SketchOptions, "loss_weights": LossWeightOptions}.get(key)
        if nested is not None and isinstance(value, dict):  # (a SketchConfig or lambdas instance is the class's to check)
            check_options(f"{name}.{key}", value, nested)
