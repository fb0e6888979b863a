"""Every figure the README quotes comes from one place: the "Current results" section at the top of
BENCHMARKS.md (issue 26). A figure is a number with a unit: ``-24.3%``, ``3.5x``, ``27 s``,
``7.2 GB``; code blocks are not prose and are left out."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FIGURE = re.compile(r"(?<![\w.])[-+]?\d+(?:\.\d+)?(?:%|x\b| s\b| GB\b| min\b)")


def prose(markdown: str) -> str:
    """``markdown`` without its fenced code blocks."""
    return re.sub(r"^```.*?^```", "", markdown, flags=re.S | re.M)


def figures(text: str) -> set[str]:
    return set(FIGURE.findall(prose(text)))


def current_results(benchmarks: str) -> str:
    """The "## Current results" section of BENCHMARKS.md (up to the next top-level heading)."""
    match = re.search(r"^## Current results\n(.*?)(?=^# |\Z)", benchmarks, re.S | re.M)
    assert match, "BENCHMARKS.md has no '## Current results' section"
    return match.group(1)


def unsourced(readme: str, benchmarks: str) -> set[str]:
    """The README's figures that the current results do not hold."""
    return figures(readme) - figures(current_results(benchmarks))


def test_every_figure_in_the_readme_is_in_the_current_results() -> None:
    readme, benchmarks = (ROOT / "README.md").read_text(), (ROOT / "BENCHMARKS.md").read_text()
    assert len(figures(readme)) >= 15  # the README does quote results
    assert unsourced(readme, benchmarks) == set()


def test_the_current_results_come_first_and_the_check_catches_a_changed_figure() -> None:
    benchmarks = (ROOT / "BENCHMARKS.md").read_text()
    headings = re.findall(r"^##? .*$", benchmarks, re.M)
    assert headings[:2] == ["# Benchmarks", "## Current results"]
    assert "### GPU (one NVIDIA H200" in current_results(benchmarks)  # the device is named
    readme = (ROOT / "README.md").read_text()
    quoted = sorted(f for f in figures(readme) if f.endswith("%"))[0]  # a figure the README quotes
    changed = f"{quoted[:-1]}01%"  # one more digit: a figure the current results do not hold
    assert changed not in figures(current_results(benchmarks))
    assert unsourced(readme.replace(quoted, changed), benchmarks) == {changed}
    assert unsourced(readme + "\nIt takes 19 s.\n", benchmarks) == {"19 s"}
    assert figures("```bash\nsleep 5 s\n```\nabout 2.4x") == {"2.4x"}
