"""What both pose refiners share: the Lightning plumbing of a per-video optimisation.

A refiner holds the video's variables as parameters and its fixed inputs as buffers. It is
built in ``setup`` from the datamodule's ``scene`` and ``flows`` (see :class:`PoseData`), or
beforehand by :meth:`RefinerBase.prepare`. Every training step is one Adam step on the
whole video. Loss terms are logged every ``trainer.log_every_n_steps`` steps (Lightning's
``self.log`` costs milliseconds per call: logging every step would dominate the run), the
evaluation against ground truth before the first step, every ``eval_every_n_steps`` steps
and after the last. At the end, :attr:`RefinerBase.result` holds a :class:`PoseResult`, also
saved (poses.npz, pose_report.json) into the run folder. A non-finite loss, gradient or variable
stops the optimisation with the last finite variables restored
(:class:`~lit_boot.finite.FiniteGuard`; the result's ``steps`` counts the steps kept).
Validation (``trainer.validate``, ``lit-boot validate``) evaluates the current poses without
changing them: the initial estimates of a fresh refiner, the refined poses after fitting.
"""

from __future__ import annotations

import inspect
import time
from dataclasses import asdict, fields
from pathlib import Path
from typing import Any

import lightning as L
import torch
from lightning.pytorch.callbacks import Callback
from lightning.pytorch.trainer.states import TrainerFn

from ..core import Person, Scene
from ..data.readers.pose_file import PoseEstimates
from ..finite import FiniteGuard, finite_fault
from ..optim import adam
from .keypoints import CONFIDENCE_MODES
from .losses import flow_residual, inside_image
from .people import PEOPLE_CHOICES
from .result import PoseResult
from .stopping import LossPlateauStopping

__all__ = ["RefinerBase", "TorchThreads"]


