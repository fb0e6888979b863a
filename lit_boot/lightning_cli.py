"""Lightning's CLI for lit-boot: ``lit-boot fit|validate|predict --config FILE``.

The model and the data are chosen by the config (``model.class_path``, ``data.class_path``), so
FlowTTT and the later stages share one command. Without ``trainer.default_root_dir`` a run goes
to ``runs/<scene folder name>/<model class name>``.
"""

from __future__ import annotations

from pathlib import Path

import lightning as L
from lightning.pytorch.cli import LightningCLI

__all__ = ["LitBootCLI", "run_lightning_cli"]


class LitBootCLI(LightningCLI):
    """LightningCLI with a per-scene default run folder."""

    def before_instantiate_classes(self) -> None:
        config = self.config[self.subcommand] if self.subcommand else self.config
        root = config.trainer.get("default_root_dir")
        if root in (None, "", "."):
            scene = config.data.init_args.get("scene") if config.get("data") else None
            model = config.model.class_path.rsplit(".", 1)[-1] if config.get("model") else "model"
            name = Path(str(scene)).name if scene else "scene"
            config.trainer.default_root_dir = str(Path("runs") / name / model)


def run_lightning_cli(argv: list[str]) -> LitBootCLI:
    """Run ``fit``/``validate``/``predict`` with ``argv`` (the subcommand first)."""
    return LitBootCLI(
        L.LightningModule,
        L.LightningDataModule,
        subclass_mode_model=True,
        subclass_mode_data=True,
        args=argv,
        save_config_kwargs={"overwrite": True},
    )
