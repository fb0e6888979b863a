"""Joint layouts, their bones, and mappings between layouts.

A :class:`JointLayout` names the joints of one convention (LSP-14, COCO-17, H36M-17,
MediaPipe-33) and lists two kinds of bones as index pairs:

- ``sketch_bones``: the stick-man drawn for the target flow (paper section 3.1);
- ``length_bones``: the bones whose lengths the temporal term keeps constant.

Some layouts lack a joint the stick-man needs (COCO has no neck). Such joints are
*virtual*: weighted means of real joints, appended after the real ones. Bone indices may
point at them; :meth:`JointLayout.with_virtual` appends them to an array of joints.

The 24 SMPL joints are the layout ``"smpl"`` (:data:`SMPL24`).

Mappings to LSP-14 are (14, K) weight matrices: each LSP joint is a weighted mean of source
joints, or undefined (a zero row; ``defined`` is False there).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import torch

__all__ = [
    "JointLayout",
    "LSP14",
    "COCO17",
    "H36M17",
    "MEDIAPIPE33",
    "SMPL24",
    "SMPL24_TO_LSP14",
    "LAYOUTS",
    "get_layout",
    "H36M_J17_TO_J14",
    "mapping_matrix",
    "map_joints",
]


@dataclass(frozen=True, eq=False)
class JointLayout:
    """A named joint order with its bones.

    ``virtual`` maps a virtual joint's name to ``((index, weight), ...)`` over real joints;
    virtual joint ``i`` has index ``len(names) + i`` in bone lists.
    """

    name: str
    names: tuple[str, ...]
    sketch_bones: tuple[tuple[int, int], ...]
    length_bones: tuple[tuple[int, int], ...]
    virtual: dict[str, tuple[tuple[int, float], ...]] = field(default_factory=dict)
    root: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        n = len(self.names) + len(self.virtual)
        for bone in self.sketch_bones + self.length_bones:
            if not all(0 <= i < n for i in bone):
                raise ValueError(f"layout {self.name}: bone {bone} out of range 0..{n - 1}")

    @property
    def num_joints(self) -> int:
        """Number of real joints (the K of arrays in this layout)."""
        return len(self.names)

    @property
    def all_names(self) -> tuple[str, ...]:
        """Real joint names followed by virtual ones (the index space of the bones)."""
        return self.names + tuple(self.virtual)

    def index(self, name: str) -> int:
        """Index of a real or virtual joint by name."""
        try:
            return self.all_names.index(name)
        except ValueError:
            raise KeyError(f"layout {self.name} has no joint {name!r}") from None

    def virtual_matrix(self) -> torch.Tensor:
        """(V, K) weights that make the virtual joints from the real ones."""
        w = torch.zeros(len(self.virtual), self.num_joints)
        for row, parts in enumerate(self.virtual.values()):
            for idx, weight in parts:
                w[row, idx] = weight
        return w

    def with_virtual(
        self, joints: torch.Tensor, confidence: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor | None]:
        """Append virtual joints: (..., K, D) -> (..., K+V, D).

        A virtual joint's confidence is the minimum of its parts' confidences.
        """
        if joints.shape[-2] != self.num_joints:
            raise ValueError(
                f"layout {self.name}: expected {self.num_joints} joints, got shape {tuple(joints.shape)}"
            )
        if not self.virtual:
            return joints, confidence
        w = self.virtual_matrix().to(joints)
        extra = torch.einsum("vk,...kd->...vd", w, joints)
        out = torch.cat([joints, extra], dim=-2)
        if confidence is None:
            return out, None
        parts = [torch.stack([confidence[..., i] for i, _ in p], -1).amin(-1) for p in self.virtual.values()]
        return out, torch.cat([confidence, torch.stack(parts, -1)], dim=-1)


def _pairs(names: tuple[str, ...], pairs: list[tuple[str, str]]) -> tuple[tuple[int, int], ...]:
    return tuple((names.index(a), names.index(b)) for a, b in pairs)


# --- LSP-14: the paper's order (REFERENCE section 4) -----------------------------------------
_LSP_NAMES = (
    "right_ankle", "right_knee", "right_hip", "left_hip", "left_knee", "left_ankle",
    "right_wrist", "right_elbow", "right_shoulder", "left_shoulder", "left_elbow",
    "left_wrist", "neck", "head_top",
)  # fmt: skip
_LSP_SKETCH = ((0, 1), (1, 2), (2, 8), (5, 4), (4, 3), (3, 9), (12, 8), (12, 9), (9, 10),
               (10, 11), (8, 7), (7, 6), (12, 13))  # fmt: skip
LSP14 = JointLayout(
    name="lsp14",
    names=_LSP_NAMES,
    sketch_bones=_LSP_SKETCH,
    length_bones=_LSP_SKETCH + ((2, 3), (8, 9)),
    root=(2, 3),
)

# --- COCO-17 -----------------------------------------------------------------------------------
_COCO_NAMES = (
    "nose", "left_eye", "right_eye", "left_ear", "right_ear", "left_shoulder",
    "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_hip",
    "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle",
)  # fmt: skip
_COCO_VIRTUAL = {
    "neck": ((5, 0.5), (6, 0.5)),  # shoulders' midpoint
    "head": ((3, 0.5), (4, 0.5)),  # ears' midpoint: the head's centre
}
_COCO_ALL = _COCO_NAMES + tuple(_COCO_VIRTUAL)
_COCO_LIMBS = [
    ("right_ankle", "right_knee"), ("right_knee", "right_hip"), ("right_hip", "right_shoulder"),
    ("left_ankle", "left_knee"), ("left_knee", "left_hip"), ("left_hip", "left_shoulder"),
    ("neck", "right_shoulder"), ("neck", "left_shoulder"), ("left_shoulder", "left_elbow"),
    ("left_elbow", "left_wrist"), ("right_shoulder", "right_elbow"), ("right_elbow", "right_wrist"),
]  # fmt: skip
# The paper: LSP's (head, neck) bone becomes (head, nose) and (nose, neck).
_COCO_SKETCH = _pairs(_COCO_ALL, _COCO_LIMBS + [("head", "nose"), ("nose", "neck")])
COCO17 = JointLayout(
    name="coco17",
    names=_COCO_NAMES,
    sketch_bones=_COCO_SKETCH,
    length_bones=_COCO_SKETCH
    + _pairs(_COCO_ALL, [("left_hip", "right_hip"), ("left_shoulder", "right_shoulder")]),
    virtual=_COCO_VIRTUAL,
    root=(11, 12),
)

# --- Human3.6M-17 (the order of VideoPose3D / METRO) -----------------------------------------
_H36M_NAMES = (
    "pelvis", "right_hip", "right_knee", "right_ankle", "left_hip", "left_knee", "left_ankle",
    "spine", "thorax", "neck_nose", "head_top", "left_shoulder", "left_elbow", "left_wrist",
    "right_shoulder", "right_elbow", "right_wrist",
)  # fmt: skip
_H36M_BONES = ((0, 1), (1, 2), (2, 3), (0, 4), (4, 5), (5, 6), (0, 7), (7, 8), (8, 9), (9, 10),
               (8, 11), (11, 12), (12, 13), (8, 14), (14, 15), (15, 16))  # fmt: skip
H36M17 = JointLayout(
    name="h36m17", names=_H36M_NAMES, sketch_bones=_H36M_BONES, length_bones=_H36M_BONES, root=(0,)
)
H36M_J17_TO_J14 = (3, 2, 1, 4, 5, 6, 16, 15, 14, 11, 12, 13, 8, 10)

# --- MediaPipe Pose-33 -------------------------------------------------------------------------
_MP_NAMES = (
    "nose", "left_eye_inner", "left_eye", "left_eye_outer", "right_eye_inner", "right_eye",
    "right_eye_outer", "left_ear", "right_ear", "mouth_left", "mouth_right", "left_shoulder",
    "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_pinky",
    "right_pinky", "left_index", "right_index", "left_thumb", "right_thumb", "left_hip",
    "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle", "left_heel",
    "right_heel", "left_foot_index", "right_foot_index",
)  # fmt: skip
#: MediaPipe-33 index of each COCO-17 joint.
MEDIAPIPE33_TO_COCO17 = tuple(_MP_NAMES.index(n) for n in _COCO_NAMES)
_MP_VIRTUAL = {
    "neck": ((11, 0.5), (12, 0.5)),
    "head": ((7, 0.5), (8, 0.5)),
}
_MP_ALL = _MP_NAMES + tuple(_MP_VIRTUAL)
_MP_SKETCH = _pairs(
    _MP_ALL,
    _COCO_LIMBS
    + [("head", "nose"), ("nose", "neck"), ("left_ankle", "left_foot_index"),
       ("right_ankle", "right_foot_index")],
)  # fmt: skip
MEDIAPIPE33 = JointLayout(
    name="mediapipe33",
    names=_MP_NAMES,
    sketch_bones=_MP_SKETCH,
    length_bones=_MP_SKETCH
    + _pairs(_MP_ALL, [("left_hip", "right_hip"), ("left_shoulder", "right_shoulder")]),
    virtual=_MP_VIRTUAL,
    root=(23, 24),
)

# --- SMPL-24: the kinematic joints of the SMPL body model (3DPW's jointPositions) -------------
_SMPL_NAMES = (
    "pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2",
    "left_ankle", "right_ankle", "spine3", "left_foot", "right_foot", "neck", "left_collar",
    "right_collar", "head", "left_shoulder", "right_shoulder", "left_elbow", "right_elbow",
    "left_wrist", "right_wrist", "left_hand", "right_hand",
)  # fmt: skip
_SMPL_PARENTS = (-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21)
_SMPL_BONES = tuple((p, c) for c, p in enumerate(_SMPL_PARENTS) if p >= 0)
#: The 24 SMPL joints (layout name ``"smpl"``); bones = the kinematic tree.
SMPL24 = JointLayout(name="smpl", names=_SMPL_NAMES, sketch_bones=_SMPL_BONES, length_bones=_SMPL_BONES, root=(0,))
#: SMPL-24 index of each LSP-14 joint. Approximations: SMPL has no head top, its "head" joint
#: (the centre of the head, about 10 cm below the top) stands in; SMPL's hips, neck and
#: shoulders are its kinematic joints, not the marker-based joints of LSP / Human3.6M.
SMPL24_TO_LSP14 = (8, 5, 2, 1, 4, 7, 21, 19, 17, 16, 18, 20, 12, 15)

LAYOUTS: dict[str, JointLayout] = {l.name: l for l in (LSP14, COCO17, H36M17, MEDIAPIPE33, SMPL24)}


def get_layout(layout: str | JointLayout) -> JointLayout:
    """Look a layout up by name (``lsp14``, ``coco17``, ``h36m17``, ``mediapipe33``, ``smpl``)."""
    if isinstance(layout, JointLayout):
        return layout
    try:
        return LAYOUTS[layout]
    except KeyError:
        raise ValueError(f"unknown joint layout {layout!r}; expected one of {sorted(LAYOUTS)}") from None


def mapping_matrix(src: str | JointLayout, dst: str | JointLayout = "lsp14") -> torch.Tensor:
    """(K_dst, K_src) weights mapping joints of ``src`` to ``dst``; undefined rows are zero.

    Defined: identity; H36M-17, COCO-17 and MediaPipe-33 to LSP-14 (COCO and MediaPipe have
    no head top: that row is zero; the neck is the shoulders' midpoint); SMPL-24 to LSP-14
    (:data:`SMPL24_TO_LSP14`: the head top is SMPL's head joint); MediaPipe-33 to COCO-17.
    """
    src, dst = get_layout(src), get_layout(dst)
    w = torch.zeros(dst.num_joints, src.num_joints)
    if src.name == dst.name:
        return torch.eye(src.num_joints)
    if dst.name == "lsp14" and src.name == "h36m17":
        w[torch.arange(14), torch.tensor(H36M_J17_TO_J14)] = 1.0
        return w
    if dst.name == "lsp14" and src.name == "smpl":
        w[torch.arange(14), torch.tensor(SMPL24_TO_LSP14)] = 1.0
        return w
    if dst.name == "coco17" and src.name == "mediapipe33":
        w[torch.arange(17), torch.tensor(MEDIAPIPE33_TO_COCO17)] = 1.0
        return w
    if dst.name == "lsp14" and src.name in ("coco17", "mediapipe33"):
        for i, name in enumerate(dst.names):
            if name == "neck":
                w[i, src.index("left_shoulder")] = 0.5
                w[i, src.index("right_shoulder")] = 0.5
            elif name in src.names:
                w[i, src.index(name)] = 1.0
        return w
    raise ValueError(f"no mapping from joint layout {src.name!r} to {dst.name!r}")


def map_joints(
    joints: torch.Tensor,
    src: str | JointLayout,
    dst: str | JointLayout = "lsp14",
    confidence: torch.Tensor | None = None,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
    """Map joints (..., K_src, D) to ``dst``: returns (joints (..., K_dst, D), defined (K_dst,)
    bool, confidence (..., K_dst) or None).

    Undefined joints come out as zeros with confidence 0. A mapped joint's confidence is the
    minimum over the source joints it is made of.
    """
    src_l = get_layout(src)
    if joints.shape[-2] != src_l.num_joints:
        raise ValueError(
            f"map_joints: expected {src_l.num_joints} joints for layout {src_l.name!r}, got shape {tuple(joints.shape)}"
        )
    w = mapping_matrix(src_l, dst).to(joints)
    defined = w.abs().sum(-1) > 0
    out = torch.einsum("jk,...kd->...jd", w, joints)
    if confidence is None:
        return out, defined, None
    used = (w != 0).to(confidence.device)
    big = torch.finfo(confidence.dtype).max
    conf = torch.where(used, confidence.unsqueeze(-2), torch.full_like(confidence.unsqueeze(-2), big)).amin(-1)
    conf = torch.where(defined.to(conf.device), conf, torch.zeros_like(conf))
    return out, defined, conf
