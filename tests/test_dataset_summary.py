"""Tests for lit_boot.dataset.summary: the per-scene and pooled dataset rows, as markdown and CSV,
on hand-made records whose answers are known."""

from __future__ import annotations

import csv

import pytest

from lit_boot.dataset.summary import dataset_metrics, summary_rows, write_summary


def _states(epe: tuple[float, float], mpjpe: tuple[float, float], joints: tuple[float, float] | None = None):
    """A scene's states: (sum, count) of epe (px, pixels) and mpjpe_mm (mm, joints), optionally
    epe_joints."""
    out = {"epe": {"epe_sum": epe[0], "count": epe[1]}, "mpjpe_mm": {"error_sum": mpjpe[0], "count": mpjpe[1]}}
    if joints is not None:
        out["epe_joints"] = {"epe_sum": joints[0], "count": joints[1]}
    return out


RECORDS = [
    {"name": "a", "state": "done", "frames": 5, "seconds": 2.0, "error": None,
     "states": {"initial": _states((10.0, 5.0), (800.0, 10.0), (3.0, 2.0)),
                "final": _states((5.0, 5.0), (600.0, 10.0), (2.0, 2.0))}},
    {"name": "b", "state": "done", "frames": 3, "seconds": 1.5, "error": None,
     "states": {"initial": _states((6.0, 15.0), (100.0, 2.0)), "final": _states((3.0, 15.0), (110.0, 2.0))}},
    {"name": "c", "state": "failed", "frames": None, "seconds": 0.5, "error": "RuntimeError: out of | memory",
     "states": None},
    {"name": "d", "state": "pending", "frames": None, "seconds": None, "error": None, "states": None},
]  # fmt: skip


def test_dataset_metrics_pool_the_states_of_the_done_scenes():
    merged = dataset_metrics(RECORDS)
    # epe: a 10/5 = 2.0 and b 6/15 = 0.4; pooled 16/20 = 0.8, not their mean 1.2
    assert merged["initial"] == pytest.approx({"epe": 0.8, "epe_joints": 1.5, "mpjpe_mm": 900 / 12})
    assert merged["final"] == pytest.approx({"epe": 0.4, "epe_joints": 1.0, "mpjpe_mm": 710 / 12})
    b_failed = [RECORDS[0], RECORDS[1] | {"state": "failed"}]
    assert dataset_metrics(b_failed)["initial"]["epe"] == pytest.approx(2.0)  # only done scenes count
    assert dataset_metrics([]) == {"initial": {}, "final": {}}


def test_summary_rows_per_scene_and_dataset():
    rows = summary_rows(RECORDS)
    assert [row["name"] for row in rows] == ["a", "b", "c", "d", "dataset"]
    assert all(list(row) == list(rows[0]) for row in rows)  # the same columns everywhere
    assert list(rows[0])[:7] == ["name", "state", "frames", "seconds", "epe before", "epe after", "epe change %"]
    assert list(rows[0])[-1] == "error"
    a, b, c, d, dataset = rows
    assert a["epe before"] == 2.0 and a["epe after"] == 1.0 and a["epe change %"] == pytest.approx(-50.0)
    assert b["mpjpe_mm change %"] == pytest.approx(10.0)
    assert b["epe_joints before"] is None and b["epe_joints change %"] is None  # b has no joints EPE
    assert c["state"] == "failed" and c["error"] == "RuntimeError: out of | memory" and c["epe before"] is None
    assert d["state"] == "pending" and d["error"] is None and d["seconds"] is None
    assert dataset["state"] == "2/4 done" and dataset["frames"] == 8 and dataset["seconds"] == 4.0
    assert dataset["epe before"] == pytest.approx(0.8) and dataset["epe change %"] == pytest.approx(-50.0)
    assert dataset["mpjpe_mm after"] == pytest.approx(710 / 12)
    assert dataset["mpjpe_mm change %"] == pytest.approx(100 * (710 / 12 - 75) / 75)


def test_write_summary_markdown_and_csv(tmp_path):
    md_path, csv_path = write_summary(tmp_path / "run", RECORDS)
    assert (md_path, csv_path) == (tmp_path / "run" / "summary.md", tmp_path / "run" / "summary.csv")
    assert sorted(p.name for p in md_path.parent.iterdir()) == ["summary.csv", "summary.md"]  # no leftovers
    table = [line for line in md_path.read_text().splitlines() if line.startswith("|")]
    assert len(table) == 2 + len(RECORDS) + 1  # header, rule, one line per scene, the dataset row
    dataset = table[-1]
    assert dataset.startswith("| dataset | 2/4 done | 8 | 4.0 | 0.800 -> 0.400 (-50.0%) | 1.500 -> 1.000 (-33.3%) |")
    assert "| 75.0 -> 59.2 (-21.1%) |" in dataset
    assert "out of \\| memory" in table[4]  # the failed scene's error, its "|" escaped
    rows = summary_rows(RECORDS)
    with open(csv_path, newline="") as f:
        parsed = list(csv.DictReader(f))
    assert [list(row) for row in parsed] == [list(row) for row in rows]
    for row, back in zip(rows, parsed):
        for key, value in row.items():
            if value is None:
                assert back[key] == ""
            elif isinstance(value, str):
                assert back[key] == value
            else:
                assert float(back[key]) == value  # full precision
