"""PoseData and flow sources: .flo folders, flows.npz, GT; clear errors; the Lightning CLI."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from lit_boot.cli import main
from lit_boot.data import save_scene, write_flo
from lit_boot.pose import FlowSourceError, PoseData, load_flows, load_pose_result
from lit_boot.synth import make_scene


@pytest.fixture(scope="module")
def scene():
    return make_scene(motion="jump", frames=4, height=40, width=56, seed=2)


@pytest.fixture(scope="module")
def scene_dir(scene, tmp_path_factory):
    folder = tmp_path_factory.mktemp("pose") / "jump_scene"
    save_scene(scene, folder)
    return folder


def write_flows(folder, flows: torch.Tensor) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    for t, flow in enumerate(flows):
        write_flo(folder / f"flow_{t:06d}.flo", flow)


def test_flows_from_a_flo_folder_an_npz_and_the_ground_truth(scene, tmp_path):
    write_flows(tmp_path / "flo", scene.gt.flow)
    (tmp_path / "flo" / "flow_000000.png").write_bytes(b"")  # FlowWriter's pictures are ignored
    torch.testing.assert_close(load_flows(tmp_path / "flo", scene), scene.gt.flow)
    order = np.array([2, 0, 1])  # stored out of order: "index" says which pair each is
    np.savez(tmp_path / "flows.npz", flow=scene.gt.flow.numpy()[order], index=order)
    torch.testing.assert_close(load_flows(tmp_path / "flows.npz", scene), scene.gt.flow)
    assert load_flows("gt", scene) is scene.gt.flow or torch.equal(load_flows("gt", scene), scene.gt.flow)


def test_wrong_count_wrong_size_and_missing_paths_name_what_was_expected(scene, tmp_path):
    write_flows(tmp_path / "few", scene.gt.flow[:2])
    with pytest.raises(FlowSourceError, match=r"few: expected 3 flows .*missing flow_000002\.flo"):
        load_flows(tmp_path / "few", scene)
    write_flows(tmp_path / "small", torch.zeros(3, 2, 20, 30))
    with pytest.raises(FlowSourceError, match=r"flow_000000\.flo: flow is 30x20 px, expected 56x40"):
        load_flows(tmp_path / "small", scene)
    with pytest.raises(FileNotFoundError, match="nowhere"):
        load_flows(tmp_path / "nowhere", scene)
    np.savez(tmp_path / "bad.npz", flow=np.zeros((5, 2, 40, 56), np.float32))
    with pytest.raises(FlowSourceError, match=r"bad\.npz: expected 3 flows .*got 5"):
        load_flows(tmp_path / "bad.npz", scene)
    np.savez(tmp_path / "nokey.npz", flows=np.zeros((3, 2, 40, 56), np.float32))
    with pytest.raises(FlowSourceError, match="'flow'"):
        load_flows(tmp_path / "nokey.npz", scene)
    (tmp_path / "empty.npz").write_bytes(b"")
    with pytest.raises(FlowSourceError, match=r"empty\.npz: not a readable \.npz file"):
        load_flows(tmp_path / "empty.npz", scene)
    nan = np.zeros((3, 2, 40, 56), np.float32)
    nan[1, :, 5, 7] = np.nan
    np.savez(tmp_path / "nan.npz", flow=nan)
    with pytest.raises(FlowSourceError, match=r"nan\.npz: 'flow' holds NaN or infinite values at 1 pixels"):
        load_flows(tmp_path / "nan.npz", scene)
    with pytest.raises(FlowSourceError, match=r"expected flows of shape \(3, 2, 40, 56\)"):
        load_flows(torch.zeros(3, 40, 56), scene)
    no_gt = make_scene(motion="jump", frames=2, height=40, width=56, seed=2)
    no_gt.gt = None
    with pytest.raises(FlowSourceError, match="no ground-truth flow"):
        load_flows("gt", no_gt)


def test_gt_flows_refused_where_a_pair_has_no_valid_gt(scene):
    """A partial Sintel copy: a pair without its .flo has zero flow marked invalid everywhere;
    the refiner must not take it for "no motion"."""
    partial = make_scene(motion="jump", frames=4, height=40, width=56, seed=2)
    partial.gt.flow_valid[1] = False
    partial.gt.flow[1] = 0.0
    with pytest.raises(FlowSourceError, match=r"no ground-truth flow for pair\(s\) 1->2"):
        load_flows("gt", partial)
    partial.gt.flow_valid[1, :5] = True  # some valid pixels: accepted
    assert torch.equal(load_flows("gt", partial), partial.gt.flow)


def test_pose_data_serves_one_epoch_of_step_indices(scene):
    data = PoseData(scene, "gt", steps=7)
    data.setup("fit")
    assert data.flows.shape == (3, 2, 40, 56)
    assert list(data.train_dataloader()) == list(range(7))
    with pytest.raises(ValueError, match="steps"):
        PoseData(scene, steps=0)


CLI = ["--trainer.max_steps", "30", "--trainer.enable_progress_bar", "false", "--trainer.logger", "false"]


@pytest.mark.parametrize("config, flows", [("pose_refiner", "gt"), ("pose_refiner", "flo"), ("pose_refiner_2d", "flo")])
def test_cli_fit_runs_and_saves_the_poses(config, flows, scene, scene_dir, tmp_path):
    if flows == "flo":
        write_flows(tmp_path / "flo", scene.gt.flow)
        flows = str(tmp_path / "flo")
    run = tmp_path / "run"
    argv = ["fit", "--config", f"configs/{config}.yaml", "--data.scene", str(scene_dir), "--data.flows", flows,
            "--trainer.default_root_dir", str(run), *CLI]  # fmt: skip
    assert main(argv) == 0
    result = load_pose_result(run)
    assert result.steps == 30 and result.scene == scene.name
    if config == "pose_refiner":
        assert result.mode == "3d" and result.joints3d.shape == (4, 14, 3)
        assert result.metrics_after["mpjpe_mm"] > 0
    else:
        assert result.mode == "2d" and result.keypoints2d.shape == (4, 17, 2)


def test_cli_reports_bad_flows_as_one_line_errors(scene, scene_dir, tmp_path, capsys):
    write_flows(tmp_path / "few", scene.gt.flow[:1])
    argv = ["fit", "--config", "configs/pose_refiner.yaml", "--data.scene", str(scene_dir), *CLI]
    assert main([*argv, "--data.flows", str(tmp_path / "few")]) == 2
    assert "expected 3 flows" in capsys.readouterr().err
    assert main([*argv, "--data.flows", str(tmp_path / "absent")]) == 2
    assert "absent: no such flow folder" in capsys.readouterr().err
    assert main(["fit", "--config", "configs/pose_refiner.yaml", "--data.scene", str(tmp_path / "noscene"), *CLI]) == 2
    assert "noscene" in capsys.readouterr().err
