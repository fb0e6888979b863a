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
from kornia.morphology import dilation
from lightning.pytorch.utilities import rank_zero_warn

from ..finite import FiniteGuard
from ..metrics import EndPointError, FlowMetrics
from .gate import gate_sketch
from .raft import load_raft, predict_flow
from .sketch import SketchConfig, sketch_from_layout, target_flow

__all__ = ["FlowTTT"]

LOSSES = ("final", "sequence")
TRAIN_PARTS = ("all", "update_block")


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
        train_parts: all (the paper) or update_block (update block and mask predictor only).
        freeze_batchnorm: keep BatchNorm statistics fixed (the paper does not).
        crop_margin: train on a crop around the sketch (its bounding box plus this margin, px)
            while predicting on full frames; None trains on full frames.
        hold_weight: in crop mode, weight of a second crop elsewhere in the frame whose target is
            the base flow, which holds the unseen rest of the frame in place (0: off).
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
        train_parts: str = "all",
        freeze_batchnorm: bool = False,
        crop_margin: int | None = None,
        hold_weight: float = 1.0,
        sketch: SketchConfig | None = None,
    ):
        super().__init__()
        if loss not in LOSSES:
            raise ValueError(f"loss: expected one of {LOSSES}, got {loss!r}")
        if train_parts not in TRAIN_PARTS:
            raise ValueError(f"train_parts: expected one of {TRAIN_PARTS}, got {train_parts!r}")
        if grad_updates is not None and not 1 <= grad_updates <= train_updates:
            raise ValueError(f"grad_updates: expected None or 1..{train_updates} (train_updates), got {grad_updates}")
        self.sketch_config = sketch or SketchConfig()
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
        its datamodule's poses (the orchestrator's next flow stage, after the poses changed)."""
        self.targets = self.sketch_masks = self.original = None

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
        if self.original is None and dm is not None and self.trainer.limit_val_batches:
            self.original = self._predict_all(dm.val_dataloader(), self.hparams.predict_updates)

    # --- training -------------------------------------------------------------------------------
    def on_train_epoch_start(self) -> None:
        self.train()  # whatever mode the network was left in (BatchNorm frozen if asked)

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

    def _crop(self, mask: torch.Tensor) -> tuple[int, int, int, int] | None:
        """(y0, y1, x0, x1): the sketch's bounding box plus the margin, or None."""
        ys, xs = torch.nonzero(mask, as_tuple=True)
        if ys.numel() == 0:
            return None
        m, (H, W) = self.hparams.crop_margin, mask.shape
        return max(0, int(ys.min()) - m), min(H, int(ys.max()) + m + 1), max(0, int(xs.min()) - m), min(W, int(xs.max()) + m + 1)

    def _anchor(self, box: tuple[int, int, int, int], H: int, W: int) -> tuple[int, int, int, int]:
        """A box of the same size elsewhere in the frame, overlapping ``box`` the least."""
        y0, y1, x0, x1 = box
        h, w = y1 - y0, x1 - x0
        best, best_overlap = (0, h, 0, w), None
        for _ in range(8):
            ay = int(torch.randint(0, H - h + 1, ()))
            ax = int(torch.randint(0, W - w + 1, ()))
            overlap = max(0, min(y1, ay + h) - max(y0, ay)) * max(0, min(x1, ax + w) - max(x0, ax))
            if best_overlap is None or overlap < best_overlap:
                best, best_overlap = (ay, ay + h, ax, ax + w), overlap
        return best

    def _step_pair(self, image1, image2, target, weight) -> torch.Tensor:
        flows = predict_flow(self.raft, image1, image2, self.hparams.train_updates, all_updates=True,
                             grad_updates=self.hparams.grad_updates)  # fmt: skip
        return self._loss(flows, target, weight)

    def training_step(self, batch: dict[str, torch.Tensor], batch_idx: int) -> torch.Tensor:
        idx = batch["index"].cpu()
        target = self.targets[idx].to(self.device)
        mask = self.sketch_masks[idx].to(self.device)
        weight = 1.0 + (self.hparams.sketch_weight - 1.0) * mask.float()
        if self.hparams.crop_margin is None:
            loss = self._step_pair(batch["image1"], batch["image2"], target, weight)
        else:
            losses = []
            for b in range(len(idx)):
                box = self._crop(mask[b]) or (0, mask.shape[1], 0, mask.shape[2])
                # Outside the sketch the target is the base flow: the anchor crop holds it there.
                boxes = [(box, 1.0)]
                if self.hparams.hold_weight > 0:
                    boxes.append((self._anchor(box, *mask.shape[1:]), self.hparams.hold_weight))
                for (y0, y1, x0, x1), w in boxes:
                    crop = lambda x: x[..., y0:y1, x0:x1]  # noqa: E731
                    losses.append(w * self._step_pair(crop(batch["image1"][b]), crop(batch["image2"][b]),
                                                      crop(target[b])[None], crop(weight[b])[None]))  # fmt: skip
            loss = sum(losses) / len(idx)
        self.log("train/loss", loss, prog_bar=True, on_step=True, on_epoch=True, batch_size=len(idx))
        return loss

    def configure_callbacks(self) -> list[L.Callback]:
        return [FiniteGuard()]

    def configure_optimizers(self) -> torch.optim.Optimizer:
        params = [p for p in self.raft.parameters() if p.requires_grad]
        return torch.optim.Adam(params, lr=self.hparams.lr)

    # --- validation and prediction ----------------------------------------------------------------
    def _predict(self, batch: dict[str, torch.Tensor]) -> torch.Tensor:
        return predict_flow(self.raft, batch["image1"], batch["image2"], self.hparams.predict_updates).float()

    def validation_step(self, batch: dict[str, torch.Tensor], batch_idx: int) -> None:
        flow = self._predict(batch)
        idx = batch["index"].cpu()
        self.val_metrics.update(flow, batch.get("gt_flow"), batch.get("gt_valid"), batch.get("person"),
                                batch.get("gt_joints"), batch.get("gt_joints_next"))  # fmt: skip
        if self.original is not None and self.sketch_masks is not None:
            outside = ~self.person_region(self.sketch_masks[idx]).to(self.device)
            self.val_drift.update(flow, self.original[idx].to(self.device), outside)

    def person_region(self, sketch_masks: torch.Tensor, margin: int | None = None) -> torch.Tensor:
        """The sketch dilated by ``margin`` px (default: the crop margin, else 16) (B, H, W)
        bool: 'the person' without ground truth."""
        r = margin if margin is not None else (self.hparams.crop_margin or 16)
        square = torch.ones(2 * r + 1, 2 * r + 1, device=sketch_masks.device)
        return dilation(sketch_masks[:, None].float(), square)[:, 0] > 0

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
