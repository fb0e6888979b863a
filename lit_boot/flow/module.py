"""FlowTTT: fine-tune RAFT on one video to follow the pose-sketched target flow (paper 3.1).

At the start of fitting (:meth:`FlowTTT.prepare`, from the SceneFlowData's scene unless the
module was prepared), the module predicts RAFT's own flow for every pair (the base flow), draws
the stick-man from the scene's poses, and paints it over the base flow: the targets. Each
training step runs RAFT with ``train_updates`` iterations on one pair and pulls the final
prediction towards the target (:class:`~lit_boot.flow.losses.SketchLoss`; with ``warm_start``
through :class:`~lit_boot.flow.warm.WarmStart`). Few epochs are the regulariser (8 in 3D
mode, 50 in 2D-only mode: the Trainer's ``max_epochs``). Validation predicts with
``predict_updates`` iterations and logs EPE (all pixels, person, at joints) when the scene has
ground truth, and always the drift: how far the flow outside the person moved from the
original network's prediction. Training stops at the first non-finite loss, gradient or
weight, with the weights of the last good step restored (:class:`~lit_boot.finite.FiniteGuard`).
"""

from __future__ import annotations

from dataclasses import asdict, replace

import lightning as L
import torch
from lightning.pytorch.callbacks import EarlyStopping
from lightning.pytorch.utilities import rank_zero_warn
from torch.utils.data import DataLoader

from ..core import Scene, get_layout
from ..finite import FiniteGuard
from ..metrics import EndPointError, FlowMetrics
from ..optim import adam
from .crops import crop_loss, person_region
from .data import ScenePairs, SketchInputs, sketch_inputs
from .evidence import forward_backward_check
from .gate import gate_sketch
from .losses import SketchLoss
from .raft import load_raft, predict_flow
from .people_sketch import person_balance, sketch_people
from .sketch import SketchConfig, footprint_offsets, sketch_from_layout, target_flow
from .warm import TUNED_PARTS, WarmStart

__all__ = ["FlowTTT"]

TRAIN_PARTS = ("all", "update_block")
#: Which unpainted pixels are held to the base flow: all (the paper), or only those whose base
#: flow passes the forward-backward check (pseudo-labels; the others are free).
HOLDS = ("all", "consistent")


