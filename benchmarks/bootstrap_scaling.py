"""How the whole method's cost grows with the number of frames and with the resolution.

Usage:
  python benchmarks/bootstrap_scaling.py [--frames 8,16,32,64] [--sizes 128x256,218x512]
      [--mode 3d] [--out benchmarks/results/scaling] [-- extra bootstrap_speed.py options]

Runs ``bootstrap_speed.py`` once per (frames, size), each in a fresh process (so its peak memory
is its own), and writes ``<out>.json``, a markdown table ``<out>.md`` (seconds of the method and
of plain RAFT inference, their ratio, seconds per frame, peak memory) and a plot ``<out>.png``
(seconds against frames, one line per size, method and RAFT). Linear growth in frames shows as
a constant seconds-per-frame column.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def run_one(frames: int, size: str, mode: str, extra: list[str]) -> dict:
    height, width = (int(v) for v in size.split("x"))
    cmd = [sys.executable, str(HERE / "bootstrap_speed.py"), "--frames", str(frames), "--height", str(height),
           "--width", str(width), "--mode", mode, *extra]  # fmt: skip
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    return {"frames": frames, "size": size, **json.loads(out[out.index("{") :])}


def table(rows: list[dict]) -> str:
    lines = ["| size | frames | method s | RAFT s | x RAFT | s/frame | peak MiB |", "| --- " * 7 + "|"]
    for r in rows:
        lines.append(f"| {r['size']} | {r['frames']} | {r['total_s']:.1f} | {r['raft_inference_s']:.1f} "
                     f"| {r['ratio_to_raft']:.1f} | {r['s_per_frame']:.2f} | {r['peak_mib']:.0f} |")  # fmt: skip
    return "\n".join(lines)


def plot(rows: list[dict], path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for size in dict.fromkeys(r["size"] for r in rows):
        mine = [r for r in rows if r["size"] == size]
        frames = [r["frames"] for r in mine]
        line = ax.plot(frames, [r["total_s"] for r in mine], "o-", label=f"{size} method")[0]
        ax.plot(frames, [r["raft_inference_s"] for r in mine], "s--", color=line.get_color(), label=f"{size} RAFT")
    ax.set_xlabel("frames")
    ax.set_ylabel("seconds")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--frames", default="8,16,32,64")
    p.add_argument("--sizes", default="128x256,218x512")
    p.add_argument("--mode", default="3d", choices=("3d", "2d"))
    p.add_argument("--out", default=str(HERE / "results" / "scaling"))
    args, extra = p.parse_known_args()
    extra = [a for a in extra if a != "--"]
    rows = []
    for size in args.sizes.split(","):
        for frames in (int(f) for f in args.frames.split(",")):
            rows.append(run_one(frames, size, args.mode, extra))
            print(json.dumps({k: rows[-1][k] for k in ("size", "frames", "total_s", "ratio_to_raft")}), flush=True)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(json.dumps({"settings": vars(args), "extra": extra, "rows": rows}, indent=1))
    out.with_suffix(".md").write_text(table(rows) + "\n")
    plot(rows, out.with_suffix(".png"), f"lit-boot {args.mode} on {rows[0]['device']}")
    print(table(rows))


if __name__ == "__main__":
    main()
