"""report.html: one self-contained page (images inlined, no network) that shows whether a run
made its video better, built from the finished run folder alone (:func:`write_report`).

From the top: what the ground truth says (when there is one) and what the frames say, in
sentences with how sure they are (:mod:`~lit_boot.bootstrap.verdict`); every metric before and
after, its change and which direction is better; what each stage decided (the zoom stage: pairs
zoomed, scales, where its flow was kept; the flow stages: painted, kept); the metrics plot;
then, for up to ``max_pairs`` pairs evenly spaced, the frame with both skeletons, RAFT's flow and
the final flow, the change between them, the census error of each flow and its change, the
decision map, and with GT the end-point error maps (:mod:`~lit_boot.bootstrap.pair_maps`); last,
every pair's numbers. Each image has its legend under it; one kind of map shares one scale.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..core import Scene
from ..data.atomic import atomic_write_bytes
from ..data.visualize import flow_image
from .decisions import decision_key, decision_summary
from .finished import FinishedRun, read_run
from .guard import guard_text
from .html_parts import colour_bar, esc, img, page, swatches, table
from .pair_maps import DIVERGING, SEQUENTIAL, Scales, pair_maps, pair_panels, pair_stats, pick_pairs, shared_scales
from .report import metric_rows
from .verdict import EvidenceTally, evidence_sentence, gt_sentence, ids_sentence

__all__ = ["write_report", "render_report", "REPORT_HTML"]

REPORT_HTML = "report.html"


def write_report(
    run_dir: str | os.PathLike,
    scene: Scene | str | os.PathLike | None = None,
    *,
    max_pairs: int = 8,
    panel_width: int = 320,
    ensembled: bool = False,
) -> Path:
    """Write ``run_dir``/report.html (atomically) for the finished run there; returns its path.

    ``scene`` (a Scene or a scene folder) gives the frames, initial poses and GT when summary.json
    names no scene folder (a run from a video or a Scene object); without either, the report
    shows the flows, their change and the decisions only, and says so. ``max_pairs``: pairs
    pictured (evenly spaced; the table lists all); ``panel_width``: px per picture at most;
    ``ensembled``: ``scene``'s estimates already hold the run's pose ensemble (else averaged in).
    """
    if max_pairs < 1 or panel_width < 16:
        raise ValueError(f"write_report: expected max_pairs >= 1 and panel_width >= 16, got {max_pairs}, {panel_width}")
    run = read_run(run_dir, scene, ensembled=ensembled)
    return atomic_write_bytes(run.run_dir / REPORT_HTML, render_report(run, max_pairs, panel_width).encode())


def _number(value: float | None, digits: int = 3) -> str:
    return "" if value is None or not math.isfinite(value) else f"{value:.{digits}g}"


def _pct(value: float | None) -> str:
    return "" if value is None or not math.isfinite(value) else f"{value:+.1f}%"


def _header(run: FinishedRun) -> str:
    summary, config = run.summary, run.summary.get("config", {})
    T = run.flows.shape[0] + 1
    H, W = run.flows.shape[-2:]
    name = run.scene.name if run.scene is not None else str(summary.get("scene", "?"))
    stages = " → ".join(r["stage"] + (" (rolled back)" if r.get("rolled_back") else "") for r in run.history)
    seconds = summary.get("speed", {}).get("total_s")
    took = f" · {seconds:.0f} s" if isinstance(seconds, (int, float)) else ""
    meta = (f"{T} frames, {W}x{H} px · {run.mode} mode, preset {config.get('preset', '?')} · "
            f"{summary.get('device', '?')}, {summary.get('precision', '?')}{took} · stages: {stages}")
    why = summary.get("plan", {}).get("why")
    meta += f" · what ran and why: {why}" if why else ""
    return (f"<h1>lit-boot run report: {esc(name)}</h1><p class=\"meta\">{esc(meta)}<br>run folder "
            f"{esc(str(run.run_dir))} · lit-boot {esc(str(summary.get('lit_boot', '?')))}</p>")  # fmt: skip


def _metrics_section(run: FinishedRun) -> str:
    rows = []
    for row in metric_rows(run.history):
        rows.append([(row["metric"], ""), (row["unit"], ""), (_number(row["before"], 4), ""),
                     (_number(row["after"], 4), ""), (_pct(row["change_pct"]), row["verdict"]),
                     (row["verdict"], row["verdict"]),
                     (f"{row['better']} is better" if row["better"] != "neither" else "neither (a diagnostic)", ""),
                     (row["meaning"], "")])  # fmt: skip
    head = ["metric", "unit", "before", "after", "change", "verdict", "direction", "what it measures"]
    plot = run.run_dir / "metrics.png"
    picture = ""
    if plot.is_file():
        import cv2

        image = cv2.imread(str(plot), cv2.IMREAD_COLOR)
        if image is not None:
            picture = "<h3>Per stage</h3>" + img(cv2.cvtColor(image, cv2.COLOR_BGR2RGB), "metrics per stage", "plot")
    note = ("Before: the initial stage (pretrained RAFT's flow, the input poses); after: each metric's last stage "
            "that was kept. % change is after against before.")  # fmt: skip
    return (f"<h2 id=\"metrics\">Metrics, before and after</h2>{table(head, rows, left=(0, 7))}"
            f"<p class=\"note\">{esc(note)}</p>{picture}")


def _zoom_record(run: FinishedRun) -> dict[str, Any] | None:
    """The zoom stage's record, None without one."""
    return next((r for r in run.history if r.get("kind") == "zoom"), None)


