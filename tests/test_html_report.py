"""report.html (issue 26): built from a finished run folder alone, self-contained, and its pictures
really show in a browser (Chromium, headless: the screenshot's pixels where the flow images are).

Tiny synthetic runs with random RAFT weights (no weights file); Chromium comes from the system's
packages (.ci/run installs it, and fails when this test skips for want of it)."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from html import unescape
from pathlib import Path

import numpy as np
import pytest
import torch

import lit_boot
from lit_boot.bootstrap import bootstrap
from lit_boot.bootstrap.decisions import DECISION_COLOURS, decision_map, final_decisions
from lit_boot.bootstrap.finished import read_run
from lit_boot.bootstrap.html_report import REPORT_HTML, write_report
from lit_boot.bootstrap.overlay import _key_rows, nice_ceiling
from lit_boot.bootstrap.pair_maps import CHANGED_PX, PairMaps, pick_pairs
from lit_boot.bootstrap.verdict import EvidenceTally, certainty, evidence_sentence
from lit_boot.cli import main
from lit_boot.data.flows import read_flows

RANDOM_RAFT = {"weights": None, "train_updates": 2, "predict_updates": 3}  # no weights file needed
FAST = dict(flow_epochs=1, pose_steps=15, progress_bar=False, video=False, accelerator="cpu")
CHROMIUM = next((p for p in map(shutil.which, ("chromium", "chromium-browser")) if p), None)


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Path:
    """A finished run whose summary.json names its scene folder (5 frames, 64x96, GT)."""
    root = tmp_path_factory.mktemp("report")
    lit_boot.save_scene(lit_boot.make_scene(motion="run", frames=5, height=64, width=96, seed=0), root / "scene")
    bootstrap(root / "scene", root / "run", flow=RANDOM_RAFT, **FAST)
    return root / "run"


def images(html: str) -> list[str]:
    """The alt texts of the page's images, in order."""
    return [unescape(alt) for alt in re.findall(r'<img [^>]*alt="([^"]*)"', html)]


def test_the_report_is_one_self_contained_file_with_every_part(run: Path) -> None:
    path = write_report(run, max_pairs=2)
    html = path.read_text()
    assert path == run / REPORT_HTML
    assert not re.search(r"(src|href)=\"(?!data:|#)", html) and "<script" not in html and "<link" not in html
    assert "Did it get better?" in html and "Against the ground truth:" in html and "What the frames say" in html
    for metric in ("epe", "epe_person", "mpjpe_mm", "photo_error", "track_error", "drift_px"):
        assert f"<td class=\"l\">{metric}</td>" in html
    assert html.count("lower is better") >= 5 and "neither (a diagnostic)" in html
    alts = images(html)
    per_pair = ["RAFT's flow", "final flow", "change |final - RAFT|", "census error, RAFT's flow",
                "census error, final flow", "census error change (final - RAFT)", "EPE vs GT, RAFT's flow",
                "EPE vs GT, final flow", "EPE change (final - RAFT)"]  # fmt: skip
    for alt in per_pair:
        assert alts.count(alt) == 2, alt  # the first and the last pair (max_pairs=2 of 4)
    assert sum(a.startswith("decisions (flow_2)") for a in alts) == 2
    assert sum(a.startswith("frame ") for a in alts) == 2
    assert "Pair 0 → 1" in html and "Pair 3 → 4" in html and "Pair 1 → 2" not in html
    assert html.count("<tr>") >= 4 + 4  # every pair in the last table


def test_without_the_scene_it_shows_the_flows_and_says_what_is_missing(run: Path, tmp_path: Path) -> None:
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    summary = json.loads((copy / "summary.json").read_text())
    summary["scene"] = "<Scene synth_run_s0>"  # a run made from a Scene object or a video
    (copy / "summary.json").write_text(json.dumps(summary))
    html = write_report(copy, max_pairs=1).read_text()
    assert "frames were not found" in html and "--scene" in html
    assert {"RAFT's flow", "final flow", "change |final - RAFT|"} <= set(images(html))
    assert "census error, final flow" not in images(html)
    html = write_report(copy, run.parent / "scene", max_pairs=1).read_text()  # the scene given
    assert "census error, final flow" in images(html) and "frames were not found" not in html


