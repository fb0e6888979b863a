"""The GPU check: on a machine with CUDA, everything lit-boot has not yet been measured on, into
one results file.

Usage (from the project root, on a CUDA machine):
  OMP_NUM_THREADS=4 .venv/bin/python benchmarks/gpu_check.py --out benchmarks/results/gpu_check.json

Parts (each recorded with its seconds; a part that fails is recorded with its error, the others run):

- ``cuda_tests``: the tests that need CUDA (``pytest -k cuda``; they skip on a CPU machine; the
  import contract's test, which needs the dev extra's import-linter and no GPU, is left out);
- ``mixed_precision``: the whole method on one synthetic scene (run s0, 8 frames, 128x256, seed 0,
  3D) on CUDA at 16-mixed (the presets' CUDA precision) and at 32-true: the EPE of each, finite;
- ``resume``: the same run killed (SIGKILL) once its first flow stage has finished, then resumed,
  against an uninterrupted run: which stages the rerun loaded, and how far the final flows are
  apart (CUDA kernels need not be bit-exact);
- ``speed``: ``benchmarks/bootstrap_speed.py`` at 436x1024, 8 frames, 3D and 2D mode, at the
  preset's precision: the rows of BENCHMARKS.md's speed bar, on this device;
- ``speed_bar_size``: the same at the CPU speed bar's size (128x256, 8 frames).

The results file is rewritten (atomically) after each part, so a run stopped part-way keeps the
parts it finished. The commit is ``git rev-parse HEAD``, else ``$LIT_BOOT_COMMIT``, else "unknown".

Without CUDA it refuses (one line, exit status 2) and writes nothing. ``--cpu-smoke`` runs every
part on the CPU at toy sizes with random RAFT weights, to check the script itself: its figures
mean nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Callable

ROOT = Path(__file__).resolve().parents[1]
WEIGHTS = ROOT.parent / "shared" / "checkpoints" / "raft-small.pth"


def parse(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "gpu_check.json")
    p.add_argument("--weights", default=str(WEIGHTS), help="RAFT-small weights (a file or a torchvision name)")
    p.add_argument("--parts", default="cuda_tests,mixed_precision,resume,speed,speed_bar_size", help="comma-separated")
    p.add_argument("--cpu-smoke", action="store_true", help="run on the CPU at toy sizes (checks the script only)")
    return p.parse_args(argv)


def settings(args: argparse.Namespace) -> dict[str, Any]:
    """The sizes and options of each part: the real ones, or toy ones for ``--cpu-smoke``."""
    if args.cpu_smoke:
        toy = ["--epochs", "1", "--pose-steps", "10", "--flow", '{"weights": null}']
        return {"device": "cpu", "precision": "bf16-mixed", "scene": dict(frames=3, height=64, width=96),
                "flow": {"weights": None, "train_updates": 2, "predict_updates": 3}, "epochs": 1, "pose_steps": 10,
                "speed": {"height": 64, "width": 96, "frames": 3, "extra": toy},
                "speed_bar_size": {"height": 48, "width": 64, "frames": 3, "extra": toy}}  # fmt: skip
    return {"device": "cuda", "precision": "16-mixed", "scene": dict(frames=8, height=128, width=256),
            "flow": {"weights": args.weights}, "epochs": None, "pose_steps": 1500,
            "speed": {"height": 436, "width": 1024, "frames": 8, "extra": ["--weights", args.weights]},
            "speed_bar_size": {"height": 128, "width": 256, "frames": 8,
                               "extra": ["--weights", args.weights]}}  # fmt: skip


def run_options(s: dict[str, Any], precision: str) -> dict[str, Any]:
    return dict(flow=s["flow"], flow_epochs=s["epochs"], pose_steps=s["pose_steps"], accelerator=s["device"],
                precision=precision, progress_bar=False, video=False)  # fmt: skip


def cuda_tests(s: dict[str, Any], tmp: Path) -> dict[str, Any]:
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-rs", "-p", "no:cacheprovider", "-k", "cuda",
                           "--ignore", "tests/test_architecture.py", "tests"],
                          cwd=ROOT, capture_output=True, text=True, timeout=1800)  # fmt: skip
    return {"exit_status": done.returncode, "summary": done.stdout.strip().splitlines()[-1:]}


def mixed_precision(s: dict[str, Any], tmp: Path) -> dict[str, Any]:
    import lit_boot
    from lit_boot.bootstrap import bootstrap

    scene = lit_boot.make_scene(motion="run", seed=0, **s["scene"])
    out = {}
    for precision in (s["precision"], "32-true"):
        result = bootstrap(scene, tmp / precision, **run_options(s, precision))
        values = result.before_after()
        out[precision] = {"epe": values["epe"], "epe_person": values["epe_person"],
                          "seconds": sum(result.seconds.values()), "finite": bool(result.flows.isfinite().all())}
    return out


_CHILD = """
import json, sys
import lit_boot
from lit_boot.bootstrap import bootstrap
s, run_dir, options = json.loads(sys.argv[1]), sys.argv[2], json.loads(sys.argv[3])
bootstrap(lit_boot.make_scene(motion="run", seed=0, **s["scene"]), run_dir, **options)
"""


def resume(s: dict[str, Any], tmp: Path) -> dict[str, Any]:
    import lit_boot
    import torch
    from lit_boot.bootstrap import bootstrap

    options = run_options(s, s["precision"])
    child = subprocess.Popen([sys.executable, "-c", _CHILD, json.dumps(s), str(tmp / "killed"), json.dumps(options)],
                             cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
    marker, start = tmp / "killed" / "stages" / "flow_1" / "stage.json", time.monotonic()
    while not marker.is_file() and child.poll() is None and time.monotonic() - start < 1800:
        time.sleep(0.2)
    killed = child.poll() is None
    if killed:
        os.kill(child.pid, signal.SIGKILL)
    child.wait()
    done_before = sorted(p.parent.name for p in marker.parent.parent.glob("*/stage.json"))
    scene = lit_boot.make_scene(motion="run", seed=0, **s["scene"])
    resumed = bootstrap(scene, tmp / "killed", **options)
    whole = bootstrap(scene, tmp / "whole", **options)
    gap = (resumed.flows - whole.flows).abs()
    return {"killed_after_flow_1": killed, "stages_done_when_killed": done_before,
            "max_abs_flow_difference_px": float(gap.max()), "mean_abs_flow_difference_px": float(gap.mean()),
            "epe_resumed": resumed.before_after().get("epe"), "epe_whole": whole.before_after().get("epe"),
            "bit_exact": bool(torch.equal(resumed.flows, whole.flows))}


def speed(s: dict[str, Any], tmp: Path, size_key: str = "speed") -> dict[str, Any]:
    rows = {}
    for mode in ("3d", "2d"):
        size = s[size_key]
        command = [sys.executable, "benchmarks/bootstrap_speed.py", "--height", str(size["height"]), "--width",
                   str(size["width"]), "--frames", str(size["frames"]), "--mode", mode, *size["extra"]]  # fmt: skip
        done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=3600)
        if done.returncode:
            raise RuntimeError(f"bootstrap_speed.py --mode {mode}: exit {done.returncode}: {done.stderr[-500:]}")
        report = json.loads(done.stdout[done.stdout.rindex("\n{") + 1 :] if "\n{" in done.stdout else done.stdout)
        rows[mode] = {k: report.get(k) for k in ("total_s", "raft_inference_s", "ratio_to_raft", "s_per_frame",
                                                 "peak_mib", "device", "stages_s")}  # fmt: skip
    return rows


def speed_bar_size(s: dict[str, Any], tmp: Path) -> dict[str, Any]:
    return speed(s, tmp, size_key="speed_bar_size")


def current_commit() -> str:
    try:
        done = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True)
    except OSError:  # no git on the machine
        done = None
    if done is not None and done.returncode == 0:
        return done.stdout.strip()
    return os.environ.get("LIT_BOOT_COMMIT", "unknown")


PARTS: dict[str, Callable[[dict[str, Any], Path], dict[str, Any]]] = {
    "cuda_tests": cuda_tests, "mixed_precision": mixed_precision, "resume": resume, "speed": speed,
    "speed_bar_size": speed_bar_size}


def write(out: Path, results: dict[str, Any]) -> None:
    from lit_boot.data.atomic import atomic_write_bytes

    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(out, (json.dumps(results, indent=1, default=str) + "\n").encode())


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    import torch

    if not args.cpu_smoke and not torch.cuda.is_available():
        print("gpu_check: needs a CUDA device (torch.cuda.is_available() is False here); nothing was run or written",
              file=sys.stderr)  # fmt: skip
        return 2
    unknown = sorted(set(args.parts.split(",")) - set(PARTS))
    if unknown:
        print(f"gpu_check: --parts: unknown {', '.join(unknown)}; expected some of {', '.join(PARTS)}", file=sys.stderr)
        return 2
    s = settings(args)
    device = torch.cuda.get_device_name() if s["device"] == "cuda" else "cpu (smoke check: the figures mean nothing)"
    commit = current_commit()
    results: dict[str, Any] = {"format": "lit-boot-gpu-check", "version": 1, "device": device,
                               "torch": torch.__version__, "cuda": torch.version.cuda, "commit": commit,
                               "smoke": args.cpu_smoke, "started": time.strftime("%Y-%m-%d %H:%M:%S"), "parts": {}}
    for name in args.parts.split(","):
        start = time.perf_counter()
        with tempfile.TemporaryDirectory() as tmp:
            try:
                results["parts"][name] = {"ok": True, **PARTS[name](s, Path(tmp))}
            except Exception as err:  # one part failing leaves the others
                results["parts"][name] = {"ok": False, "error": f"{type(err).__name__}: {err}"}
        results["parts"][name]["seconds"] = time.perf_counter() - start
        print(f"gpu_check: {name}: {'ok' if results['parts'][name]['ok'] else 'FAILED'}", flush=True)
        write(args.out, results)
    print(f"gpu_check: wrote {args.out}")
    return 0 if all(part["ok"] for part in results["parts"].values()) else 1


if __name__ == "__main__":
    sys.exit(main())