class TorchThreads(Callback):
    """Fit with ``num_threads`` torch CPU threads; the previous number is restored at the end,
    also when fitting fails."""

    def __init__(self, num_threads: int):
        super().__init__()
        self.num_threads = num_threads
        self._before: int | None = None

    def on_fit_start(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        self._before = torch.get_num_threads()
        torch.set_num_threads(self.num_threads)

    def on_fit_end(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        self._restore()

    def on_exception(self, trainer: L.Trainer, pl_module: L.LightningModule, exception: BaseException) -> None:
        self._restore()

    def _restore(self) -> None:
        if self._before is not None:
            torch.set_num_threads(self._before)
            self._before = None


class RefinerBase(L.LightningModule):
    """Base of :class:`PoseRefiner` and :class:`KeypointRefiner`.

    A subclass's ``__init__`` calls ``super().__init__(...)``, then :meth:`save_settings`.
    Subclasses implement ``build(scene, flows)`` (create parameters, buffers, and the
    :class:`~lit_boot.pose.objective.Objective` ``self.objective``), ``residuals()`` (the
    active terms' residuals in ``objective.names`` order), ``evaluate()`` (metrics against
    ground truth, {} without it) and ``make_result()``.

    Args:
        lr: Adam learning rate.
        eval_every_n_steps: evaluate against ground truth every this many steps (0: only before
            and after); a multiple of the trainer's log_every_n_steps reaches the loggers.
        save: write the refined poses into ``output_dir`` at the end of fitting.
        output_dir: where to save (default: the trainer's log_dir, i.e. the run folder).
        num_threads: torch CPU threads during fitting (restored afterwards); None leaves them.
            The problem is small: one thread avoids thread-synchronisation costs that, on a
            busy CPU, made a step of this size several times slower.
        people: "all" refines every person of the scene at once (:mod:`lit_boot.pose.people`),
            "main" the main person alone (the others keep their estimates).
    """

    mode = "3d"

    def __init__(
        self,
        lr: float,
        eval_every_n_steps: int = 100,
        save: bool = True,
        output_dir: str | None = None,
        num_threads: int | None = 1,
        people: str = "all",
    ):
        super().__init__()
        if people not in PEOPLE_CHOICES:
            raise ValueError(f"people: expected one of {PEOPLE_CHOICES}, got {people!r}")
        if lr <= 0:
            raise ValueError(f"lr: expected a positive learning rate, got {lr}")
        self.scene_name = "scene"
        self.prepared = False
        self.result: PoseResult | None = None
        self.metrics_before: dict[str, float] = {}
        self._started = 0.0
        self._scene_key: tuple | None = None
        self.track_ids: list[int] = [0]

    def save_settings(self, loss_weights: Any, weights_type: type, confidence: str) -> None:
        """The constructor tail both refiners share; a subclass's ``__init__`` calls it.

        Checks ``confidence``, makes ``self.loss_weights`` a ``weights_type`` (the lambdas dataclass)
        from an instance, a dict of some of its fields, or None (the defaults), and saves every
        argument of the calling ``__init__`` as ``hparams``, the lambdas as a plain dict.
        """
        if confidence not in CONFIDENCE_MODES:
            raise ValueError(f"confidence: expected one of {CONFIDENCE_MODES}, got {confidence!r}")
        weights = loss_weights
        if isinstance(weights, dict):
            known = [f.name for f in fields(weights_type)]
            unknown = sorted(set(weights) - set(known))
            if unknown:
                raise ValueError(f"loss_weights: unknown lambda {unknown[0]!r}; expected some of {known}")
            weights = weights_type(**weights)
        elif weights is None:
            weights = weights_type()
        elif not isinstance(weights, weights_type):
            raise TypeError(f"loss_weights: expected a {weights_type.__name__}, a dict or None, got {type(weights).__name__}")
        self.loss_weights = weights
        # Saved from a helper: Lightning must read the arguments of the caller's frame (the
        # subclass __init__), not this one's.
        self.save_hyperparameters(ignore=["loss_weights"], frame=inspect.currentframe().f_back)
        self.hparams["loss_weights"] = asdict(weights)
        self._hparams_initial["loss_weights"] = asdict(weights)  # what loggers record as hparams
        self.image_size = (1, 1)

    def __setattr__(self, name: str, value: object) -> None:
        # Lightning sets _current_fx_name around every hook call (~40 times a step); a plain
        # string attribute needs none of nn.Module.__setattr__'s checks, which cost ~10 us each
        # on a busy CPU: several percent of a whole refinement step.
        if name == "_current_fx_name":
            object.__setattr__(self, name, value)
        else:
            super().__setattr__(name, value)

    # --- to be implemented by subclasses -----------------------------------------------------
    def build(self, scene: Scene, flows: torch.Tensor | None) -> None:
        raise NotImplementedError

    def residuals(self) -> list[torch.Tensor]:
        raise NotImplementedError

    def evaluate(self) -> dict[str, float]:
        """The current poses against ground truth under :mod:`lit_boot.metrics.suite`'s names
        (``mpjpe_mm``, ``kp2d_px``, ...); {} without ground truth."""
        raise NotImplementedError

    def make_result(self) -> PoseResult:
        raise NotImplementedError

    def result_with(self, mode: str, people: list[Person], **layouts: Any) -> PoseResult:
        """This fit's :class:`PoseResult`: ``people``'s refined poses (the main person first; the
        fields their mode has) for the scene's frames in ``layouts`` (``keypoints_layout`` or
        ``joints3d_layout``), with the report (steps, early stop, loss, metrics, settings)."""
        main, *others = people
        estimates = PoseEstimates(**main.fields(), track_id=main.track_id, others=tuple(others), **layouts,
                                  frame_indices=self.frame_indices, image_size=self.image_size,
                                  source=f"lit-boot {type(self).__name__}")  # fmt: skip
        return PoseResult(
            mode=mode, estimates=estimates, scene=self.scene_name, steps=int(self.global_step),
            stopped_early=self.stopped_early(), loss=self.final_loss(), metrics_before=dict(self.metrics_before),
            metrics_after=self.evaluate(), settings=dict(self.hparams),
        )  # fmt: skip

    # --- building ------------------------------------------------------------------------------
    def prepare(self, scene: Scene, flows: torch.Tensor | None) -> None:
        """Initialise the variables from ``scene`` and hold ``flows`` (T-1, 2, H, W) px or None."""
        if flows is not None and tuple(flows.shape) != (scene.num_frames - 1, 2, scene.height, scene.width):
            raise ValueError(
                f"flows: expected shape {(scene.num_frames - 1, 2, scene.height, scene.width)} "
                f"for scene {scene.name!r}, got {tuple(flows.shape)}"
            )
        self.scene_name = scene.name
        frames = scene.metadata.get("frame_indices")  # the video frames the rows are (a clip of a longer video)
        self.frame_indices = torch.as_tensor(frames if frames is not None else range(scene.num_frames), dtype=torch.int64)
        self.image_size = (scene.height, scene.width)
        self.build(scene, None if flows is None else flows.float())
        self.result = None
        self.prepared = True
        self._scene_key = (scene.name, scene.num_frames, scene.height, scene.width)

    def setup(self, stage: str) -> None:
        """Build from the datamodule's scene: always before fitting; before validating only if
        the refiner does not hold that scene's poses yet (so the refined poses are evaluated)."""
        dm = self.trainer.datamodule if self._trainer is not None else None
        scene = getattr(dm, "scene", None) if dm is not None else None
        if scene is not None:
            key = (scene.name, scene.num_frames, scene.height, scene.width)
            if stage == TrainerFn.FITTING or not self.prepared or key != self._scene_key:
                self.prepare(scene, getattr(dm, "flows", None))
        elif not self.prepared:
            raise RuntimeError(
                f"{type(self).__name__}: give the data with a PoseData datamodule "
                "(trainer.fit(model, datamodule=PoseData(scene, flows))) or call prepare(scene, flows) first"
            )

    # --- optimisation -------------------------------------------------------------------------
    def configure_optimizers(self) -> torch.optim.Optimizer:
        """Adam (:func:`lit_boot.optim.adam`: fused where the device has one)."""
        return adam(self.parameters(), lr=self.hparams.lr)

    def total_loss(self, with_terms: bool = False) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        """The loss (a zero with a gradient if every term is off) and, if asked, each weighted
        term by name (without gradient)."""
        residuals = self.residuals()
        if len(self.objective):
            total = self.objective(residuals)
        else:
            total = sum(p.sum() * 0.0 for p in self.parameters())
        return total, self.objective.split(residuals) if with_terms else {}

    def flow_term(self, points: torch.Tensor, pixel_scale: float = 1.0) -> torch.Tensor:
        """L_opt's residual (T-1, J, 2) for image points (T, J, 2) px under ``self.flows``; zero
        for points outside the image at t-1 when ``flow_inside_only``."""
        r = flow_residual(points, self.flows, pixel_scale)
        if self.hparams.flow_inside_only:
            r = r * inside_image(points[:-1].detach(), *self.image_size)[..., None]
        return r

    def training_step(self, batch: int, batch_idx: int) -> torch.Tensor:
        every = self.trainer.log_every_n_steps if self._trainer is not None else 1
        step = self.global_step
        log_now = bool(every) and (step + 1) % every == 0
        loss, terms = self.total_loss(with_terms=log_now)
        if log_now:
            logged = {f"loss/{k}": v for k, v in terms.items()}
            logged["loss/total"] = loss.detach()
            self.log_dict(logged, on_step=True, on_epoch=False, batch_size=1)
        n = self.hparams.eval_every_n_steps
        if n and (step + 1) % n == 0:
            self._log_evaluation(on_step=True)
        return loss

    def _log_evaluation(self, on_step: bool, extra: dict[str, Any] | None = None) -> None:
        """Log :meth:`evaluate` as ``val/<name>`` (and ``extra`` as given), if anything."""
        logged = {**(extra or {}), **{f"val/{k}": v for k, v in self.evaluate().items()}}
        if logged:
            self.log_dict(logged, on_step=on_step, on_epoch=not on_step, batch_size=1)

    def validation_step(self, batch: int, batch_idx: int) -> None:
        """Log the current poses' evaluation (val/*, with ground truth) and loss terms
        (loss/*). While fitting it logs nothing: the training epoch's end logs the same."""
        if self.trainer.state.fn == TrainerFn.FITTING:
            return
        self._log_evaluation(on_step=False, extra={f"loss/{k}": v for k, v in self.final_loss().items()})

    # --- hooks -----------------------------------------------------------------------------------
    def configure_callbacks(self) -> list[Callback]:
        n = self.hparams.num_threads
        return ([TorchThreads(n)] if n is not None else []) + [FiniteGuard()]

    def on_fit_start(self) -> None:
        self._started = time.perf_counter()

    def on_train_start(self) -> None:
        self.metrics_before = self.evaluate()
        if self.metrics_before:
            for logger in self.loggers:
                logger.log_metrics({f"val/{k}": v for k, v in self.metrics_before.items()}, step=0)

    def on_train_epoch_end(self) -> None:
        self._log_evaluation(on_step=False)

    def on_train_end(self) -> None:
        self.result = self.make_result()
        self.result.seconds = time.perf_counter() - self._started
        fault = finite_fault(self.trainer)
        if fault is not None:  # the variables are those of the last good step
            self.result.steps = fault["good_steps"]
        if self.hparams.save:
            self.result.save(self.output_folder())

    # --- results ---------------------------------------------------------------------------------
    def output_folder(self) -> Path:
        """Where the poses are saved: ``output_dir``, else the trainer's log_dir."""
        if self.hparams.output_dir:
            return Path(self.hparams.output_dir)
        trainer = self._trainer
        return Path(trainer.log_dir or trainer.default_root_dir) if trainer is not None else Path(".")

    def stopped_early(self) -> bool:
        """Whether a :class:`LossPlateauStopping` callback stopped the run."""
        trainer = self._trainer
        if trainer is None:
            return False
        return any(isinstance(c, LossPlateauStopping) and c.stopped_step is not None for c in trainer.callbacks)

    @torch.no_grad()
    def final_loss(self) -> dict[str, float]:
        """The weighted loss terms at the current variables, as floats."""
        loss, terms = self.total_loss(with_terms=True)
        out = {k: float(v) for k, v in terms.items()}
        out["total"] = float(loss)
        return out
