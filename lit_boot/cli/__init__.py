"""The ``lit-boot`` command line: :func:`main` (the console script) and the table of commands.

Commands, one module per group (each imported only when one of its commands runs):

- ``lit-boot synth --out DIR [--motion walk --frames 24 ...]`` (:mod:`.synthetic`): a synthetic
  scene folder with exact ground truth; every field of :class:`lit_boot.synth.SynthConfig` is an
  option.
- ``lit-boot import {sintel,3dpw,h36m,video} ... --out DIR`` and ``lit-boot estimate-pose VIDEO
  --out poses.npz`` (:mod:`.importing`): a dataset scene or a video (with a pose file, or
  MediaPipe poses) into a scene folder; MediaPipe Pose on a video to a pose file.
- ``lit-boot ids SCENE_OR_POSES [--sheet ids.png] [--fix "swap 1 2 at 7-" --out FIXED]``
  (:mod:`.ids`): the frames where a person's id may have switched, drawn; a copy with ids fixed.
- ``lit-boot bootstrap --config configs/bootstrap.yaml --data.scene DIR [--out RUN]`` (or
  ``--data.video VIDEO``) and ``lit-boot demo`` (:mod:`.runs`): the whole method (flow -> pose
  -> flow) on one scene, resumed when rerun; the demo on a small synthetic scene.
- ``lit-boot bootstrap-many SOURCE PATH [--out DIR] [--engine local|ray --workers N]``
  (:mod:`.dataset`): the method on every scene of a dataset, resumable, with a summary table.
- ``lit-boot report RUN_DIR [--scene DIR]`` (:mod:`.reporting`): report.html for a finished run
  folder, or a dataset run's (each scene's, and the page linking them).
- ``lit-boot fit|validate|predict --config configs/flow_ttt.yaml --data.scene DIR``
  (:mod:`.lightning`): a LightningModule (FlowTTT ...) on one scene through a LightningCLI
  subclass; the run goes to ``runs/<scene>/<model>`` unless ``--trainer.default_root_dir`` says
  otherwise.

``--print_config`` shows every option as YAML and ``--config FILE`` reads them from one.

Nothing heavy (torch, Lightning) is imported before a command's arguments are parsed, so
``lit-boot --help`` and ``lit-boot COMMAND --help`` answer at once. A command prints lit-boot's
own lines (its log records) and progress bars; Lightning's info lines and known dependency
warnings are dropped (:mod:`.console`) unless ``lit-boot --verbose COMMAND ...`` or
``LIT_BOOT_VERBOSE=1``. A bad argument or input file is one ``lit-boot COMMAND: error: ...``
line on stderr, naming the option or file, and exit status 2; an unknown option gets the closest
known one ("did you mean"). Ctrl-C is one line, ``lit-boot bootstrap: interrupted after flow_1;
rerun the same command to resume`` (the run's last finished stage), and exit status 130.
Options are spelled with ``_`` or ``-`` alike (``--flow_epochs``, ``--flow-epochs``).
"""

from __future__ import annotations

import contextlib
import importlib
import os
import sys
from argparse import ArgumentError
from typing import Callable, NamedTuple

from .console import command_output, error_line, is_user_error, normalize_options, verbose_requested

__all__ = ["main", "COMMANDS", "Command"]


class Command(NamedTuple):
    """A command: ``function`` of module ``lit_boot.cli.<module>`` runs it with the arguments after
    its name (``with_name``: with its name first, as Lightning's CLI wants); ``summary`` is its
    line in ``lit-boot --help``."""

    module: str
    function: str
    summary: str
    with_name: bool = False

    def load(self) -> Callable[[list[str]], int]:
        return getattr(importlib.import_module(f".{self.module}", __name__), self.function)


def _lightning(summary: str) -> Command:
    return Command("lightning", "lightning", summary + " (Lightning's CLI)", with_name=True)


