"""The authors' early stop for per-video pose optimisation, as a Lightning callback.

The authors stop when the total loss, rounded to 4 decimals, has not changed for 10
consecutive steps. Lightning's ``EarlyStopping`` cannot express this: it compares a monitored
value with the best so far (not with the previous step) and checks only at epoch or
validation ends, while a refiner's optimisation is one epoch of many steps. This callback
checks after every training step and sets ``trainer.should_stop``, which the training loop
honours before the next step (after ``min_steps``, if set).
"""

from __future__ import annotations

import logging
from typing import Any

import lightning as L
from lightning.pytorch.callbacks import Callback

__all__ = ["LossPlateauStopping"]

log = logging.getLogger(__name__)


class LossPlateauStopping(Callback):
    """Stop when ``round(loss, decimals)`` is unchanged for ``patience`` consecutive steps.

    Args:
        decimals: rounding of the loss before comparing (the authors: 4).
        patience: consecutive unchanged steps that stop the run (the authors: 10).
        verbose: log the stop at INFO (shown by ``lit-boot``); otherwise at DEBUG.

    After fitting, ``stopped_step`` is the global step at which it stopped (None if it did not).
    """

    def __init__(self, decimals: int = 4, patience: int = 10, verbose: bool = False):
        super().__init__()
        if patience < 1:
            raise ValueError(f"patience: expected a positive number of steps, got {patience}")
        self.decimals = decimals
        self.patience = patience
        self.verbose = verbose
        self._last: float | None = None
        self._unchanged = 0
        self.stopped_step: int | None = None

    def on_train_start(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        self._last, self._unchanged, self.stopped_step = None, 0, None

    def on_train_batch_end(
        self, trainer: L.Trainer, pl_module: L.LightningModule, outputs: Any, batch: Any, batch_idx: int
    ) -> None:
        loss = outputs["loss"] if isinstance(outputs, dict) else outputs
        if loss is None:
            return
        value = round(float(loss), self.decimals)
        self._unchanged = self._unchanged + 1 if value == self._last else 0
        self._last = value
        if self._unchanged >= self.patience and not trainer.should_stop:
            trainer.should_stop = True
            self.stopped_step = trainer.global_step
            log.log(logging.INFO if self.verbose else logging.DEBUG,
                    "LossPlateauStopping: loss %s unchanged for %d steps; stop at step %d",
                    value, self.patience, trainer.global_step)  # fmt: skip

    def state_dict(self) -> dict[str, Any]:
        return {"last": self._last, "unchanged": self._unchanged, "stopped_step": self.stopped_step}

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        self._last = state_dict["last"]
        self._unchanged = state_dict["unchanged"]
        self.stopped_step = state_dict["stopped_step"]
