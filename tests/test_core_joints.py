"""Joint layouts, bones and mappings (lit_boot.core.joints) against REFERENCE sections 3-4."""

from __future__ import annotations

import pytest
import torch

from lit_boot.core.joints import (
    COCO17,
    H36M17,
    H36M_J17_TO_J14,
    LAYOUTS,
    LSP14,
    MEDIAPIPE33,
    JointLayout,
    get_layout,
    map_joints,
    mapping_matrix,
)

# REFERENCE section 3/4, copied literally (not from the library).
REF_LSP_SKETCH = [[0, 1], [1, 2], [2, 8], [5, 4], [4, 3], [3, 9], [12, 8], [12, 9], [9, 10], [10, 11],
                  [8, 7], [7, 6], [12, 13]]  # fmt: skip
REF_LSP_LENGTH = REF_LSP_SKETCH + [[2, 3], [8, 9]]
REF_H36M_TO_LSP = [3, 2, 1, 4, 5, 6, 16, 15, 14, 11, 12, 13, 8, 10]
REF_LSP_NAMES = [
    "right_ankle", "right_knee", "right_hip", "left_hip", "left_knee", "left_ankle", "right_wrist",
    "right_elbow", "right_shoulder", "left_shoulder", "left_elbow", "left_wrist", "neck", "head_top",
]  # fmt: skip
# COCO-17 indices of LSP joints 0..11 (by hand from the COCO order): no left/right swap.
COCO_FOR_LSP = [16, 14, 12, 11, 13, 15, 10, 8, 6, 5, 7, 9]
MP_FOR_COCO = [0, 2, 5, 7, 8, 11, 12, 13, 14, 15, 16, 23, 24, 25, 26, 27, 28]


def arange_joints(k: int, d: int = 2, dtype=torch.float64) -> torch.Tensor:
    """(k, d) joints whose joint i holds the value i in every coordinate."""
    return torch.arange(k, dtype=dtype)[:, None].expand(k, d).clone()


# --- layouts ------------------------------------------------------------------------------------


@pytest.mark.parametrize("name,count", [("lsp14", 14), ("coco17", 17), ("h36m17", 17), ("mediapipe33", 33)])
def test_layout_joint_counts_and_unique_names(name, count):
    layout = get_layout(name)
    assert layout.name == name
    assert layout.num_joints == count
    assert len(layout.names) == count
    assert len(set(layout.all_names)) == len(layout.all_names)
    assert LAYOUTS[name] is layout
    assert get_layout(layout) is layout


def test_lsp_names_follow_reference_order():
    assert list(LSP14.names) == REF_LSP_NAMES


def test_lsp_bones_equal_reference_exactly():
    assert [list(b) for b in LSP14.sketch_bones] == REF_LSP_SKETCH
    assert [list(b) for b in LSP14.length_bones] == REF_LSP_LENGTH
    assert len(LSP14.sketch_bones) == 13 and len(LSP14.length_bones) == 15
    assert LSP14.virtual == {}


def test_coco_virtual_joints_and_head_bones():
    neck, head, nose = COCO17.index("neck"), COCO17.index("head"), COCO17.index("nose")
    assert (neck, head) == (17, 18)  # virtual joints come after the 17 real ones
    assert nose == 0
    assert dict(COCO17.virtual["neck"]) == {COCO17.index("left_shoulder"): 0.5, COCO17.index("right_shoulder"): 0.5}
    assert dict(COCO17.virtual["head"]) == {COCO17.index("left_ear"): 0.5, COCO17.index("right_ear"): 0.5}
    bones = {tuple(sorted(b)) for b in COCO17.sketch_bones}
    assert tuple(sorted((head, nose))) in bones
    assert tuple(sorted((nose, neck))) in bones
    assert tuple(sorted((head, neck))) not in bones
    # 12 limbs + (head, nose) + (nose, neck) replacing LSP's (neck, head_top)
    assert len(COCO17.sketch_bones) == 14
    assert len(bones) == 14  # no duplicates


def test_coco_limbs_mirror_lsp_limbs():
    """Every LSP sketch bone except (neck, head_top) exists in COCO under the same joint names."""
    coco = {frozenset(COCO17.all_names[i] for i in b) for b in COCO17.sketch_bones}
    for a, b in LSP14.sketch_bones:
        pair = frozenset((LSP14.names[a], LSP14.names[b]))
        if pair == frozenset(("neck", "head_top")):
            assert pair not in coco
        else:
            assert pair in coco, pair
    extra = {frozenset(COCO17.all_names[i] for i in b) for b in COCO17.length_bones} - coco
    assert extra == {frozenset(("left_hip", "right_hip")), frozenset(("left_shoulder", "right_shoulder"))}


def test_mediapipe_has_head_and_nose_bones_too():
    head, nose, neck = (MEDIAPIPE33.index(n) for n in ("head", "nose", "neck"))
    assert (neck, head) == (33, 34)
    bones = {tuple(sorted(b)) for b in MEDIAPIPE33.sketch_bones}
    assert tuple(sorted((head, nose))) in bones and tuple(sorted((nose, neck))) in bones
    assert tuple(sorted((head, neck))) not in bones


