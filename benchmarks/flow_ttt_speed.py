"""Seconds per FlowTTT training step and peak memory (forward + backward + Adam step).

Usage: python benchmarks/flow_ttt_speed.py [--device cpu|cuda] [--steps 3] [--precision 32|bf16]
Sizes: a 256x256 crop and a full Sintel frame (436x1024); raft_small and raft_large; 20 RAFT
updates per step (the authors' setting); batch size 1. Each size runs in a fresh process so the
peak memory is its own (CPU: peak resident set size of the process; CUDA: peak allocated).
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time

import torch
import torch.nn.functional as F

from lit_boot.flow import load_raft, predict_flow

CASES = [("raft_small", 256, 256), ("raft_small", 436, 1024), ("raft_large", 256, 256), ("raft_large", 436, 1024)]


def one(arch: str, height: int, width: int, device: str, steps: int, precision: str) -> dict:
    torch.manual_seed(0)
    model = load_raft(arch, None).to(device).train()
    opt = torch.optim.Adam(model.parameters(), lr=1e-5)
    a = torch.randint(0, 256, (1, 3, height, width), dtype=torch.uint8, device=device)
    b = torch.randint(0, 256, (1, 3, height, width), dtype=torch.uint8, device=device)
    target = torch.randn(1, 2, height, width, device=device)
    times = []
    for i in range(steps + 1):
        if device == "cuda":
            torch.cuda.synchronize()
        start = time.perf_counter()
        with torch.autocast(device_type=device, dtype=torch.bfloat16, enabled=precision == "bf16"):
            flow = predict_flow(model, a, b, num_flow_updates=20)
        loss = F.smooth_l1_loss(flow.float(), target)
        opt.zero_grad()
        loss.backward()
        opt.step()
        if device == "cuda":
            torch.cuda.synchronize()
        if i > 0:  # the first step warms up
            times.append(time.perf_counter() - start)
    peak = (
        torch.cuda.max_memory_allocated() / 2**20
        if device == "cuda"
        else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    )
    return {"arch": arch, "size": f"{height}x{width}", "s_per_step": sorted(times)[len(times) // 2], "peak_mib": peak}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    p.add_argument("--steps", type=int, default=3)
    p.add_argument("--precision", default="32", choices=["32", "bf16"])
    p.add_argument("--case", default=None, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.case:
        arch, h, w = args.case.split(":")
        print(json.dumps(one(arch, int(h), int(w), args.device, args.steps, args.precision)))
        return
    name = torch.cuda.get_device_name() if args.device == "cuda" else "CPU"
    print(f"device: {name}, torch {torch.__version__}, {torch.get_num_threads()} threads, precision {args.precision}")
    print("| arch | size | s/step | peak memory (MiB) |\n| --- | --- | --- | --- |")
    for arch, h, w in CASES:
        cmd = [sys.executable, __file__, "--case", f"{arch}:{h}:{w}", "--device", args.device,
               "--steps", str(args.steps), "--precision", args.precision]  # fmt: skip
        r = json.loads(subprocess.run(cmd, capture_output=True, text=True, check=True).stdout.strip().splitlines()[-1])
        print(f"| {r['arch']} | {r['size']} | {r['s_per_step']:.2f} | {r['peak_mib']:.0f} |", flush=True)


if __name__ == "__main__":
    main()
