"""The overlay video's mosaics: frame, flows before / after (and GT), EPE change, skeletons, legend.

Images are uint8 tensors (3, H, W) in RGB order; flows are (2, H, W) px, the displacement from
frame t to frame t+1; keypoints are (x, y) pixels with pixel centres at integer coordinates.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence

import cv2
import numpy as np
import torch
from matplotlib import colormaps

from ..core import Scene
from ..core.joints import JointLayout, get_layout
from ..data.visualize import OTHER_COLOURS, OTHER_RGB, draw_skeleton, flow_image
from .decisions import decision_map

__all__ = ["overlay_frames", "flow_colour_scale", "video_fps", "change_image", "draw_poses", "resize_image",
           "clean_flow", "nice_ceiling", "sequential_image", "CHANGE_CMAP"]

MOVING_PX = 0.5  # a pixel "moves" when its flow is longer than this (px)
FLOW_PERCENTILE = 90.0  # of the moving pixels' magnitudes: the flow colour scale
ERROR_PERCENTILE = 99.0  # of |EPE change| over valid pixels: the error map's scale
_SAMPLES = 1_000_000  # percentiles from at most about this many values per array
_INVALID = 128  # grey where a map is not defined (no GT flow; a warp leaving the image)
CHANGE_CMAP = "Purples"  #: |refined - RAFT| px: white unchanged, dark purple at the scale


def video_fps(num_frames: int, source_fps: float, seconds: float = 5.0, slowest: float = 2.0) -> float:
    """Playback rate of a video of ``num_frames``: slow enough to last ``seconds`` (5 s), at
    least ``slowest`` fps (2), never faster than the scene's ``source_fps``. 7 mosaics of a
    30 fps scene play at 2 fps (3.5 s); 300 play at 30 fps (10 s)."""
    return float(min(source_fps, max(slowest, num_frames / seconds))) if source_fps > 0 else slowest


def _sample(values: np.ndarray) -> np.ndarray:
    values = values.reshape(-1)
    return values[:: max(1, values.size // _SAMPLES)]


def flow_colour_scale(magnitudes: list[np.ndarray]) -> float:
    """The colour scale (px) shared by every flow panel of a video: the 90th percentile of the
    magnitudes (px, any shape) that exceed 0.5 px, or the 99th percentile of all of them when
    none does; at least 0.01 px. A few large outliers (a limb tip, a RAFT artefact) cannot
    wash the rest out, and still pixels (most of a frame with a small person) do not count."""
    values = np.concatenate([_sample(m[np.isfinite(m)]) for m in magnitudes] + [np.zeros(0, np.float32)])
    moving = values[values > MOVING_PX]
    if moving.size:
        return max(0.01, float(np.percentile(moving, FLOW_PERCENTILE)))
    return max(0.01, float(np.percentile(values, 99.0))) if values.size else 1.0


def nice_ceiling(value: float, floor: float) -> float:
    """The smallest of 1, 2, 2.5, 5 x 10^k at or above max(``value``, ``floor``) (a legend's end)."""
    value = max(float(value), floor)
    power = 10.0 ** np.floor(np.log10(value))
    return float(next(m * power for m in (1, 2, 2.5, 5, 10) if m * power >= value * (1 - 1e-9)))


def sequential_image(values: torch.Tensor, scale: float, cmap: str, valid: torch.Tensor | None = None) -> np.ndarray:
    """``values`` (H, W) in [0, ``scale``] through the colour map ``cmap`` (beyond: its end),
    grey where not ``valid``: HWC uint8."""
    rgb = colormaps[cmap]((values.float().numpy() / scale).clip(0, 1), bytes=True)[..., :3].copy()
    if valid is not None:
        rgb[~valid.numpy()] = _INVALID
    return rgb


def change_image(change: torch.Tensor, valid: torch.Tensor, scale: float) -> np.ndarray:
    """A change (H, W), after - before (the EPE change, px; a census error change), coloured with
    the diverging RdBu_r map over [-scale, scale] (blue: lower after, i.e. better; white: no
    change; red: higher); grey where not ``valid``. HWC uint8."""
    rgb = colormaps["RdBu_r"]((change.numpy() / scale).clip(-1, 1) * 0.5 + 0.5, bytes=True)[..., :3]
    rgb[~valid.numpy()] = _INVALID
    return rgb


def _check(
    tensor: object, name: str, shape: tuple[int | None, ...], expected: str, dtype: torch.dtype | None = None
) -> None:
    """ValueError naming ``name`` unless ``tensor`` is a tensor of ``shape`` (None: any size)."""
    ok = isinstance(tensor, torch.Tensor) and tensor.ndim == len(shape)
    ok = ok and all(s is None or s == t for s, t in zip(shape, tensor.shape))
    ok = ok and (dtype is None or tensor.dtype == dtype) and (dtype is not None or tensor.is_floating_point())
    if not ok:
        got = f"{tensor.dtype} {tuple(tensor.shape)}" if isinstance(tensor, torch.Tensor) else type(tensor).__name__
        kind = {torch.uint8: "uint8", torch.bool: "bool"}.get(dtype, "float")
        raise ValueError(f"overlay_frames: expected {name} as a {kind} tensor of shape {expected}, got {got}")


def _label(image: np.ndarray, text: str) -> np.ndarray:
    """A copy of an HWC uint8 image with ``text`` top left: white on a black box (an outline
    drawn thicker would not line up: OpenCV's glyph advance grows with the thickness)."""
    scale = max(0.3, min(image.shape[:2]) / 400)
    org = (3, 3 + round(22 * scale))
    image = np.array(image, order="C", copy=True)  # never draw into a caller's (or shared) buffer
    (w, h), baseline = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)
    cv2.rectangle(image, (0, 0), (org[0] + w + 2, org[1] + baseline), (0, 0, 0), cv2.FILLED)
    cv2.putText(image, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, (255, 255, 255), 1, cv2.LINE_AA)
    return image


