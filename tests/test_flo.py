from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from lit_boot.data.flo import read_flo, write_flo


@pytest.fixture
def sintel_flows(shared: Path) -> list[Path]:
    """The Sintel .flo samples in ../shared (the conftest's ``shared`` skips when it is absent)."""
    sintel = shared / "data" / "sintel_samples"
    files = sorted(sintel.glob("training/flow/*/frame_*.flo"))
    assert files, f"no training/flow/*/frame_*.flo files under {sintel}"
    return files


def test_round_trip_exact(tmp_path: Path) -> None:
    flow = torch.randn(2, 7, 11) * 50
    path = write_flo(tmp_path / "a.flo", flow)
    back = read_flo(path)
    assert back.dtype == torch.float32 and back.shape == (2, 7, 11)
    assert torch.equal(back, flow)
    assert path.stat().st_size == 12 + 8 * 7 * 11
    assert [p.name for p in tmp_path.iterdir()] == ["a.flo"]  # no temporary file left


def test_layout_is_interleaved_u_v(tmp_path: Path) -> None:
    flow = torch.zeros(2, 2, 3)
    flow[0, 1, 2] = 5.0  # u at row 1, column 2
    flow[1, 0, 1] = -3.0  # v at row 0, column 1
    path = write_flo(tmp_path / "b.flo", flow)
    raw = np.fromfile(path, dtype="<f4", offset=12).reshape(2, 3, 2)
    assert raw[1, 2, 0] == 5.0 and raw[0, 1, 1] == -3.0
    assert np.fromfile(path, dtype="<i4", count=3)[1:].tolist() == [3, 2]  # width, height


def test_write_replaces_existing_file(tmp_path: Path) -> None:
    path = tmp_path / "c.flo"
    write_flo(path, torch.ones(2, 4, 4))
    write_flo(path, torch.full((2, 3, 5), 2.0))
    assert torch.equal(read_flo(path), torch.full((2, 3, 5), 2.0))


@pytest.mark.parametrize("shape", [(4, 5, 2), (3, 4, 5), (2, 4), (2, 0, 4)])
def test_write_rejects_bad_shape(tmp_path: Path, shape: tuple[int, ...]) -> None:
    with pytest.raises(ValueError, match=r"\(2, H, W\)"):
        write_flo(tmp_path / "d.flo", torch.zeros(shape))
    assert not any(tmp_path.iterdir())


def test_write_rejects_integer_flow(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="floating"):
        write_flo(tmp_path / "e.flo", torch.zeros(2, 3, 3, dtype=torch.int32))


@pytest.mark.shared
def test_sintel_files(sintel_flows: list[Path]) -> None:
    for path in sintel_flows:
        flow = read_flo(path)
        assert flow.shape == (2, 436, 1024), path
        assert flow.dtype == torch.float32
        assert torch.isfinite(flow).all(), path
        assert flow.abs().max() > 0, path


@pytest.mark.shared
def test_truncated_file(tmp_path: Path, sintel_flows: list[Path]) -> None:
    source = sintel_flows[0]
    cut = tmp_path / "cut.flo"
    cut.write_bytes(source.read_bytes()[:100_000])
    with pytest.raises(ValueError, match="cut.flo") as info:
        read_flo(cut)
    message = str(info.value)
    assert "truncated" in message and str(12 + 8 * 436 * 1024) in message and "100000" in message


def test_truncated_or_padded_own_file(tmp_path: Path) -> None:
    data = write_flo(tmp_path / "full.flo", torch.randn(2, 5, 6)).read_bytes()
    (tmp_path / "short.flo").write_bytes(data[:-4])
    with pytest.raises(ValueError, match=f"short.flo.*truncated.*expected {len(data)} bytes.*found {len(data) - 4}"):
        read_flo(tmp_path / "short.flo")
    (tmp_path / "long.flo").write_bytes(data + bytes(8))
    with pytest.raises(ValueError, match=f"long.flo.*trailing.*expected {len(data)} bytes.*found {len(data) + 8}"):
        read_flo(tmp_path / "long.flo")


def test_foreign_file(tmp_path: Path) -> None:
    foreign = tmp_path / "image.flo"
    foreign.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(100))
    with pytest.raises(ValueError, match="image.flo.*not a Middlebury .flo.*magic"):
        read_flo(foreign)


def test_tiny_and_corrupted_header(tmp_path: Path) -> None:
    tiny = tmp_path / "tiny.flo"
    tiny.write_bytes(b"PIE")
    with pytest.raises(ValueError, match="tiny.flo"):
        read_flo(tiny)
    bad = tmp_path / "bad.flo"
    bad.write_bytes(np.array([202021.25], "<f4").tobytes() + np.array([-4, 3], "<i4").tobytes())
    with pytest.raises(ValueError, match="bad.flo.*width -4"):
        read_flo(bad)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="nothere.flo"):
        read_flo(tmp_path / "nothere.flo")
