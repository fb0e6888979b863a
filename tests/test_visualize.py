from __future__ import annotations

from pathlib import Path

import pytest
import torch

from lit_boot.core.cameras import Cameras
from lit_boot.core.joints import COCO17, LSP14
from lit_boot.core.scene import GroundTruth, Scene
from lit_boot.data.visualize import draw_skeleton, flow_image, read_png, scene_preview, write_png

LIME = torch.tensor([0, 255, 0], dtype=torch.uint8)


def uniform_flow(u: float, v: float, h: int = 6, w: int = 9) -> torch.Tensor:
    return torch.tensor([u, v]).view(2, 1, 1).expand(2, h, w).clone()


# --- flow_image ----------------------------------------------------------------------------


def test_uniform_flow_is_constant_colour() -> None:
    right, left = flow_image(uniform_flow(3.0, 0.0)), flow_image(uniform_flow(-3.0, 0.0))
    assert right.dtype == torch.uint8 and right.shape == (3, 6, 9)
    assert (right == right[:, :1, :1]).all() and (left == left[:, :1, :1]).all()
    assert not torch.equal(right[:, 0, 0], left[:, 0, 0])
    assert not (right == 255).all()  # saturated, not white


def test_batch_is_normalised_per_flow() -> None:
    small, large = uniform_flow(0.5, 0.25), uniform_flow(40.0, 20.0)
    batch = flow_image(torch.stack([small, large]))
    assert batch.shape == (2, 3, 6, 9)
    assert torch.equal(batch[0], flow_image(small)) and torch.equal(batch[1], flow_image(large))
    assert torch.equal(batch[0], batch[1])  # same direction, each saturated on its own


def test_common_scale() -> None:
    small, large = uniform_flow(1.0, 0.0), uniform_flow(4.0, 0.0)
    a, b = flow_image(small, max_magnitude=4.0), flow_image(large, max_magnitude=4.0)
    assert a.shape == (3, 6, 9)
    assert torch.equal(b, flow_image(large))  # max_magnitude == the flow's max: same as default
    assert not torch.equal(a, b)  # the small flow is paler
    assert (a.int().sum(0) > b.int().sum(0)).all()
    # Beyond max_magnitude the colour saturates (clipped), same direction.
    assert torch.equal(flow_image(uniform_flow(100.0, 0.0), max_magnitude=4.0), b)
    with pytest.raises(ValueError, match="max_magnitude"):
        flow_image(small, max_magnitude=0.0)


def test_flow_image_rejects_bad_shape() -> None:
    with pytest.raises(ValueError, match=r"\(2, H, W\)"):
        flow_image(torch.zeros(3, 4, 4))


# --- draw_skeleton -------------------------------------------------------------------------


def lsp_two_joints(conf_knee: float = 1.0) -> tuple[torch.Tensor, torch.Tensor]:
    """Right ankle (0) at (10, 32) and right knee (1) at (50, 32); the rest hidden."""
    points = torch.zeros(14, 2)
    points[0], points[1] = torch.tensor([10.0, 32.0]), torch.tensor([50.0, 32.0])
    conf = torch.zeros(14)
    conf[0], conf[1] = 1.0, conf_knee
    return points, conf


def test_bone_is_drawn_and_far_pixels_untouched() -> None:
    image = torch.full((3, 64, 64), 40, dtype=torch.uint8)
    points, conf = lsp_two_joints()
    out = draw_skeleton(image, points, "lsp14", conf, threshold=0.5)
    assert out.shape == image.shape and out.dtype == torch.uint8
    for x in (10, 20, 30, 40, 50):
        assert torch.equal(out[:, 32, x], LIME), x
    assert torch.equal(out[:, 5:20, :], image[:, 5:20, :])
    assert torch.equal(out[:, 45:, :], image[:, 45:, :])
    assert torch.equal(image, torch.full((3, 64, 64), 40, dtype=torch.uint8))  # input untouched


def test_joint_below_threshold_is_not_drawn() -> None:
    image = torch.zeros(3, 64, 64, dtype=torch.uint8)
    points, conf = lsp_two_joints(conf_knee=0.2)
    out = draw_skeleton(image, points, LSP14, conf, threshold=0.5)
    assert torch.equal(out[:, 32, 10], LIME)  # the ankle is drawn
    assert (out[:, 28:37, 20:] == 0).all()  # neither the bone nor the knee