def _span(values: list[float], unit: str) -> str:
    return "" if not values else f"{min(values):.3g}{unit}" + (f"–{max(values):.3g}{unit}" if max(values) > min(values)
                                                                else "")  # fmt: skip


def _zoom_table(record: dict[str, Any], pairs: int) -> str:
    """The zoom stage's decisions: pairs zoomed, their scales and motion, where its flow was kept, its cost."""
    zoom = record.get("info", {}).get("zoom", {})
    zoomed = [p for p in zoom.get("per_pair", []) if p.get("region") is not None]
    kept = zoom.get("kept_fraction")
    row = [(record["stage"], ""), (f"{zoom.get('zoomed_pairs', len(zoomed))} of {pairs}", ""),
           (_span([p["scale"] for p in zoomed], "x"), ""), (_span([p["motion_px"] for p in zoomed], " px"), ""),
           ("" if kept is None else f"{100 * kept:.1f}%", ""),
           (_number(zoom.get("cost")), ""), ("yes", "worse") if record.get("rolled_back") else ("no", "")]  # fmt: skip
    head = ["zoom stage", "pairs zoomed", "scale", "motion (p95 on the box)", "pixels keeping the zoomed flow",
            "cost (RAFT passes)", "rolled back"]  # fmt: skip
    return (f"<h3>The zoom stage</h3>{table(head, [row])}<p class=\"note\">RAFT again on a zoomed crop around the "
            "person; its flow is kept only where it refines RAFT's and the frames do not refuse it. Per pair: "
            "the table at the end.</p>")  # fmt: skip


def _guard_part(run: FinishedRun) -> str:
    """The guards' events (a stage that made its image evidence worse, a non-finite value), in words."""
    actions = {"record": "recorded, the run went on", "stop": "the run stopped", "rollback": "rolled back, the run stopped"}
    events = [(r["stage"], r["guard"]) for r in run.history if "guard" in r]
    lines = [f"{stage}: {guard_text(g) if g.get('guard') == 'drift' else 'a non-finite value'} "
             f"({actions.get(g.get('action'), g.get('action'))})" for stage, g in events]  # fmt: skip
    text = "; ".join(lines) if lines else "no stage made its image evidence worse"
    return f"<h3>The drift guard</h3><p class=\"note\">{esc(text)}.</p>"