def test_every_run_ends_with_its_report_made_from_the_scene_it_started_from(run: Path, tmp_path: Path) -> None:
    scene = lit_boot.make_scene(motion="run", frames=5, height=64, width=96, seed=0)
    options = {**FAST, "flow": RANDOM_RAFT, "pose_ensemble": [str(run)]}
    result = bootstrap(scene, tmp_path / "run", **options)  # a Scene: summary.json names no folder
    html = (tmp_path / "run" / REPORT_HTML).read_text()
    assert "frames were not found" not in html and "census error, final flow" in images(html)
    # the initial poses pictured are the run's: the ensemble averaged in once, not twice
    finished = read_run(tmp_path / "run", result.initial_scene, ensembled=True)
    shown = finished.initial_points[0]
    assert torch.equal(shown, result.initial_scene.pose_points("3d")[0])
    twice = read_run(tmp_path / "run", result.initial_scene).initial_points[0]
    assert not torch.allclose(twice, shown)
    # the run's decision maps (overlay, TensorBoard) and the report's, read back, are the same
    assert set(result.decisions) == set(finished.decisions) == {"painted", "kept", "zoom"}
    for key, value in result.decisions.items():
        assert torch.allclose(value.float(), finished.decisions[key].float(), atol=1 / 255), key


def test_the_zoom_stage_has_its_colour_its_table_and_its_columns(run: Path) -> None:
    finished = read_run(run)
    assert [r["stage"] for r in finished.history][:3] == ["initial", "zoom", "flow_1"]
    zoom = finished.decisions["zoom"]
    assert zoom.max() > 0 and (zoom + finished.decisions["kept"]).max() <= 1 + 1e-6  # shares of one pixel
    html = write_report(run, max_pairs=2).read_text()
    assert html.count("the zoomed flow kept (zoom stage)") == 2  # each pictured pair's decision legend
    assert f"background: rgb{DECISION_COLOURS['zoom']}".replace(" ", "") in html.replace(" ", "")
    zoom_table = html.split("<h3>The zoom stage</h3>")[1].split("</table>")[0]
    record = next(r for r in finished.history if r["kind"] == "zoom")["info"]["zoom"]
    scales = [p["scale"] for p in record["per_pair"] if p["region"] is not None]
    assert f">{record['zoomed_pairs']} of 4<" in zoom_table and f">{min(scales):.3g}x" in zoom_table
    assert f"{100 * record['kept_fraction']:.1f}%" in zoom_table
    flow_table = html.split("<h3>The flow stages</h3>")[1].split("</table>")[0]
    assert ">flow_1<" in flow_table and ">zoom<" not in flow_table  # the zoom is not a flow stage
    every = html.split('id="every-pair"')[1]
    assert "zoomed flow kept (of its region)" in every
    assert every.count(f">{record['per_pair'][0]['scale']:.2f}x<") >= 1
    assert "zoomed flow on " in html  # each pictured pair's line


def test_decision_maps_say_where_the_final_flow_comes_from() -> None:
    shape = (1, 1, 4)  # four pixels: RAFT's, the zoom's, flow_1's, flow_2's
    zoom = {"painted": torch.zeros(shape, dtype=torch.bool), "kept": torch.tensor([[[0.0, 1, 1, 1]]])}
    flow_1 = {"painted": torch.zeros(shape, dtype=torch.bool), "kept": torch.tensor([[[0.0, 0, 1, 0]]])}
    flow_2 = {"painted": torch.tensor([[[False, False, False, True]]]), "kept": torch.tensor([[[0.0, 0, 0, 1]]])}
    maps = None
    for kind, own in (("zoom", zoom), ("flow", flow_1), ("pose", None), ("flow", flow_2)):
        maps = final_decisions(maps, kind, own)
    assert maps["zoom"].tolist() == [[[0.0, 1, 0, 0]]] and maps["kept"].tolist() == [[[0.0, 0, 1, 1]]]
    assert maps["painted"].tolist() == [[[False, False, False, True]]]  # the last flow stage's target
    assert "zoom" not in final_decisions(None, "flow", flow_1)  # without a zoom stage, no zoom share
    frame = torch.full((3, 1, 4), 100, dtype=torch.uint8)
    image = decision_map(frame, maps, 0).float()
    grey = image[:, 0, 0]
    for x, colour in ((1, "zoom"), (2, "kept")):  # each tinted 45% of the way to its own colour
        assert torch.allclose(image[:, 0, x], grey + 0.45 * (torch.tensor(DECISION_COLOURS[colour]).float() - grey),
                              atol=1)  # fmt: skip
    assert image[:, 0, 3].tolist() == list(DECISION_COLOURS["painted"])
    rows = [text for text, _ in _key_rows(None, None, maps)]
    assert "magenta = the zoomed flow kept" in rows[-1]
    assert "magenta" not in _key_rows(None, None, final_decisions(None, "flow", flow_1))[-1][0]


