from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from lit_boot.bootstrap import overlay, report
from lit_boot.bootstrap.metric_history import metric_value, stage_series, unit
from lit_boot.bootstrap.metrics_plot import MIN_RELATIVE_SPAN, MIN_SPAN, history_figure, y_limits
from lit_boot.bootstrap.report import overlay_frames, plot_history, write_video
from lit_boot.data import flow_image, read_png
from lit_boot.synth import make_scene

HISTORY = [
    {"stage": "initial", "kind": None, "cycle": None, "epe": 0.25, "epe_person": 5.0, "mpjpe_mm": 60.0,
     "agreement_px": 4.0},
    {"stage": "flow_0", "kind": "flow", "cycle": 0, "epe": 0.18, "epe_person": 4.3, "epe_joints": 4.2,
     "agreement_px": 3.1},
    {"stage": "pose_0", "kind": "pose", "cycle": 0, "mpjpe_mm": 53.6, "pa_mpjpe_mm": 43.5,
     "accel_mm_per_frame2": 30.7, "agreement_px": 2.0},
    {"stage": "flow_1", "kind": "flow", "cycle": 1, "epe": 0.17, "epe_person": None, "agreement_px": 1.8},
]  # fmt: skip


def uniform_flow(n: int, u: float, v: float, h: int, w: int) -> torch.Tensor:
    return torch.tensor([u, v]).view(1, 2, 1, 1).expand(n, 2, h, w).clone()


# --- plot_history ----------------------------------------------------------------------------


def assert_plot(path: Path) -> torch.Tensor:
    image = read_png(path)
    assert image.shape[1] > 100 and image.shape[2] > 100
    grey = image.float().mean(0)
    assert (grey < 128).float().mean() > 0.002  # text, axes and lines, not a blank page
    assert image.float().std() > 5
    return image


def test_plot_history_writes_png(tmp_path: Path) -> None:
    path = plot_history(HISTORY, tmp_path / "metrics.png")
    assert path == tmp_path / "metrics.png"
    image = assert_plot(path)
    # 8 metrics -> a 3 x 3 grid (wider and taller than a single subplot)
    single = assert_plot(plot_history([{"stage": "initial", "agreement_px": 3.0}], tmp_path / "one.png"))
    assert image.shape[1] > 2 * single.shape[1] and image.shape[2] > 2 * single.shape[2]
    # markers in matplotlib's default blue (#1f77b4) appear
    blue = (image[0] < 80) & (image[1] > 90) & (image[1] < 150) & (image[2] > 150)
    assert blue.sum() > 50
    assert sorted(p.name for p in tmp_path.iterdir()) == ["metrics.png", "one.png"]  # no temporary left


def test_plot_history_without_gt(tmp_path: Path) -> None:
    history = [
        {"stage": "initial", "kind": None, "cycle": None, "agreement_px": 3.5, "epe": None},
        {"stage": "flow_0", "kind": "flow", "cycle": 0, "agreement_px": 2.9},
        {"stage": "pose_0", "kind": "pose", "cycle": 0, "agreement_px": 2.0},
    ]
    alone = assert_plot(plot_history(history, tmp_path / "m.png"))
    history[1]["epochs"], history[2]["note"] = 8, "text"  # an int and a string: not metrics
    assert torch.equal(assert_plot(plot_history(history, tmp_path / "m.png")), alone)
    assert metric_value(8) is None and metric_value(float("nan")) is None
    assert metric_value(np.float32(2.5)) == 2.5
    assert_plot(plot_history(history, tmp_path / "m.png"))


def test_plot_history_units() -> None:
    assert unit("agreement_px") == "px"
    assert unit("mpjpe_mm") == "mm"
    assert unit("epe_person") == "px" and unit("epe") == "px"
    assert unit("accel_mm_per_frame2") == "mm/frame²" and unit("photo_error") == "of 48"


def test_plot_history_errors(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="empty history"):
        plot_history([], tmp_path / "m.png")
    with pytest.raises(ValueError, match="no metrics"):
        plot_history([{"stage": "initial", "kind": None, "cycle": 0, "epe": None}], tmp_path / "m.png")
    with pytest.raises(ValueError, match=r"history\[1\]"):
        plot_history([{"stage": "initial", "epe": 1.0}, {"epe": 2.0}], tmp_path / "m.png")
    assert not any(tmp_path.iterdir())


