"""Whether a change left the single-person method as it was: the default bootstrap (3D and 2D)
on a synthetic scene with this checkout and with another one (e.g. a git worktree of an earlier
commit), and the largest difference of the final flows and poses.

Usage:
  git worktree add /tmp/old <commit>
  OMP_NUM_THREADS=1 python benchmarks/single_person_unchanged.py --old /tmp/old
      [--weights ../shared/checkpoints/raft-small.pth]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import torch

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
RUN = """
import sys, tempfile, torch
sys.path.insert(0, {root!r})
import lit_boot
from lit_boot.bootstrap import bootstrap
out = {{}}
for mode in ("3d", "2d"):
    scene = lit_boot.make_scene(motion="run", frames=6, height=96, width=192, seed=3)
    r = bootstrap(scene, tempfile.mkdtemp() + "/run", mode=mode, flow={{"weights": {weights!r}}}, flow_epochs=2,
                  pose_steps=200, progress_bar=False, video=False)
    out[mode] = {{"flows": r.flows, "poses": r.scene.joints3d if mode == "3d" else r.scene.keypoints2d}}
torch.save(out, {path!r})
"""


def run(root: Path, weights: str, path: str) -> dict:
    subprocess.run([sys.executable, "-c", RUN.format(root=str(root), weights=weights, path=path)], check=True,
                   capture_output=True)  # fmt: skip
    return torch.load(path)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--old", type=Path, required=True, help="the other checkout's root")
    p.add_argument("--weights", default=str(SHARED / "checkpoints/raft-small.pth"))
    args = p.parse_args()
    tmp = tempfile.mkdtemp()
    new = run(Path(__file__).resolve().parents[1], args.weights, f"{tmp}/new.pt")
    old = run(args.old.resolve(), args.weights, f"{tmp}/old.pt")
    for mode in ("3d", "2d"):
        flows = float((new[mode]["flows"] - old[mode]["flows"]).abs().max())
        poses = float((new[mode]["poses"] - old[mode]["poses"]).abs().max())
        unit = "mm" if mode == "3d" else "px"
        print(f"{mode}: final flows differ by at most {flows:.3g} px, poses by {poses:.3g} ({unit})")


if __name__ == "__main__":
    main()
