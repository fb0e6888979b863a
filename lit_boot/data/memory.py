"""The memory a scene will take, checked before it is loaded rather than being killed by the OS.

The estimate for T frames of H x W px (what running the method on them holds at once):

- frames: T x H x W x 3 bytes (uint8 RGB);
- flows: 2 x (T-1) x 2 x H x W x 4 bytes (float32; RAFT's initial flow and the current one);
- RAFT's working memory: its all-pairs correlation pyramid for one pair, (h x w)^2 x 4 bytes
  x 4/3 with h, w the sides / 8 after padding to at least 128 px, three times over while
  fine-tuning (forward, gradient, pyramid), or the zoom stage's inference on a zoomed crop of up
  to four frames of pixels and at most :data:`ZOOM_PIXELS`, 1.6 times its pyramid (measured,
  RAFT-small on the CPU: 2.1 GiB at 1024 x 1024 px, 8.2 GiB at 1448 x 1448), whichever is
  larger; plus 256 MiB for the network and optimiser.

Available memory: ``MemAvailable`` of /proc/meminfo, else free pages x page size; unknown
means no check. ``LIT_BOOT_MEMORY_CHECK=0`` turns the check off.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

__all__ = ["MEMORY_CHECK_ENV", "ZOOM_PIXELS", "MemoryEstimate", "NotEnoughMemoryError", "available_memory",
           "check_memory", "estimate_memory", "format_bytes"]  # fmt: skip

MEMORY_CHECK_ENV = "LIT_BOOT_MEMORY_CHECK"
_MODEL_BASE = 256 * 2**20
_RAFT_MIN_SIDE = 128
_RESIZE_HEIGHTS = (1080, 720, 540, 480, 360, 288, 240, 180, 128)
#: The zoom stage's default limit on a zoomed crop's pixels (lit_boot.bootstrap.stage_configs.ZoomConfig's
#: max_pixels, spelled there too: the settings modules import nothing of the library's data layer).
ZOOM_PIXELS = 2**21


class NotEnoughMemoryError(ValueError):
    """A scene would not fit in the available memory; the message gives the figures and the way out."""


def available_memory() -> int | None:
    """Bytes of memory available now (MemAvailable, else free pages); None when unknown."""
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_AVPHYS_PAGES")
    except (AttributeError, OSError, ValueError):
        return None


@dataclass(frozen=True)
class MemoryEstimate:
    """Bytes for the frames, the flows and RAFT's working memory (module docstring)."""

    frames: int
    flows: int
    model: int

    @property
    def total(self) -> int:
        return self.frames + self.flows + self.model


def _pyramid_bytes(cells: int) -> int:
    """RAFT's all-pairs correlation pyramid for ``cells`` grid cells (1/8 of the pixels): cells^2
    float32 at the finest level, 4/3 of it over the levels."""
    return cells * cells * 4 * 4 // 3


def estimate_memory(num_frames: int, height: int, width: int) -> MemoryEstimate:
    """The estimate (module docstring) for ``num_frames`` frames of ``width`` x ``height`` px."""
    T, H, W = int(num_frames), int(height), int(width)
    cells = math.ceil(max(H, _RAFT_MIN_SIDE) / 8) * math.ceil(max(W, _RAFT_MIN_SIDE) / 8)
    zoom_cells = min(4 * H * W, ZOOM_PIXELS) // 64
    flows = 2 * max(T - 1, 0) * 2 * H * W * 4
    model = max(3 * _pyramid_bytes(cells), _pyramid_bytes(zoom_cells) * 8 // 5) + _MODEL_BASE
    return MemoryEstimate(frames=T * H * W * 3, flows=flows, model=model)


def format_bytes(n: float) -> str:
    """``n`` bytes in GiB, MiB or KiB (``"1.5 GiB"``, ``"791 MiB"``, ``"27 KiB"``)."""
    if n >= 2**30:
        return f"{n / 2**30:.1f} GiB"
    return f"{n / 2**20:.0f} MiB" if n >= 2**20 else f"{max(n / 2**10, 1):.0f} KiB"


def _suggestions(T: int, H: int, W: int, free: int) -> list[str]:
    """What would fit: a stride, a frame count, a height; each with its estimate."""
    need = lambda t, h, w: estimate_memory(t, h, w).total  # noqa: E731
    width = lambda h: max(1, round(W * h / H))  # noqa: E731
    stride = next((s for s in range(2, T + 1) if need(math.ceil(T / s), H, W) <= free), None)
    frames = max((t for t in range(2, T) if need(t, H, W) <= free), default=None)
    height = next((h for h in _RESIZE_HEIGHTS if h < H and need(T, h, width(h)) <= free), None)
    options = [("--stride", stride, (math.ceil(T / (stride or 1)), H, W)), ("--max_frames", frames, (frames, H, W)),
               ("--resize", height, (T, height, width(height or H)))]  # fmt: skip
    return [f"{flag} {value} (~{format_bytes(need(*size))})" for flag, value, size in options if value is not None]


def check_memory(where: object, num_frames: int, height: int, width: int, advice: str = "try") -> None:
    """Raise :class:`NotEnoughMemoryError` naming ``where`` when the estimate for the scene
    exceeds the available memory; ``advice`` introduces the options that would fit."""
    if os.environ.get(MEMORY_CHECK_ENV, "1").strip().lower() in ("0", "false", "no", "off"):
        return
    free = available_memory()
    need = estimate_memory(num_frames, height, width)
    if free is None or need.total <= free:
        return
    options = _suggestions(num_frames, height, width, free)
    way_out = f"{advice} {', '.join(options)}" if options else "use a machine with more memory"
    raise NotEnoughMemoryError(
        f"{where}: {num_frames} frames of {width}x{height} px need about {format_bytes(need.total)} of memory "
        f"(frames {format_bytes(need.frames)}, flows {format_bytes(need.flows)}, RAFT {format_bytes(need.model)}) "
        f"but {format_bytes(free)} is available; {way_out} (or set {MEMORY_CHECK_ENV}=0 to skip this check)"
    )
