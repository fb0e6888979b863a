"""Test fixtures: where the shared real data and weights are.

``../shared`` beside the project root (or ``$LIT_BOOT_SHARED``) holds real RAFT weights,
Sintel samples, CMU BVH files and videos. Tests that need it take the ``shared`` fixture: it
skips when the folder is absent, and fails instead when ``LIT_BOOT_REQUIRE_SHARED=1`` (CI).

No test sees the weights a user placed in ``checkpoints/`` (or ``./checkpoints``): the lookup's
default folders are replaced by an empty one for every test, unless the test is marked
``real_checkpoint_dirs``; a test that wants weights names them (``$LIT_BOOT_CHECKPOINTS`` or a path).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def shared_dir() -> Path:
    """The shared folder: $LIT_BOOT_SHARED, else ../shared beside the project root."""
    return Path(os.environ.get("LIT_BOOT_SHARED", ROOT.parent / "shared"))


@pytest.fixture(scope="session")
def shared() -> Path:
    path = shared_dir()
    if not path.is_dir():
        if os.environ.get("LIT_BOOT_REQUIRE_SHARED") == "1":
            pytest.fail(f"LIT_BOOT_REQUIRE_SHARED=1 but the shared folder {path} is missing")
        pytest.skip(f"needs ../shared: {path} is absent")
    return path


@pytest.fixture(autouse=True)
def no_user_checkpoints(request, tmp_path_factory, monkeypatch):
    """Hide the project's and the working directory's checkpoints/ from the weights lookup."""
    if request.node.get_closest_marker("real_checkpoint_dirs") is None:
        from lit_boot.flow import weights

        empty = tmp_path_factory.mktemp("no_user_checkpoints")
        monkeypatch.setattr(weights, "_default_dirs", lambda: [empty])


@pytest.fixture
def trainer(tmp_path):
    """A quiet Lightning Trainer factory for tiny fits on the CPU: ``trainer(epochs=1, **kw)``
    (no logger, checkpoints, bars, summary or sanity check; ``kw`` are more Trainer arguments)."""
    import lightning as L

    def make(epochs: int = 1, **kw) -> L.Trainer:
        return L.Trainer(max_epochs=epochs, default_root_dir=tmp_path, logger=False, enable_checkpointing=False,
                         enable_progress_bar=False, enable_model_summary=False, num_sanity_val_steps=0,
                         **kw)  # fmt: skip

    return make
