"""``lit-boot ids INPUT``: check and fix the people's ids of a scene folder or a pose file.

Without ``--fix``: the people, the frames where an id may have switched ("ids to check"), and with
``--sheet ids.png`` (a scene folder: it has the frames) those frames drawn, every person in its
colour with its track id (:func:`lit_boot.estimate.id_sheet`; ``--frames 3-9`` or ``all``: other
frames). With ``--fix "swap 1 2 at 7-"`` (repeatable; the fixes of :mod:`lit_boot.estimate.id_fixes`):
a fixed copy written to ``--out`` (a scene folder for a scene folder, a pose file for a pose file;
the input is never changed), what each fix did, and the frames to check after it.
"""

from __future__ import annotations

from pathlib import Path

from .console import ArgumentParser, CliError

__all__ = ["ids", "ids_parser"]

_FIX_HELP = ("a fix, repeatable, applied in turn: 'swap A B [at FRAMES]', 'join B into A', 'split A at FRAMES', "
             "'drop A [at FRAMES]' (A, B: track ids; FRAMES: video frame numbers, '7', '7-9', '7-' or '3-5, 9')")


def ids_parser() -> ArgumentParser:
    """The parser of ``lit-boot ids``."""
    parser = ArgumentParser(prog="lit-boot ids", description=(
        "Check and fix the people's ids of a scene folder or a pose file: list the frames where an id may have "
        "switched (people overlapping, new or found again), draw them with every person named (--sheet), and "
        "write a copy with the ids fixed (--fix ... --out)."))  # fmt: skip
    parser.add_argument("input", type=Path, help="a scene folder (lit-boot import) or a pose file (.npz or .json)")
    parser.add_argument("--fix", type=str, action="append", default=[], help=_FIX_HELP)
    parser.add_argument("--out", type=Path | None, default=None,
                        help="where the fixed copy goes: a new scene folder, or a pose file (.npz, .json)")
    parser.add_argument("--sheet", type=Path | None, default=None,
                        help="a PNG of the frames to check (after the fixes), each person named (scene folders)")
    parser.add_argument("--frames", type=str | None, default=None,
                        help="the frames --sheet draws: 'all', or video frame numbers like '3-9, 12' (default: "
                             "the frames to check)")  # fmt: skip
    parser.add_argument("--overwrite", type=bool, nargs="?", const=True, default=False, help="replace --out")
    return parser


def _check_args(args) -> bool:
    """CliError for a bad combination (before torch is imported); True for a scene folder."""
    source: Path = args.input
    is_scene = source.is_dir()
    if is_scene and not (source / "scene.json").is_file():
        raise CliError(f"INPUT {source}: a folder without scene.json, not a scene folder (lit-boot import makes one)")
    if not is_scene and not source.is_file():
        raise CliError(f"INPUT {source}: no such scene folder or pose file")
    if not is_scene and source.suffix.lower() not in (".npz", ".json"):
        raise CliError(f"INPUT {source}: expected a scene folder or a pose file (.npz or .json)")
    if args.fix and args.out is None:
        raise CliError("--out: required with --fix (the fixed copy is written there; INPUT is never changed)")
    if args.out is not None and not args.fix:
        raise CliError("--out: nothing to write without --fix")
    if args.out is not None:
        if args.out.resolve() == source.resolve():
            raise CliError(f"--out {args.out}: is INPUT; write the fixed copy elsewhere (INPUT is never changed)")
        if not is_scene and args.out.suffix.lower() not in (".npz", ".json"):
            raise CliError(f"--out {args.out}: expected a pose file name (.npz or .json), as INPUT is one")
        if args.out.exists() and not args.overwrite:
            raise CliError(f"--out {args.out}: exists; add --overwrite to replace it")
    if args.sheet is not None:
        if not is_scene:
            raise CliError(f"--sheet: needs the frames, which a pose file does not hold; give the scene folder "
                           f"(lit-boot import video VIDEO --poses {source} --people all makes one)")  # fmt: skip
        if args.sheet.suffix.lower() != ".png":
            raise CliError(f"--sheet {args.sheet}: expected a .png file name")
    elif args.frames is not None:
        raise CliError("--frames: says which frames --sheet draws; give --sheet too")
    return is_scene


def ids(argv: list[str]) -> int:
    """``lit-boot ids``: print the people's frames to check; fix and write a copy; draw the sheet."""
    args = ids_parser().parse_args(argv)
    is_scene = _check_args(args)
    from ..estimate import checks_line, frames_to_check
    from ..estimate.id_checks import beside_line

    if is_scene:
        from ..data import load_scene, save_scene
        from ..estimate.id_checks import frame_numbers
        from ..estimate.id_fixes import fix_scene

        item = load_scene(args.input)
        numbers = frame_numbers(item)
    else:
        from ..data.readers.pose_file import load_poses, save_poses
        from ..estimate.id_fixes import fix_estimates

        item = load_poses(args.input)
        numbers = item.frame_indices.tolist()
    picked = None
    if args.frames is not None:
        from ..estimate.id_fixes import frame_rows

        picked = frame_rows(args.frames, numbers, "--frames").nonzero().flatten().tolist()
    if args.fix:
        item, notes = (fix_scene if is_scene else fix_estimates)(item, args.fix)
        for note in notes:
            print(note)
    people = item.people()
    marks = frames_to_check(people) if len(people) > 1 else []
    found = ", ".join(f"{p.track_id} ({int(p.found().sum())})" for p in people)
    print(f"{len(people)} {'person' if len(people) == 1 else 'people'} (frames with them): {found}")
    line = checks_line([(p.track_id, [numbers[t] for t in m.nonzero().flatten().tolist()])
                        for p, m in zip(people, marks)])  # fmt: skip
    print(line or "no frame to check")
    if line:
        print(f"  why: {beside_line(people, marks, numbers)}")
    if line and not args.fix:
        print(f"  look at them (--sheet ids.png draws them), then: lit-boot ids {args.input} --fix \"swap A B at "
              f"FRAMES\" --out NEW (swap, join, split, drop: lit-boot ids --help)")  # fmt: skip
    if args.out is not None:
        if is_scene:
            save_scene(item, args.out, overwrite=args.overwrite)
        else:
            save_poses(item, args.out)
        print(f"wrote {args.out}")
    if args.sheet is not None:
        _write_sheet(item, numbers, args.sheet, picked)
    return 0


def _write_sheet(scene, numbers: list[int], path: Path, rows: list[int] | None) -> None:
    """The id sheet of ``scene``'s frames to check (or of the frame ``rows``, --frames) to ``path``;
    a line saying so (or why none)."""
    from ..data import write_png
    from ..estimate import id_sheet, sheet_rows

    if rows is None:
        rows = sheet_rows(scene.people()) if scene.num_people > 1 else []
    if not rows:
        print(f"no frame to check: {path} not written (--frames all draws every frame)")
        return
    write_png(path, id_sheet(scene.frames, scene.people(), scene.keypoints_layout, rows, numbers))
    shown = f" (the first 48 of {len(rows)})" if len(rows) > 48 else ""
    print(f"wrote {path}: {min(len(rows), 48)} frames{shown}")
