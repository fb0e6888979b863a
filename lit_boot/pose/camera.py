"""Which camera parameters the 3D refiner optimises, and the projection it differentiates.

The paper optimises METRO's weak-perspective camera (s, tx, ty) per frame, with tx, ty in
metres. For the pinhole model the intrinsics are known and fixed; only the per-frame
translation is optimised, expressed in metres so that Adam's step size (lr, a distance per
step) and the camera-smoothness lambda mean the same as for the joints.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from ..core import Cameras, project_pinhole, project_weak_perspective

__all__ = ["CameraModel"]


class CameraModel(nn.Module):
    """Fixed parts of per-frame cameras (buffers, so they follow the module's device) and the
    map from the optimised variables (T, 3) to pixels.

    weak_perspective: variables = (s, tx, ty), fixed = crops (T, 3) and the crop size.
    pinhole: variables = translation (tx, ty, tz) in metres, fixed = (fx, fy, cx, cy) (T, 4).

    Given a sequence of P people's cameras (one model and crop size), every tensor gets a person
    axis after the frames: variables (T, P, 3), fixed (T, P, k), joints (T, P, J, 3).
    """

    def __init__(self, cameras: Cameras | Sequence[Cameras]):
        super().__init__()
        people = [cameras] if isinstance(cameras, Cameras) else list(cameras)
        first = people[0]
        if any((c.model, float(c.crop_size)) != (first.model, float(first.crop_size)) for c in people):
            raise ValueError("CameraModel: every person's cameras need one model and crop size")
        self.model = first.model
        self.crop_size = float(first.crop_size)
        self.people = None if isinstance(cameras, Cameras) else len(people)

        def stacked(get) -> torch.Tensor:
            values = [get(c).detach().float() for c in people]
            return values[0] if self.people is None else torch.stack(values, dim=1)

        params = stacked(lambda c: c.params)
        if self.model == "weak_perspective":
            self.register_buffer("fixed", stacked(lambda c: c.crops), persistent=False)
            self.register_buffer("start", params.clone(), persistent=False)
        else:
            self.register_buffer("fixed", params[..., :4].clone(), persistent=False)
            self.register_buffer("start", params[..., 4:7] / 1000.0, persistent=False)

    def initial(self) -> torch.Tensor:
        """Initial variables (T, 3), or (T, P, 3) for P people."""
        return self.start.clone()

    def project(self, joints_m: torch.Tensor, variables: torch.Tensor) -> torch.Tensor:
        """Joints (T, J, 3) in metres -> pixels (T, J, 2) (with people: (T, P, J, 3) -> (T, P, J,
        2)), differentiable in both arguments."""
        joints_mm = joints_m * 1000.0
        if self.model == "weak_perspective":
            return project_weak_perspective(joints_mm, variables, self.fixed, self.crop_size)
        return project_pinhole(joints_mm, torch.cat([self.fixed, variables * 1000.0], dim=-1))

    def to_cameras(self, variables: torch.Tensor, person: int | None = None) -> Cameras:
        """The refined cameras (on the CPU) in the scene's convention; with people, ``person``'s."""
        v = variables.detach().float().cpu()
        fixed = self.fixed.detach().cpu()
        if self.people is not None:
            if person is None:
                raise ValueError(f"CameraModel of {self.people} people: to_cameras needs a person index")
            v, fixed = v[:, person], fixed[:, person]
        if self.model == "weak_perspective":
            return Cameras("weak_perspective", v.clone(), fixed.clone(), self.crop_size)
        return Cameras("pinhole", torch.cat([fixed, v * 1000.0], dim=-1))