def test_a_zoom_kept_after_a_rolled_back_flow_stage_is_the_final_flow(run: Path, tmp_path: Path) -> None:
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    summary = json.loads((copy / "summary.json").read_text())
    summary["stages"] = [{**r, "rolled_back": r["stage"] == "flow_1"} for r in summary["stages"][:3]]
    (copy / "summary.json").write_text(json.dumps(summary))
    finished = read_run(copy)
    assert finished.flow_stage == "zoom"
    assert torch.equal(finished.flows, read_flows(copy / "stages/zoom/flows.npz"))
    assert finished.decisions["kept"].max() == 0 and finished.decisions["zoom"].max() == 1


def test_the_drift_guards_events_are_in_words(run: Path, tmp_path: Path) -> None:
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    summary = json.loads((copy / "summary.json").read_text())
    summary["stages"] = [{k: v for k, v in r.items() if k != "guard"} for r in summary["stages"]]
    (copy / "summary.json").write_text(json.dumps(summary))
    assert "no stage made its image evidence worse." in write_report(copy).read_text()
    event = {"guard": "drift", "evidence": "photo_error", "before": 0.8, "after": 0.9, "action": "record"}
    summary["stages"][-1]["guard"] = event
    (copy / "summary.json").write_text(json.dumps(summary))
    html = unescape(write_report(copy).read_text())
    assert "flow_2: the flow's census error rose 0.800 -> 0.900 (recorded, the run went on)." in html


def test_a_scene_of_another_size_is_refused(run: Path) -> None:
    other = lit_boot.make_scene(motion="run", frames=5, height=32, width=96, seed=0)
    with pytest.raises(ValueError, match="32"):
        write_report(run, other)