COMMANDS: dict[str, Command] = {
    "synth": Command("synthetic", "synth",
                     "write a synthetic human scene folder with exact ground truth (flow, joints, masks)"),
    "import": Command("importing", "import_scene",
                      "read a dataset scene (MPI-Sintel, 3DPW, Human3.6M) or a video into a scene folder"),
    "bootstrap": Command("runs", "bootstrap",
                         "run the method (flow -> pose -> flow) on a scene folder or a video; reruns resume"),
    "bootstrap-many": Command("dataset", "bootstrap_many",
                              "run the method on every scene of a dataset (Sintel, 3DPW, H36M, videos); "
                              "resumable, Ray"),
    "demo": Command("runs", "demo", "make a small synthetic scene, bootstrap it, print EPE and MPJPE before and after"),
    "report": Command("reporting", "report",
                      "write report.html for a finished run (or a dataset run): did the video get better, and where"),
    "estimate-pose": Command("importing", "estimate_pose",
                             "MediaPipe Pose on a video: 2D keypoints, 3D joints and cameras to a pose file"),
    "ids": Command("ids", "ids",
                   "check the people's ids of a scene or pose file (the frames to look at, drawn) and fix them"),
    "fit": _lightning("train one stage's model (FlowTTT, PoseRefiner, ...) on one scene"),
    "validate": _lightning("evaluate one stage's model on one scene without training"),
    "predict": _lightning("write one stage's predictions (e.g. flow files) for one scene"),
}  # fmt: skip


def usage() -> str:
    """``lit-boot --help``: the commands with one line each."""
    rows = "\n".join(f"  {name:<14} {command.summary}" for name, command in COMMANDS.items())
    return (
        "usage: lit-boot [--verbose] COMMAND [options]\n\n"
        "Test-time bootstrapping of human optical flow and human pose.\n\n"
        f"commands:\n{rows}\n\n"
        "options:\n"
        "  -h, --help     show this message; lit-boot COMMAND --help shows a command's options\n"
        "  --verbose      keep Lightning's info lines and all dependency warnings (or LIT_BOOT_VERBOSE=1)"
    )


def interrupted_line(err: KeyboardInterrupt) -> str:
    """What Ctrl-C stopped: ``interrupted after flow_1; rerun the same command to resume`` for a
    run (:class:`~lit_boot.bootstrap.RunInterrupted`), else ``interrupted``."""
    from ..bootstrap.interrupt import RunInterrupted  # signal and threading only

    if isinstance(err, RunInterrupted):
        return f"interrupted {err.where}; rerun the same command to resume"
    return "interrupted"


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``lit-boot`` console script: exit status 0, 2 with one error line, or
    130 with one line after Ctrl-C (``COMMAND --help`` exits through SystemExit(0), as argparse
    does). Output cut off by its reader (``lit-boot --help | head``) ends it quietly, status 141
    (128 + SIGPIPE, as the shells count it)."""
    try:
        try:
            return _main(sys.argv[1:] if argv is None else list(argv))
        finally:
            sys.stdout.flush()  # a reader that went away shows here, not as a message at exit
    except BrokenPipeError:
        with contextlib.suppress(OSError, ValueError):  # nothing more reaches it, at exit neither
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141


def _main(argv: list[str]) -> int:
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
    command, argv = COMMANDS[name], normalize_options(argv)  # --flow-epochs is --flow_epochs
    try:
        with command_output(verbose):
            return command.load()(argv if command.with_name else argv[1:])
    except BrokenPipeError:
        raise
    except KeyboardInterrupt as err:
        sys.stdout.flush()
        start = "\n" if sys.stderr.isatty() else ""  # off the line of ^C and a cut-off progress bar
        print(f"{start}lit-boot {name}: {interrupted_line(err)}", file=sys.stderr)
        return 130
    except Exception as err:
        if not is_user_error(err):
            raise
        hint = f" (lit-boot {name} --help lists the options)" if isinstance(err, ArgumentError) else ""
        print(f"lit-boot {name}: error: {error_line(err)}{hint}", file=sys.stderr)
        return 2