def _legend(width: int, panel: int, flow_scale: float, rows: list[tuple[str, tuple | None]]) -> np.ndarray:
    """The key under the mosaic, HWC uint8 (rows, ``width``): a flow colour wheel (flow_image of
    vectors up to ``flow_scale`` px) beside the flow line, then ``rows``: (text, sample) with
    sample None, ("line", RGB) as the skeletons are drawn, or ("bar", colour map name).
    ``panel``: the panel's shorter side, px, sets the text size; a key wider than ``width`` is
    scaled down to fit."""
    lines = [(f"flow: hue = direction, white = still, full colour >= {flow_scale:.2g} px", None), *rows]
    font, text = cv2.FONT_HERSHEY_SIMPLEX, max(0.4, panel / 400)
    row = round(34 * text)
    wheel, mark = 3 * row - 4, 3 * row  # the wheel's diameter; line samples and colour bar
    left = 10 + wheel
    widest = max(cv2.getTextSize(s, font, text, 1)[0][0] for s, _ in lines)
    image = np.full((max(len(lines) * row, wheel) + 4, max(width, left + mark + widest + 6), 3), 255, np.uint8)
    y, x = np.mgrid[:wheel, :wheel].astype(np.float32) - (wheel - 1) / 2
    disk = flow_image(torch.from_numpy(np.stack([x, y]) * (2 * flow_scale / wheel)), max_magnitude=flow_scale)
    inside = (x**2 + y**2 <= (wheel / 2) ** 2)[..., None]
    image[2 : 2 + wheel, 4 : 4 + wheel] = np.where(inside, disk.permute(1, 2, 0).numpy(), 255)
    for i, (line, sample) in enumerate(lines):
        top, at = 2 + i * row, left + (mark if i else 0)
        if sample is not None and sample[0] == "line":
            cv2.line(image, (left, top + row // 2), (left + mark - 8, top + row // 2), sample[1], 3)
        elif sample is not None:  # a colour bar
            image[top + 3 : top + row - 3, left : left + mark - 8] = colormaps[sample[1]](
                np.linspace(0, 1, mark - 8), bytes=True)[None, :, :3]  # fmt: skip
        cv2.putText(image, line, (at, top + row - round(0.3 * row)), font, text, (0, 0, 0), 1, cv2.LINE_AA)
    if image.shape[1] > width:
        height = max(1, round(image.shape[0] * width / image.shape[1]))
        image = cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA)
    return image


def _key_rows(error_scale: float | None, evidence: tuple[float, float] | None, decisions: dict | None,
              others: int = 0) -> list:  # fmt: skip
    """The legend's rows after the flow line (see :func:`_legend`); ``decisions``: the maps drawn;
    ``others``: how many other people are drawn."""
    rows: list = [("pose before (input)", ("line", (255, 0, 0))), ("pose after (refined)", ("line", (0, 255, 0)))]
    if others:
        rows.append((f"the other {others} people's poses after the run (one colour per track)",
                     ("line", OTHER_RGB[0])))
    if error_scale is not None:
        rows.append((f"+-{error_scale:.2g} px: EPE change vs GT, refined - RAFT (blue better, red worse, grey no GT)",
                     ("bar", "RdBu_r")))  # fmt: skip
    if evidence is not None:
        rows.append((f"0..{evidence[0]:g} px: change |refined - RAFT| (white: unchanged)", ("bar", CHANGE_CMAP)))
        rows.append((f"+-{evidence[1]:g} of 48: census error change, refined - RAFT (blue: the frames say better)",
                     ("bar", "RdBu_r")))  # fmt: skip
    if decisions is not None:
        zoom = ", magenta = the zoomed flow kept" if "zoom" in decisions else ""
        rows.append((f"decisions: orange = the target painted, blue = a tuned flow kept{zoom} (grey: RAFT's flow kept)",
                     None))  # fmt: skip
    return rows


@torch.no_grad()
def _evidence_column(frames: torch.Tensor, flows: dict, size: tuple[int, int]) -> tuple[list, list, float, float]:
    """Without GT, the third column of each pair at panel ``size`` (h, w): the change
    |after - before| px (:data:`CHANGE_CMAP`) and the census error change after - before (0..48
    units, RdBu_r; grey where a warp leaves the image), measured on the frames scaled to the
    panel with the flows scaled alike (cheap for long videos); and their scales (99th
    percentiles rounded up by :func:`nice_ceiling`, at least 0.5)."""
    from ..flow.evidence import photometric_error  # imports kornia: only when a video is made

    (h, w), (H, W) = size, frames.shape[-2:]
    change = (flows["after"] - flows["before"]).norm(dim=1)
    change_scale = nice_ceiling(float(np.percentile(_sample(change.numpy()), 99.0)), 0.5)
    small = torch.stack([torch.from_numpy(np.ascontiguousarray(resize_image(f, size))).permute(2, 0, 1)
                         for f in frames.detach().cpu()])  # fmt: skip
    per_px = torch.tensor([w / W, h / H])[:, None, None]
    deltas, valids = [], []
    for t in range(frames.shape[0] - 1):
        errors = []
        for key in ("before", "after"):
            flow = torch.from_numpy(np.ascontiguousarray(resize_image(flows[key][t], size))).permute(2, 0, 1) * per_px
            (error,), (valid,) = photometric_error(small[t : t + 1], small[t + 1 : t + 2], flow[None])
            errors.append((error, valid))
        deltas.append(errors[1][0] - errors[0][0])
        valids.append(errors[0][1] & errors[1][1])
    gains = torch.cat([d[v] for d, v in zip(deltas, valids)]).abs()
    census_scale = nice_ceiling(float(np.percentile(_sample(gains.numpy()), 99.0)) if gains.numel() else 0.0, 0.5)
    changes = [resize_image(sequential_image(c, change_scale, CHANGE_CMAP), size) for c in change]
    evidence = [change_image(d, v, census_scale) for d, v in zip(deltas, valids)]
    return changes, evidence, change_scale, census_scale


def _check_inputs(frames, flow_before, flow_after, joints, layout, gt_flow, gt_valid) -> JointLayout | None:
    """Raise ValueError naming the argument for a wrong shape; the layout (None without joints)."""
    _check(frames, "frames", (None, 3, None, None), "(T, 3, H, W)", torch.uint8)
    T, _, H, W = frames.shape
    if T < 2:
        raise ValueError(f"overlay_frames: expected frames with T >= 2 frames, got {tuple(frames.shape)}")
    pairs = f"(T-1, 2, H, W) = ({T - 1}, 2, {H}, {W})"
    for name, flow in (("flow_before", flow_before), ("flow_after", flow_after), ("gt_flow", gt_flow)):
        if flow is not None or name != "gt_flow":
            _check(flow, name, (T - 1, 2, H, W), pairs)
    if gt_valid is not None:
        if gt_flow is None:
            raise ValueError("overlay_frames: gt_valid given without gt_flow")
        _check(gt_valid, "gt_valid", (T - 1, H, W), f"(T-1, H, W) = ({T - 1}, {H}, {W})", torch.bool)
    if all(j is None for j in joints.values()):
        return None
    if layout is None:
        raise ValueError("overlay_frames: layout is required when joints_before or joints_after is given")
    layout = get_layout(layout)
    for name, j in joints.items():
        if j is not None:
            _check(j, f"joints_{name}", (T, layout.num_joints, 2),
                   f"(T, J, 2) = ({T}, {layout.num_joints}, 2) for layout {layout.name!r}")  # fmt: skip
    return layout


def overlay_frames(
    frames: torch.Tensor,
    flow_before: torch.Tensor,
    flow_after: torch.Tensor,
    joints_before: torch.Tensor | None,
    joints_after: torch.Tensor | None,
    layout: str | JointLayout | None,
    max_side: int = 1280,
    flow_labels: tuple[str, str] = ("RAFT", "refined"),
    gt_flow: torch.Tensor | None = None,
    gt_valid: torch.Tensor | None = None,
    legend: bool = True,
    decisions: dict[str, torch.Tensor] | None = None,
    others: Sequence[torch.Tensor] = (),
) -> torch.Tensor:
    """Before/after mosaics, one per frame pair: uint8 (T-1, 3, 2h + key, 3 w).

    frames uint8 (T, 3, H, W) RGB; flow_before / flow_after float (T-1, 2, H, W) px, pair t ->
    t+1; joints_before / joints_after (T, J, 2) px in ``layout`` (J = its number of joints,
    NaN: not drawn), or None; gt_flow float (T-1, 2, H, W) px or None, gt_valid bool (T-1, H,
    W) where the GT counts (None: everywhere; grey elsewhere). Mosaic for pair t: [frame t | flow
    before] over [frame t with the skeleton before in red and after in green (on top) | flow
    after], and a third column: with GT, [GT flow] over [EPE change], the per-pixel
    |after - GT| - |before - GT| px in RdBu_r (blue: nearer the GT), the flow labels carrying
    each pair's mean EPE; without GT, [change |after - before| px] over [census error change,
    after - before, what the frames say: blue better] (:func:`_evidence_column`). Every flow
    panel of the video shares one colour scale, :func:`flow_colour_scale` of all of them, longer
    vectors clipped to full colour; zero flow is white; the EPE change spans +-its 99th
    percentile |value|. Each panel has a text label; ``legend`` adds the key below (colour wheel
    and scale, skeleton colours, colour bars). ``decisions`` ({"painted": (T-1, H, W) bool,
    "kept": (T-1, H, W) float, optionally "zoom": (T-1, H, W) float}, see
    :func:`~lit_boot.bootstrap.decisions.final_decisions`) replaces the top-left frame with the
    decision map (:func:`~lit_boot.bootstrap.decisions.decision_map`). ``others``: the other
    people's joints (T, J, 2) px each (NaN: not drawn), drawn under the main person's skeletons
    in :data:`OTHER_COLOURS`, one per track (:func:`other_people`). Panels
    are h x w = H x W, scaled down (INTER_AREA; joints scaled with them) when the mosaic's
    longer side would exceed ``max_side``. Raises ValueError naming the argument
    for a wrong shape.
    """
    joints = {"before": joints_before, "after": joints_after}
    layout = _check_inputs(frames, flow_before, flow_after, joints, layout, gt_flow, gt_valid)
    if max_side < 2:
        raise ValueError(f"overlay_frames: max_side must be >= 2, got {max_side}")
    T, _, H, W = frames.shape
    cols = 3
    scale = min(1.0, max_side / max(2 * H, cols * W))
    h, w = max(1, int(H * scale)), max(1, int(W * scale))
    resize = functools.partial(resize_image, size=(h, w))
    flows = {"before": clean_flow(flow_before), "after": clean_flow(flow_after)}
    valid = torch.ones(T - 1, H, W, dtype=torch.bool) if gt_valid is None else gt_valid.detach().cpu()
    magnitudes = [flows["before"].norm(dim=1).numpy(), flows["after"].norm(dim=1).numpy()]
    errors, error_scale, labels = None, None, list(flow_labels)
    if gt_flow is not None:
        gt = clean_flow(gt_flow)
        magnitudes.append(gt.norm(dim=1)[valid].numpy())
        epe, errors, error_scale = _epe_change(flows, gt, valid)
    flow_scale = flow_colour_scale(magnitudes)
    evidence = _evidence_column(frames, flows, (h, w)) if gt_flow is None else None
    scales = evidence[2:] if evidence is not None else None
    rows = _key_rows(error_scale, scales, decisions, len(others))
    key = _legend(cols * w, min(h, w), flow_scale, rows) if legend else None
    mosaics = []
    for t in range(T - 1):
        frame = torch.from_numpy(np.ascontiguousarray(resize(frames[t].detach().cpu())))
        pose = draw_poses(frame.permute(2, 0, 1), joints, t, layout, (w / W, h / H), others)
        before_img, after_img = flow_image(torch.stack([flows["before"][t], flows["after"][t]]), flow_scale)
        if gt_flow is not None:
            pair = valid[t]
            labels = [f"{name} EPE {float(epe[k][t][pair].mean()) if pair.any() else math.nan:.2f}"
                      for name, k in zip(flow_labels, ("before", "after"))]  # fmt: skip
        first = _label(frame.numpy(), f"frame {t}")
        if decisions is not None:
            image = decision_map(frames[t].detach().cpu(), decisions, t)
            first = _label(resize(image), f"frame {t}: decisions")
        top = [first, _label(resize(before_img), labels[0])]
        bottom = [_label(pose.permute(1, 2, 0).numpy(), "pose before/after"), _label(resize(after_img), labels[1])]
        if gt_flow is not None:
            gt_img = flow_image(gt[t], flow_scale).permute(1, 2, 0).numpy().copy()
            gt_img[~valid[t].numpy()] = _INVALID
            top.append(_label(resize(gt_img), "GT flow"))
            bottom.append(_label(resize(change_image(errors[t], valid[t], error_scale)), "EPE change"))
        else:
            top.append(_label(evidence[0][t], "change |refined - RAFT|"))
            bottom.append(_label(evidence[1][t], "census error change"))
        rows = [np.concatenate(top, 1), np.concatenate(bottom, 1)] + ([key] if key is not None else [])
        mosaics.append(torch.from_numpy(np.concatenate(rows, 0)).permute(2, 0, 1))
    return torch.stack(mosaics).contiguous()


def resize_image(image: torch.Tensor | np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """(3, H, W) tensor or (H, W, 3) array -> (h, w, 3) array (INTER_AREA; as is when the size agrees)."""
    array = image.permute(1, 2, 0).numpy() if isinstance(image, torch.Tensor) else image
    h, w = size
    return array if array.shape[:2] == (h, w) else cv2.resize(array, (w, h), interpolation=cv2.INTER_AREA)


def clean_flow(flow: torch.Tensor) -> torch.Tensor:
    """The flow as a float CPU tensor with NaN and inf set to 0."""
    return torch.nan_to_num(flow.detach().cpu().float(), 0.0, 0.0, 0.0)


def _epe_change(flows: dict, gt: torch.Tensor, valid: torch.Tensor) -> tuple[dict, torch.Tensor, float]:
    """Per-pixel EPE (T-1, H, W) px of the "before" and "after" flows against ``gt``, the change
    after - before (0 where not ``valid``), and its scale: the 99th percentile of |change| over
    the valid pixels, at least 0.01 px (1 px when none is valid)."""
    epe = {k: (f - gt).norm(dim=1) for k, f in flows.items()}
    change = torch.where(valid, epe["after"] - epe["before"], 0.0)
    if not valid.any():
        return epe, change, 1.0
    return epe, change, max(0.01, float(np.percentile(_sample(change[valid].abs().numpy()), ERROR_PERCENTILE)))


def draw_poses(frame: torch.Tensor, joints: dict, t: int, layout: JointLayout | None, scale: tuple,
               others: Sequence[torch.Tensor] = ()) -> torch.Tensor:  # fmt: skip
    """``frame`` (3, h, w) with pair t's skeletons: the other people's (``others``, each (T, J,
    2) px) in :data:`OTHER_COLOURS`, then the main person's before in red, after in green (on
    top); joints are scaled by ``scale`` (sx, sy) about pixel centres."""
    drawn = [(j, OTHER_COLOURS[p % len(OTHER_COLOURS)]) for p, j in enumerate(others)]
    for j, colour in drawn + list(zip(joints.values(), ("red", "lime"))):
        if j is not None:
            points = (j[t].detach().cpu().float() + 0.5) * torch.tensor(scale) - 0.5
            frame = draw_skeleton(frame, points, layout, color=colour)
    return frame


def other_people(scene: Scene, mode: str) -> list[torch.Tensor]:
    """The pose points of ``mode`` (T, J, 2) px of every person but the main one, NaN where they
    do not count (:meth:`Scene.pose_points`), in track order."""
    out = []
    for p in range(1, scene.num_people):
        points, keep = scene.person(p).pose_points(mode)
        out.append(torch.where(keep[..., None], points.float(), float("nan")))
    return out
