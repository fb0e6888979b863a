"""From Python, lit-boot prints nothing at the default logging level (issue 26): no "GPU
available", no Lightning tips, no dependency deprecation warnings, no progress bars. Each run is a
fresh interpreter, as a user's script is (Lightning adds its own stream handler at import)."""

from __future__ import annotations

import logging
import re
import subprocess
import sys
import textwrap
import warnings

import pytest

from lit_boot.quiet import LIGHTNING_INFO_LOGGERS, keep_lightning, quiet_lightning

NOISE = ("GPU available", "TPU available", "Tip", "litlogger", "deprecated", "Warning", "it/s", "Epoch", "%|")


def run_python(tmp_path, body: str) -> subprocess.CompletedProcess:
    code = textwrap.dedent(f"""
        import lit_boot
        from lit_boot.bootstrap import bootstrap
        from lit_boot.quiet import quiet_lightning
        scene = lit_boot.make_scene(motion="run", frames=3, height=64, width=96, seed=0)
        RANDOM_RAFT = {{"weights": None, "train_updates": 2, "predict_updates": 3}}
        FAST = dict(flow_epochs=1, pose_steps=10, video=False, accelerator="cpu")
    """) + textwrap.dedent(body)  # fmt: skip
    env = {"OMP_NUM_THREADS": "1", "PATH": "/usr/bin:/bin"}
    return subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=600,
                          env=env)  # fmt: skip


def test_a_run_inside_quiet_lightning_prints_nothing_but_what_the_user_asks_for(tmp_path) -> None:
    done = run_python(tmp_path, """
        with quiet_lightning():
            bootstrap(scene, "run_a", flow=RANDOM_RAFT, progress_bar=False, **FAST)
        import logging
        logging.basicConfig(level=logging.INFO)  # the user asks for lit-boot's lines
        with quiet_lightning():
            bootstrap(scene, "run_b", flow=RANDOM_RAFT, progress_bar=False, **FAST)
    """)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout == ""
    assert re.search(r"\[lit-boot\] stage \d/\d flow_1", done.stderr)  # lit-boot's own records, when logging is on
    lines = [line for line in done.stderr.splitlines() if "lit_boot" not in line]
    assert not [line for line in lines if any(n in line for n in NOISE)], lines


def test_a_plain_run_from_python_prints_nothing(tmp_path) -> None:
    done = run_python(tmp_path, """
        bootstrap(scene, "run", flow=RANDOM_RAFT, **FAST)
    """)
    assert done.returncode == 0, done.stderr[-3000:]
    assert (done.stdout, done.stderr) == ("", "")


def test_quiet_lightning_restores_the_levels_and_filters() -> None:
    logger = logging.getLogger(LIGHTNING_INFO_LOGGERS[0])
    level, filters = logger.level, list(warnings.filters)
    with quiet_lightning():
        assert logger.getEffectiveLevel() == logging.WARNING
    assert logger.level == level and warnings.filters == filters


def test_keep_lightning_and_the_environment_keep_everything(monkeypatch) -> None:
    logger = logging.getLogger(LIGHTNING_INFO_LOGGERS[0])
    monkeypatch.setattr(logger, "level", logging.INFO)  # as Lightning sets it when imported
    level = logging.INFO
    with keep_lightning(), quiet_lightning():  # lit-boot --verbose
        assert logger.getEffectiveLevel() == level
    monkeypatch.setenv("LIT_BOOT_VERBOSE", "1")
    with quiet_lightning():
        assert logger.getEffectiveLevel() == level
    monkeypatch.setenv("LIT_BOOT_VERBOSE", "0")
    with quiet_lightning():
        assert logger.getEffectiveLevel() == logging.WARNING


def test_the_tips_of_a_gpu_machine_are_dropped(monkeypatch) -> None:
    """On a many-core CUDA machine (the H200 of the GPU check) every run warned "GPU available but
    not used" (the pose stage runs on the CPU on purpose) and "does not have many workers" (the
    datasets are in-memory tensors). Here the machine is made to look like that one."""
    import lightning as L
    import torch
    from lightning.pytorch.trainer import setup
    from lightning.pytorch.trainer.connectors import data_connector

    monkeypatch.setattr(setup.CUDAAccelerator, "is_available", staticmethod(lambda: True))
    monkeypatch.setattr(data_connector, "suggested_max_num_workers", lambda devices: 15)
    trainer = L.Trainer(accelerator="cpu", devices=1, logger=False, enable_progress_bar=False)
    loader = torch.utils.data.DataLoader(torch.zeros(4, 2), num_workers=0)

    def warned() -> list[str]:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            with quiet_lightning():
                setup._log_device_info(trainer)
                data_connector._worker_check(trainer, loader, "train_dataloader")
        return [str(w.message) for w in caught]

    with keep_lightning():  # lit-boot --verbose: both show, so the check above is not vacuous
        loud = warned()
    assert any("GPU available but not used" in m for m in loud) and any("many workers" in m for m in loud), loud
    assert warned() == []


def test_a_skipped_training_step_is_not_a_warning(monkeypatch) -> None:
    """FlowTTT returns None from ``training_step`` for a batch with nothing to learn (no person's
    box in it); Lightning warns "If this was on purpose, ignore this warning", once per run (seen in
    the Sintel benchmark's runs from Python)."""
    import lightning as L
    import torch
    from lightning.pytorch.loops.optimization import automatic
    from lightning.pytorch.utilities.rank_zero import WarningCache

    class Skips(L.LightningModule):
        def __init__(self) -> None:
            super().__init__()
            self.weight = torch.nn.Parameter(torch.zeros(1))

        def training_step(self, batch, batch_idx):
            return None if batch_idx == 0 else (self.weight - batch.sum()).square().sum()

        def configure_optimizers(self):
            return torch.optim.SGD(self.parameters(), lr=0.1)

    def warned() -> list[str]:
        monkeypatch.setattr(automatic.Closure, "warning_cache", WarningCache())  # once per process
        trainer = L.Trainer(accelerator="cpu", max_epochs=1, logger=False, enable_progress_bar=False,
                            enable_checkpointing=False, enable_model_summary=False)  # fmt: skip
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            with quiet_lightning():
                trainer.fit(Skips(), torch.utils.data.DataLoader(torch.ones(2, 1), batch_size=1))
        return [str(w.message) for w in caught]

    with keep_lightning():  # lit-boot --verbose: it shows, so the check below is not vacuous
        assert any("returned `None`" in m for m in warned())
    assert not any("returned `None`" in m for m in warned())
