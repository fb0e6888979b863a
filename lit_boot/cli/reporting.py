"""``lit-boot report RUN_DIR``: write report.html for a finished run folder, or for a dataset run
(each finished scene's report, then the dataset's page linking them).

A bootstrap run made from ``--data.video`` names no scene folder: ``--scene`` gives the frames
and initial poses (a scene folder; ``lit-boot import video`` makes one).
"""

from __future__ import annotations

from pathlib import Path

from .console import ArgumentParser, CliError

__all__ = ["report", "report_parser"]


def report_parser() -> ArgumentParser:
    """The parser of ``lit-boot report``."""
    parser = ArgumentParser(prog="lit-boot report", description=(
        "Write report.html into a finished run folder (lit-boot bootstrap) or a dataset run folder (lit-boot "
        "bootstrap-many): whether the flow and poses got better, per metric and per frame pair, with pictures; "
        "one self-contained file for any browser."))  # fmt: skip
    parser.add_argument("run_dir", type=Path, help="a bootstrap run folder (summary.json) or a dataset run folder")
    parser.add_argument("--scene", type=Path | None, default=None,
                        help="the scene folder, if summary.json names none (a run from --data.video)")  # fmt: skip
    parser.add_argument("--max_pairs", type=int, default=8, help="frame pairs pictured per scene, evenly spaced")
    parser.add_argument("--panel_width", type=int, default=320, help="width of each picture, px")
    return parser


def report(argv: list[str]) -> int:
    """``lit-boot report``: write the report(s); print where."""
    args = report_parser().parse_args(argv)
    run_dir: Path = args.run_dir
    if args.max_pairs < 1:
        raise CliError(f"--max_pairs: expected an integer >= 1, got {args.max_pairs}")
    if args.panel_width < 16:
        raise CliError(f"--panel_width: expected an integer >= 16 (px), got {args.panel_width}")
    if not run_dir.is_dir():
        raise CliError(f"RUN_DIR {run_dir}: no such folder")
    if args.scene is not None and not args.scene.is_dir():
        raise CliError(f"--scene {args.scene}: no such scene folder")
    options = {"max_pairs": args.max_pairs, "panel_width": args.panel_width}
    if (run_dir / "manifest.json").is_file():
        if args.scene is not None:
            raise CliError("--scene: a dataset run reads each scene from its task; give --scene for one run only")
        from ..dataset.html_report import write_dataset_report

        path = write_dataset_report(run_dir, **options)
    elif (run_dir / "summary.json").is_file():
        from ..bootstrap.html_report import write_report

        path = write_report(run_dir, args.scene, **options)
    else:
        raise CliError(f"RUN_DIR {run_dir}: holds neither summary.json (a finished lit-boot bootstrap run) nor "
                       "manifest.json (a dataset run)")  # fmt: skip
    print(f"wrote {path}")
    return 0
