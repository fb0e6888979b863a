"""benchmarks/gpu_check.py, the script a CUDA machine runs once (issue 26): without CUDA it refuses
in one line and writes nothing; its parts work (checked on the CPU at toy sizes, --cpu-smoke)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "benchmarks" / "gpu_check.py"


def run(*args: str, tmp: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "CUDA_VISIBLE_DEVICES": "", "OMP_NUM_THREADS": "1"}  # no GPU, even on a GPU machine
    return subprocess.run([sys.executable, str(SCRIPT), *args], cwd=tmp, env=env, capture_output=True, text=True,
                          timeout=900)  # fmt: skip


def test_without_cuda_it_refuses_and_writes_nothing(tmp_path) -> None:
    done = run("--out", str(tmp_path / "gpu.json"), tmp=tmp_path)
    assert done.returncode == 2
    assert done.stderr.strip() == ("gpu_check: needs a CUDA device (torch.cuda.is_available() is False here); "
                                   "nothing was run or written")  # fmt: skip
    assert not any(tmp_path.iterdir())


def test_its_parts_run_and_write_one_results_file(tmp_path) -> None:
    out = tmp_path / "results" / "gpu.json"
    done = run("--cpu-smoke", "--parts", "mixed_precision,resume,speed", "--out", str(out), tmp=tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    results = json.loads(out.read_text())
    assert results["format"] == "lit-boot-gpu-check" and results["smoke"] and "smoke check" in results["device"]
    parts = results["parts"]
    assert all(parts[name]["ok"] for name in ("mixed_precision", "resume", "speed")), parts
    assert set(parts["mixed_precision"]) >= {"bf16-mixed", "32-true"}
    assert all(parts["mixed_precision"][p]["finite"] for p in ("bf16-mixed", "32-true"))
    resume = parts["resume"]
    assert resume["killed_after_flow_1"] and "flow_1" in resume["stages_done_when_killed"]
    assert resume["bit_exact"] and resume["epe_resumed"] == resume["epe_whole"]  # on the CPU: the same result
    assert all(parts["speed"][mode]["ratio_to_raft"] > 0 for mode in ("3d", "2d"))
    assert run("--cpu-smoke", "--parts", "nope", "--out", str(out), tmp=tmp_path).returncode == 2
