"""A dataset run's summary: one row per scene and a last ``dataset`` row, as markdown and CSV.

Input: per-scene records, dicts ``{"name", "state" ("done", "failed", "pending", ...),
"frames" (int | None), "seconds" (float | None), "error" (str | None), "states": {"initial":
<states>, "final": <states>} | None}`` where ``<states>`` is a
:func:`~lit_boot.metrics.scene_metric_states` dict. The dataset row pools the metric states of
the scenes that are done (every pixel / joint of every scene weighs the same), it does not
average the scenes' values.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ..data.atomic import atomic_write_bytes
from ..metrics import METRIC_NAMES, compute_metric_states, merge_metric_states, metric_person

__all__ = ["dataset_metrics", "summary_records", "summary_rows", "summary_markdown", "summary_csv", "write_summary"]

Record = dict[str, Any]
_STAGES = ("initial", "final")


def summary_records(tasks: dict[str, dict[str, Any]]) -> list[Record]:
    """The per-scene records (see the module doc) of a manifest's ``tasks`` ({name: manifest
    record}), in order; chunks are left out (their scene's record holds the stitched result)."""
    records = []
    for name, record in tasks.items():
        if record["task"].get("parent"):
            continue
        result = record.get("result") or {}
        records.append({"name": name, "state": record["state"], "frames": result.get("frames"),
                        "seconds": result.get("seconds"), "error": record.get("error"),
                        "states": result.get("states")})  # fmt: skip
    return records


def _counted(record: Record) -> bool:
    """Whether the record's states enter the dataset metrics: done, with states."""
    return record.get("state") == "done" and bool(record.get("states"))


def dataset_metrics(records: Sequence[Record]) -> dict[str, dict[str, float]]:
    """{"initial": {metric: value}, "final": {metric: value}}, pooled over the records that are
    done and have states."""
    counted = [record["states"] for record in records if _counted(record)]
    return {stage: compute_metric_states(merge_metric_states(s.get(stage) or {} for s in counted)) for stage in _STAGES}


def _scene_metrics(record: Record) -> dict[str, dict[str, float]]:
    """The record's own {"initial": ..., "final": ...} values ({} per missing stage)."""
    states = record.get("states") or {}
    return {stage: compute_metric_states(states.get(stage) or {}) for stage in _STAGES}


def _change(before: float | None, after: float | None) -> float | None:
    """100 * (after - before) / before, None where undefined."""
    if before is None or after is None or before == 0 or not math.isfinite(before):
        return None
    return 100.0 * (after - before) / before


def _metric_columns(values: dict[str, dict[str, float]], names: Sequence[str]) -> dict[str, float | None]:
    row: dict[str, float | None] = {}
    for name in names:
        before, after = values["initial"].get(name), values["final"].get(name)
        row |= {f"{name} before": before, f"{name} after": after, f"{name} change %": _change(before, after)}
    return row


def _ordered(names: set[str]) -> list[str]:
    """Metric names in reporting order (unknown ones last, sorted), without the per-person ones
    (``..._person<id>``: a track id names a person of one scene only; the pooled ``_all`` stay)."""
    names = {n for n in names if metric_person(n) is None}
    return [n for n in METRIC_NAMES if n in names] + sorted(names - set(METRIC_NAMES))


def summary_rows(records: Sequence[Record]) -> list[dict[str, Any]]:
    """One row per record, then a ``dataset`` row (the pooled metrics). Columns, the same in
    every row: name, state, frames, seconds; "<metric> before" / "after" / "change %" for each
    metric any row has; error. Missing values are None. A scene row shows the scene's own states
    whatever its state; the dataset row's frames count the merged scenes, its seconds all."""
    per_scene = [_scene_metrics(record) for record in records]
    pooled = dataset_metrics(records)
    names = _ordered({n for values in [*per_scene, pooled] for stage in values.values() for n in stage})
    rows = []
    for record, values in zip(records, per_scene):
        row = {key: record.get(key) for key in ("name", "state", "frames", "seconds")}
        rows.append(row | _metric_columns(values, names) | {"error": record.get("error")})
    counted = [record for record in records if _counted(record)]
    frames = [r["frames"] for r in counted if r.get("frames") is not None]
    seconds = [r["seconds"] for r in records if r.get("seconds") is not None]
    totals = {"frames": sum(frames) if frames else None, "seconds": sum(seconds) if seconds else None}
    rows.append({"name": "dataset", "state": f"{len(counted)}/{len(records)} done"} | totals
                | _metric_columns(pooled, names) | {"error": None})  # fmt: skip
    return rows


def _number(name: str, value: float | None) -> str:
    """A value of metric ``name``: EPE to 3 decimals, mm / px to 1."""
    if value is None:
        return "-"
    return f"{value:.3f}" if name.startswith("epe") else f"{value:.1f}"


def _cell(row: dict[str, Any], column: str) -> str:
    """A markdown cell: a metric as "before -> after (+1.2%)", text with ``|`` escaped."""
    if f"{column} before" in row:
        before, after, change = (row[f"{column} {k}"] for k in ("before", "after", "change %"))
        if before is None and after is None:
            return ""
        text = f"{_number(column, before)} -> {_number(column, after)}"
        return text + (f" ({change:+.1f}%)" if change is not None else "")
    value = row[column]
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.1f}"
    return str(value).replace("|", "\\|").replace("\n", " ")


def summary_markdown(rows: Sequence[dict[str, Any]]) -> str:
    """The rows as a markdown table (header, rule, one line per row): a column per metric, each
    cell "before -> after (change)"; the error column only when a row has an error."""
    metrics = [c[: -len(" before")] for c in rows[0] if c.endswith(" before")]
    columns = ["name", "state", "frames", "seconds", *metrics] + (["error"] if any(r.get("error") for r in rows) else [])
    lines = ["| " + " | ".join(columns) + " |", "|" + "|".join("---" for _ in columns) + "|"]
    lines += ["| " + " | ".join(_cell(row, c) for c in columns) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def summary_csv(rows: Sequence[dict[str, Any]]) -> str:
    """The rows as CSV (header first; floats at full precision, None as an empty cell)."""
    buffer = io.StringIO(newline="")
    writer = csv.DictWriter(buffer, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows({key: "" if value is None else value for key, value in row.items()} for row in rows)
    return buffer.getvalue()


def write_summary(folder: Path, records: Sequence[Record]) -> tuple[Path, Path]:
    """Write ``folder``/summary.md and ``folder``/summary.csv (each atomically); returns their
    paths (md, csv)."""
    rows = summary_rows(records)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    md = atomic_write_bytes(folder / "summary.md", summary_markdown(rows).encode())
    table = atomic_write_bytes(folder / "summary.csv", summary_csv(rows).encode())
    return md, table