def _decisions_section(run: FinishedRun) -> str:
    zoom = _zoom_record(run)
    entries = [e for e in decision_summary(run.history) if zoom is None or e["stage"] != zoom["stage"]]
    if not entries and zoom is None:
        return ""

    def share(value: Any) -> str:
        return "" if value is None else f"{100 * float(value):.1f}%"

    rows = [[(e["stage"], ""), (share(e["painted_fraction"]), ""), (share(e["gate_kept_fraction"]), ""),
             (f"{e['bones_rejected']:.0f}", ""), (share(e["kept_tuned_fraction"]), ""),
             (share(e["person_tuned_fraction"]), ""),
             ("yes", "worse") if e["rolled_back"] else ("no", "")] for e in entries]  # fmt: skip
    head = ["flow stage", "pixels painted", "sketch kept by the gate", "bones rejected",
            "pixels keeping the tuned flow", "of the person", "rolled back"]  # fmt: skip
    zoom_part = _zoom_table(zoom, run.flows.shape[0]) if zoom is not None else ""
    flow_part = f"<h3>The flow stages</h3>{table(head, rows)}" if rows else ""
    return f"<h2 id=\"decisions\">What each stage decided</h2>{zoom_part}{flow_part}{_guard_part(run)}"


def _wheel(scale: float, size: int = 56) -> np.ndarray:
    """A flow colour wheel: the colour of a vector from the centre, full colour at ``scale`` px."""
    y, x = np.mgrid[:size, :size].astype(np.float32) - (size - 1) / 2
    vectors = torch.from_numpy(np.stack([x, y]) * (2 * scale / size))
    wheel = flow_image(vectors, max_magnitude=scale).permute(1, 2, 0).numpy().copy()
    wheel[x**2 + y**2 > (size / 2) ** 2] = 255
    return wheel


def _legend(key: str, scales: Scales, zoom: bool = False) -> str:
    """The legend under a picture of kind ``key`` (``zoom``: the decision map has the zoom's colour)."""
    if key == "poses":
        return swatches((((255, 0, 0), "before (input)"), ((0, 255, 0), "after (refined)")))
    if key == "decisions":
        return swatches(decision_key(zoom))
    if key == "flow":
        return (f'<div class="bar">{img(_wheel(scales.flow, 28), "flow colour wheel")}<span>hue = direction, white = '
                f"still, full colour at {scales.flow:.2g} px and beyond</span></div>")  # fmt: skip
    value = getattr(scales, key)
    if key in ("census_change", "epe_change"):
        unit = "px" if key == "epe_change" else "of 48"
        return colour_bar(DIVERGING, f"-{value:g}", f"+{value:g} {unit}",
                          "blue: lower with the final flow (better); red: higher")  # fmt: skip
    unit = "of 48 (census)" if key == "census" else "px"
    note = "grey: not defined" if key != "change" else ""
    return colour_bar(SEQUENTIAL[key.split("_")[0]], "0", f"{value:g} {unit}", note)