def test_lit_boot_report_writes_it_and_refuses_other_folders(run: Path, tmp_path: Path, capsys) -> None:
    (run / REPORT_HTML).unlink(missing_ok=True)
    assert main(["report", str(run), "--max_pairs", "1"]) == 0
    assert (run / REPORT_HTML).is_file() and f"wrote {run / REPORT_HTML}" in capsys.readouterr().out
    assert main(["report", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "neither summary.json" in err and str(tmp_path) in err
    assert main(["report", str(run), "--max_pairs", "0"]) == 2
    assert "--max_pairs" in capsys.readouterr().err


def maps(change: float, census_gain: float, size: int = 64, seed: int = 0) -> PairMaps:
    g = torch.Generator().manual_seed(seed)
    raft = 10 + torch.rand(size, size, generator=g)
    final = raft - census_gain + 0.5 * torch.randn(size, size, generator=g)
    return PairMaps(change=torch.full((size, size), change), census_raft=raft, census_final=final,
                    valid=torch.ones(size, size, dtype=torch.bool))  # fmt: skip


def test_the_evidence_sentence_says_which_way_and_how_sure() -> None:
    history = [{"stage": "initial", "kind": "initial", "track_error": 20.0},
               {"stage": "flow_1", "kind": "flow", "info": {"target": {"target/painted_fraction": 0.1}}},
               {"stage": "pose_1", "kind": "pose", "track_error": 19.0}]  # fmt: skip
    better, worse, still = EvidenceTally(), EvidenceTally(), EvidenceTally()
    for seed in range(3):
        better.add(maps(1.0, 1.0, seed=seed))
        worse.add(maps(1.0, -1.0, seed=seed))
        still.add(maps(CHANGED_PX / 2, 1.0, seed=seed))  # below the change that counts
    assert better.z > 3 and worse.z < -3 and better.pairs_better == 3 and worse.pairs_better == 0
    text = evidence_sentence(better, history)
    assert "matches frame t better" in text and "strong evidence that it got better" in text and "3 of the 3" in text
    assert "fell from" in text and "the refined joints follow the image content better" in text
    assert "strong evidence that it got worse" in evidence_sentence(worse, history)
    assert "RAFT's flow on every pixel" in evidence_sentence(still, history)
    nothing = [history[0], {"stage": "flow_1", "kind": "flow", "info": {"target": {"target/painted_fraction": 0.0}}}]
    assert "painted nothing" in evidence_sentence(still, nothing)
    assert certainty(0.5) == "no clear evidence either way" and certainty(-2.5).startswith("moderate")
    assert certainty(float("nan")).startswith("too few")


def test_scales_and_pair_picks() -> None:
    assert nice_ceiling(0.0002, 0.5) == 0.5 and nice_ceiling(3.7, 0.5) == 5 and nice_ceiling(11, 1) == 20
    assert nice_ceiling(2.0, 0.5) == 2 and nice_ceiling(0.26, 0.1) == 0.5
    assert pick_pairs(3, 8) == [0, 1, 2] and pick_pairs(100, 3) == [0, 50, 99] and len(pick_pairs(300, 8)) == 8


# --- in a real browser ----------------------------------------------------------------------------
WINDOW = (1400, 4000)
_BOXES = """<script>window.addEventListener("load", () => {
  const boxes = [...document.images].map(i => { const r = i.getBoundingClientRect();
    return {alt: i.alt, natural: i.naturalWidth, x: r.left, y: r.top, w: r.width, h: r.height}; });
  const out = document.createElement("pre"); out.id = "boxes"; out.textContent = JSON.stringify(boxes);
  document.body.appendChild(out); });</script>"""


def chromium(page: Path, tmp: Path, *args: str) -> subprocess.CompletedProcess:
    flags = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
             "--disable-background-networking", "--disable-component-update", "--disable-sync",
             f"--user-data-dir={tmp / 'profile'}", "--force-device-scale-factor=1", "--hide-scrollbars",
             f"--window-size={WINDOW[0]},{WINDOW[1]}", "--virtual-time-budget=10000"]  # fmt: skip
    return subprocess.run([CHROMIUM, *flags, *args, page.as_uri()], capture_output=True, text=True, timeout=120)


def flow_pictures_show(html: str, tmp: Path) -> bool:
    """Render ``html`` in Chromium; True when every flow picture inside the window was decoded and
    its screenshot pixels vary (colour, not a blank box)."""
    page = tmp / "page.html"
    page.write_text(html.replace("</body>", _BOXES + "</body>"))
    dom = chromium(page, tmp, "--dump-dom")
    boxes = json.loads(re.search(r'<pre id="boxes">(.*?)</pre>', dom.stdout, re.S).group(1).replace("&quot;", '"'))
    shot = tmp / "shot.png"
    done = chromium(page, tmp, f"--screenshot={shot}")
    assert done.returncode == 0 and shot.is_file(), done.stderr[-2000:]
    import cv2

    pixels = cv2.imread(str(shot))
    assert pixels.shape[:2] == (WINDOW[1], WINDOW[0])
    flows = [b for b in boxes if b["alt"] in ("RAFT's flow", "final flow") and b["y"] + b["h"] <= WINDOW[1]]
    if not flows:
        return False
    for box in flows:
        x, y, w, h = (round(box[k]) for k in ("x", "y", "w", "h"))
        crop = pixels[y + 1 : y + h - 1, x + 1 : x + w - 1].reshape(-1, 3).astype(np.float32)
        distinct = len(np.unique(crop.astype(np.uint8), axis=0))
        if box["natural"] == 0 or crop.size == 0 or crop.std(0).max() < 2.0 or distinct < 20:
            return False
    return True


@pytest.mark.skipif(CHROMIUM is None, reason="needs chromium (apt-get install chromium; .ci/run installs it)")
def test_the_flow_pictures_show_in_a_browser(run: Path, tmp_path: Path) -> None:
    html = write_report(run, max_pairs=2).read_text()
    assert flow_pictures_show(html, tmp_path)
    blank = re.sub(r'src="data:image/png;base64,[^"]*"', 'src=""', html)  # the same page, the images missing
    assert not flow_pictures_show(blank, tmp_path)


def test_a_dataset_run_links_its_scenes_reports(run: Path, tmp_path: Path, capsys) -> None:
    from lit_boot.dataset import Task, run_dataset

    scene = run.parent / "scene"
    tasks = [Task(name=n, kind="scene", args={"path": str(scene)}) for n in ("a", "b")]
    out = tmp_path / "data"
    run_dataset(tasks, out, {**FAST, "flow": RANDOM_RAFT}, workers=0)
    index = (out / REPORT_HTML).read_text()
    for name in ("a", "b"):  # the scene runs wrote their own (outputs.py), linked at once
        assert f'<a href="scenes/{name}/report.html">{name}</a>' in index
    assert main(["report", str(out), "--max_pairs", "1"]) == 0
    assert f"wrote {out / REPORT_HTML}" in capsys.readouterr().out
    index = (out / REPORT_HTML).read_text()
    for name in ("a", "b"):
        assert (out / "scenes" / name / REPORT_HTML).is_file()
        assert f'<a href="scenes/{name}/report.html">{name}</a>' in index
    assert "<td class=\"l\">dataset</td>" in index and "→" in index