def test_colour_and_all_visible_without_confidence() -> None:
    image = torch.zeros(3, 64, 64, dtype=torch.uint8)
    points, _ = lsp_two_joints()
    out = draw_skeleton(image, points, "lsp14", color=(200, 10, 30))
    assert out[:, 32, 30].tolist() == [200, 10, 30]  # the bone takes the colour too


def test_virtual_joints_are_drawn() -> None:
    image = torch.zeros(3, 64, 64, dtype=torch.uint8)
    points = torch.full((17, 2), 60.0)
    points[COCO17.index("left_shoulder")] = torch.tensor([20.0, 20.0])
    points[COCO17.index("right_shoulder")] = torch.tensor([40.0, 20.0])
    points[COCO17.index("nose")] = torch.tensor([30.0, 44.0])
    out = draw_skeleton(image, points, "coco17")
    assert torch.equal(out[:, 32, 30], LIME)  # on the bone nose -> neck (shoulders' midpoint)


def test_draw_skeleton_rejects_bad_input() -> None:
    image = torch.zeros(3, 16, 16, dtype=torch.uint8)
    with pytest.raises(ValueError, match=r"\(14, 2\)"):
        draw_skeleton(image, torch.zeros(17, 2), "lsp14")
    with pytest.raises(ValueError, match="uint8"):
        draw_skeleton(image.float(), torch.zeros(14, 2), "lsp14")


# --- PNG -----------------------------------------------------------------------------------


def test_png_round_trip(tmp_path: Path) -> None:
    image = torch.randint(0, 256, (3, 13, 17), dtype=torch.uint8)
    path = write_png(tmp_path / "a.png", image)
    assert torch.equal(read_png(path), image)
    assert [p.name for p in tmp_path.iterdir()] == ["a.png"]
    write_png(path, image.flip(0))  # replace
    assert torch.equal(read_png(path), image.flip(0))


def test_png_errors(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="missing.png"):
        read_png(tmp_path / "missing.png")
    (tmp_path / "junk.png").write_bytes(b"junk")
    with pytest.raises(ValueError, match="junk.png.*unreadable"):
        read_png(tmp_path / "junk.png")
    (tmp_path / "empty.png").write_bytes(b"")
    with pytest.raises(ValueError, match="empty.png"):
        read_png(tmp_path / "empty.png")
    with pytest.raises(ValueError, match=r"out.png.*\(3, H, W\)"):
        write_png(tmp_path / "out.png", torch.zeros(4, 5, 5, dtype=torch.uint8))
    assert not (tmp_path / "out.png").exists()


# --- scene_preview -------------------------------------------------------------------------


def make_scene(with_gt: bool) -> Scene:
    T, H, W = 3, 40, 48
    frames = torch.randint(0, 256, (T, 3, H, W), dtype=torch.uint8)
    keypoints = torch.rand(T, 17, 2) * torch.tensor([W, H])
    gt = None
    if with_gt:
        gt = GroundTruth(flow=torch.randn(T - 1, 2, H, W), joints2d=torch.rand(T, 14, 2) * W, joints_layout="lsp14")
    return Scene(
        frames=frames, keypoints2d=keypoints, keypoints_conf=torch.ones(T, 17),
        cameras=Cameras("pinhole", torch.rand(T, 7)), gt=gt,
    )  # fmt: skip


def test_scene_preview() -> None:
    scene = make_scene(with_gt=True)
    preview = scene_preview(scene, 1)
    assert preview.shape == (3, 40, 3 * 48) and preview.dtype == torch.uint8
    assert torch.equal(preview[:, :, :48], scene.frames[1])
    assert torch.equal(preview[:, :, 48:96], flow_image(scene.gt.flow[1]))
    assert not torch.equal(preview[:, :, 96:], scene.frames[1])  # something was drawn
    assert (preview[:, :, 96:] == torch.tensor([255, 0, 0], dtype=torch.uint8)[:, None, None]).all(0).any()
    last = scene_preview(scene, -1)  # no flow after the last frame: grey frame
    assert (last[0, :, 48:96] == last[1, :, 48:96]).all() and (last[1, :, 48:96] == last[2, :, 48:96]).all()
    with pytest.raises(IndexError):
        scene_preview(scene, 3)


def test_scene_preview_without_gt() -> None:
    scene = make_scene(with_gt=False)
    preview = scene_preview(scene)
    assert preview.shape == (3, 40, 144)
    middle = preview[:, :, 48:96]
    assert (middle[0] == middle[1]).all() and (middle[1] == middle[2]).all()
