"""The orchestrator's settings, and the presets that fill in the method's choices (the zoom
stage's and the self-check's own settings: :mod:`~lit_boot.bootstrap.stage_configs`).

Presets (``BootstrapConfig.preset``), each described once, beside its entry in :data:`PRESETS`:
``paper``, what the authors' code does, and ``default``, the paper's text where it differs,
the self-check on and the fast fine-tune.

A user's ``flow`` / ``pose`` dicts (FlowTTT's / the refiner's constructor arguments, typed by
:mod:`~lit_boot.bootstrap.options`) override the preset, key by key (``sketch`` too:
``{"sketch": {"size": 5}}`` keeps the preset's footprint).
"""

from __future__ import annotations

import copy
from dataclasses import asdict, dataclass, field
from typing import Any

from .options import FlowOptions, PoseOptions, check_options
from .stage_configs import SELF_CHECKS, WHOLE_FRAME_MAX_CHANGE_PX, ZOOMS, SelfCheckConfig, ZoomConfig


__all__ = ["PRESETS", "MODES", "DRIFT_GUARDS", "SELF_CHECKS", "ZOOMS", "ACCELERATORS", "PRECISIONS", "SelfCheckConfig",
           "ZoomConfig", "BootstrapConfig"]

MODES = ("3d", "2d")  # lit_boot.core.POSE_MODES, literal here: the CLI reads this module without torch
DRIFT_GUARDS = ("record", "stop", "rollback")
#: Lightning accelerators a run may name (auto: CUDA when available, else the CPU).
ACCELERATORS = ("auto", "cpu", "cuda", "gpu", "mps")
#: Lightning precisions (its short forms too: "16" is 16-mixed, "bf16" bf16-mixed, "32" / 32 32-true).
PRECISIONS = ("32-true", "16-mixed", "bf16-mixed", "16-true", "bf16-true", "64-true", "32", "16", "bf16", "64", 32, 16,
              64)

#: The default preset's fast fine-tune (issue 15): see lit_boot.flow.warm.
FAST_FLOW: dict[str, Any] = {"train_parts": "update_block", "warm_start": True, "train_updates": 2, "crop_margin": 24,
                              "sketch_gap": 2.0}

#: Per preset and mode: FlowTTT arguments, refiner arguments, options of the orchestrator.
PRESETS: dict[str, dict[str, dict[str, Any]]] = {
    "paper": {
        # what the authors' code does (REFERENCE section 3): the stick-man painted with 30x30 px
        # squares at 22 points per bone (6x6 in the 2D-only Sintel script) whatever the person's
        # size, binary confidences, 20 RAFT updates per step from zero, every weight trained, lr
        # 1e-5, SmoothL1 (beta 1) on the final prediction, BatchNorm not frozen, 16-bit mixed
        # precision on CUDA (fp16), the refiners' paper lambdas, no self-check
        "flow_3d": {"sketch": {"footprint": "square", "size": 30, "points_per_bone": 22}, "loss": "final",
                    "train_updates": 20, "freeze_batchnorm": False, "lr": 1e-5},
        "flow_2d": {"sketch": {"footprint": "square", "size": 6, "points_per_bone": 22}, "loss": "final",
                    "train_updates": 20, "freeze_batchnorm": False, "lr": 1e-5},
        "pose_3d": {"confidence": "binary"},
        "pose_2d": {"confidence": "binary"},
        "options": {"scale_footprint": False, "cuda_precision": "16-mixed", "self_check": "off", "zoom": "off"},
    },
    "default": {
        # the paper's text instead of its code where they differ: a cross of radius 15 px at a
        # person 450 px tall (as on Human3.6M), scaled to the person's height in the video and
        # never below 2 px (a fixed 30 px square paints most of a small person and the background
        # around it); the self-check on, which holds the background; and the fast fine-tune
        # (lit_boot.flow.warm): frozen cached encoders, 2 RAFT updates per step from RAFT's own
        # flow on a crop around the person, pasted into RAFT's flow, lr 3e-5 (2e-5 in 2D); the
        # sketch's pixels weigh 5x in a SmoothL1 with beta 0.1, the unpainted ones within 2
        # footprint radii of it not at all (they may be the limb's: sketch_gap); in 2D (50
        # epochs) the fit stops when its loss stops falling (3 epochs without a 2% fall) and
        # backpropagates through the last update only; before the flow stages, the zoom stage
        # refines RAFT's flow where the person is (ZoomConfig); in 2D, with several people,
        # every person's painted pixels weigh the same (people_balance; no effect on one person).
        # Everything else as paper. (BENCHMARKS.md, "Speed", "Do no harm", "The unknown zone" and
        # "Several people")
        "flow_3d": {**FAST_FLOW, "sketch": {"footprint": "cross", "size": 15}, "loss": "final", "lr": 3e-5,
                    "sketch_weight": 5.0, "loss_beta": 0.1},
        "flow_2d": {**FAST_FLOW, "sketch": {"footprint": "cross", "size": 15}, "loss": "final", "lr": 2e-5,
                    "sketch_weight": 5.0, "loss_beta": 0.1, "plateau_patience": 3, "plateau_delta": 0.02,
                    "grad_updates": 1, "people_balance": True},
        "pose_3d": {"confidence": "binary"},
        "pose_2d": {"confidence": "binary"},
        "options": {"scale_footprint": True, "cuda_precision": "16-mixed", "self_check": "photometric",
                    "zoom": "person"},
    },
}  # fmt: skip

