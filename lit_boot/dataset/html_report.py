"""A dataset run's report.html: the pooled metrics and one row per scene, linking each scene's
own report (:mod:`lit_boot.bootstrap.html_report`); self-contained, like the scenes' reports.

:func:`write_dataset_report` writes it from the dataset folder (manifest.json); with
``scene_reports`` it first writes the report of every finished scene that has none, reading the
scene again from its task when its run folder names no scene folder (a video's frames, a
dataset reader's scene: its pose estimates are made again, as the run made them).
"""

from __future__ import annotations

import json
import logging
import math
import os
from pathlib import Path
from typing import Any

from ..bootstrap.html_parts import Markup, esc, link, page, table
from ..bootstrap.html_report import REPORT_HTML, write_report
from ..data.atomic import atomic_write_bytes
from .manifest import MANIFEST_JSON
from .summary import summary_records, summary_rows
from .tasks import Task
from .worker import task_files

__all__ = ["write_dataset_report"]

log = logging.getLogger(__name__)


def _manifest(out: Path) -> dict[str, Any]:
    path = out / MANIFEST_JSON
    if not path.is_file():
        raise FileNotFoundError(f"{out}: no {MANIFEST_JSON} (not a lit-boot dataset run folder)")
    return json.loads(path.read_text())


def _scene_report(out: Path, name: str, record: dict[str, Any], **options: Any) -> str | None:
    """Write task ``name``'s report if it is done and has none; None, or why it has no report."""
    run_dir = task_files(out, name)[0]
    if (run_dir / REPORT_HTML).is_file():
        return None
    if record["state"] != "done" or not (run_dir / "summary.json").is_file():
        return "not finished" if record["state"] != "done" else "a stitched scene: see its chunks"
    summary = json.loads((run_dir / "summary.json").read_text())
    scene = None if Path(str(summary.get("scene", ""))).is_dir() else Task.from_dict(record["task"]).load()
    log.info("report: %s", run_dir / REPORT_HTML)
    write_report(run_dir, scene, **options)
    return None


def _link(out: Path, name: str) -> str:
    """The relative link to task ``name``'s report ("" if it has none)."""
    path = task_files(out, name)[0] / REPORT_HTML
    return path.relative_to(out).as_posix() if path.is_file() else ""


def _cell(row: dict[str, Any], metric: str) -> str:
    before, after, change = (row.get(f"{metric} {k}") for k in ("before", "after", "change %"))
    if before is None and after is None:
        return ""
    number = (lambda v: "-" if v is None or not math.isfinite(v) else f"{v:.3g}")  # noqa: E731
    return f"{number(before)} → {number(after)}" + (f" ({change:+.1f}%)" if change is not None else "")


def write_dataset_report(
    out: str | os.PathLike, *, scene_reports: bool = True, max_pairs: int = 8, panel_width: int = 320
) -> Path:
    """Write ``out``/report.html for the dataset run in ``out`` (atomically); returns its path.
    ``scene_reports``: first write the missing reports of the finished scenes (and chunks); a
    scene whose report cannot be written is listed with the reason. Metric cells read
    "before → after (change)"; lower is better for every metric but drift_px."""
    out = Path(out)
    tasks = _manifest(out)["tasks"]
    why: dict[str, str] = {}
    if scene_reports:
        for name, record in tasks.items():
            if "chunks" in record:
                continue
            try:
                reason = _scene_report(out, name, record, max_pairs=max_pairs, panel_width=panel_width)
            except Exception as err:  # one scene's report failing leaves the others
                reason = f"{type(err).__name__}: {err}"
                log.warning("report of %s: %s", name, reason)
            if reason:
                why[name] = reason
    rows = summary_rows(summary_records(tasks))
    metrics = [c[: -len(" before")] for c in rows[0] if c.endswith(" before")]
    cells = []
    for row in rows:
        name = row["name"]
        chunks = tasks.get(name, {}).get("chunks", [])
        links = [(c, _link(out, c)) for c in chunks] if chunks else [(name, _link(out, name))]
        report = Markup(", ".join(link(href, c) if href else esc(f"{c}: {why.get(c, 'no report')}")
                                  for c, href in links))  # fmt: skip
        metric_cells = [(_cell(row, m), "") for m in metrics]
        cells.append([(name, ""), (str(row["state"]), ""), (str(row.get("frames") or ""), ""), *metric_cells,
                      ("" if name == "dataset" else report, "")])  # fmt: skip
    head = ["scene", "state", "frames", *metrics, "report"]
    html = table(head, cells, left=(0, len(head) - 1))
    body = (f"<h1>lit-boot dataset report: {esc(out.name)}</h1><p class=\"note\">Each metric: before → after "
            "(change), lower is better (drift_px: a diagnostic). The dataset row pools every pixel and joint of the "
            f"finished scenes. Each scene's own report shows where its flow changed and whether the frames "
            f"support it.</p>{html}")  # fmt: skip
    return atomic_write_bytes(out / REPORT_HTML, page(f"lit-boot dataset report: {out.name}", body).encode())

