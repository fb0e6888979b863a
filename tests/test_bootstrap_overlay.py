"""The overlay video: colour scale, GT panels, error map, legend, playback rate."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from lit_boot.bootstrap.overlay import _key_rows, _legend, flow_colour_scale, overlay_frames, video_fps
from lit_boot.bootstrap.report import write_video
from lit_boot.data import flow_image
from lit_boot.synth import make_scene

T, H, W = 3, 40, 56


def uniform_flow(n: int, u: float, v: float, h: int = H, w: int = W) -> torch.Tensor:
    return torch.tensor([u, v]).view(1, 2, 1, 1).expand(n, 2, h, w).clone()


def grid(mosaic: torch.Tensor, cols: int) -> list[list[torch.Tensor]]:
    """The mosaic's panels by row and column (each (3, H, W))."""
    return [[mosaic[:, r * H : (r + 1) * H, c * W : (c + 1) * W] for c in range(cols)] for r in range(2)]


BELOW = (slice(None), slice(H // 2, None), slice(None))  # away from the panel's label


def test_colour_scale_ignores_outliers_and_still_pixels() -> None:
    flow = torch.zeros(2, H, W)
    flow[0, 10:20, 10:20] = 3.0  # a small person moving 3 px on a still background
    flow[0, 0, 0] = 200.0  # one wild vector
    assert flow_colour_scale([flow.norm(dim=0).numpy()]) == pytest.approx(3.0)
    assert flow_colour_scale([np.full((4, 4), 0.2, np.float32)]) == pytest.approx(0.2)  # nothing moves 0.5 px
    assert flow_colour_scale([np.zeros((4, 4), np.float32)]) == 0.01
    assert flow_colour_scale([np.full(3, np.nan, np.float32)]) == 1.0


def test_small_flow_with_an_outlier_is_coloured_not_white() -> None:
    frames = torch.zeros(T, 3, H, W, dtype=torch.uint8)
    small = uniform_flow(T - 1, 0.8, 0.0)
    small[:, :, 5, 5] = 80.0  # a RAFT artefact 100x longer than the motion
    before_scale = small[0].norm(dim=0).max().item()
    old = flow_image(small[0], before_scale)  # the former scale: the pair's largest vector
    assert (old[BELOW].int().amin(0) > 240).all()  # nearly white
    out = overlay_frames(frames, small, small, None, None, None, legend=False)
    for t in range(T - 1):
        _, before = grid(out[t], 2)[0]
        assert (before[BELOW].int().amin(0) < 60).all()  # saturated: the flow's colour shows
        assert torch.equal(before[BELOW], flow_image(small[t], 0.8)[BELOW])


def test_gt_panels_error_map_and_labels() -> None:
    frames = torch.zeros(T, 3, H, W, dtype=torch.uint8)
    gt = uniform_flow(T - 1, 2.0, 0.0)
    before = gt.clone()
    before[:, 0, :, : W // 2] += 1.0  # RAFT 1 px off on the left half
    after = gt.clone()
    after[:, 0, :, W // 2 :] += 1.0  # refined: right on the left, 1 px off on the right
    valid = torch.ones(T - 1, H, W, dtype=torch.bool)
    valid[:, H - 6 :] = False  # no GT in the bottom rows
    out = overlay_frames(frames, before, after, None, None, None, gt_flow=gt, gt_valid=valid, legend=False)
    assert out.shape == (T - 1, 3, 2 * H, 3 * W)
    (_, raft, gt_panel), (_, refined, error) = grid(out[0], 3)
    scale = flow_colour_scale([f.norm(dim=1).numpy() for f in (before, after, gt)])
    rows = slice(H // 2, H - 6)
    assert torch.equal(gt_panel[:, rows], flow_image(gt[0], scale)[:, rows])  # the same scale as the flows
    assert (gt_panel[:, H - 5 :] == 128).all()  # grey where the GT is not valid
    left, right = error[:, rows, 2 : W // 2 - 2].int(), error[:, rows, W // 2 + 2 :].int()
    assert (left[2] > left[0] + 50).all()  # (dark) blue: the refined flow is nearer the GT
    assert (right[0] > right[2] + 50).all()  # (dark) red: farther
    assert (error[:, H - 5 :] == 128).all()
    assert not torch.equal(raft[:, :10], refined[:, :10])  # labels: "RAFT EPE 0.50", "refined EPE 0.50"
    without = overlay_frames(frames, before, after, None, None, None, legend=False)
    assert without.shape == (T - 1, 3, 2 * H, 3 * W)  # no GT: the change column instead


def test_without_gt_the_third_column_shows_where_the_flow_changed_and_what_the_frames_say() -> None:
    scene = make_scene(motion="run", frames=3, height=64, width=96, seed=0)
    T, _, H, W = scene.frames.shape
    right = scene.gt.flow.clone()  # the refined flow: the true motion
    wrong = right.clone()
    wrong[:, :, :, : W // 2] += 3.0  # RAFT's: 3 px off on the left half
    out = overlay_frames(scene.frames, wrong, right, None, None, None, legend=False)
    change, evidence = out[0, :, :H, 2 * W :], out[0, :, H:, 2 * W :]  # the third column
    rows = slice(18, H - 2)  # below the label
    left, untouched = change[:, rows, 4 : W // 2 - 4].int(), change[:, rows, W // 2 + 4 : -4].int()
    assert (untouched >= 245).all()  # unchanged: white
    assert (left.amin(0) < 160).float().mean() > 0.9  # changed by 4.2 px: dark purple
    blue = (evidence[2, rows, 8 : W // 2 - 8].int() - evidence[0, rows, 8 : W // 2 - 8].int() > 30).float().mean()
    assert blue > 0.5  # the frames say the refined flow is better there
    assert (evidence[:, rows, W // 2 + 6 : -6] >= 245).float().mean() > 0.9  # the same flow: no change


def test_legend_shows_the_wheel_the_skeleton_colours_and_the_error_bar() -> None:
    frames = torch.zeros(T, 3, 120, 160, dtype=torch.uint8)
    flow = uniform_flow(T - 1, 1.0, 1.0, 120, 160)
    plain = overlay_frames(frames, flow, flow, None, None, None)
    with_gt = overlay_frames(frames, flow, flow, None, None, None, gt_flow=flow)
    for out, cols in ((plain, 3), (with_gt, 3)):
        key = out[0, :, 240:].permute(1, 2, 0).int()
        assert key.shape[0] > 20 and key.shape[1] == cols * 160
        red = (key[..., 0] > 200) & (key[..., 1] < 60) & (key[..., 2] < 60)
        green = (key[..., 1] > 200) & (key[..., 0] < 60) & (key[..., 2] < 60)
        assert red.sum() > 20 and green.sum() > 20  # the skeletons' line samples
        hues = key[(key.amax(-1) - key.amin(-1)) > 100]  # saturated colours: the wheel (and the bar)
        assert len(hues) > 200 and (hues.argmax(-1).bincount(minlength=3) > 20).all()
        dark = (key.amax(-1) < 60).sum()
        assert dark > 50  # text
    purple = lambda k: ((k[..., 0] > k[..., 1] + 40) & (k[..., 2] > k[..., 1] + 40)).sum()  # noqa: E731
    keys = [out[0, :, 240:].permute(1, 2, 0).int() for out in (plain, with_gt)]
    assert purple(keys[0]) > purple(keys[1]) + 20  # without GT: the change's colour bar
    assert keys[0].shape[0] > keys[1].shape[0]  # and one more line: the census error change


def test_video_plays_at_a_watchable_rate(tmp_path: Path) -> None:
    assert video_fps(7, 30.0) == 2.0  # the demo's 7 pairs: 3.5 s
    assert video_fps(60, 30.0) == 12.0  # 5 s
    assert video_fps(300, 30.0) == 30.0  # never faster than the scene
    assert video_fps(300, 24.0) == 24.0 and video_fps(3, 0.0) == 2.0
    frames = torch.zeros(T, 3, H, W, dtype=torch.uint8)
    mosaic = overlay_frames(frames, uniform_flow(T - 1, 1.0, 0.0), uniform_flow(T - 1, 0.0, 1.0), None, None, None)
    path = write_video(mosaic, tmp_path / "overlay.mp4", fps=video_fps(len(mosaic), 30.0))
    capture = cv2.VideoCapture(str(path))
    try:
        assert capture.get(cv2.CAP_PROP_FPS) == pytest.approx(2.0)
        assert int(capture.get(cv2.CAP_PROP_FRAME_COUNT)) == T - 1
        assert int(capture.get(cv2.CAP_PROP_FRAME_HEIGHT)) == mosaic.shape[2] + mosaic.shape[2] % 2
    finally:
        capture.release()


def test_gt_shapes_are_checked() -> None:
    frames = torch.zeros(T, 3, H, W, dtype=torch.uint8)
    flow = torch.zeros(T - 1, 2, H, W)
    with pytest.raises(ValueError, match=r"gt_flow.*\(2, 2, 40, 56\)"):
        overlay_frames(frames, flow, flow, None, None, None, gt_flow=torch.zeros(T, 2, H, W))
    with pytest.raises(ValueError, match=r"gt_valid.*bool.*\(2, 40, 56\)"):
        overlay_frames(frames, flow, flow, None, None, None, gt_flow=flow, gt_valid=torch.ones(T - 1, H, W))
    with pytest.raises(ValueError, match="gt_valid given without gt_flow"):
        overlay_frames(frames, flow, flow, None, None, None, gt_valid=torch.ones(T - 1, H, W, dtype=torch.bool))


def test_decision_panel_replaces_the_frame_and_gets_a_legend_line() -> None:
    frames = torch.full((T, 3, H, W), 100, dtype=torch.uint8)
    flow = uniform_flow(T - 1, 1.0, 0.0)
    painted = torch.zeros(T - 1, H, W, dtype=torch.bool)
    painted[:, 25:35, 10:20] = True
    kept = torch.zeros(T - 1, H, W)
    kept[..., 30:] = 1.0
    plain = overlay_frames(frames, flow, flow, None, None, None, legend=False)
    shown = overlay_frames(frames, flow, flow, None, None, None, legend=False,
                           decisions={"painted": painted, "kept": kept})  # fmt: skip
    panel = grid(shown[0], 2)[0][0]
    assert (panel[:, 25:35, 10:20] == torch.tensor([255, 140, 0]).view(3, 1, 1)).all()  # painted: orange
    assert (panel[2, 25:, 40:] > panel[0, 25:, 40:]).all()  # tuned kept: blue tint
    assert (panel[0, 25:, :5] == panel[2, 25:, :5]).all()  # RAFT kept: grey
    assert torch.equal(grid(shown[0], 2)[0][1], grid(plain[0], 2)[0][1])  # the other panels as before
    rows = _legend(4000, 400, 1.0, _key_rows(None, None, None)).shape[0]
    with_decisions = _key_rows(None, None, {"painted": painted, "kept": kept})
    assert _legend(4000, 400, 1.0, with_decisions).shape[0] == rows + round(34 * 1.0)  # one more line