class FlowTTT(L.LightningModule):
    """RAFT fine-tuned per scene on the sketched target flow.

    ``loss``, ``gamma``, ``loss_beta``, ``sketch_weight`` and ``sketch_gap`` build its loss,
    ``loss_fn`` (:class:`~lit_boot.flow.losses.SketchLoss`); ``warm_start`` builds ``warm``
    (:class:`~lit_boot.flow.warm.WarmStart`, else None). Every argument is keyword-only.

    Args:
        arch: raft_small or raft_large.
        weights: a weights file (torchvision or original princeton-vl format) or a torchvision
            weights name (C_T_V1, C_T_V2, C_T_SKHT_V2, ...).
        train_updates: RAFT iterations per training step (the authors: 20).
        grad_updates: backpropagate through the last this many of them only (truncated
            backpropagation: the earlier iterations run without gradient, and only the returned
            iterations are upsampled); None: through all (the authors).
        predict_updates: RAFT iterations for predictions and validation.
        lr: Adam learning rate, > 0 (the paper: 1e-5).
        loss: final (SmoothL1 on the last prediction, as the authors) or sequence (RAFT's
            gamma-weighted loss over every update).
        gamma: decay of the sequence loss.
        loss_beta: SmoothL1's beta, px (1: the authors). Below it the loss is quadratic, so a
            small beta holds small residuals (the background's) as firmly as large ones.
        target_updates: RAFT iterations for the base flow the target is painted over (None:
            ``train_updates``, the authors).
        sketch_weight: weight of sketch pixels in the loss relative to the others (1: every
            pixel alike, the paper).
        sketch_gap: unpainted pixels within this many footprint radii (the footprint's largest
            offset, px) of the sketch get no loss: the footprint guesses a limb's half-width, so
            these may be the person's, whose base flow is what the sketch corrects; 0: every
            pixel is held to the base flow (the authors).
        train_parts: all (the paper) or update_block (update block and mask predictor only).
        freeze_batchnorm: keep BatchNorm statistics fixed (the paper does not).
        crop_margin: train on a crop around the sketch (its bounding box plus this margin, px)
            while predicting on full frames; None trains on full frames. With ``warm_start``
            the crop is of the cached feature maps (see ``paste_crop``).
        hold_weight: in crop mode, weight of a second crop elsewhere in the frame whose target is
            the base flow, which holds the unseen rest of the frame in place (0: off; not used
            with ``warm_start``, where every prediction starts from the untuned flow).
        hold: which unpainted pixels are held to the base flow: all (the paper), or consistent:
            only those whose base flow passes the forward-backward check against RAFT's backward
            flow (one more RAFT pass per pair): RAFT's confident flow as pseudo-labels (cf. Sun,
            Harley and Guibas, "Refining Pre-Trained Motion Models", 2024), the rest left free
            (no loss) where RAFT's flow fails its own check.
        people_balance: with several people, weigh each person's painted pixels so that every
            person weighs the same in the loss (:func:`~lit_boot.flow.people_sketch.person_balance`;
            False: every painted pixel alike, so a small person weighs little).
        warm_start: the fast fine-tune (:mod:`lit_boot.flow.warm`; needs
            ``train_parts="update_block"``): the frozen encoders' outputs and the untuned flow
            (``predict_updates`` iterations, also the target's base flow) are computed once per
            scene; training steps and predictions run ``train_updates`` iterations from that
            flow (on other frames than the fit's too: their cache is built first).
        paste_crop: with ``warm_start`` and ``crop_margin``: predict on the crop only and paste
            it into the untuned flow (True: outside the crop the output is the untuned flow,
            exactly), or predict the whole frame from the untuned flow (False: the update block
            then also moves flow it was never taught; BENCHMARKS.md, "Speed").
        plateau_patience: stop fitting when the epoch's mean training loss has not fallen below
            the best epoch's by ``plateau_delta`` times the first epoch's for this many epochs
            (Lightning's EarlyStopping on ``train/loss_rel``); None: always ``max_epochs``.
        plateau_delta: the smallest fall that counts, as a fraction of the first epoch's loss.
        sketch: how the stick-man is drawn and guarded.
    """

    def __init__(
        self,
        *,
        arch: str = "raft_small",
        weights: str | None = "C_T_V1",
        train_updates: int = 20,
        grad_updates: int | None = None,
        predict_updates: int = 32,
        lr: float = 1e-5,
        loss: str = "final",
        gamma: float = 0.8,
        loss_beta: float = 1.0,
        target_updates: int | None = None,
        sketch_weight: float = 1.0,
        sketch_gap: float = 0.0,
        train_parts: str = "all",
        freeze_batchnorm: bool = False,
        crop_margin: int | None = None,
        hold_weight: float = 1.0,
        hold: str = "all",
        people_balance: bool = False,
        warm_start: bool = False,
        paste_crop: bool = True,
        plateau_patience: int | None = None,
        plateau_delta: float = 0.01,
        sketch: SketchConfig | None = None,
    ):
        super().__init__()
        if not lr > 0:
            raise ValueError(f"lr: expected > 0, got {lr}")
        if train_parts not in TRAIN_PARTS:
            raise ValueError(f"train_parts: expected one of {TRAIN_PARTS}, got {train_parts!r}")
        if hold not in HOLDS:
            raise ValueError(f"hold: expected one of {HOLDS}, got {hold!r}")
        if grad_updates is not None and not 1 <= grad_updates <= train_updates:
            raise ValueError(f"grad_updates: expected None or 1..{train_updates} (train_updates), got {grad_updates}")
        if plateau_patience is not None and plateau_patience < 1:
            raise ValueError(f"plateau_patience: expected None or >= 1 epochs, got {plateau_patience}")
        if warm_start and train_parts != "update_block":
            raise ValueError(f"warm_start: needs train_parts='update_block' (frozen, cached encoders), got {train_parts!r}")
        if not sketch_gap >= 0:
            raise ValueError(f"sketch_gap: expected >= 0 footprint radii, got {sketch_gap}")
        self.sketch_config = sketch or SketchConfig()
        reach = int(footprint_offsets(self.sketch_config.footprint, self.sketch_config.size).abs().max())
        # the unknown zone beside the sketch: sketch_gap footprint radii, in px
        self.loss_fn = SketchLoss(loss=loss, gamma=gamma, beta=loss_beta, sketch_weight=sketch_weight,
                                  gap=round(sketch_gap * max(reach, 1)))  # fmt: skip
        self.save_hyperparameters(ignore=["sketch"])
        self.hparams["sketch"] = asdict(self.sketch_config)
        self.raft = load_raft(arch, weights)
        if train_parts == "update_block":
            for name, p in self.raft.named_parameters():
                p.requires_grad_(name.startswith(TUNED_PARTS))
        self.targets: torch.Tensor | None = None  # (P, 2, H, W) on CPU
        self.sketch_masks: torch.Tensor | None = None  # (P, H, W)
        self.held: torch.Tensor | None = None  # (P, H, W) bool with hold="consistent": the unpainted pixels held
        self.sketch_people: torch.Tensor | None = None  # (P, H, W) int8 with several people: who painted it, -1
        self.scene: Scene | None = None  # the scene the targets were prepared for
        self.original: torch.Tensor | None = None  # (P, 2, H, W): the untuned network's prediction
        self.target_report: dict[str, float] = {}
        self.warm = None if not warm_start else WarmStart(
            self.raft, self.loss_fn, train_updates=train_updates, grad_updates=grad_updates,
            predict_updates=predict_updates, crop_margin=crop_margin, paste_crop=paste_crop,
        )  # fmt: skip
        self._first_loss: float | None = None  # the fit's first epoch's mean loss (train/loss_rel)
        self.val_metrics = FlowMetrics(prefix="val/")  # lit_boot.metrics.suite: the one convention
        self.val_drift = EndPointError()

    # --- targets --------------------------------------------------------------------------------
    @torch.no_grad()
    def _predict_all(self, scene: Scene, updates: int, backward: bool = False) -> torch.Tensor:
        """(P, 2, H, W) flows t -> t+1 of every pair of ``scene`` (t+1 -> t with ``backward``), on
        CPU, one pair at a time (through a DataLoader, as a predict run)."""
        was_training = self.raft.training
        self.raft.eval()
        first, second = ("image2", "image1") if backward else ("image1", "image2")
        flows = [predict_flow(self.raft, b[first], b[second], updates).float().cpu()
                 for b in DataLoader(ScenePairs(scene), batch_size=1)]  # fmt: skip
        self.raft.train(was_training)
        return torch.cat(flows)

    @torch.no_grad()
    def base_flows(self, scene: Scene) -> tuple[torch.Tensor, torch.Tensor | None]:
        """RAFT's own flows (P, 2, H, W) px for every pair of ``scene``, and the backward ones
        when the sketch's gate needs them ("photometric+fb"; one more pass per pair), else None.
        With ``warm_start`` the forward ones are the cache's."""
        updates = self.hparams.target_updates or self.hparams.train_updates
        if self.warm is not None:
            base, updates = self.warm.build(scene.frames).base, self.hparams.predict_updates
        else:
            base = self._predict_all(scene, updates)
        if self.sketch_config.gate != "photometric+fb" and self.hparams.hold != "consistent":
            return base, None
        return base, self._predict_all(scene, updates, backward=True)

    @torch.no_grad()
    def prepare(self, scene: Scene, inputs: SketchInputs | None = None, *, teacher: torch.Tensor | None = None,
                confirmed: torch.Tensor | None = None) -> dict[str, float]:  # fmt: skip
        """Base flows, sketches and targets for every pair of ``scene``, the stick-man drawn from
        ``inputs`` (default: :func:`~lit_boot.flow.data.sketch_inputs` of the scene); sets and
        returns ``target_report`` (see :meth:`targets_from`). A fit calls it from its
        SceneFlowData unless the module holds targets. ``teacher`` (P, 2, H, W) px: the flow the
        stick-man is painted over instead of RAFT's own (the zoom stage's, which the frames
        confirmed); ``confirmed`` (P, H, W) bool: where the teacher is confirmed, it is painted
        instead of the stick-man (which says where a limb is; the teacher says how it moved)."""
        base, base_bw = self.base_flows(scene)
        if teacher is not None:
            if teacher.shape != base.shape:
                raise ValueError(f"teacher: expected shape {tuple(base.shape)}, got {tuple(teacher.shape)}")
            base = teacher.float()
        self.target_report = self.targets_from(scene, base, base_bw, inputs=inputs, confirmed=confirmed)
        return self.target_report

    @torch.no_grad()
    def targets_from(self, scene: Scene, base: torch.Tensor, base_bw: torch.Tensor | None = None, *,
                     inputs: SketchInputs | None = None, confirmed: torch.Tensor | None = None) -> dict[str, float]:  # fmt: skip
        """Sketch, gate and set the targets of ``scene`` over given base flows (P, 2, H, W) px (and
        the backward ones for the fb gate); where ``confirmed`` (P, H, W) bool, the base itself is
        painted instead of the sketch (it counts as painted: weighted and cropped like the sketch).
        Returns a report: bones rejected by the guard, the gate's counts (target/gate_*, see
        :data:`~lit_boot.flow.gate.GATE_REPORT_KEYS`), the painted fraction after both and, with
        GT flow, the sketch's and the base flow's EPE on the painted pixels."""
        inputs = inputs if inputs is not None else sketch_inputs(scene)
        frames = scene.frames
        if tuple(base.shape) != (frames.shape[0] - 1, 2, *frames.shape[-2:]):
            raise ValueError(f"base: expected shape {(frames.shape[0] - 1, 2, *frames.shape[-2:])} for scene "
                             f"{scene.name!r}, got {tuple(base.shape)}")  # fmt: skip
        H, W = base.shape[-2:]
        draw = sketch_people if inputs.joints_t.ndim == 4 else sketch_from_layout  # every person, or one
        sketch = draw(
            inputs.layout, inputs.joints_t, inputs.joints_t1, H, W,
            confidence_t=inputs.confidence_t, confidence_t1=inputs.confidence_t1,
            depths=inputs.depths, base_flow=base, config=self.sketch_config,
        )  # fmt: skip
        sketch, gated = gate_sketch(frames[:-1], frames[1:], base, sketch, self.sketch_config, base_bw)
        if confirmed is not None:  # the base (the teacher) is confirmed there: it is the target, not the sketch
            confirmed = confirmed.to(sketch.mask.device)
            sketch = replace(sketch, mask=sketch.mask | confirmed,
                             flow=torch.where(confirmed[:, None], base.to(sketch.flow), sketch.flow))
        self.targets, self.sketch_masks, self.scene = target_flow(base, sketch), sketch.mask, scene
        report = {f"target/rejected_{k}": float(v) for k, v in sketch.rejected.items()}
        self.held = None
        self.balance = self.sketch_people = None
        if inputs.joints_t.ndim == 4 and sketch.owner is not None:  # several people: whose each painted pixel is
            bones = len(get_layout(inputs.layout).sketch_bones)
            self.sketch_people = torch.where(sketch.mask, sketch.owner // bones, -1).to(torch.int8).cpu()
            if self.hparams.people_balance:
                self.balance = person_balance(sketch.owner, sketch.mask, bones).cpu()
        if self.hparams.hold == "consistent":
            self.held = ~forward_backward_check(base.float(), base_bw.float())[1].cpu()
            report["target/held_fraction"] = self.held.float().mean().item()
        report.update({f"target/{k}": v for k, v in gated.items()})
        report["target/painted_fraction"] = sketch.mask.float().mean().item()
        gt = scene.gt
        if gt is not None and gt.flow is not None and sketch.mask.any():
            painted = sketch.mask & gt.flow_mask().to(sketch.mask.device)
            err = lambda f: (f - gt.flow).norm(dim=1)[painted].mean().item()  # noqa: E731
            report["target/epe_sketch_painted"] = err(sketch.flow)
            report["target/epe_base_painted"] = err(base)
        return report

    def forget_targets(self) -> None:
        """Drop the targets, sketches and untuned flows, so that the next fit rebuilds them from
        its datamodule's poses (the orchestrator's next flow stage, after the poses changed).
        The warm start's cache stays: the encoders are frozen and the untuned flow is the untuned
        network's."""
        self.targets = self.sketch_masks = self.scene = self.original = self.held = self.balance = None
        self.sketch_people = None
        if self.warm is not None:
            self.warm.boxes = None

    # --- the data's scene ---------------------------------------------------------------------------
    def _data_scene(self) -> Scene | None:
        """The scene of the trainer's datamodule (a SceneFlowData), or None."""
        dm = self.trainer.datamodule if self._trainer is not None else None
        return getattr(dm, "scene", None)

    def on_fit_start(self) -> None:
        if self.targets is None:
            scene = self._data_scene()
            if scene is None:
                raise RuntimeError("FlowTTT: give the data with a SceneFlowData datamodule (trainer.fit(model, "
                                   "datamodule=SceneFlowData(scene))) or call prepare(scene) first")  # fmt: skip
            self.prepare(scene, self.trainer.datamodule.sketch_inputs())
            for logger in self.loggers:
                logger.log_metrics(self.target_report, step=0)
        if not self.sketch_masks.any():  # the target is the base flow: nothing to learn
            rank_zero_warn(
                "FlowTTT: nothing painted (no bone is confident in two consecutive frames); "
                "training skipped, the flow stays as it is"
            )
            self.trainer.should_stop = True
        if self.warm is not None:
            cache = self.warm.fit(self.scene.frames, self.sketch_masks, self.targets)
            if self.original is None:
                self.original = cache.base
        if self.original is None and self.trainer.limit_val_batches:
            self.original = self._predict_all(self.scene, self.hparams.predict_updates)

    def on_predict_start(self) -> None:
        self._begin_prediction()

    def on_validation_start(self) -> None:
        self._begin_prediction()

    def _begin_prediction(self) -> None:
        """With ``warm_start``, predict from the feature cache of the datamodule's frames (RAFT's
        own flow while untuned, the tuned iterations from it after); without a datamodule, or
        without ``warm_start``, ``predict_updates`` iterations from zero."""
        if self.warm is not None:
            scene = self._data_scene()
            self.warm.begin(None if scene is None else scene.frames)

    # --- training -------------------------------------------------------------------------------
    def on_train_epoch_start(self) -> None:
        self.train()  # whatever mode the network was left in (BatchNorm frozen if asked)
        self._epoch_loss = torch.zeros(2, device=self.device)  # sum, count

    def on_train_epoch_end(self) -> None:
        """Log ``train/loss_rel``: the epoch's mean loss over the first epoch's (the plateau stop's)."""
        total, count = self._epoch_loss.tolist()
        if count:
            mean = total / count
            if self.current_epoch == 0 or self._first_loss is None:
                self._first_loss = mean
            self.log("train/loss_rel", mean / self._first_loss if self._first_loss > 0 else 0.0)

    def train(self, mode: bool = True) -> FlowTTT:
        super().train(mode)
        if mode and self.hparams.freeze_batchnorm:
            for m in self.raft.modules():
                if isinstance(m, torch.nn.modules.batchnorm._BatchNorm):
                    m.eval()
        return self

    def _step_pair(self, image1, image2, target, weight) -> torch.Tensor:
        flows = predict_flow(self.raft, image1, image2, self.hparams.train_updates, all_updates=True,
                             grad_updates=self.hparams.grad_updates)  # fmt: skip
        return self.loss_fn(flows, target, weight)

    def training_step(self, batch: dict[str, torch.Tensor], batch_idx: int) -> torch.Tensor | None:
        idx = batch["index"].cpu()
        target = self.targets[idx].to(self.device)
        mask = self.sketch_masks[idx].to(self.device)
        weight = self.loss_fn.weights(mask)
        if self.held is not None:  # pseudo-labels: the unpainted pixels RAFT's own check passed
            weight = weight * (mask | self.held[idx].to(self.device)).float()
        if self.balance is not None:  # every person weighs the same
            weight = weight * self.balance[idx].to(self.device)
        if self.warm is not None:
            loss = self.warm.loss(idx, target, weight)
            if loss is None:  # no pair of the batch has a box: nothing to learn here
                return None
        elif self.hparams.crop_margin is None:
            loss = self._step_pair(batch["image1"], batch["image2"], target, weight)
        else:
            loss = crop_loss(self._step_pair, batch["image1"], batch["image2"], target, weight, mask,
                             margin=self.hparams.crop_margin, hold_weight=self.hparams.hold_weight)  # fmt: skip
        self.log("train/loss", loss, prog_bar=True, on_step=True, on_epoch=True, batch_size=len(idx))
        self._epoch_loss += torch.stack([loss.detach().float(), torch.ones((), device=loss.device)])
        return loss

    def configure_callbacks(self) -> list[L.Callback]:
        callbacks: list[L.Callback] = [FiniteGuard()]
        if self.hparams.plateau_patience is not None:
            callbacks.append(EarlyStopping("train/loss_rel", min_delta=self.hparams.plateau_delta, mode="min",
                                           patience=self.hparams.plateau_patience, check_on_train_epoch_end=True,
                                           check_finite=False))  # fmt: skip
        return callbacks

    def configure_optimizers(self) -> torch.optim.Optimizer:
        """Adam over the trained weights (:func:`lit_boot.optim.adam`: fused where the device has one)."""
        return adam([p for p in self.raft.parameters() if p.requires_grad], lr=self.hparams.lr)

    # --- validation and prediction ----------------------------------------------------------------
    def _predict(self, batch: dict[str, torch.Tensor]) -> torch.Tensor:
        if self.warm is not None and self.warm.active:
            return self.warm.predict(batch["index"].cpu()).to(self.device)
        return predict_flow(self.raft, batch["image1"], batch["image2"], self.hparams.predict_updates).float()

    def validation_step(self, batch: dict[str, torch.Tensor], batch_idx: int) -> None:
        flow = self._predict(batch)
        idx = batch["index"].cpu()
        self.val_metrics.update(flow, batch.get("gt_flow"), batch.get("gt_valid"), batch.get("person"),
                                batch.get("gt_joints"), batch.get("gt_joints_next"), batch.get("gt_unmatched"))  # fmt: skip
        if self.original is not None and self.sketch_masks is not None:
            outside = ~person_region(self.sketch_masks[idx]).to(self.device)
            self.val_drift.update(flow, self.original[idx].to(self.device), outside)

    def on_validation_epoch_end(self) -> None:
        metrics = self.val_metrics.compute()
        if self.val_drift.update_called:
            metrics["val/drift_px"] = self.val_drift.compute()
        for name, value in metrics.items():
            self.log(name, value, prog_bar=name in ("val/epe_person", "val/drift_px"))
        self.val_metrics.reset()
        self.val_drift.reset()

    def predict_step(self, batch: dict[str, torch.Tensor], batch_idx: int) -> dict[str, torch.Tensor]:
        """{"index": (B,), "flow": (B, 2, H, W)} with ``predict_updates`` iterations."""
        return {"index": batch["index"], "flow": self._predict(batch)}
