"""FlowTTT: fine-tune RAFT on one video to follow the pose-sketched target flow (paper 3.1).

At the start of fitting, the module predicts RAFT's own flow for every pair (the base flow),
draws the stick-man from the data's poses, and paints it over the base flow: the targets.
Each training step runs RAFT with ``train_updates`` iterations on one pair and pulls the final
prediction towards the target with SmoothL1 (beta 1). Few epochs are the regulariser (8 in 3D
mode, 50 in 2D-only mode: the Trainer's ``max_epochs``). Validation predicts with
``predict_updates`` iterations and logs EPE (all pixels, person, at joints) when the scene has
ground truth, and always the drift: how far the flow outside the person moved from the
original network's prediction. Training stops at the first non-finite loss, gradient or
weight, with the weights of the last good step restored (:class:`~lit_boot.finite.FiniteGuard`).
"""

from __future__ import annotations

from dataclasses import asdict

import lightning as L
import torch
import torch.nn.functional as F
from lightning.pytorch.callbacks import EarlyStopping
from lightning.pytorch.utilities import rank_zero_warn

from ..finite import FiniteGuard
from ..metrics import EndPointError, FlowMetrics
from ..optim import adam
from .crops import crop_loss
from .gate import gate_sketch
from .raft import load_raft, predict_flow
from .sketch import SketchConfig, footprint_offsets, sketch_from_layout, target_flow
from .warm import FeatureCache, box_region, crop_box, paste

__all__ = ["FlowTTT"]

LOSSES = ("final", "sequence")
TRAIN_PARTS = ("all", "update_block")
#: px around the sketch that count as the person (:meth:`FlowTTT.person_region`).
PERSON_MARGIN = 16