def test_small_changes_are_drawn_small() -> None:
    def share(values, unit_name):  # of the panel's height the change takes
        bottom, top = y_limits(values, unit_name)
        assert bottom <= min(values) and top >= max(values)
        return (max(values) - min(values)) / (top - bottom)

    assert share([0.0701, 0.0713], "px") < 0.1  # +1.7% on the background: a small step, not a climb
    assert share([0.0, 0.0002], "px") < 0.05  # drift 0 -> 0.0002 px: flat
    assert share([70.0, 67.7], "mm") < 0.2 and share([25.5, 27.3], "of 48") < 0.4
    assert share([3.6, 1.8], "px") > 0.8  # a halving fills the panel
    assert y_limits([0.0, 0.0002], "px")[0] > -0.001  # errors start at 0: no axis far below it
    bottom, top = y_limits([5.0], "mm")
    assert top - bottom >= max(MIN_SPAN["mm"], MIN_RELATIVE_SPAN * 5.0) and bottom < 5.0 < top
    assert y_limits([float("nan"), 0.5, float("nan")], "px") == y_limits([0.5], "px")


def test_no_line_is_drawn_across_a_stage_without_a_value() -> None:
    series = stage_series(HISTORY)
    assert np.isnan(series["mpjpe_mm"][1]) and np.isnan(series["mpjpe_mm"][3]) and series["mpjpe_mm"][2] == 53.6
    assert np.isnan(series["epe"][2]) and np.isnan(series["epe_person"][3])  # None is no value
    fig = history_figure(HISTORY)
    axes = {ax.get_title().split(":")[0]: ax for ax in fig.axes}
    line = axes["mpjpe_mm"].lines[0]
    assert np.isnan(line.get_ydata()[1]) and list(line.get_xdata()) == [0, 1, 2, 3]  # a gap, not a line 0 -> 2
    assert axes["mpjpe_mm"].get_title() == "mpjpe_mm: -10.7%, better"
    assert axes["epe"].get_title() == "epe: -32.0%, better" and "lower is better" in axes["epe"].get_ylabel()
    assert "Metrics per stage" in fig._suptitle.get_text()
    worse = history_figure([{"stage": "initial", "epe_background": 0.0701, "drift_px": 0.0},
                            {"stage": "flow_1", "epe_background": 0.0713, "drift_px": 0.0002}])  # fmt: skip
    titles = {ax.get_title() for ax in worse.axes}
    assert titles == {"epe_background: +1.7%, worse", "drift_px: +0.0002 px"}
    assert {ax.get_ylabel() for ax in worse.axes} == {"px · lower is better", "px · a diagnostic"}


# --- overlay_frames ------------------------------------------------------------------------


def panels(mosaic: torch.Tensor, h: int, w: int) -> list[torch.Tensor]:
    """[frame, flow before, pose, flow after] of a mosaic (its first two columns)."""
    return [mosaic[:, :h, :w], mosaic[:, :h, w : 2 * w], mosaic[:, h : 2 * h, :w], mosaic[:, h : 2 * h, w : 2 * w]]