def _pair_section(run: FinishedRun, t: int, panels: list, stats: dict[str, float], scales: Scales, width: int) -> str:
    parts = [f"changed {100 * stats['changed']:.1f}% of the pixels"]
    if math.isfinite(stats["census_raft"]):
        parts.append(f"census error {stats['census_raft']:.2f} → {stats['census_final']:.2f}")
    if math.isfinite(stats["epe_raft"]):
        parts.append(f"EPE {stats['epe_raft']:.3f} → {stats['epe_final']:.3f} px")
    if "painted" in stats:
        parts.append(f"painted {100 * stats['painted']:.1f}%, tuned flow kept on {100 * stats['tuned_kept']:.1f}%"
                     + (f", zoomed flow on {100 * stats['zoom_kept']:.1f}%" if "zoom_kept" in stats else ""))
    zoom = run.decisions is not None and "zoom" in run.decisions
    rows = {}
    for panel in panels:
        zoom = max(1, width // panel.image.shape[1])  # small scenes shown larger, pixels kept sharp
        width_px = max(220, zoom * panel.image.shape[1])
        figure = (f'<figure style="width: {width_px}px">{img(panel.image, panel.title, zoom=zoom)}'
                  f"<figcaption>{esc(panel.title)}{_legend(panel.legend, scales, zoom)}</figcaption></figure>")  # fmt: skip
        rows.setdefault(panel.row, []).append(figure)
    names = {"flow": "Flow", "evidence": "Image evidence (no ground truth needed)", "gt": "Against the ground truth"}
    body = "".join(f"<h3>{names[row]}</h3><div class=\"row\">{''.join(figs)}</div>" for row, figs in rows.items())
    return (f"<section class=\"pair\" id=\"pair-{t}\"><h2>Pair {t} → {t + 1}</h2><p class=\"note\">"
            f"{esc('; '.join(parts))}</p>{body}</section>")  # fmt: skip


def _pairs_table(stats: dict[int, dict[str, float]], zoom: dict[str, Any] | None) -> str:
    """Every pair's numbers; after a zoom stage, its scale, the motion it was chosen from and the
    share of the zoomed region that kept the zoomed flow."""
    head = ["pair", "flow changed", "census RAFT", "census final", "change", "EPE RAFT", "EPE final", "change"]
    per_pair = zoom.get("info", {}).get("zoom", {}).get("per_pair", []) if zoom is not None else []
    if zoom is not None:
        head += ["zoom", "motion px", "zoomed flow kept (of its region)"]
    rows = []
    for t, s in stats.items():
        census = 100 * (s["census_final"] - s["census_raft"]) / s["census_raft"] if s["census_raft"] else math.nan
        epe = 100 * (s["epe_final"] - s["epe_raft"]) / s["epe_raft"] if s["epe_raft"] else math.nan
        verdict = {True: "better", False: "worse"}
        rows.append([(f"{t} → {t + 1}", ""), (f"{100 * s['changed']:.1f}%", ""), (_number(s["census_raft"], 4), ""),
                     (_number(s["census_final"], 4), ""), (_pct(census), verdict.get(census < 0, "") if census else ""),
                     (_number(s["epe_raft"], 4), ""), (_number(s["epe_final"], 4), ""),
                     (_pct(epe), verdict.get(epe < 0, "") if epe else "")])  # fmt: skip
        if zoom is not None:
            p = per_pair[t] if t < len(per_pair) else {}
            zoomed = p.get("region") is not None
            rows[-1] += [(f"{p['scale']:.2f}x" if zoomed else "not zoomed", ""),
                         (_number(p.get("motion_px")) if zoomed else "", ""),
                         (f"{100 * p['kept_fraction']:.1f}%" if "kept_fraction" in p else "", "")]  # fmt: skip
    return f"<h2 id=\"every-pair\">Every pair</h2>{table(head, rows)}"


def render_report(run: FinishedRun, max_pairs: int = 8, panel_width: int = 320) -> str:
    """The report's HTML for ``run`` (see the module doc)."""
    pairs = run.flows.shape[0]
    shown = set(pick_pairs(pairs, max_pairs))
    tally, stats, maps = EvidenceTally(), {}, {}
    for t in range(pairs):  # one pair at a time: only the shown pairs' maps are kept
        pair = pair_maps(run, t)
        stats[t] = pair_stats(pair, run.decisions, t)
        if pair.valid is not None:
            tally.add(pair)
        if t in shown:
            maps[t] = pair
    scales = shared_scales(run, maps)
    verdict = [s for s in (gt_sentence(run.history), evidence_sentence(tally, run.history), ids_sentence(run.scene))
               if s]  # fmt: skip
    if run.scene is None:
        verdict.append("The scene's frames were not found (summary.json names no scene folder that exists): pass the "
                       "scene to see the frames, poses, image evidence and GT maps (lit-boot report RUN --scene DIR).")
    body = [_header(run), '<section class="verdict"><h2>Did it get better?</h2>'
            + "".join(f"<p>{esc(s)}</p>" for s in verdict) + "</section>",
            _metrics_section(run), _decisions_section(run),
            f"<p class=\"note\">Pictured: {len(shown)} of the {pairs} pairs, evenly spaced; the table at the end lists "
            "every pair. Maps of one kind share one colour scale across the report.</p>"]  # fmt: skip
    for t in sorted(shown):
        panels = pair_panels(run, t, maps[t], scales, panel_width)
        body.append(_pair_section(run, t, panels, stats[t], scales, panel_width))
    body.append(_pairs_table(stats, _zoom_record(run)))
    title = f"lit-boot report: {run.scene.name if run.scene is not None else run.run_dir.name}"
    return page(title, "\n".join(body))
