"""lit_boot.data.flows: the one flow file format (a .flo folder or one .npz), written and read back."""

from __future__ import annotations

import pytest
import torch

from lit_boot.data import FlowSourceError, read_flows, write_flows, write_flows_npz


def test_flows_round_trip_in_both_formats_with_or_without_an_expected_size(tmp_path):
    flows = torch.randn(3, 2, 10, 12)
    write_flows(tmp_path / "flo", flows, png=False)
    write_flows_npz(tmp_path / "flows.npz", flows)
    for path in (tmp_path / "flo", tmp_path / "flows.npz"):
        torch.testing.assert_close(read_flows(path), flows)  # count and size from the files
        torch.testing.assert_close(read_flows(path, 3, 10, 12), flows)
        with pytest.raises(FlowSourceError, match=r"expected 4 flows|the pairs 0\.\.3"):
            read_flows(path, 4, 10, 12)


def test_a_folder_with_a_gap_or_no_flows_says_what_it_expected(tmp_path):
    write_flows(tmp_path / "gap", torch.zeros(3, 2, 4, 4), indices=[0, 2, 3], png=False)
    with pytest.raises(FlowSourceError, match=r"gap: expected 4 flows .*missing flow_000001\.flo"):
        read_flows(tmp_path / "gap")
    (tmp_path / "none").mkdir()
    with pytest.raises(FlowSourceError, match=r"none: expected flow_000000\.flo, .* found none"):
        read_flows(tmp_path / "none")
    with pytest.raises(FileNotFoundError, match="absent"):
        read_flows(tmp_path / "absent")
