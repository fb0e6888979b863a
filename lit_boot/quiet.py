"""Lightning's chatter off while lit-boot runs its own Trainers: :func:`quiet_lightning`
(every :meth:`~lit_boot.bootstrap.Bootstrap.run` is inside it), unless :func:`keep_lightning` or
``LIT_BOOT_VERBOSE=1`` asks for all of it (``lit-boot --verbose``).

Every Trainer lit-boot builds would otherwise print Lightning's start-up lines ("GPU available:
...", "TPU available: ...", a litlogger / litmodels tip, "`Trainer.fit` stopped: ...", "Seed set
to 0", the model summary) through Lightning's own stream handler, and torch/Lightning warn about
their own internals. Both the command line (:func:`lit_boot.cli.console.command_output`) and the
library's runs use this one list of what is noise.

Cheap to import: logging and warnings only.
"""

from __future__ import annotations

import logging
import os
import warnings
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["quiet_lightning", "keep_lightning", "LIGHTNING_INFO_LOGGERS", "KNOWN_WARNINGS"]

#: Lightning loggers whose INFO records are noise to a lit-boot user (WARNING and up stay).
LIGHTNING_INFO_LOGGERS = (
    "lightning.pytorch.utilities.rank_zero",  # "GPU available: ...", "TPU available: ...", the 💡 litlogger /
    "lightning.fabric.utilities.rank_zero",  # litmodels tips, "`Trainer.fit` stopped: ...", "Restoring states ..."
    "lightning.fabric.utilities.seed",  # "Seed set to 0"
    "lightning.pytorch.callbacks.model_summary",  # the parameter table at the start of fit
    "lightning.pytorch.accelerators.cuda",  # "LOCAL_RANK: 0 - CUDA_VISIBLE_DEVICES: [0]"
)

#: (message regex, matched from the start, category, module regex) of dependency warnings that say nothing to a user.
KNOWN_WARNINGS = (
    # torch >= 2.10 deprecates LeafSpec, which Lightning's pytree helper still builds (every Trainer run)
    (r"`isinstance\(treespec, LeafSpec\)` is deprecated", FutureWarning, r"lightning\.pytorch\.utilities\._pytree"),
    # lit-boot passes the command line to LightningCLI as args on purpose
    (r"LightningCLI's args parameter is intended to run from within Python", UserWarning, r"lightning\.pytorch\.cli"),
    # on a GPU machine: the pose stages run on the CPU on purpose (pose_accelerator, a few thousand numbers)
    (r"GPU available but not used", UserWarning, r"lightning\.pytorch\.trainer\.setup"),
    # on a machine with more than 2 cores: lit-boot's datasets are tensors in memory, worker processes would only
    # copy them (seen on the 16-core GPU machine, one warning per Trainer kind)
    (r".* does not have many workers which may be a bottleneck", UserWarning,
     r"lightning\.pytorch\.trainer\.connectors\.data_connector"),
    # FlowTTT skips a batch with nothing to learn (no person's box in it) by returning None, on purpose
    (r"`training_step` returned `None`", UserWarning, r"lightning\.pytorch\.loops\.optimization\.automatic"),
)


_kept = 0  # how many keep_lightning() blocks are open


@contextmanager
def keep_lightning() -> Iterator[None]:
    """Within the block, :func:`quiet_lightning` changes nothing: Lightning's info lines and every
    warning show (``lit-boot --verbose``)."""
    global _kept
    _kept += 1
    try:
        yield
    finally:
        _kept -= 1


@contextmanager
def quiet_lightning() -> Iterator[None]:
    """Within the block: Lightning's info lines (:data:`LIGHTNING_INFO_LOGGERS`) are not logged,
    :data:`KNOWN_WARNINGS` are dropped, and every other warning from Lightning or torch* shows
    once per message (not once per Trainer). The loggers' levels and the warning filters are
    restored after. Nothing changes inside :func:`keep_lightning` or with ``LIT_BOOT_VERBOSE`` set
    to anything but ""/"0". Warnings' filters are process-wide: not for use from several threads
    at once."""
    if _kept or os.environ.get("LIT_BOOT_VERBOSE", "") not in ("", "0"):
        yield
        return
    loggers = [logging.getLogger(name) for name in LIGHTNING_INFO_LOGGERS]
    levels = [logger.level for logger in loggers]
    with warnings.catch_warnings():
        for logger in loggers:  # children of Lightning's loggers: kept when it is imported
            logger.setLevel(logging.WARNING)
        for category in (UserWarning, RuntimeWarning, FutureWarning):  # the ones Python shows by default
            warnings.filterwarnings("once", category=category, module=r"(lightning|torch\w*)(\.|$)")
        for message, category, module in KNOWN_WARNINGS:
            warnings.filterwarnings("ignore", message=message, category=category, module=module)
        try:
            yield
        finally:
            for logger, level in zip(loggers, levels):
                logger.setLevel(level)
