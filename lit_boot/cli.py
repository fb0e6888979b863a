"""The ``lit-boot`` command line.

Subcommands:

- ``lit-boot synth --out DIR [--motion walk --frames 24 --height 256 --width 256 --seed 0 ...]``
  writes a synthetic scene folder (with exact ground truth) and prints its summary. Every
  option of :class:`lit_boot.synth.SynthConfig` is a flag.
- ``lit-boot fit|validate|predict --config configs/flow_ttt.yaml --data.scene DIR`` runs a
  LightningModule (FlowTTT ...) on one scene through Lightning's CLI; the run goes to
  ``runs/<scene>/<model>`` unless ``--trainer.default_root_dir`` says otherwise.
- ``lit-boot bootstrap --config configs/bootstrap.yaml --data.scene DIR [--out RUN]`` runs the
  whole method (flow -> pose -> flow) on one scene; rerunning an interrupted run resumes it.
- ``lit-boot import {sintel,3dpw,h36m,video} ... --out DIR`` reads a dataset scene or a video
  (with a pose file, or MediaPipe poses) into a scene folder.
- ``lit-boot bootstrap --config configs/bootstrap.yaml --data.video VIDEO [--data.poses FILE]``
  bootstraps a video directly (MediaPipe poses when no pose file is given).
- ``lit-boot estimate-pose VIDEO --out poses.npz`` runs MediaPipe Pose (the ``mediapipe``
  extra) on a video file or folder of frames and writes 2D keypoints, 3D joints and cameras.
- ``lit-boot demo`` makes a synthetic scene, bootstraps it with the local RAFT weights, and
  prints a before/after table.

``--print_config`` shows every option as YAML and ``--config FILE`` reads them from one.

Nothing heavy (torch, Lightning) is imported before a command's arguments are parsed, so
``lit-boot --help`` answers at once. A command prints lit-boot's own lines and progress bars;
Lightning's info lines and known dependency warnings are dropped (:mod:`lit_boot.console`)
unless ``lit-boot --verbose COMMAND ...`` or ``LIT_BOOT_VERBOSE=1``. A bad argument or input
file is one ``lit-boot COMMAND: error: ...`` line on stderr and exit status 2.
"""

from __future__ import annotations

import json
import sys
from argparse import ArgumentError
from pathlib import Path

from jsonargparse import ActionConfigFile

from .console import (
    ArgumentParser,
    CliError,
    command_output,
    drop_native_noise,
    error_line,
    is_user_error,
    verbose_requested,
)

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


def _bootstrap_parser() -> ArgumentParser:
    from .bootstrap import BootstrapConfig

    parser = ArgumentParser(prog="lit-boot bootstrap", description="Bootstrap flow and pose on one scene.")
    parser.add_argument("--config", action=ActionConfigFile, help="YAML file with the options below")
    parser.add_argument("--data.scene", type=Path | None, default=None, help="scene folder (never written)")
    parser.add_argument("--data.video", type=Path | None, default=None,
                        help="or a video file / frame folder: poses from --data.poses, else MediaPipe Pose")  # fmt: skip
    parser.add_argument("--data.poses", type=Path | None, default=None, help="pose file for --data.video")
    parser.add_argument("--data.stride", type=int, default=1, help="--data.video: every N-th frame")
    parser.add_argument("--data.max_frames", type=int | None, default=None, help="--data.video: at most N frames")
    parser.add_argument("--data.resize", type=int | float | None, default=None,
                        help="--data.video: a height in px (int) or a scale (float)")  # fmt: skip
    parser.add_argument("--out", type=Path | None, default=None, help="run folder (default runs/<scene>/bootstrap)")
    parser.add_argument("--overwrite", type=bool, default=False, help="delete an existing run folder first")
    parser.add_class_arguments(BootstrapConfig, nested_key=None, as_group=False)
    return parser


def _config_from(args, config_type):
    return config_type(**{k: args[k] for k in config_type.__dataclass_fields__})


def bootstrap(argv: list[str]) -> int:
    """``lit-boot bootstrap``: run (or resume) the method on one scene; print the table."""
    from .bootstrap import Bootstrap, BootstrapConfig

    args = _bootstrap_parser().parse_args(argv)
    data = args.data
    if (data.scene is None) == (data.video is None):
        raise CliError("give one of --data.scene DIR (a scene folder) or --data.video PATH (a video or frame folder)")
    scene, out = data.scene, args.out
    if data.video is not None:
        from .data.readers import read_video
        from .import_cli import with_poses

        scene = read_video(data.video, stride=data.stride, max_frames=data.max_frames, resize=data.resize,
                           poses=data.poses)  # fmt: skip
        scene = with_poses(scene, None, estimate=data.poses is None)
        out = out or Path("runs") / data.video.stem / "bootstrap"
    result = Bootstrap(scene, out, _config_from(args, BootstrapConfig), overwrite=args.overwrite).run()
    print(result.table())
    print(f"wrote {result.run_dir}")
    return 0


