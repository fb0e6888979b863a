"""The whole method from the command line: ``lit-boot bootstrap`` and ``lit-boot demo``.

- ``lit-boot bootstrap --config configs/bootstrap.yaml --data.scene DIR [--out RUN]`` runs
  (or resumes) flow -> pose -> flow on a scene folder, or on ``--data.video PATH`` (poses from
  ``--data.poses FILE``, else MediaPipe Pose). Every field of
  :class:`lit_boot.bootstrap.BootstrapConfig` is an option, read from the dataclass.
- ``lit-boot demo [--quick]`` makes a small synthetic scene (its options are
  :class:`lit_boot.synth.SynthConfig`'s fields of the same names, with the demo's defaults),
  bootstraps it and prints the before/after table.

The stages' lines come from the runner's log records (see :func:`~lit_boot.cli.console.command_output`).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from jsonargparse import ActionConfigFile

from .checks import check_input_paths, check_video_options, name_option
from .console import ArgumentParser, CliError, dataclass_from, set_help

__all__ = ["bootstrap", "bootstrap_parser", "demo", "demo_parser", "DEMO_SCENE"]

#: The demo scene's SynthConfig fields (the demo's options) and their defaults: small, so that it
#: runs in minutes on a CPU.
DEMO_SCENE = {"motion": "run", "frames": 8, "height": 128, "width": 256, "seed": 0}


def bootstrap_parser() -> ArgumentParser:
    """The parser of ``lit-boot bootstrap``: the input (``--data.*``; read_video's options, written
    out because its module imports torch and the help must not), the run folder, and
    BootstrapConfig's fields."""
    from ..bootstrap import BootstrapConfig

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
    parser.set_defaults(progress_bar=True)  # the command shows its bars (from Python, the config's default)
    return parser


def _options(parser: ArgumentParser) -> list[str]:
    return list(parser._option_string_actions)


def bootstrap(argv: list[str]) -> int:
    """``lit-boot bootstrap``: run (or resume) the method on one scene; print the table. The
    inputs and the settings are checked before torch is imported; an error from a setting names
    its option."""
    parser = bootstrap_parser()
    args = parser.parse_args(argv)
    from ..bootstrap import BootstrapConfig

    data = args.data
    if (data.scene is None) == (data.video is None):
        raise CliError("give one of --data.scene DIR (a scene folder) or --data.video PATH (a video or frame folder)")
    check_input_paths(data.scene, data.video, data.poses)
    check_video_options("data.", data.stride, data.max_frames, data.resize)
    try:
        config = dataclass_from(args, BootstrapConfig)
    except ValueError as err:
        raise name_option(err, _options(parser)) from err
    aliases = {key: f"--flow.{key}" for key in config.flow} | {key: f"--pose.{key}" for key in config.pose}
    try:
        return _run_bootstrap(args, config)
    except ValueError as err:  # a FlowTTT / refiner argument the user gave, checked when it is built
        raise name_option(err, _options(parser), aliases) from err


def _run_bootstrap(args, config) -> int:
    from ..bootstrap import Bootstrap

    data = args.data
    scene, out = data.scene, args.out
    if data.video is not None:
        from ..data.readers import read_video
        from .importing import with_poses

        scene = read_video(data.video, stride=data.stride, max_frames=data.max_frames, resize=data.resize,
                           poses=data.poses)  # fmt: skip
        scene = with_poses(scene, None, estimate=data.poses is None)
        out = out or Path("runs") / data.video.stem / "bootstrap"
    result = Bootstrap(scene, out, config, overwrite=args.overwrite).run()
    print(result.table())
    print(f"wrote {result.run_dir}")
    return 0


def demo_parser() -> ArgumentParser:
    """The parser of ``lit-boot demo``: SynthConfig's :data:`DEMO_SCENE` fields, and FlowTTT's
    ``arch`` and ``weights`` (written out: FlowTTT's module imports Lightning, the help must not)."""
    from ..synth import SynthConfig

    parser = ArgumentParser(prog="lit-boot demo", description=(
        "Make a synthetic scene with exact ground truth, bootstrap it (flow -> pose -> flow) with RAFT-small "
        "weights found in checkpoints/ (or downloaded), and print EPE and MPJPE before and after. "
        "--quick: 2 epochs per flow stage instead of 8 (a smaller gain; the fixed costs stay)."))  # fmt: skip
    parser.add_argument("--quick", type=bool, nargs="?", const=True, default=False,
                        help="the same scene, 2 epochs per flow stage, into runs/demo_quick")  # fmt: skip
    parser.add_argument("--out", type=Path | None, default=None,
                        help="folder for the scene and the run (default runs/demo, runs/demo_quick)")  # fmt: skip
    parser.add_class_arguments(SynthConfig, nested_key=None, as_group=False,
                               skip=set(SynthConfig.__dataclass_fields__) - set(DEMO_SCENE))  # fmt: skip
    parser.set_defaults(DEMO_SCENE)
    set_help(parser, {"motion": "walk, run, wave, jump, turn"}, replace=True)  # the demo takes no --bvh
    parser.add_argument("--arch", type=str, default="raft_small", help="raft_small or raft_large")
    parser.add_argument("--weights", type=str, default="C_T_V1", help="a file or torchvision name (looked up locally first)")
    parser.add_argument("--epochs", type=int | None, default=None, help="FlowTTT epochs per flow stage (8; --quick 2)")
    parser.add_argument("--overwrite", type=bool, default=False, help="start again instead of resuming")
    return parser