def test_overlay_shape_and_flow_panels() -> None:
    T, H, W = 3, 40, 56
    frames = torch.randint(0, 256, (T, 3, H, W), dtype=torch.uint8)
    zero, moving = torch.zeros(T - 1, 2, H, W), uniform_flow(T - 1, 2.0, -1.0, H, W)
    original = frames.clone()
    out = overlay_frames(frames, zero, moving, None, None, None, legend=False)
    assert out.shape == (T - 1, 3, 2 * H, 3 * W) and out.dtype == torch.uint8  # without GT: the change column
    keyed = overlay_frames(frames, zero, moving, None, None, None)
    assert keyed.shape[:2] == (T - 1, 3) and keyed.shape[2] > 2 * H and keyed.shape[3] == 3 * W
    assert torch.equal(keyed[:, :, : 2 * H], out)  # the key goes below
    for t in range(T - 1):
        frame, before, pose, after = panels(out[t], H, W)
        below = (slice(None), slice(H // 2, None), slice(None))  # away from the labels
        assert torch.equal(frame[below], frames[t][below]) and torch.equal(pose[below], frames[t][below])
        assert (before[below] >= 250).all()  # zero flow is white
        assert (after[below].int().amin(0) < 200).all()  # saturated colour, not white
        assert torch.equal(after[below], flow_image(moving[t], 5**0.5)[below])  # all move alike: full scale
    # labels in the top band: each panel its own ("frame 0" is not written over the pose panel)
    frame, _, pose, _ = panels(out[0], H, W)
    assert not torch.equal(frame[:, :12], frames[0][:, :12]) and not torch.equal(pose[:, :12], frames[0][:, :12])
    assert not torch.equal(frame[:, :12], pose[:, :12])
    assert torch.equal(frames, original)  # the input is not drawn on


def test_overlay_common_scale() -> None:
    H, W = 16, 20
    frames = torch.zeros(2, 3, H, W, dtype=torch.uint8)
    small, large = uniform_flow(1, 1.0, 0.0, H, W), uniform_flow(1, 4.0, 0.0, H, W)
    a = overlay_frames(frames, small, large, None, None, None)[0]
    b = overlay_frames(frames, large, large, None, None, None)[0]
    _, small_img, _, large_img = panels(a, H, W)
    # the smaller flow is paler than the larger one (same direction, same scale)
    assert (small_img[:, -4:].int().sum(0) > large_img[:, -4:].int().sum(0)).all()
    assert torch.equal(panels(b, H, W)[1][:, -4:], large_img[:, -4:])


def test_overlay_skeleton_colours() -> None:
    scene = make_scene(motion="run", frames=4, height=64, width=96, seed=0)
    T, _, H, W = scene.frames.shape
    after = scene.gt.joints2d
    before = after + torch.tensor([-25.0, 0.0])  # 25 px to the left
    out = overlay_frames(scene.frames, scene.gt.flow, scene.gt.flow, before, after, scene.gt.joints_layout)
    assert out.shape[:2] == (T - 1, 3) and out.shape[2] > 2 * H and out.shape[3] == 3 * W
    for t in range(T - 1):
        pose = panels(out[t], H, W)[2].int()
        for j in (1, 4):  # knees: below the label band
            x, y = after[t, j].round().long().tolist()
            r, g, b = pose[:, y, x].tolist()
            assert g > 200 and r < 60 and b < 60, (t, j, (r, g, b))
            x, y = before[t, j].round().long().tolist()
            r, g, b = pose[:, y, x].tolist()
            assert r > 200 and g < 60 and b < 60, (t, j, (r, g, b))
    without = overlay_frames(scene.frames, scene.gt.flow, scene.gt.flow, None, None, None)
    below = (slice(None), slice(H + 20, 2 * H), slice(None, W))
    assert torch.equal(without[0][below], scene.frames[0][:, 20:])
    assert not torch.equal(out[0][below], scene.frames[0][:, 20:])


def test_overlay_downscales() -> None:
    T, H, W = 2, 60, 100
    scene_like = torch.zeros(T, 3, H, W, dtype=torch.uint8)
    joints = torch.tensor([[float(x), 40.0] for x in range(20, 90, 5)]).expand(T, 14, 2).clone()
    flows = torch.zeros(1, 2, H, W), torch.ones(1, 2, H, W)
    out = overlay_frames(scene_like, *flows, None, joints, "lsp14", max_side=150, legend=False)
    assert out.shape == (1, 3, 60, 150)  # the 120 x 300 mosaic halved
    pose = panels(out[0], 30, 50)[2]
    r, g, b = pose[:, 20, 25].tolist()  # joint 6 at (50, 40) px -> (24.75, 19.75) px
    assert g > 200 and r < 60 and b < 60, (r, g, b)


def test_overlay_rejects_bad_shapes() -> None:
    T, H, W = 3, 8, 10
    frames = torch.zeros(T, 3, H, W, dtype=torch.uint8)
    flow = torch.zeros(T - 1, 2, H, W)
    joints = torch.zeros(T, 14, 2)
    with pytest.raises(ValueError, match=r"frames.*\(T, 3, H, W\)"):
        overlay_frames(frames.float(), flow, flow, None, None, None)
    with pytest.raises(ValueError, match=r"frames.*\(T, 3, H, W\)"):
        overlay_frames(frames[:, :1], flow, flow, None, None, None)
    with pytest.raises(ValueError, match=r"flow_before.*\(2, 2, 8, 10\).*\(3, 2, 8, 10\)"):
        overlay_frames(frames, torch.zeros(T, 2, H, W), flow, None, None, None)
    with pytest.raises(ValueError, match=r"flow_after.*\(2, 2, 8, 10\)"):
        overlay_frames(frames, flow, torch.zeros(T - 1, 2, H, W + 1), None, None, None)
    with pytest.raises(ValueError, match=r"joints_after.*\(3, 14, 2\).*lsp14"):
        overlay_frames(frames, flow, flow, joints, torch.zeros(T, 17, 2), "lsp14")
    with pytest.raises(ValueError, match=r"joints_before.*\(3, 17, 2\).*coco17"):
        overlay_frames(frames, flow, flow, joints, None, "coco17")
    with pytest.raises(ValueError, match="layout is required"):
        overlay_frames(frames, flow, flow, joints, joints, None)
    with pytest.raises(ValueError, match="T >= 2"):
        overlay_frames(frames[:1], flow[:0], flow[:0], None, None, None)


# --- write_video ---------------------------------------------------------------------------


def read_video(path: Path) -> list[np.ndarray]:
    capture = cv2.VideoCapture(str(path))
    assert capture.isOpened()
    frames = []
    while True:
        ok, frame = capture.read()
        if not ok:
            break
        frames.append(frame)
    capture.release()
    return frames


def grey_frames(n: int, h: int, w: int) -> torch.Tensor:
    levels = torch.tensor([30, 80, 130, 180, 230][:n], dtype=torch.uint8)
    return levels.view(n, 1, 1, 1).expand(n, 3, h, w).contiguous()


def test_write_video_round_trip(tmp_path: Path) -> None:
    frames = grey_frames(5, 48, 64)
    path = write_video(frames, tmp_path / "overlay.mp4", fps=10)
    assert path == tmp_path / "overlay.mp4"
    back = read_video(path)
    assert len(back) == 5 and all(f.shape == (48, 64, 3) for f in back)
    means = [float(f.mean()) for f in back]
    assert all(abs(m - level) < 8 for m, level in zip(means, (30, 80, 130, 180, 230))), means
    assert [p.name for p in tmp_path.iterdir()] == ["overlay.mp4"]  # no temporary left


def test_write_video_odd_size_and_colour(tmp_path: Path) -> None:
    frames = torch.zeros(3, 3, 33, 47, dtype=torch.uint8)
    frames[:, 0] = 220  # red in RGB
    back = read_video(write_video(frames, tmp_path / "odd.mp4", fps=5))
    assert len(back) == 3 and all(f.shape == (34, 48, 3) for f in back)
    b, g, r = (float(back[0][..., c].mean()) for c in range(3))  # OpenCV reads BGR
    assert r > 180 and g < 50 and b < 50, (r, g, b)


def test_write_video_errors(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    with pytest.raises(ValueError, match=r"frames_uint8.*\(N, 3, H, W\)"):
        write_video(torch.zeros(2, 3, 8, 8), tmp_path / "v.mp4", fps=5)
    with pytest.raises(ValueError, match="fps"):
        write_video(grey_frames(2, 8, 8), tmp_path / "v.mp4", fps=0)
    with pytest.raises(FileNotFoundError, match="missing"):
        write_video(grey_frames(2, 8, 8), tmp_path / "missing" / "v.mp4", fps=5)
    tried = []

    class ClosedWriter:
        def __init__(self, filename: str, fourcc: int, fps: float, size: tuple[int, int]) -> None:
            tried.append(fourcc)

        def isOpened(self) -> bool:
            return False

        def release(self) -> None:
            pass

    monkeypatch.setattr(report.cv2, "VideoWriter", ClosedWriter)
    with pytest.raises(RuntimeError, match=r"v\.mp4.*mp4v or avc1"):
        write_video(grey_frames(2, 8, 8), tmp_path / "v.mp4", fps=5)
    assert tried == [cv2.VideoWriter_fourcc(*"mp4v"), cv2.VideoWriter_fourcc(*"avc1")]
    assert not any(tmp_path.iterdir())


def test_panel_labels_are_white_on_a_solid_black_box() -> None:
    grey = np.full((270, 480, 3), 200, np.uint8)
    out = overlay._label(grey, "refined")
    changed = np.nonzero((out != 200).any(2))
    box = out[: changed[0].max() + 1, : changed[1].max() + 1]
    assert 60 < box.shape[1] < 200 and 10 < box.shape[0] < 40  # top left, about the text's size
    assert not (box == 200).all(2).any()  # no background shows through the label
    assert (box == 0).all(2).mean() > 0.4 and (box.min(2) > 128).any()  # a black box with light text
    assert (grey == 200).all()  # the input is not drawn on


# --- the before/after table ------------------------------------------------------------------


def table_rows(table: str) -> dict[str, list[str]]:
    """metric -> [unit, before, after, change] of a markdown table."""
    rows = [line for line in table.splitlines() if line.startswith("| ") and not line.startswith(("| metric", "| ---"))]
    return {cells[0]: cells[1:] for cells in ([c.strip() for c in r.strip("|").split("|")] for r in rows)}


RUN = [
    {"stage": "initial", "kind": "initial", "cycle": 0, "epe": 0.30, "epe_person": 5.0, "mpjpe_mm": 60.0,
     "agreement_px": 4.0, "info": {"seconds": 1.0}},
    {"stage": "flow_1", "kind": "flow", "cycle": 1, "epe": 0.33, "epe_person": 4.0, "drift_px": 0.2,
     "agreement_px": 3.0},
    {"stage": "pose_1", "kind": "pose", "cycle": 1, "mpjpe_mm": 50.0, "pa_mpjpe_mm": 40.0, "agreement_px": 2.0},
    {"stage": "flow_2", "kind": "flow", "cycle": 2, "epe": 0.36, "epe_person": 3.0, "drift_px": 0.25,
     "agreement_px": 2.0},
    {"stage": "pose_2", "kind": "pose", "cycle": 2, "mpjpe_mm": 99.0, "agreement_px": 9.0, "rolled_back": True},
]  # fmt: skip


def test_before_after_starts_drift_at_zero_and_skips_rolled_back_stages() -> None:
    values = report.before_after(RUN)
    assert list(values) == ["epe", "epe_person", "mpjpe_mm", "agreement_px", "drift_px", "pa_mpjpe_mm"]
    assert values["drift_px"] == (0.0, 0.25)  # RAFT's own flow has no drift
    assert values["mpjpe_mm"] == (60.0, 50.0) and values["agreement_px"] == (4.0, 2.0)  # pose_2 rolled back
    assert values["epe"] == (0.30, 0.36)


def test_table_says_units_direction_worse_and_explains_the_metrics() -> None:
    table = report.metrics_table(RUN)
    rows = table_rows(table)
    assert set(rows) == {"epe", "epe_person", "mpjpe_mm", "pa_mpjpe_mm", "agreement_px", "drift_px"}
    assert all(len(cells) == 4 for cells in rows.values())  # a well-formed markdown table
    assert rows["epe"] == ["px", "0.300", "0.360", "+20.0% **worse**"]
    assert rows["epe_person"] == ["px", "5.000", "3.000", "-40.0% better"]
    assert rows["mpjpe_mm"] == ["mm", "60.000", "50.000", "-16.7% better"]
    assert rows["agreement_px"][3] == "-50.0% better"
    assert rows["pa_mpjpe_mm"] == ["mm", "40.000", "40.000", "unchanged"]
    assert rows["drift_px"] == ["px", "0.000", "0.250", "+0.250 px"]  # neither better nor worse
    assert "lower is better" in table.splitlines()[0]
    assert "worse: epe." in table and "but drift_px" in table
    legend = {line.split(":")[0]: line for line in table.splitlines() if line.startswith("- ")}
    assert set(legend) == {"- epe / epe_person", "- mpjpe_mm / pa_mpjpe_mm", "- agreement_px", "- drift_px"}
    assert "L_opt residual" in legend["- agreement_px"] and "not accuracy" in legend["- agreement_px"]
    assert "outside the person" in legend["- drift_px"] and "RAFT" in legend["- drift_px"]


def test_table_covers_every_metric_the_history_can_hold() -> None:
    names = ["epe", "epe_person", "epe_background", "epe_joints", "mpjpe_mm", "pa_mpjpe_mm",
             "accel_mm_per_frame2", "proj2d_px", "kp2d_px", "agreement_px", "photo_error", "track_error",
             "drift_px"]  # fmt: skip
    history = [{"stage": "initial", **{k: 2.0 for k in names}}, {"stage": "flow_1", **{k: 1.0 for k in names}}]
    table = report.metrics_table(history)
    rows = table_rows(table)
    assert set(rows) == set(names) and "none got worse." in table
    assert rows["accel_mm_per_frame2"][0] == "mm/frame²" and rows["kp2d_px"][0] == "px"
    assert all(cells[3] == "-50.0% better" for k, cells in rows.items() if k != "drift_px")
    legended = " ".join(line.split(":")[0] for line in table.splitlines() if line.startswith("- "))
    assert all(k in legended for k in names)
    # NaN (no joint counted) and a zero start are shown without a percentage
    rows = table_rows(report.metrics_table([{"stage": "a", "agreement_px": float("nan"), "epe": 0.0},
                                            {"stage": "b", "agreement_px": 1.0, "epe": 0.5}]))  # fmt: skip
    assert rows["agreement_px"][3] == "" and rows["epe"][3] == "+0.500 px **worse**"
