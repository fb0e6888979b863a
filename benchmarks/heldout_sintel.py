"""The held-out Sintel windows (real_data.py's HELDOUT) in the official layout, from a git clone of
fperezgamonal/faldoi-ipol, whose example_data/ holds MPI-Sintel training frames with their GT.

None of these windows is in ../shared, and no default was chosen on them: they check the claims
made on the shared windows (issue 24, "Figures nobody tuned on"). The files are read from the
clone's history (``git show COMMIT:PATH``; later commits removed some) and written, byte for
byte, under ``--out`` as ``training/<pass>/<scene>/frame_NNNN.png`` and ``training/{flow,
occlusions,invalid}/<scene>/frame_NNNN.{flo,png}``, the layout real_data.py's ``--heldout-root``
and zoom_stage.py read. Sintel: research and benchmarking use (see ../shared/data/SOURCES.md).

Usage:
  git clone https://github.com/fperezgamonal/faldoi-ipol /tmp/faldoi-ipol
  python benchmarks/heldout_sintel.py --repo /tmp/faldoi-ipol [--out ../heldout/sintel]
"""

from __future__ import annotations

import argparse
import subprocess
from pathlib import Path

#: (commit, folder under example_data/, Sintel scene, pass, frames, the GT frame). The scene of each folder is named in its README.txt, except
#: sequence1 and the iterated one (ambush and shaman scenes the repository does not name).
WINDOWS = [
    ("561809f", "final/medium", "cave_2", "final", (1, 2, 3, 4), 2),
    ("464bb566", "faldoi_functionals_comparison/sequence2", "cave_2", "final", (10, 11, 12, 13), 11),
    ("95ccceb8", "dm_vs_sift/difficult_sift", "cave_4", "final", (40, 41, 42, 43), 41),
    ("95ccceb8", "few_seeds/ambush_2", "ambush_2", "final", (20, 21), 20),
    ("464bb566", "faldoi_functionals_comparison/sequence1", "unidentified_ambush", "final", (2, 3, 4, 5), 3),
    ("464bb566", "iterated_faldoi_evol_and_final_flow", "unidentified_shaman", "final", (41, 42, 43, 44), 42),
    ("464bb566", "alley_2_clean", "alley_2", "clean", (1, 2, 3, 4), 2),
]
HELDOUT_ROOT = Path(__file__).resolve().parents[1].parent / "heldout/sintel"


def show(repo: Path, commit: str, path: str) -> bytes:
    """The bytes of ``path`` at ``commit`` in the clone ``repo``; a clear error when absent."""
    done = subprocess.run(["git", "-C", str(repo), "show", f"{commit}:{path}"], capture_output=True)
    if done.returncode:
        raise SystemExit(f"--repo {repo}: cannot read {commit}:{path} ({done.stderr.decode().strip()}); "
                         "expected a full clone of fperezgamonal/faldoi-ipol")  # fmt: skip
    return done.stdout


def write(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(data)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repo", required=True, help="a git clone of fperezgamonal/faldoi-ipol (full history)")
    p.add_argument("--out", default=str(HELDOUT_ROOT), help="the Sintel root to write (real_data.py's --heldout-root)")
    args = p.parse_args()
    repo, root = Path(args.repo), Path(args.out) / "training"
    for commit, folder, scene, pass_name, frames, gt in WINDOWS:
        src = f"example_data/{folder}"
        for f in frames:
            write(root / pass_name / scene / f"frame_{f:04d}.png", show(repo, commit, f"{src}/frame_{f:04d}.png"))
        name = f"frame_{gt:04d}"
        write(root / "flow" / scene / f"{name}.flo", show(repo, commit, f"{src}/gt/{name}.flo"))
        for kind in ("occlusions", "invalid"):
            write(root / kind / scene / f"{name}.png", show(repo, commit, f"{src}/gt/{kind}/{name}.png"))
        print(f"{scene} ({pass_name}) frames {frames[0]}-{frames[-1]}, GT {gt} -> {gt + 1}")
    print(f"wrote {root}")


if __name__ == "__main__":
    main()
