"""``lit-boot fit|validate|predict --config FILE``: Lightning's CLI over lit-boot's modules and data.

:class:`LitBootCLI` subclasses LightningCLI. The model and the data are chosen by the config
(``model.class_path``, ``data.class_path``), so FlowTTT and the later stages share one command.
Without ``trainer.default_root_dir`` a run goes to ``runs/<scene folder name>/<model class name>``.

As lit-boot's own commands: no abbreviated options, a bad argument raises
:class:`argparse.ArgumentError`, and a model or data that cannot be built (missing scene, bad
weights file) raises :class:`~lit_boot.cli.console.CliError` with the reason in one line, before
any run folder exists. A run that fails before it trained anything leaves no folder behind.

Imports Lightning: :mod:`lit_boot.cli` imports this module only when one of these commands runs.
"""

from __future__ import annotations

import re
import shutil
from fnmatch import fnmatch
from pathlib import Path

import lightning as L
from lightning.pytorch.callbacks import Callback, ModelSummary, ProgressBar
from lightning.pytorch.cli import LightningArgumentParser, LightningCLI

from ..progress import progress_bar
from .console import CliError, HelpFormatter, Suggesting, error_line

__all__ = ["LitBootArgumentParser", "LitBootCLI", "lightning", "run_lightning_cli"]

#: Files a Lightning run writes before it has done anything: a folder holding only these is no loss.
BOOKKEEPING = ("events.out.tfevents.*", "hparams.yaml", "config.yaml", "metrics.csv")


class LitBootArgumentParser(Suggesting, LightningArgumentParser):
    """Lightning's parser with lit-boot's defaults (see :class:`lit_boot.cli.console.ArgumentParser`)."""

    def __init__(self, *args, allow_abbrev: bool = False, exit_on_error: bool = False, **kwargs) -> None:
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, allow_abbrev=allow_abbrev, exit_on_error=exit_on_error, **kwargs)


class LitBootCLI(LightningCLI):
    """LightningCLI with a per-scene default run folder, one-line build errors, no empty run
    folders left by a failed run, and the plain progress bar and model summary."""

    def before_instantiate_classes(self) -> None:
        config = self.config[self.subcommand] if self.subcommand else self.config
        root = config.trainer.get("default_root_dir")
        if root in (None, "", "."):
            scene = config.data.init_args.get("scene") if config.get("data") else None
            model = config.model.class_path.rsplit(".", 1)[-1] if config.get("model") else "model"
            name = Path(str(scene)).name if scene else "scene"
            config.trainer.default_root_dir = str(Path("runs") / name / model)

    def instantiate_classes(self) -> None:
        """Build the model, data and trainer; a failure is a :class:`CliError` naming its cause."""
        try:
            super().instantiate_classes()
        except (ValueError, OSError) as err:
            config = self.config[self.subcommand] if self.subcommand else self.config
            raise CliError(build_error(err, config)) from err

    def instantiate_trainer(self, **kwargs) -> L.Trainer:
        """Lightning's Trainer, with tqdm's progress bar and the logged model summary unless the
        config names others or turns them off. (Lightning >= 2.6 picks rich's when rich is
        installed, as import-linter in the dev extra does; rich's summary table would be printed
        past :func:`~lit_boot.cli.console.command_output`.)"""
        trainer = {**self._get(self.config_init, "trainer", default={}), **kwargs}
        configured = trainer.get("callbacks") or []
        configured = configured if isinstance(configured, list) else [configured]
        return super().instantiate_trainer(**kwargs, callbacks=[*configured, *plain_callbacks(trainer, configured)])

    def _run_subcommand(self, subcommand: str) -> None:
        roots = {Path(self.trainer.default_root_dir).resolve()}
        roots |= {Path(logger.save_dir).resolve() for logger in self.trainer.loggers if logger.save_dir}
        before = {root: existing_folders(root) for root in roots}
        try:
            super()._run_subcommand(subcommand)
        except BaseException:
            if self.trainer.global_step == 0:  # nothing trained: drop what this run created, if only bookkeeping
                for root, existed in before.items():
                    remove_new_bookkeeping(root, existed)
            raise


def plain_callbacks(trainer: dict, configured: list[Callback]) -> list[Callback]:
    """The progress bar and model summary callbacks a Trainer with arguments ``trainer`` and
    callbacks ``configured`` would add itself, as tqdm's and the plain (logged) ones."""
    missing = []
    if trainer.get("enable_progress_bar") is not False and not any(isinstance(c, ProgressBar) for c in configured):
        missing.append(progress_bar())
    if trainer.get("enable_model_summary") is not False and not any(isinstance(c, ModelSummary) for c in configured):
        missing.append(ModelSummary())
    return missing


def build_error(err: BaseException, config) -> str:
    """Why a class could not be built, in one line: the option (``--model``, ``--data``) and class,
    then the reason jsonargparse wrapped in its report of the union's subtypes."""
    building = re.search(r"class_path='([\w.]+)'", str(err))
    if building is None:
        return error_line(err)
    keys = [k for k in ("model", "data") if config.get(k) and config[k].get("class_path") == building.group(1)]
    return f"could not build {'--' + keys[0] + ' ' if keys else ''}{building.group(1)}: {error_line(err)}"


def existing_folders(root: Path, depth: int = 3) -> set[Path]:
    """``root``, its existing ancestors and the folders up to ``depth`` levels under it (Lightning's
    ``lightning_logs/version_N/checkpoints``), as they are now."""
    folders = {p for p in (root, *root.parents) if p.is_dir()}
    return folders | {p for level in range(1, depth + 1) for p in root.glob("/".join(["*"] * level)) if p.is_dir()}


def remove_new_bookkeeping(root: Path, existed: set[Path]) -> None:
    """Remove each outermost folder on, above or under ``root`` that is not in ``existed`` (made
    since) and holds only :data:`BOOKKEEPING` files."""
    new = existing_folders(root) - existed
    for folder in sorted(new):
        if folder.parent not in new and folder.is_dir():
            files = [p for p in folder.rglob("*") if p.is_file()]
            if all(any(fnmatch(p.name, pattern) for pattern in BOOKKEEPING) for p in files):
                shutil.rmtree(folder)


def run_lightning_cli(argv: list[str]) -> LitBootCLI:
    """Run ``fit``/``validate``/``predict`` with ``argv`` (the subcommand first)."""
    return LitBootCLI(
        L.LightningModule,
        L.LightningDataModule,
        subclass_mode_model=True,
        subclass_mode_data=True,
        args=argv,
        save_config_kwargs={"overwrite": True},
        parser_class=LitBootArgumentParser,
    )


def lightning(argv: list[str]) -> int:
    """``lit-boot fit|validate|predict`` (``argv``: the subcommand first): run it, name the run folder."""
    trainer = run_lightning_cli(argv).trainer
    print(f"run folder: {trainer.default_root_dir} (this run's logs: {trainer.log_dir})")
    return 0