def test_bones_in_range_for_every_layout():
    for layout in LAYOUTS.values():
        n = len(layout.all_names)
        for a, b in layout.sketch_bones + layout.length_bones:
            assert 0 <= a < n and 0 <= b < n and a != b


def test_layout_rejects_out_of_range_bone():
    with pytest.raises(ValueError, match="bad.*out of range"):
        JointLayout(name="bad", names=("a", "b"), sketch_bones=((0, 2),), length_bones=())


def test_index_unknown_name_raises():
    with pytest.raises(KeyError, match="tail"):
        LSP14.index("tail")


def test_with_virtual_coco_midpoints_and_min_confidence():
    g = torch.Generator().manual_seed(0)
    joints = torch.randn(2, 3, 17, 2, generator=g, dtype=torch.float64)
    conf = torch.rand(2, 3, 17, generator=g, dtype=torch.float64)
    out, out_conf = COCO17.with_virtual(joints, conf)
    assert out.shape == (2, 3, 19, 2) and out_conf.shape == (2, 3, 19)
    torch.testing.assert_close(out[..., :17, :], joints)
    torch.testing.assert_close(out[..., 17, :], (joints[..., 5, :] + joints[..., 6, :]) / 2)  # neck
    torch.testing.assert_close(out[..., 18, :], (joints[..., 3, :] + joints[..., 4, :]) / 2)  # head
    torch.testing.assert_close(out_conf[..., :17], conf)
    torch.testing.assert_close(out_conf[..., 17], torch.minimum(conf[..., 5], conf[..., 6]))
    torch.testing.assert_close(out_conf[..., 18], torch.minimum(conf[..., 3], conf[..., 4]))


def test_with_virtual_hand_values():
    joints = torch.zeros(17, 3)
    joints[5] = torch.tensor([2.0, 4.0, 6.0])  # left shoulder
    joints[6] = torch.tensor([4.0, 0.0, -2.0])  # right shoulder
    joints[3] = torch.tensor([10.0, 10.0, 10.0])  # left ear
    joints[4] = torch.tensor([12.0, 14.0, 10.0])  # right ear
    conf = torch.full((17,), 0.9)
    conf[6] = 0.3
    conf[3] = 0.1
    out, c = COCO17.with_virtual(joints, conf)
    torch.testing.assert_close(out[17], torch.tensor([3.0, 2.0, 2.0]))
    torch.testing.assert_close(out[18], torch.tensor([11.0, 12.0, 10.0]))
    torch.testing.assert_close(c[17:], torch.tensor([0.3, 0.1]))


def test_with_virtual_without_confidence_and_without_virtual_joints():
    joints = torch.randn(4, 14, 3)
    out, conf = LSP14.with_virtual(joints)
    assert out is joints and conf is None
    out, conf = MEDIAPIPE33.with_virtual(torch.randn(33, 2))
    assert out.shape == (35, 2) and conf is None


@pytest.mark.parametrize("layout,k", [(COCO17, 14), (LSP14, 17), (MEDIAPIPE33, 17)])
def test_with_virtual_wrong_joint_count_raises(layout, k):
    with pytest.raises(ValueError, match=f"{layout.name}.*expected {layout.num_joints} joints"):
        layout.with_virtual(torch.zeros(2, k, 2))


# --- mappings -------------------------------------------------------------------------------


def test_h36m_to_lsp_equals_reference_indices():
    assert list(H36M_J17_TO_J14) == REF_H36M_TO_LSP
    out, defined, conf = map_joints(arange_joints(17, 3), "h36m17")
    assert conf is None
    assert defined.all()
    assert out[:, 0].tolist() == REF_H36M_TO_LSP
    assert out[:, 2].tolist() == REF_H36M_TO_LSP


def test_h36m_to_lsp_names_match():
    """Every LSP joint comes from the H36M joint of the same name (neck = thorax)."""
    for lsp_i, h36m_i in enumerate(REF_H36M_TO_LSP):
        lsp_name, h_name = LSP14.names[lsp_i], H36M17.names[h36m_i]
        expected = {"neck": "thorax"}.get(lsp_name, lsp_name)
        assert h_name == expected, (lsp_name, h_name)


def test_h36m_to_lsp_batched_and_confidence():
    g = torch.Generator().manual_seed(1)
    joints = torch.randn(5, 17, 3, generator=g)
    conf = torch.rand(5, 17, generator=g)
    out, defined, c = map_joints(joints, "h36m17", "lsp14", conf)
    torch.testing.assert_close(out, joints[:, REF_H36M_TO_LSP])
    torch.testing.assert_close(c, conf[:, REF_H36M_TO_LSP])
    assert defined.dtype == torch.bool and defined.shape == (14,)


