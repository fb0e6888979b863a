"""FiniteGuard: training stops at the first non-finite loss, gradient or weight, and the module
goes back to its last finite state (a Lightning callback; FlowTTT and the pose refiners add it
through ``configure_callbacks``).

Checked at every training step, with one host sync per step: the loss (before backward), the
gradients (before the optimizer step; not under a GradScaler, which skips steps with
non-finite gradients itself), and, after the step, the trainable parameters and the
normalisation layers' running statistics. At a fault the guard copies back those tensors as
they were after the last good step (before the first step if none was good), sets
``trainer.should_stop`` (the loop ends after this step), warns, and records the fault.
"""

from __future__ import annotations

from typing import Any

import lightning as L
import torch
from lightning.pytorch.callbacks import Callback
from lightning.pytorch.utilities import rank_zero_warn

__all__ = ["FiniteGuard", "NonFiniteError", "finite_fault"]


class NonFiniteError(RuntimeError):
    """A stage met a non-finite value; ``fault`` says what (loss, gradient, parameters, or an
    output such as flows) and at which step (see :class:`FiniteGuard`)."""

    def __init__(self, message: str, fault: dict[str, Any]):
        super().__init__(message)
        self.fault = fault


def _max_abs(tensors: list[torch.Tensor]) -> torch.Tensor:
    """The largest |value| over ``tensors`` (NaN if any is NaN), a 0-d float tensor; no sync."""
    tensors = [t for t in tensors if t.numel()]
    if not tensors:
        return torch.zeros(())
    if tensors[0].device.type == "cpu":  # foreach's inf-norm is a plain loop there, ~8x slower
        maxima = [t.detach().abs().amax().float() for t in tensors]
    else:
        maxima = [n.float() for n in torch._foreach_norm(tensors, float("inf"))]
    return torch.stack(maxima).max()


def _copy(dst: list[torch.Tensor], src: list[torch.Tensor]) -> None:
    with torch.no_grad():
        torch._foreach_copy_(dst, src)


class FiniteGuard(Callback):
    """Stop training at the first non-finite loss, gradient or weight; restore the last finite
    weights (see the module doc).

    After fitting, ``fault`` is None, or {"what": "loss" | "gradient" | "parameters", "step":
    the 0-based global step that went wrong (None: the weights were not finite at the start),
    "good_steps": optimizer steps whose result was kept, "value": the loss (a string: "nan",
    "inf")}.
    """

    def __init__(self) -> None:
        super().__init__()
        self.fault: dict[str, Any] | None = None
        self._tracked: list[torch.Tensor] = []
        self._floating: list[torch.Tensor] = []
        self._snapshot: list[torch.Tensor] = []
        self._loss: torch.Tensor | None = None
        self._grad: torch.Tensor | None = None
        self._good_steps = 0

    @staticmethod
    def tracked(module: torch.nn.Module) -> list[torch.Tensor]:
        """What training changes: trainable parameters, and normalisation layers' buffers."""
        params = [p for p in module.parameters() if p.requires_grad]
        norms = [m for m in module.modules() if isinstance(m, torch.nn.modules.batchnorm._NormBase)]
        return params + [b for m in norms for b in m.buffers(recurse=False) if b is not None]

    def on_train_start(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        self.fault, self._loss, self._grad = None, None, None
        self._tracked = self.tracked(pl_module)
        self._floating = [t for t in self._tracked if t.is_floating_point()]
        self._snapshot = [t.detach().clone() for t in self._tracked]
        self._good_steps = trainer.global_step
        if not bool(torch.isfinite(_max_abs(self._floating))):
            self._stop(trainer, {"what": "parameters", "step": None, "good_steps": 0, "value": None}, restore=False)

    def on_before_backward(self, trainer: L.Trainer, pl_module: L.LightningModule, loss: torch.Tensor) -> None:
        self._loss = loss.detach().float()

    def on_before_optimizer_step(self, trainer: L.Trainer, pl_module: L.LightningModule, optimizer: Any) -> None:
        if getattr(trainer.precision_plugin, "scaler", None) is not None:
            return  # the GradScaler skips steps whose (unscaled) gradients are not finite
        grads = [p.grad for group in optimizer.param_groups for p in group["params"] if p.grad is not None]
        self._grad = _max_abs(grads)

    def on_train_batch_end(
        self, trainer: L.Trainer, pl_module: L.LightningModule, outputs: Any, batch: Any, batch_idx: int
    ) -> None:
        if not self._tracked:
            return
        values = {"loss": self._loss, "gradient": self._grad, "parameters": _max_abs(self._floating)}
        names = [k for k, v in values.items() if v is not None]
        device = values["parameters"].device
        finite = torch.isfinite(torch.stack([values[k].to(device).reshape(()) for k in names])).tolist()  # one sync
        loss, self._loss, self._grad = self._loss, None, None
        bad = [k for k, ok in zip(names, finite) if not ok]
        if not bad:
            _copy(self._snapshot, self._tracked)
            self._good_steps = trainer.global_step
            return
        step = max(trainer.global_step - 1, self._good_steps)
        self._stop(trainer, {"what": bad[0], "step": step, "good_steps": self._good_steps,
                             "value": None if loss is None else str(float(loss))})  # fmt: skip

    def _stop(self, trainer: L.Trainer, fault: dict[str, Any], restore: bool = True) -> None:
        if restore:
            _copy(self._tracked, self._snapshot)
        self.fault = fault
        trainer.should_stop = True
        where = "at the start" if fault["step"] is None else f"at step {fault['step']}"
        kept = f"weights of step {fault['good_steps']} restored" if restore else "nothing to restore"
        what = f"non-finite {fault['what']} {where} (loss {fault['value']})"
        rank_zero_warn(f"FiniteGuard: {what}; {kept}; training stopped")


def finite_fault(trainer: L.Trainer) -> dict[str, Any] | None:
    """The fault a :class:`FiniteGuard` among ``trainer``'s callbacks recorded, or None."""
    for callback in trainer.callbacks:
        if isinstance(callback, FiniteGuard) and callback.fault is not None:
            return callback.fault
    return None