def demo_minutes(frames: int, height: int, width: int, epochs: int) -> float:
    """About how long the demo takes from scratch on 2 free CPU cores, minutes. Measured
    (BENCHMARKS.md, "Current results": 25 s, --quick 20 s): ~20 s of start-up, RAFT, zoom and pose
    stage, plus ~0.06 s per training step (one pair, 2 warm RAFT updates on a crop) at 256x128,
    growing about as the square root of the pixels; far longer on busy cores."""
    steps = 2 * (frames - 1) * epochs  # both flow stages train on every pair
    return (20 + 0.06 * steps * (height * width / (128 * 256)) ** 0.5) / 60


def about(minutes: float) -> str:
    """``about 30 s`` (under 1.5 min: seconds, rounded up to 10) or ``about 4 min``."""
    if minutes < 1.5:
        return f"about {10 * math.ceil(minutes * 6)} s"
    return f"about {round(minutes)} min"


def demo(argv: list[str]) -> int:
    """``lit-boot demo``: synthetic scene -> bootstrap -> before/after table. Prints first what it
    will do and about how long it takes from scratch on a 2-core CPU (measured: see README)."""
    parser = demo_parser()
    args = parser.parse_args(argv)
    from ..synth import SynthConfig

    try:
        SynthConfig(**{k: args[k] for k in DEMO_SCENE})  # its checks, before the banner and torch
    except ValueError as err:
        raise name_option(err, _options(parser)) from err
    if args.epochs is not None and args.epochs < 1:
        raise CliError(f"--epochs: expected an integer >= 1, got {args.epochs}")
    from ..bootstrap import Bootstrap
    from ..data import load_scene, save_scene
    from ..synth import make_scene

    epochs = args.epochs if args.epochs is not None else (2 if args.quick else 8)
    out = args.out or Path("runs/demo_quick" if args.quick else "runs/demo")
    scene_dir, spec_file = out / "scene", out / "demo.json"
    spec = {k: args[k] for k in DEMO_SCENE}
    stored = {**spec, "epochs": epochs}  # another scene or size: start again
    fresh = args.overwrite or not spec_file.is_file() or json.loads(spec_file.read_text()) != stored
    minutes = demo_minutes(args.frames, args.height, args.width, epochs)
    if not fresh and (out / "bootstrap" / "summary.json").is_file():  # finished before: nothing runs again
        print(f"lit-boot demo: {out / 'bootstrap'} holds this demo's finished run; its table again, nothing is run "
              "(--overwrite true starts again)", flush=True)  # fmt: skip
    else:
        print(f"lit-boot demo: a synthetic {args.motion!r} scene ({args.frames} frames, {args.width}x{args.height}, "
              f"exact GT); RAFT-small fine-tuned {epochs} epochs per flow stage, flow -> pose -> flow; from scratch "
              f"{about(minutes)} on 2 free CPU cores" + ("" if args.quick else " (--quick: 2 epochs)"),
              flush=True)  # fmt: skip
    if fresh:
        save_scene(make_scene(**spec), scene_dir, overwrite=True)
        spec_file.write_text(json.dumps(stored) + "\n")
    scene = load_scene(scene_dir)
    print(scene.summary())
    run = Bootstrap(scene_dir, out / "bootstrap", overwrite=fresh, flow_epochs=epochs, progress_bar=True,
                    flow={"arch": args.arch, "weights": args.weights})  # fmt: skip
    result = run.run()
    print(f"\nlit-boot demo: {scene.name}, {scene.num_frames} frames {scene.width}x{scene.height}; "
          "EPE in px (person = GT person mask, joints = at the GT joints), MPJPE in mm")  # fmt: skip
    print(result.table())
    print(f"outputs in {result.run_dir} (report.html: open it in a browser; summary.json, metrics.png, overlay.mp4; "
          f"tensorboard --logdir {result.run_dir / 'logs' / 'tensorboard'})")  # fmt: skip
    return 0
