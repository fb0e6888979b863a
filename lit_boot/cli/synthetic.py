"""``lit-boot synth --out DIR [--motion walk --frames 24 ...]``: a synthetic scene folder.

Every field of :class:`lit_boot.synth.SynthConfig` (and of its ``estimates``,
``--estimates.mpjpe_mm``) is an option, read from the dataclass with its docstring's help: a new
field is a new option (``--people 3``: three people who cross and hide each other).
"""

from __future__ import annotations

from pathlib import Path

from jsonargparse import ActionConfigFile

from .checks import name_option
from .console import ArgumentParser, dataclass_from, refuse_to_overwrite

__all__ = ["synth", "synth_parser"]


def synth_parser() -> ArgumentParser:
    """The parser of ``lit-boot synth``: the output options, then SynthConfig's fields."""
    from ..synth import SynthConfig

    parser = ArgumentParser(prog="lit-boot synth",
                            description="Generate a synthetic human scene with exact ground truth.")  # fmt: skip
    parser.add_argument("--config", action=ActionConfigFile, help="YAML file with the options below")
    parser.add_argument("--out", type=Path, required=True, help="scene folder to write (must not exist, or be empty)")
    parser.add_argument("--overwrite", type=bool, default=False, help="replace an existing scene folder")
    parser.add_argument("--preview", type=bool, default=True, help="also write preview.png into the scene folder")
    parser.add_class_arguments(SynthConfig, nested_key=None, as_group=False)
    return parser


def synth(argv: list[str]) -> int:
    """``lit-boot synth``: generate, save, summarise."""
    parser = synth_parser()
    args = parser.parse_args(argv)
    from ..synth import SynthConfig

    out: Path = args.out
    refuse_to_overwrite(out, args.overwrite, "a saved scene")
    try:
        config = dataclass_from(args, SynthConfig)
    except ValueError as err:  # before torch is imported, naming the option
        raise name_option(err, parser._option_string_actions) from err
    from ..data import save_scene, scene_preview, write_png
    from ..synth import make_scene

    scene = make_scene(config)
    save_scene(scene, out, overwrite=args.overwrite)
    print(scene.summary())
    failures = [len(scene.metadata["keypoint_failures"])]
    failures += [len(person["keypoint_failures"]) for person in scene.metadata.get("people", [])]
    per_person = f" ({', '.join(map(str, failures))} per person)" if len(failures) > 1 else ""
    print(f"  estimates: METRO-like MPJPE {config.estimates.mpjpe_mm:g} mm (root-aligned), "
          f"{sum(failures)} keypoint failure events{per_person}")  # fmt: skip
    if args.preview:
        write_png(out / "preview.png", scene_preview(scene))
    print(f"wrote {out}")
    return 0