#: The person height (px) at which the paper's footprint sizes hold (Human3.6M, 1000x1000 frames).
REFERENCE_PERSON_PX = 450.0


def _nested(name: str, value: Any, kind: type) -> Any:
    """``value`` as a ``kind`` dataclass (a dict of its fields is taken); ValueError naming
    ``name`` otherwise."""
    fields = kind.__dataclass_fields__
    if isinstance(value, dict):
        unknown = sorted(set(value) - set(fields))
        if unknown:
            raise ValueError(f"{name}: unknown key {unknown[0]!r}; expected some of {list(fields)}")
        value = kind(**value)
    if not isinstance(value, kind):
        raise ValueError(f"{name}: expected a {kind.__name__} or a dict of its fields ({', '.join(fields)}), "
                         f"got {value!r}")
    return value


def merge(base: dict[str, Any], override: dict[str, Any]) -> dict[str, Any]:
    """``base`` updated by ``override``, nested dicts merged key by key (copies; inputs kept)."""
    out = copy.deepcopy(base)
    for key, value in override.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = merge(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


@dataclass
class BootstrapConfig:
    """How a bootstrap run goes.

    Args:
        mode: 3d (joints and cameras; the stick-man from projected joints) or 2d (2D keypoints
            only; paper 3.3).
        preset: the method's choices the run starts from. default: the paper's text where it
            differs from the authors' code (a cross footprint scaled to the person), the
            self-check on and the fast fine-tune. paper: the authors' code. Each is described
            beside its entry in PRESETS (lit_boot/bootstrap/config.py). --flow and --pose
            override them key by key.
        cycles: pose cycles; the run is flow, (pose, flow) x cycles: the paper's 1 gives
            flow -> pose -> flow.
        flow: FlowTTT arguments over the preset's (arch, weights, lr, sketch, crop_margin, ...).
        pose: PoseRefiner / KeypointRefiner arguments over the preset's (lr, loss_weights, ...).
        flow_epochs: epochs per flow stage; None: 8 in 3D mode, 50 in 2D mode (the paper).
        pose_steps: Adam steps per pose stage (the paper: 1500).
        early_stop: the authors' early stop of the pose stage (loss unchanged to 4 decimals for
            10 steps).
        restart_flow: each flow stage starts from the pretrained weights (else, as the
            authors, it continues from the previous flow stage's).
        flow_ensemble: extra FlowTTT argument dicts (e.g. [{"arch": "raft_large", "weights":
            "C_T_V1"}]): each network is fine-tuned alike and the flows are averaged (Table 2).
        pose_ensemble: extra refined-pose folders (poses.npz + pose_report.json, e.g. another
            estimator's joints in the same layout) averaged with the scene's estimates first.
        accelerator: for the flow stages: auto (CUDA when available, else the CPU), cpu, cuda,
            gpu or mps.
        pose_accelerator: for the pose stages (a few thousand numbers: the CPU is faster).
        precision: Lightning precision of the flow stages (32-true, 16-mixed, bf16-mixed,
            16-true, bf16-true, 64-true, or Lightning's short forms 32, 16, bf16, 64); None: the
            preset's on CUDA (mixed), 32-true on CPU.
        drift_guard: after each stage its image evidence (no ground truth; see
            :mod:`lit_boot.bootstrap.guard`) is compared with the last stage's: a flow stage's
            census error of the frames warped by its flow, a pose stage's census error along
            the joint tracks. When a stage made it worse by more than drift_tolerance: record
            (the event goes into summary.json, the log and report.html; the run goes on), stop
            (stop the run there) or rollback (undo that stage and stop).
        drift_tolerance: how much worse, as a fraction (0.01: 1%), a stage's evidence may get
            before the drift guard acts.
        flow_format: flo (one Middlebury file per pair) or npz for the run's final flows.
        video: write overlay.mp4.
        progress_bar: Lightning's progress bars (off from Python; ``lit-boot bootstrap`` and the
            demo turn them on).
        self_check: after each flow stage, without ground truth: keep the tuned flow only where
            the frames say it beats the flow it started from (:class:`SelfCheckConfig`:
            ``method`` None is the preset's; a dict of its fields is taken too).
        zoom: before the flow stages, RAFT on a zoomed crop around the person, kept unless the
            frames refuse it (:class:`ZoomConfig`: ``method`` None is the preset's; a dict of
            its fields is taken too).
        seed: seed_everything before each stage (the same run gives the same result).
    """

    mode: str = "3d"
    preset: str = "default"
    cycles: int = 1
    flow: FlowOptions = field(default_factory=dict)
    pose: PoseOptions = field(default_factory=dict)
    flow_epochs: int | None = None
    pose_steps: int = 1500
    early_stop: bool = True
    restart_flow: bool = False
    flow_ensemble: list[FlowOptions] = field(default_factory=list)
    pose_ensemble: list[str] = field(default_factory=list)
    accelerator: str = "auto"
    pose_accelerator: str = "cpu"
    precision: str | None = None
    drift_guard: str = "record"
    drift_tolerance: float = 0.0
    flow_format: str = "flo"
    video: bool = True
    progress_bar: bool = False
    self_check: SelfCheckConfig = field(default_factory=SelfCheckConfig)
    zoom: ZoomConfig = field(default_factory=ZoomConfig)
    seed: int = 0

    def __post_init__(self) -> None:
        self.self_check = _nested("self_check", self.self_check, SelfCheckConfig)
        self.zoom = _nested("zoom", self.zoom, ZoomConfig)
        checks = [("mode", MODES), ("preset", tuple(PRESETS)), ("drift_guard", DRIFT_GUARDS),
                  ("flow_format", ("flo", "npz")), ("accelerator", ACCELERATORS), ("pose_accelerator", ACCELERATORS)]
        for name, allowed in checks:
            if getattr(self, name) not in allowed:
                raise ValueError(f"{name}: expected one of {allowed}, got {getattr(self, name)!r}")
        precision = self.precision
        if precision is not None and (type(precision) not in (str, int) or precision not in PRECISIONS):
            raise ValueError(f"precision: expected None (the preset's) or a Lightning precision, one of "
                             f"{', '.join(map(str, PRECISIONS[:10]))}; got {precision!r}")  # fmt: skip
        check_options("flow", self.flow, FlowOptions)
        check_options("pose", self.pose, PoseOptions)
        for i, member in enumerate(self.flow_ensemble):
            check_options(f"flow_ensemble[{i}]", member, FlowOptions)
        if self.cycles < 0:
            raise ValueError(f"cycles: expected >= 0, got {self.cycles}")
        if self.flow_epochs is not None and self.flow_epochs < 1:
            raise ValueError(f"flow_epochs: expected >= 1 or None, got {self.flow_epochs}")
        if self.pose_steps < 1:
            raise ValueError(f"pose_steps: expected >= 1, got {self.pose_steps}")
        if self.drift_tolerance < 0:
            raise ValueError(f"drift_tolerance: expected a fraction >= 0, got {self.drift_tolerance}")

    @property
    def epochs(self) -> int:
        """Epochs per flow stage."""
        return self.flow_epochs if self.flow_epochs is not None else (8 if self.mode == "3d" else 50)

    def stages(self) -> list[str]:
        """Stage names in order: zoom (when on), flow_1, pose_1, flow_2, ..."""
        names = ["zoom", "flow_1"] if self.zooming != "off" else ["flow_1"]
        for c in range(1, self.cycles + 1):
            names += [f"pose_{c}", f"flow_{c + 1}"]
        return names

    def option(self, name: str) -> Any:
        return PRESETS[self.preset]["options"][name]

    @property
    def checking(self) -> str:
        """The self-check the flow stages use: ``self_check.method``, or the preset's when None."""
        method = self.self_check.method
        return method if method is not None else self.option("self_check")

    @property
    def change_limit(self) -> float | None:
        """The self-check's refinement limit, px: ``self_check.max_change_px``, "auto" resolved
        (:data:`WHOLE_FRAME_MAX_CHANGE_PX` where ``flow.crop_margin`` is None, else None)."""
        limit = self.self_check.max_change_px
        if limit != "auto":
            return limit
        return WHOLE_FRAME_MAX_CHANGE_PX if self.flow_kwargs().get("crop_margin") is None else None

    @property
    def zooming(self) -> str:
        """The zoom stage's method: ``zoom.method``, or the preset's when None."""
        method = self.zoom.method
        return method if method is not None else self.option("zoom")

    def flow_kwargs(self, member: int = 0, person_px: float | None = None) -> dict[str, Any]:
        """FlowTTT arguments for ensemble member ``member`` (0: ``flow``), the preset's
        footprint scaled to a person ``person_px`` tall when the preset says so and the user
        gave no size."""
        user = self.flow if member == 0 else merge(self.flow, self.flow_ensemble[member - 1])
        kwargs = merge(PRESETS[self.preset][f"flow_{self.mode}"], user)
        user_size = "size" in user.get("sketch", {})
        if self.option("scale_footprint") and not user_size and person_px:
            size = kwargs["sketch"]["size"] * person_px / REFERENCE_PERSON_PX
            kwargs["sketch"]["size"] = max(2, int(round(size)))
        return kwargs

    def pose_kwargs(self) -> dict[str, Any]:
        """Refiner arguments: the preset's, then the user's."""
        return merge(PRESETS[self.preset][f"pose_{self.mode}"], self.pose)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)