def _demo_parser() -> ArgumentParser:
    parser = ArgumentParser(prog="lit-boot demo", description=(
        "Make a synthetic scene with exact ground truth, bootstrap it (flow -> pose -> flow) with RAFT-small "
        "weights found in checkpoints/ (or downloaded), and print EPE and MPJPE before and after. "
        "--quick: 2 epochs per flow stage instead of 8 (about a minute on a 2-core CPU)."))  # fmt: skip
    parser.add_argument("--quick", type=bool, nargs="?", const=True, default=False,
                        help="the same scene, 2 epochs per flow stage, into runs/demo_quick")  # fmt: skip
    parser.add_argument("--out", type=Path | None, default=None,
                        help="folder for the scene and the run (default runs/demo, runs/demo_quick)")  # fmt: skip
    parser.add_argument("--motion", type=str, default="run", help="walk, run, wave, jump, turn")
    parser.add_argument("--frames", type=int, default=8)
    parser.add_argument("--height", type=int, default=128)
    parser.add_argument("--width", type=int, default=256)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--arch", type=str, default="raft_small")
    parser.add_argument("--weights", type=str, default="C_T_V1", help="a file or torchvision name (looked up locally first)")
    parser.add_argument("--epochs", type=int | None, default=None, help="FlowTTT epochs per flow stage (8; --quick 2)")
    parser.add_argument("--overwrite", type=bool, default=False, help="start again instead of resuming")
    return parser


def demo(argv: list[str]) -> int:
    """``lit-boot demo``: synthetic scene -> bootstrap -> before/after table. Prints first what it
    will do and about how long it takes from scratch on a 2-core CPU (measured: see README)."""
    args = _demo_parser().parse_args(argv)
    from .bootstrap import Bootstrap
    from .data import load_scene, save_scene
    from .synth import make_scene

    epochs = args.epochs if args.epochs is not None else (2 if args.quick else 8)
    out = args.out or Path("runs/demo_quick" if args.quick else "runs/demo")
    scene_dir, spec_file = out / "scene", out / "demo.json"
    spec = {k: args[k] for k in ("motion", "frames", "height", "width", "seed")}
    stored = {**spec, "epochs": epochs}  # another scene or size: start again
    fresh = args.overwrite or not spec_file.is_file() or json.loads(spec_file.read_text()) != stored
    # Measured on 2 free cores: ~1.7 s per training step (one pair, 20 RAFT updates) at 256x128,
    # growing about as the square root of the pixels, plus start-up; far longer on busy cores
    steps = 2 * (args.frames - 1) * epochs  # both flow stages train on every pair
    minutes = (8 + 1.7 * steps * (args.height * args.width / (128 * 256)) ** 0.5) / 60
    print(f"lit-boot demo: a synthetic {args.motion!r} scene ({args.frames} frames, {args.width}x{args.height}, exact "
          f"GT); RAFT-small fine-tuned {epochs} epochs per flow stage, flow -> pose -> flow; from scratch about "
          f"{max(1, round(minutes))} min on 2 free CPU cores" + ("" if args.quick else " (--quick: about 1 min)"),
          flush=True)  # fmt: skip
    if fresh:
        save_scene(make_scene(**spec), scene_dir, overwrite=True)
        spec_file.write_text(json.dumps(stored) + "\n")
    scene = load_scene(scene_dir)
    print(scene.summary())
    run = Bootstrap(scene_dir, out / "bootstrap", overwrite=fresh, flow_epochs=epochs,
                    flow={"arch": args.arch, "weights": args.weights})  # fmt: skip
    result = run.run()
    print(f"\nlit-boot demo: {scene.name}, {scene.num_frames} frames {scene.width}x{scene.height}; "
          "EPE in px (person = GT person mask, joints = at the GT joints), MPJPE in mm")  # fmt: skip
    print(result.table())
    print(f"outputs in {result.run_dir} (summary.json, metrics.png, overlay.mp4; "
          f"tensorboard --logdir {result.run_dir / 'logs' / 'tensorboard'})")  # fmt: skip
    return 0


def _estimate_pose_parser() -> ArgumentParser:
    parser = ArgumentParser(prog="lit-boot estimate-pose", description=(
        "Estimate one person's pose in every frame of a video with MediaPipe Pose (pip install "
        '"lit-boot[mediapipe]"): COCO-17 keypoints, LSP-14 3D joints and weak-perspective cameras.'))  # fmt: skip
    parser.add_argument("video", type=Path, help="a video file (e.g. .mp4) or a folder of frames")
    parser.add_argument("--out", type=Path, required=True, help="pose file to write (.npz or .json)")
    parser.add_argument("--stride", type=int, default=1, help="use every N-th frame")
    parser.add_argument("--max_frames", "--max-frames", type=int | None, default=None, help="use at most N frames")
    parser.add_argument("--resize", type=int | float | None, default=None,
                        help="resize frames first: a height in px (int, e.g. 360) or a scale (float, e.g. 0.5)")  # fmt: skip
    parser.add_argument("--model_complexity", "--model-complexity", type=int, default=1,
                        help="0, 1 or 2 (only 1 ships with mediapipe; 0 and 2 are downloaded on first use)")  # fmt: skip
    parser.add_argument("--min_detection_confidence", "--min-detection-confidence", type=float, default=0.5,
                        help="MediaPipe's person detector threshold")  # fmt: skip
    parser.add_argument("--on_jump", "--on-jump", type=str, default="keep", help="keep or drop detections that jump")
    parser.add_argument("--overwrite", type=bool, nargs="?", const=True, default=False, help="replace --out")
    return parser


