"""The typed flow / pose parts of BootstrapConfig: their keys are the classes' arguments, and an
unknown key is refused from Python and from the command line before anything runs."""

from __future__ import annotations

import dataclasses
import inspect

import pytest

from lit_boot.bootstrap import BootstrapConfig
from lit_boot.bootstrap.options import FlowOptions, LossWeightOptions, PoseOptions, SketchOptions
from lit_boot.cli import main
from lit_boot.flow import FlowTTT, SketchConfig
from lit_boot.pose import KeypointLossWeights, KeypointRefiner, PoseLossWeights, PoseRefiner


def arguments(cls: type) -> set[str]:
    return {name for name in inspect.signature(cls.__init__).parameters if name != "self"}


def test_the_options_are_the_classes_arguments():
    assert set(FlowOptions.__annotations__) == arguments(FlowTTT)
    assert set(SketchOptions.__annotations__) == {f.name for f in dataclasses.fields(SketchConfig)}
    both = arguments(PoseRefiner) | arguments(KeypointRefiner)
    assert set(PoseOptions.__annotations__) == both - {"save", "output_dir"}  # the orchestrator saves the poses
    lambdas = {f.name for cls in (PoseLossWeights, KeypointLossWeights) for f in dataclasses.fields(cls)}
    assert set(LossWeightOptions.__annotations__) == lambdas


def test_unknown_keys_are_refused_with_their_name():
    config = BootstrapConfig(flow={"lr": 1e-4, "sketch": {"size": 3}}, pose={"loss_weights": {"opt": 0.1}})
    assert config.flow_kwargs(person_px=90)["sketch"]["size"] == 3 and config.pose_kwargs()["loss_weights"] == {"opt": 0.1}
    with pytest.raises(ValueError, match=r"flow: unknown key 'lx'; expected some of \['arch'"):
        BootstrapConfig(flow={"lx": 1})
    with pytest.raises(ValueError, match=r"flow.sketch: unknown key 'sise'"):
        BootstrapConfig(flow={"sketch": {"sise": 1}})
    with pytest.raises(ValueError, match=r"pose.loss_weights: unknown key 'bones'"):
        BootstrapConfig(pose={"loss_weights": {"bones": 1.0}})
    with pytest.raises(ValueError, match=r"flow_ensemble\[0\]: unknown key 'arc'"):
        BootstrapConfig(flow_ensemble=[{"arc": "raft_large"}])


def test_the_command_line_checks_the_keys_and_their_types(tmp_path, capsys):
    base = ["bootstrap", "--config", "configs/bootstrap.yaml", "--data.scene", str(tmp_path / "scene")]
    assert main([*base, "--flow", "{lx: 1}"]) == 2
    assert "lx" in capsys.readouterr().err
    assert main([*base, "--flow.train_updates", "many"]) == 2
    assert "--flow: expected int, got 'many'" in capsys.readouterr().err
    assert not (tmp_path / "scene").exists() and not list(tmp_path.iterdir())  # nothing written


def test_the_default_preset_fine_tunes_fast_and_the_paper_preset_as_the_authors():
    for mode in ("3d", "2d"):
        fast = BootstrapConfig(mode=mode).flow_kwargs(0, 100.0)
        assert fast["warm_start"] and fast["train_parts"] == "update_block" and fast["crop_margin"] == 24
        model = FlowTTT(**{**fast, "weights": None, "sketch": None})
        assert model.hparams.warm_start and model.hparams.paste_crop  # the tuned flow only on the crop
        paper = BootstrapConfig(mode=mode, preset="paper").flow_kwargs(0, 100.0)
        assert "warm_start" not in paper and paper["train_updates"] == 20
        authors = BootstrapConfig(mode=mode, flow={"warm_start": False, "train_parts": "all"}).flow_kwargs(0, 100.0)
        assert not authors["warm_start"] and authors["train_parts"] == "all"  # the user's choice wins
