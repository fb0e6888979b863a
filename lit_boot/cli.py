"""The ``lit-boot`` command line.

Subcommands:

- ``lit-boot synth --out DIR [--motion walk --frames 24 --height 256 --width 256 --seed 0 ...]``
  writes a synthetic scene folder (with exact ground truth) and prints its summary. Every
  option of :class:`lit_boot.synth.SynthConfig` is a flag.
- ``lit-boot fit|validate|predict --config configs/flow_ttt.yaml --data.scene DIR`` runs a
  LightningModule (FlowTTT ...) on one scene through Lightning's CLI; the run goes to
  ``runs/<scene>/<model>`` unless ``--trainer.default_root_dir`` says otherwise.

``--print_config`` shows every option as YAML and ``--config FILE`` reads them from one.
"""

from __future__ import annotations

import sys
from pathlib import Path

from jsonargparse import ActionConfigFile, ArgumentParser

__all__ = ["main"]


def _synth_parser() -> ArgumentParser:
    from .synth import SynthConfig

    parser = ArgumentParser(prog="lit-boot synth", description="Generate a synthetic human scene with exact ground truth.")
    parser.add_argument("--config", action=ActionConfigFile, help="YAML file with the options below")
    parser.add_argument("--out", type=Path, required=True, help="scene folder to write (must not exist, or be empty)")
    parser.add_argument("--overwrite", type=bool, default=False, help="replace an existing scene folder")
    parser.add_argument("--preview", type=bool, default=True, help="also write preview.png into the scene folder")
    parser.add_class_arguments(SynthConfig, nested_key=None, as_group=False)
    return parser


def synth(argv: list[str]) -> int:
    """``lit-boot synth``: generate, save, summarise."""
    from .data import save_scene, scene_preview, write_png
    from .synth import EstimateConfig, SynthConfig, make_scene

    parser = _synth_parser()
    args = parser.parse_args(argv)
    out: Path = args.out
    if out.exists() and not args.overwrite and (not out.is_dir() or any(out.iterdir())):
        raise CliError(f"--out {out}: exists and is not empty (pass --overwrite true to replace a saved scene)")
    fields = {k: args[k] for k in SynthConfig.__dataclass_fields__ if k != "estimates"}
    config = SynthConfig(**fields, estimates=EstimateConfig(**vars(args.estimates)))
    scene = make_scene(config)
    save_scene(scene, out, overwrite=args.overwrite)
    print(scene.summary())
    print(f"  estimates: METRO-like MPJPE {config.estimates.mpjpe_mm:g} mm (root-aligned), "
          f"{len(scene.metadata['keypoint_failures'])} keypoint failure events")  # fmt: skip
    if args.preview:
        write_png(out / "preview.png", scene_preview(scene))
    print(f"wrote {out}")
    return 0


class CliError(Exception):
    """A user error: printed as one line, exit status 2."""


def lightning(argv: list[str]) -> int:
    """``lit-boot fit|validate|predict``: Lightning's CLI over lit-boot's modules and data."""
    from .lightning_cli import run_lightning_cli

    run_lightning_cli(argv)
    return 0


COMMANDS = {"synth": synth, "fit": lightning, "validate": lightning, "predict": lightning}


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``lit-boot`` console script."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if not argv or argv[0] in ("-h", "--help") or argv[0] not in COMMANDS:
        names = ", ".join(COMMANDS)
        print(f"usage: lit-boot {{{names}}} [options]   (lit-boot COMMAND --help for the options)")
        return 0 if argv[:1] in ([], ["-h"], ["--help"]) else 2
    try:
        return COMMANDS[argv[0]](argv if COMMANDS[argv[0]] is lightning else argv[1:])
    except (CliError, ValueError, FileExistsError, FileNotFoundError) as err:
        print(f"lit-boot {argv[0]}: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
