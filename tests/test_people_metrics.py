"""Metrics per person and pooled: the flow on each person's own pixels, the run's records, the
metrics plot and the dataset summary."""

from __future__ import annotations

import json

import pytest
import torch

from lit_boot.bootstrap import bootstrap
from lit_boot.bootstrap.metrics_plot import history_figure
from lit_boot.core import GroundTruth
from lit_boot.dataset.summary import summary_rows
from lit_boot.metrics import compute_metric_states, scene_flow_metrics, scene_metric_states, scene_pose_metrics
from lit_boot.synth import SynthConfig, make_scene

RANDOM_RAFT = {"weights": None, "train_updates": 2, "predict_updates": 3}  # no weights file needed


@pytest.fixture(scope="module")
def pair():
    return make_scene(SynthConfig(motion="walk", seed=5, frames=4, height=64, width=128, people=2))


def test_each_persons_flow_error_is_on_its_own_pixels(pair):
    gt = pair.gt
    flows = gt.flow + torch.linspace(0, 2, gt.flow.shape[-1])  # error growing to the right, 0..2 px
    values = scene_flow_metrics(gt, flows, pair.track_id)
    error = (flows - gt.flow).norm(dim=1)
    scored = gt.flow_mask()
    other = gt.others[0]
    own = {pair.track_id: gt.person_mask[:-1] & ~other.person_mask[:-1], other.track_id: other.person_mask[:-1]}
    for track_id, mask in own.items():
        assert values[f"epe_person_person{track_id}"] == pytest.approx(float(error[mask & scored].mean()), rel=1e-5)
        assert f"epe_joints_person{track_id}" in values
    counts = [int((m & scored).sum()) for m in own.values()]
    pooled = sum(c * values[f"epe_person_person{i}"] for c, i in zip(counts, own)) / sum(counts)
    assert values["epe_person"] == pytest.approx(pooled, rel=1e-5)  # every person's pixels
    assert not any(k.endswith("_all") or "background_person" in k for k in values)
    alone = scene_flow_metrics(GroundTruth(flow=gt.flow, person_mask=gt.person_mask), flows)
    assert set(alone) == {"epe", "epe_person", "epe_background"}  # one person: the names as before
    states = compute_metric_states(scene_metric_states(pair, flows, "2d"))
    assert states["epe_person_person1"] == pytest.approx(values["epe_person_person1"], rel=1e-6)
    assert states["kp2d_px_all"] > 0 and "kp2d_px_person1" in states


def test_the_plot_draws_each_person_in_its_metrics_panel():
    history = [{"stage": "initial", "kp2d_px": 3.0, "kp2d_px_all": 2.5, "kp2d_px_person4": 2.0, "epe": 1.0},
               {"stage": "pose", "kp2d_px": 2.0, "kp2d_px_all": 2.0, "kp2d_px_person4": 2.0, "epe": 1.0}]  # fmt: skip
    figure = history_figure(history)
    titles = [ax.get_title() for ax in figure.axes]
    assert len(figure.axes) == 2 and titles[0].startswith("kp2d_px")
    labels = [line.get_label() for line in figure.axes[0].get_lines()]
    assert labels == ["main person", "all people", "person 4"]


def test_the_dataset_summary_pools_people_but_lists_no_track_of_one_scene():
    states = {"kp2d_px": {"error_sum": 6.0, "count": 3.0}, "kp2d_px_all": {"error_sum": 9.0, "count": 6.0},
              "kp2d_px_person2": {"error_sum": 3.0, "count": 3.0}}  # fmt: skip
    record = {"name": "a", "state": "done", "frames": 4, "seconds": 1.0, "states": {"initial": states, "final": states}}
    row = summary_rows([record])[-1]
    assert row["kp2d_px_all after"] == pytest.approx(1.5) and row["kp2d_px after"] == pytest.approx(2.0)
    assert not any("person2" in key for key in row)


def test_a_run_on_two_people_records_every_persons_metrics(pair, tmp_path):
    result = bootstrap(pair, tmp_path / "run", mode="2d", flow=RANDOM_RAFT, flow_epochs=1, pose_steps=10,
                       progress_bar=False, video=False, accelerator="cpu")  # fmt: skip
    other = pair.others[0].track_id
    pose = next(r for r in result.history if r["kind"] == "pose")
    flow = next(r for r in result.history if r["kind"] == "flow")
    assert {"kp2d_px", "kp2d_px_all", f"kp2d_px_person{other}"} <= set(pose)
    assert {"epe_person", f"epe_person_person{other}", f"epe_person_person{pair.track_id}"} <= set(flow)
    shares = flow["info"]["self_check"]["people"]  # the self-check's share kept on each person's region
    assert [s["track_id"] for s in shares] == [pair.track_id, other]
    assert all(0.0 <= s["tuned_fraction"] <= 1.0 for s in shares)
    final = json.loads((tmp_path / "run" / "summary.json").read_text())
    text = json.dumps(final)
    assert f"kp2d_px_person{other}" in text and f"epe_person_person{other}" in text
    report = (tmp_path / "run" / "report.html").read_text()
    assert f"kp2d_px_person{other}" in report


def test_the_self_check_share_of_each_persons_region():
    from lit_boot.bootstrap.selfcheck import people_shares, summary_line

    people = torch.full((2, 40, 120), -1, dtype=torch.int8)
    people[:, 10:30, 10:20] = 0
    people[:, 10:30, 90:100] = 1
    weight = torch.zeros(2, 40, 120)
    weight[:, :, :60] = 1.0  # the tuned flow kept on the left half only
    shares = people_shares(weight, people, [4, 9])
    assert shares == [{"track_id": 4, "tuned_fraction": 1.0}, {"track_id": 9, "tuned_fraction": 0.0}]
    record = {"kept_tuned_fraction": 0.5, "person_tuned_fraction": 0.5, "regions_tuned": 1, "regions_initial": 1,
              "people": shares}  # fmt: skip
    assert "50% of the people: track 4 100%, track 9 0%; 1 of 2 background tiles" in summary_line(record)


def test_a_person_of_the_scene_is_scored_against_their_own_truth(pair):
    other = pair.others[0].track_id
    alone = pair.person(1)
    assert alone.track_id == other and alone.others == ()
    torch.testing.assert_close(alone.gt.joints3d, pair.gt.others[0].joints3d)
    assert [o.track_id for o in alone.gt.others] == [pair.track_id]  # the main person among the others
    for mode, name in (("2d", "kp2d_px"), ("3d", "mpjpe_mm")):
        assert scene_pose_metrics(alone, mode)[name] == pytest.approx(
            scene_pose_metrics(pair, mode)[f"{name}_person{other}"], rel=1e-6)
    flows = pair.gt.flow + 0.5
    mine = scene_flow_metrics(alone.gt, flows, alone.track_id)
    theirs = scene_flow_metrics(pair.gt, flows, pair.track_id)
    assert mine[f"epe_person_person{other}"] == pytest.approx(theirs[f"epe_person_person{other}"], rel=1e-6)
    assert mine["epe_joints"] == pytest.approx(theirs[f"epe_joints_person{other}"], rel=1e-6)
