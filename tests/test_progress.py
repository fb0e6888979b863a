"""lit-boot's progress bars (lit_boot.progress): redrawn every step on a terminal, only at each
epoch's start and end in a log file, where every redraw stays."""

from __future__ import annotations

import io

import lightning as L
import torch

from lit_boot.progress import LOG_REFRESH_RATE, progress_bar


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


class Tiny(L.LightningModule):
    def __init__(self) -> None:
        super().__init__()
        self.w = torch.nn.Parameter(torch.ones(1))

    def training_step(self, batch, batch_idx):
        return (self.w * batch[0]).pow(2).mean()

    def configure_optimizers(self):
        return torch.optim.SGD(self.parameters(), lr=0.01)

    def train_dataloader(self):
        return torch.utils.data.DataLoader(torch.utils.data.TensorDataset(torch.ones(40, 1)), batch_size=1)


def test_a_terminal_gets_every_step_a_log_file_each_epoch_once(capfd):
    assert progress_bar(Terminal()).refresh_rate == 1
    assert progress_bar(io.StringIO()).refresh_rate == LOG_REFRESH_RATE
    trainer = L.Trainer(max_epochs=2, logger=False, enable_checkpointing=False, enable_model_summary=False,
                        callbacks=[progress_bar()], accelerator="cpu")  # fmt: skip
    capfd.readouterr()
    trainer.fit(Tiny())
    err = capfd.readouterr().out  # Lightning's bars write to stdout; pytest's captured one is no terminal
    assert "Epoch 0: 100%" in err and "Epoch 1: 100%" in err
    assert "Epoch 0:  50%" not in err  # no redraw in the middle of an epoch
    assert err.count("\r") < 20  # 40 steps x 2 epochs: 80+ redraws every step