class FlowTTT(L.LightningModule):
    """RAFT fine-tuned per scene on the sketched target flow.

    Args:
        arch: raft_small or raft_large.
        weights: a weights file (torchvision or original princeton-vl format) or a torchvision
            weights name (C_T_V1, C_T_V2, C_T_SKHT_V2, ...).
        train_updates: RAFT iterations per training step (the authors: 20).
        grad_updates: backpropagate through the last this many of them only (truncated
            backpropagation: the earlier iterations run without gradient, and only the returned
            iterations are upsampled); None: through all (the authors).
        predict_updates: RAFT iterations for predictions and validation.
        lr: Adam learning rate (the paper: 1e-5).
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
        warm_start: bool = False,
        paste_crop: bool = True,
        plateau_patience: int | None = None,
        plateau_delta: float = 0.01,
        sketch: SketchConfig | None = None,
    ):
        super().__init__()
        if loss not in LOSSES:
            raise ValueError(f"loss: expected one of {LOSSES}, got {loss!r}")
        if train_parts not in TRAIN_PARTS:
            raise ValueError(f"train_parts: expected one of {TRAIN_PARTS}, got {train_parts!r}")
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
        self.gap_px = round(sketch_gap * max(reach, 1))  # px: the unknown zone beside the sketch
        self.save_hyperparameters(ignore=["sketch"])
        self.hparams["sketch"] = asdict(self.sketch_config)
        self.raft = load_raft(arch, weights)
        if train_parts == "update_block":
            for name, p in self.raft.named_parameters():
                p.requires_grad_(name.startswith(("update_block.", "mask_predictor.")))
        self.targets: torch.Tensor | None = None  # (P, 2, H, W) on CPU
        self.sketch_masks: torch.Tensor | None = None  # (P, H, W)
        self.original: torch.Tensor | None = None  # (P, 2, H, W): the untuned network's prediction
        self.target_report: dict[str, float] = {}
        self.cache: FeatureCache | None = None  # warm_start: the scene's encoder outputs and untuned flow
        self.boxes: list[tuple[int, int, int, int] | None] | None = None  # warm_start: each pair's crop
        self._untuned = self._trainable_state() if warm_start else None  # the cache's network
        self._prediction = "plain"  # set per predict / validation run (see _source)
        self._first_loss: float | None = None  # the fit's first epoch's mean loss (train/loss_rel)
        self.val_metrics = FlowMetrics(prefix="val/")  # lit_boot.metrics.suite: the one convention
        self.val_drift = EndPointError()

    # --- targets --------------------------------------------------------------------------------
    @torch.no_grad()
    def _predict_all(self, loader, updates: int, backward: bool = False) -> torch.Tensor:
        """(P, 2, H, W) flows t -> t+1 of every pair (t+1 -> t with ``backward``), on CPU."""
        was_training = self.raft.training
        self.raft.eval()
        first, second = ("image2", "image1") if backward else ("image1", "image2")
        flows = [predict_flow(self.raft, b[first], b[second], updates).float().cpu() for b in loader]
        self.raft.train(was_training)
        return torch.cat(flows)

    @torch.no_grad()
    def base_flows(self, datamodule) -> tuple[torch.Tensor, torch.Tensor | None]:
        """RAFT's own flows (P, 2, H, W) px for every pair, and the backward ones when the
        sketch's gate needs them ("photometric+fb"; one more pass per pair), else None."""
        loader = datamodule.predict_dataloader()
        updates = self.hparams.target_updates or self.hparams.train_updates
        if self.hparams.warm_start:
            base, updates = self.warm_cache(datamodule.scene.frames).base, self.hparams.predict_updates
        else:
            base = self._predict_all(loader, updates)
        if self.sketch_config.gate != "photometric+fb":
            return base, None
        return base, self._predict_all(loader, updates, backward=True)

    @torch.no_grad()
    def build_targets(self, datamodule) -> dict[str, float]:
        """Base flows, sketches and targets for every pair of ``datamodule`` (a SceneFlowData);
        see :meth:`targets_from`."""
        return self.targets_from(datamodule, *self.base_flows(datamodule))

    @torch.no_grad()
    def targets_from(self, datamodule, base: torch.Tensor, base_bw: torch.Tensor | None = None) -> dict[str, float]:
        """Sketch, gate and set the targets over given base flows (P, 2, H, W) px (and the
        backward ones for the fb gate). Returns a report: bones rejected by the guard, the
        gate's counts (target/gate_*, see :data:`~lit_boot.flow.gate.GATE_REPORT_KEYS`), the
        painted fraction after both and, with GT flow, the sketch's and the base flow's EPE on
        the painted pixels."""
        inputs = datamodule.sketch_inputs()
        H, W = base.shape[-2:]
        sketch = sketch_from_layout(
            inputs.layout, inputs.joints_t, inputs.joints_t1, H, W,
            confidence_t=inputs.confidence_t, confidence_t1=inputs.confidence_t1,
            depths=inputs.depths, base_flow=base, config=self.sketch_config,
        )  # fmt: skip
        frames = datamodule.scene.frames
        sketch, gated = gate_sketch(frames[:-1], frames[1:], base, sketch, self.sketch_config, base_bw)
        self.targets, self.sketch_masks = target_flow(base, sketch), sketch.mask
        report = {f"target/rejected_{k}": float(v) for k, v in sketch.rejected.items()}
        report.update({f"target/{k}": v for k, v in gated.items()})
        report["target/painted_fraction"] = sketch.mask.float().mean().item()
        gt = datamodule.scene.gt
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
        self.targets = self.sketch_masks = self.original = self.boxes = None

    # --- the warm start (lit_boot.flow.warm) ------------------------------------------------------
    def _trainable_state(self) -> dict[str, torch.Tensor]:
        return {k: v.detach().clone() for k, v in self.raft.state_dict().items()
                if k.startswith(("update_block.", "mask_predictor."))}  # fmt: skip

    def warm_cache(self, frames: torch.Tensor) -> FeatureCache:
        """The feature cache of ``frames`` (T, 3, H, W), built with the untuned update block
        (the weights this module was made with) unless the one held fits."""
        if self.cache is None or not self.cache.fits(frames):
            self.boxes = None  # the boxes were the previous frames'
            tuned = self._trainable_state()
            self.raft.load_state_dict(self._untuned, strict=False)
            try:
                self.cache = FeatureCache.build(self.raft, frames, self.hparams.predict_updates)
            finally:
                self.raft.load_state_dict(tuned, strict=False)
        return self.cache

    def _source(self) -> str:
        """How this predict or validation run predicts, with ``warm_start``: "cache" while
        untuned (the cache's base flow: RAFT's own prediction; the cache is built now if it does
        not fit the frames, and kept for the fit), else "warm" (the tuned iterations from RAFT's
        own flow, on any frames). Without ``warm_start``, or without a datamodule: "plain"
        (``predict_updates`` iterations from zero)."""
        dm = self.trainer.datamodule if self._trainer is not None else None
        if not self.hparams.warm_start or dm is None:
            return "plain"
        self.warm_cache(dm.scene.frames)
        state = self.raft.state_dict()
        untuned = all(torch.equal(state[k], v.to(state[k].device)) for k, v in self._untuned.items())
        return "cache" if untuned else "warm"

    def on_predict_start(self) -> None:
        self._prediction = self._source()

    def on_validation_start(self) -> None:
        self._prediction = self._source()

    def _boxes(self, index: torch.Tensor, grad: bool) -> list[tuple[int, int, int, int] | None]:
        """Each pair's box: its crop in training; in prediction too with ``paste_crop`` (after a
        fit on these frames), else the whole frame."""
        if grad or (self.hparams.paste_crop and self.boxes is not None):
            return [self.boxes[i] for i in index.tolist()]
        return [self.cache.whole] * len(index)

    def _warm_flows(self, index: torch.Tensor, grad: bool) -> list[torch.Tensor | None]:
        """Per pair of ``index``: the last iterations' flows on its box (None: no box)."""
        hp = self.hparams
        return [None if box is None else
                self.cache.flows(self.raft, int(i), box, hp.train_updates, hp.grad_updates if grad else 1)
                for i, box in zip(index.tolist(), self._boxes(index, grad))]  # fmt: skip

    def on_fit_start(self) -> None:
        dm = self.trainer.datamodule
        if self.targets is None:
            if dm is None:
                raise RuntimeError("FlowTTT.fit needs a SceneFlowData datamodule")
            self.target_report = self.build_targets(dm)
            for logger in self.loggers:
                logger.log_metrics(self.target_report, step=0)
            if not self.sketch_masks.any():  # the target is the base flow: nothing to learn
                rank_zero_warn(
                    "FlowTTT: nothing painted (no bone is confident in two consecutive frames); "
                    "training skipped, the flow stays as it is"
                )
                self.trainer.should_stop = True
        if self.hparams.warm_start and self.sketch_masks is not None:
            cache = self.warm_cache(dm.scene.frames)
            margin = self.hparams.crop_margin
            # with a margin, a pair with nothing painted has no box (its flow stays the untuned one)
            self.boxes = [crop_box(m, margin, cache.pad, cache.cells, t)
                          for m, t in zip(self.sketch_masks.cpu(), self.targets.cpu())]  # fmt: skip
            if self.original is None:
                self.original = cache.base
        if self.original is None and dm is not None and self.trainer.limit_val_batches:
            self.original = self._predict_all(dm.val_dataloader(), self.hparams.predict_updates)

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

    def _loss(self, flows: list[torch.Tensor], target: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:
        """SmoothL1 (beta ``loss_beta``) per pixel, weighted mean; over the final or every update."""
        def one(flow: torch.Tensor) -> torch.Tensor:
            per_pixel = F.smooth_l1_loss(flow.float(), target, beta=self.hparams.loss_beta, reduction="none").mean(1)
            return (per_pixel * weight).sum() / weight.sum()

        if self.hparams.loss == "final":
            return one(flows[-1])
        n = len(flows)
        return sum(self.hparams.gamma ** (n - 1 - i) * one(f) for i, f in enumerate(flows))

    def loss_weights(self, mask: torch.Tensor) -> torch.Tensor:
        """Per-pixel loss weights (B, H, W) from sketch masks (B, H, W) bool: ``sketch_weight`` on
        the sketch, 0 on the unpainted pixels within ``sketch_gap`` footprint radii of it (the
        unknown zone: limb or background), 1 elsewhere (held to the base flow)."""
        weight = 1.0 + (self.hparams.sketch_weight - 1.0) * mask.float()
        if self.gap_px:
            weight = weight * (mask | ~self.person_region(mask, self.gap_px)).float()
        return weight

    def _step_pair(self, image1, image2, target, weight) -> torch.Tensor:
        flows = predict_flow(self.raft, image1, image2, self.hparams.train_updates, all_updates=True,
                             grad_updates=self.hparams.grad_updates)  # fmt: skip
        return self._loss(flows, target, weight)

    def training_step(self, batch: dict[str, torch.Tensor], batch_idx: int) -> torch.Tensor:
        idx = batch["index"].cpu()
        target = self.targets[idx].to(self.device)
        mask = self.sketch_masks[idx].to(self.device)
        weight = self.loss_weights(mask)
        if self.hparams.warm_start:
            loss = self._warm_loss(idx, target, weight)
            if loss is None:  # no pair of the batch has a box: nothing to learn here
                return None
        elif self.hparams.crop_margin is None:
            loss = self._step_pair(batch["image1"], batch["image2"], target, weight)
        else:
            loss = crop_loss(self._step_pair, batch["image1"], batch["image2"], target, weight, mask,
                             self.hparams.crop_margin, self.hparams.hold_weight)  # fmt: skip
        self.log("train/loss", loss, prog_bar=True, on_step=True, on_epoch=True, batch_size=len(idx))
        self._epoch_loss += torch.stack([loss.detach().float(), torch.ones((), device=loss.device)])
        return loss

    def _warm_loss(self, idx: torch.Tensor, target: torch.Tensor, weight: torch.Tensor) -> torch.Tensor | None:
        """Mean over the batch's pairs with a box of the loss on the box (None if none has one)."""
        losses = []
        for b, flows in enumerate(self._warm_flows(idx, grad=True)):
            if flows is not None:
                (fy0, fy1, fx0, fx1), (by0, by1, bx0, bx1) = box_region(self.boxes[int(idx[b])], self.cache.pad,
                                                                        target.shape[-2:])  # fmt: skip
                region = [f[..., by0:by1, bx0:bx1] for f in flows]
                losses.append(self._loss(region, target[b : b + 1, :, fy0:fy1, fx0:fx1], weight[b : b + 1, fy0:fy1, fx0:fx1]))
        return sum(losses) / len(losses) if losses else None

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
        source, idx = getattr(self, "_prediction", "plain"), batch["index"].cpu()
        if source == "cache":
            return self.cache.base[idx].to(self.device)
        if source != "warm":
            return predict_flow(self.raft, batch["image1"], batch["image2"], self.hparams.predict_updates).float()
        out = [self.cache.base[i] if flows is None else paste(self.cache.base[i], flows[-1].float().cpu(), box, self.cache.pad)
               for i, flows, box in zip(idx.tolist(), self._warm_flows(idx, grad=False), self._boxes(idx, grad=False))]  # fmt: skip
        return torch.stack(out).to(self.device)

    def validation_step(self, batch: dict[str, torch.Tensor], batch_idx: int) -> None:
        flow = self._predict(batch)
        idx = batch["index"].cpu()
        self.val_metrics.update(flow, batch.get("gt_flow"), batch.get("gt_valid"), batch.get("person"),
                                batch.get("gt_joints"), batch.get("gt_joints_next"))  # fmt: skip
        if self.original is not None and self.sketch_masks is not None:
            outside = ~self.person_region(self.sketch_masks[idx]).to(self.device)
            self.val_drift.update(flow, self.original[idx].to(self.device), outside)

    def person_region(self, sketch_masks: torch.Tensor, margin: int | None = None) -> torch.Tensor:
        """The sketch dilated by ``margin`` px (default :data:`PERSON_MARGIN`) (B, H, W) bool:
        'the person' without ground truth (the drift's complement, the self-check's person)."""
        r = margin if margin is not None else PERSON_MARGIN
        # a flat square's dilation is a separable max filter (kornia's dilation is ~100x slower here)
        rows = F.max_pool2d(sketch_masks[:, None].float(), (1, 2 * r + 1), stride=1, padding=(0, r))
        return F.max_pool2d(rows, (2 * r + 1, 1), stride=1, padding=(r, 0))[:, 0] > 0

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
