"""metrics.png: every metric of a run per stage, drawn so that it does not mislead.

One panel per metric. Its title gives the change from before to after (the table's numbers,
:func:`~lit_boot.bootstrap.metric_history.before_after`) and whether that is better; its y label
the unit and which direction is better. The y axis spans at least :data:`MIN_RELATIVE_SPAN` of the
metric's size and :data:`MIN_SPAN` of its unit (:func:`y_limits`), so a change far below a
meaningful size is drawn small instead of as a steep climb. A stage without a value leaves a gap:
no line is drawn across it. With several people, the pooled and per-person values of a metric
(``kp2d_px_all``, ``epe_person_person2``) are dashed lines in its panel. Rendered with
Matplotlib's Agg canvas (pyplot is untouched).
"""

from __future__ import annotations

import io
import math
import os
from collections.abc import Sequence
from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from ..data.atomic import atomic_write_bytes
from ..metrics import base_metric_name
from ..metrics.suite import PERSON_SUFFIX, POOLED_SUFFIX
from .metric_history import NEUTRAL_METRICS, NOT_METRICS, before_after, change_text, stage_series, unit, verdict

__all__ = ["plot_history", "history_figure", "y_limits", "MIN_SPAN", "MIN_RELATIVE_SPAN"]

#: The smallest y span of a panel per unit: a change far below this is not worth a panel's height.
MIN_SPAN = {"px": 0.01, "mm": 1.0, "mm/frame²": 1.0, "of 48": 0.1, "": 0.01}
#: ... and at least this share of the metric's largest |value|: a 20% change fills the panel.
MIN_RELATIVE_SPAN = 0.2
_PAD = 0.08  # of the span, above and below
_COLOURS = {"better": "#1a6b2a", "worse": "#b3261e"}


def y_limits(values: Sequence[float], unit_name: str) -> tuple[float, float]:
    """(bottom, top) of a panel showing ``values`` (NaN ignored) in ``unit_name``: the values'
    range, widened about its middle to at least :data:`MIN_SPAN` of the unit and
    :data:`MIN_RELATIVE_SPAN` of the largest |value|, padded by 8%; never below -pad for
    values that are all >= 0 (errors start at 0)."""
    finite = [v for v in values if math.isfinite(v)]
    if not finite:
        return 0.0, 1.0
    low, high = min(finite), max(finite)
    span = max(high - low, MIN_SPAN.get(unit_name, MIN_SPAN[""]), MIN_RELATIVE_SPAN * max(abs(low), abs(high)))
    middle, pad = (low + high) / 2, _PAD * span
    bottom, top = middle - span / 2 - pad, middle + span / 2 + pad
    if low >= 0 and bottom < -pad:
        bottom, top = -pad, top + (-pad - bottom)
    return bottom, top


def _title(metric: str, history: Sequence[dict]) -> tuple[str, str]:
    """The panel title ("epe: -4.5%, better") and its colour."""
    values = before_after(history)
    if metric not in values:
        return metric, "black"
    a, b = values[metric]
    text, word = change_text(metric, a, b), verdict(metric, a, b)
    title = f"{metric}: {text}" + (f", {word}" if word and word != "unchanged" else "")
    return title, _COLOURS.get(word, "black")


def _panels(series: dict[str, list[float]]) -> tuple[dict[str, list[float]], dict[str, list[tuple[str, list]]]]:
    """The panels' series (one per metric) and, per panel, the pooled and per-person series of
    a scene with several people (drawn in their metric's panel, labelled "all" or "person <id>")."""
    panels: dict[str, list[float]] = {}
    people: dict[str, list[tuple[str, list]]] = {}
    for name, ys in series.items():
        base = base_metric_name(name)
        if base == name:
            panels[name] = ys
            continue
        panels.setdefault(base, [math.nan] * len(ys))
        label = "all people" if name.endswith(POOLED_SUFFIX) else "person " + name.rsplit(PERSON_SUFFIX, 1)[1]
        people.setdefault(base, []).append((label, ys))
    return panels, people


def history_figure(history: Sequence[dict], title: str = "Metrics per stage") -> Figure:
    """The figure of :func:`plot_history` (see there)."""
    if not history:
        raise ValueError("plot_history: empty history, nothing to plot")
    stages: list[str] = []
    for i, record in enumerate(history):
        if not isinstance(record, dict) or "stage" not in record:
            raise ValueError(f"plot_history: history[{i}] is not a dict with a 'stage' key: {record!r}")
        stages.append(str(record["stage"]) + ("\n(rolled back)" if record.get("rolled_back") else ""))
    series, people = _panels(stage_series(history))
    if not series:
        raise ValueError(f"plot_history: no metrics in the history (no numeric values besides {NOT_METRICS})")
    cols = min(3, len(series))
    rows = math.ceil(len(series) / cols)
    width = max(3.8, 0.6 * len(stages) + 1.6)
    fig = Figure(figsize=(width * cols, 3.0 * rows + 0.5), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    fig.suptitle(f"{title}: change from before (initial: RAFT's flow, the input poses) to after (each metric's "
                 "last kept stage)", fontsize=11)  # fmt: skip
    tilt = len(stages) > 3
    for n, (name, ys) in enumerate(series.items()):
        ax = fig.add_subplot(rows, cols, n + 1)
        ax.plot(range(len(stages)), ys, marker="o", linestyle="-", label="main person" if people.get(name) else None)
        for label, values in people.get(name, []):  # NaN: a gap, no line across it
            ax.plot(range(len(stages)), values, marker=".", linestyle="--", linewidth=1, label=label)
        if people.get(name):
            ax.legend(fontsize=7)
        text, colour = _title(name, history)
        ax.set_title(text, color=colour, fontsize=10)
        direction = "a diagnostic" if name in NEUTRAL_METRICS else "lower is better"
        ax.set_ylabel(f"{unit(name)} · {direction}" if unit(name) else direction, fontsize=9)
        ax.set_ylim(*y_limits([*ys, *(v for _, values in people.get(name, []) for v in values)], unit(name)))
        ax.set_xticks(range(len(stages)), stages, rotation=30 if tilt else 0, ha="right" if tilt else "center")
        ax.set_xlim(-0.5, len(stages) - 0.5)
        ax.grid(True, alpha=0.3)
    return fig


def plot_history(history: Sequence[dict], path: str | os.PathLike, title: str = "Metrics per stage") -> Path:
    """Plot the metrics of a bootstrap run per stage into a PNG at ``path`` (atomically); returns
    the path.

    ``history``: records in run order (see :mod:`~lit_boot.bootstrap.metric_history`), each with
    "stage" (the x tick label; "(rolled back)" added to a rolled-back one). A metric that is
    missing, None or not finite in a record leaves a gap there. One panel per metric (up to 3 per
    row), in order of first appearance; see the module doc for the titles and axes. Raises
    ValueError naming ``path`` for an empty history, a record without "stage", or no metric.
    """
    path = Path(path)
    try:
        fig = history_figure(history, title)
    except ValueError as err:
        raise ValueError(f"plot_history({path}): {str(err).removeprefix('plot_history: ')}") from None
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    return atomic_write_bytes(path, buffer.getvalue())