def test_coco_to_lsp():
    joints = arange_joints(17)
    joints[5] = torch.tensor([10.0, 20.0])  # left shoulder
    joints[6] = torch.tensor([30.0, 60.0])  # right shoulder
    conf = torch.linspace(0.05, 0.85, 17, dtype=torch.float64)
    out, defined, c = map_joints(joints, "coco17", "lsp14", conf)
    assert out.shape == (14, 2) and c.shape == (14,)
    # limbs: exact COCO joints, right stays right
    torch.testing.assert_close(out[:12], joints[COCO_FOR_LSP])
    torch.testing.assert_close(c[:12], conf[COCO_FOR_LSP])
    assert out[0, 0].item() == 16  # LSP right_ankle <- COCO right_ankle
    assert COCO17.names[16] == "right_ankle"
    # neck: the shoulders' midpoint, confidence = min of the two shoulders
    torch.testing.assert_close(out[12], torch.tensor([20.0, 40.0], dtype=torch.float64))
    assert c[12].item() == pytest.approx(min(conf[5].item(), conf[6].item()))
    # head top: undefined
    assert defined.tolist() == [True] * 13 + [False]
    assert out[13].tolist() == [0.0, 0.0]
    assert c[13].item() == 0.0


def test_coco_to_lsp_matrix_rows():
    w = mapping_matrix("coco17", "lsp14")
    assert w.shape == (14, 17)
    for i, k in enumerate(COCO_FOR_LSP):
        expected = torch.zeros(17)
        expected[k] = 1.0
        torch.testing.assert_close(w[i], expected)
    neck = torch.zeros(17)
    neck[5] = neck[6] = 0.5
    torch.testing.assert_close(w[12], neck)
    assert (w[13] == 0).all()


def test_mediapipe_to_coco_picks_reference_landmarks():
    out, defined, _ = map_joints(arange_joints(33), "mediapipe33", "coco17")
    assert defined.all()
    assert out[:, 0].tolist() == MP_FOR_COCO
    # names agree one by one
    assert [MEDIAPIPE33.names[i] for i in MP_FOR_COCO] == list(COCO17.names)


def test_mediapipe_to_lsp_equals_via_coco():
    g = torch.Generator().manual_seed(2)
    joints = torch.randn(3, 33, 2, generator=g, dtype=torch.float64)
    conf = torch.rand(3, 33, generator=g, dtype=torch.float64)
    direct, d_def, d_conf = map_joints(joints, "mediapipe33", "lsp14", conf)
    coco, _, coco_conf = map_joints(joints, "mediapipe33", "coco17", conf)
    via, v_def, v_conf = map_joints(coco, "coco17", "lsp14", coco_conf)
    torch.testing.assert_close(direct, via)
    torch.testing.assert_close(d_conf, v_conf)
    assert d_def.tolist() == v_def.tolist() == [True] * 13 + [False]
    torch.testing.assert_close(mapping_matrix("mediapipe33"), mapping_matrix("coco17") @ mapping_matrix("mediapipe33", "coco17"))


@pytest.mark.parametrize("name", ["lsp14", "coco17", "h36m17", "mediapipe33"])
def test_identity_mapping(name):
    k = get_layout(name).num_joints
    torch.testing.assert_close(mapping_matrix(name, name), torch.eye(k))
    joints = torch.randn(2, k, 3)
    out, defined, _ = map_joints(joints, name, name)
    torch.testing.assert_close(out, joints)
    assert defined.all()


def test_mapping_is_differentiable():
    joints = torch.randn(17, 2, requires_grad=True)
    out, _, _ = map_joints(joints, "coco17")
    out[12].sum().backward()  # neck: half of each shoulder
    expected = torch.zeros(17, 2)
    expected[5] = expected[6] = 0.5
    torch.testing.assert_close(joints.grad, expected)


@pytest.mark.parametrize("bad", ["smpl24", "LSP14", ""])
def test_unknown_layout_raises_naming_it(bad):
    with pytest.raises(ValueError, match=f"unknown joint layout '{bad}'"):
        get_layout(bad)
    with pytest.raises(ValueError, match=f"'{bad}'"):
        mapping_matrix(bad, "lsp14")
    with pytest.raises(ValueError, match=f"'{bad}'"):
        mapping_matrix("coco17", bad)


@pytest.mark.parametrize(
    "src,dst",
    [("lsp14", "coco17"), ("lsp14", "h36m17"), ("h36m17", "coco17"), ("coco17", "mediapipe33"), ("coco17", "h36m17")],
)
def test_unsupported_mapping_raises_naming_both(src, dst):
    with pytest.raises(ValueError, match=f"no mapping from joint layout '{src}' to '{dst}'"):
        mapping_matrix(src, dst)
    k = get_layout(src).num_joints
    with pytest.raises(ValueError, match=f"'{src}' to '{dst}'"):
        map_joints(torch.zeros(k, 2), src, dst)


@pytest.mark.parametrize("src,k", [("coco17", 14), ("h36m17", 14), ("mediapipe33", 17), ("lsp14", 17)])
def test_map_joints_wrong_count_raises(src, k):
    with pytest.raises(ValueError, match=f"expected {get_layout(src).num_joints} joints for layout '{src}'"):
        map_joints(torch.zeros(3, k, 2), src)