def estimate_pose(argv: list[str]) -> int:
    """``lit-boot estimate-pose``: MediaPipe Pose on a video -> pose file; one summary line."""
    args = _estimate_pose_parser().parse_args(argv)
    from .estimate import MediaPipeUnavailable, estimate_pose_file

    options = {k: args[k] for k in ("stride", "max_frames", "resize", "model_complexity",
                                    "min_detection_confidence", "on_jump")}  # fmt: skip
    try:
        with drop_native_noise():
            _, summary = estimate_pose_file(args.video, args.out, overwrite=args.overwrite, **options)
    except MediaPipeUnavailable as err:
        raise CliError(str(err)) from None
    print(f"{summary}; wrote {args.out}")
    return 0


def import_scene(argv: list[str]) -> int:
    """``lit-boot import KIND ... --out DIR``: see :mod:`lit_boot.import_cli`."""
    from .import_cli import import_scene as run

    return run(argv)


def lightning(argv: list[str]) -> int:
    """``lit-boot fit|validate|predict``: Lightning's CLI over lit-boot's modules and data."""
    from .lightning_cli import run_lightning_cli

    trainer = run_lightning_cli(argv).trainer
    print(f"run folder: {trainer.default_root_dir} (this run's logs: {trainer.log_dir})")
    return 0


COMMANDS = {"synth": synth, "import": import_scene, "bootstrap": bootstrap, "demo": demo, "estimate-pose": estimate_pose,
            "fit": lightning, "validate": lightning, "predict": lightning}

#: The parsers ``COMMAND --help`` answers from before the command runs (and imports what it needs).
PARSERS = {"synth": _synth_parser, "bootstrap": _bootstrap_parser, "demo": _demo_parser,
           "estimate-pose": _estimate_pose_parser}  # fmt: skip

#: One line per command for ``lit-boot --help``.
SUMMARIES = {
    "synth": "write a synthetic human scene folder with exact ground truth (flow, joints, masks)",
    "import": "read a dataset scene (MPI-Sintel, 3DPW, Human3.6M) or a video into a scene folder",
    "bootstrap": "run the method (flow -> pose -> flow) on a scene folder or a video; reruns resume",
    "demo": "make a small synthetic scene, bootstrap it, print EPE and MPJPE before and after",
    "estimate-pose": "MediaPipe Pose on a video: 2D keypoints, 3D joints and cameras to a pose file",
    "fit": "train one stage's model (FlowTTT, PoseRefiner, ...) on one scene (Lightning's CLI)",
    "validate": "evaluate one stage's model on one scene without training (Lightning's CLI)",
    "predict": "write one stage's predictions (e.g. flow files) for one scene (Lightning's CLI)",
}


def usage() -> str:
    """``lit-boot --help``: the commands with one line each."""
    rows = "\n".join(f"  {name:<14} {SUMMARIES[name]}" for name in COMMANDS)
    return (
        "usage: lit-boot [--verbose] COMMAND [options]\n\n"
        "Test-time bootstrapping of human optical flow and human pose.\n\n"
        f"commands:\n{rows}\n\n"
        "options:\n"
        "  -h, --help     show this message; lit-boot COMMAND --help shows a command's options\n"
        "  --verbose      keep Lightning's info lines and all dependency warnings (or LIT_BOOT_VERBOSE=1)"
    )


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``lit-boot`` console script: exit status 0, or 2 with one error line."""
    argv = sys.argv[1:] if argv is None else list(argv)
    verbose = verbose_requested()
    if argv[:1] == ["--verbose"]:
        argv, verbose = argv[1:], True
    if not argv or argv[0] in ("-h", "--help"):
        print(usage())
        return 0
    name = argv[0]
    if name not in COMMANDS:
        print(f"lit-boot: error: unknown command {name!r}; one of {', '.join(COMMANDS)} (lit-boot --help)",
              file=sys.stderr)  # fmt: skip
        return 2
    try:
        if name in PARSERS and any(arg in ("-h", "--help") for arg in argv[1:]):
            PARSERS[name]().parse_args(argv[1:])  # prints the help and exits
        with command_output(verbose):
            return COMMANDS[name](argv if COMMANDS[name] is lightning else argv[1:])
    except Exception as err:
        if not is_user_error(err):
            raise
        hint = f" (lit-boot {name} --help lists the options)" if isinstance(err, ArgumentError) else ""
        print(f"lit-boot {name}: error: {error_line(err)}{hint}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
