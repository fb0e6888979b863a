"""A whole dataset from the command line: ``lit-boot bootstrap-many SOURCE PATH [--out DIR]``.

SOURCE says what PATH is (:func:`lit_boot.dataset.discover`): ``sintel`` (an MPI-Sintel root;
``--scenes human`` the paper's human scenes), ``3dpw`` (a 3DPW root, ``--split``), ``h36m`` (a
Human3.6M root, ``--subjects S9,S11``), ``videos`` (a folder of videos, each with an optional
pose file of the same name), ``scenes`` (a folder of scene folders) or ``list`` (a file listing
scenes or videos). Every scene runs with the same bootstrap options (``--config`` YAML and
BootstrapConfig's fields, as ``lit-boot bootstrap``), on ``--engine local`` (``--workers N``
processes; 0 = in this process) or ``--engine ray`` (``--ray_address`` to join a cluster).
A rerun resumes: it runs only what is not done.
"""

from __future__ import annotations

from pathlib import Path

from jsonargparse import ActionConfigFile

from .console import ArgumentParser, CliError

__all__ = ["bootstrap_many", "bootstrap_many_parser", "SOURCES"]

SOURCES = ("sintel", "3dpw", "h36m", "videos", "scenes", "list")


def _names(text: str | None) -> list[str] | str | None:
    """A comma-separated list of names ("human" and None stay as they are)."""
    if text is None or text == "human":
        return text
    return [t.strip() for t in text.split(",") if t.strip()]


def bootstrap_many_parser() -> ArgumentParser:
    """The parser of ``lit-boot bootstrap-many``: the source, the run's engine and folder, and
    BootstrapConfig's fields."""
    from ..bootstrap import BootstrapConfig

    parser = ArgumentParser(prog="lit-boot bootstrap-many", description=(
        "Bootstrap flow and pose on every scene of a dataset: one task per scene (long ones in overlapping "
        "chunks), resumable, on local worker processes or Ray; a summary table with the dataset metrics."))  # fmt: skip
    parser.add_argument("--config", action=ActionConfigFile, help="YAML file with the options below")
    parser.add_argument("source", type=str, help=f"what PATH is: {', '.join(SOURCES)}")
    parser.add_argument("path", type=Path, help="the dataset root, folder or list file (never written)")
    parser.add_argument("--scenes", type=str | None, default=None,
                        help="sintel: scene names (comma-separated) or 'human'; 3dpw: sequences; h36m: actions")  # fmt: skip
    parser.add_argument("--split", type=str, default="test", help="3dpw: train, validation or test")
    parser.add_argument("--subjects", type=str, default="S9,S11", help="h36m: subjects (comma-separated)")
    parser.add_argument("--poses", type=Path | None, default=None,
                        help="a folder of pose files named after the scenes (<name>.npz / .json); a scene with "
                             "none and no estimates of its own gets MediaPipe Pose")  # fmt: skip
    parser.add_argument("--reader", type=dict | None, default=None,
                        help="reader arguments for every scene, e.g. '{size: [218, 512]}' (sintel, 3dpw) or "
                             "'{resize: 360}' (videos)")  # fmt: skip
    parser.add_argument("--out", type=Path | None, default=None, help="dataset folder (default runs/<source>_<name>)")
    parser.add_argument("--engine", type=str, default="local", help="local or ray")
    parser.add_argument("--workers", type=int, default=1,
                        help="local: worker processes (one GPU each when there are GPUs; 0 = in this process)")  # fmt: skip
    parser.add_argument("--threads", type=int | None, default=None, help="CPU threads per task (default: cores / workers)")
    parser.add_argument("--retries", type=int, default=2, help="retries of a task whose worker was lost")
    parser.add_argument("--ray_address", "--ray-address", type=str | None, default=None,
                        help="ray: the cluster to join (e.g. auto or ray://host:10001); default a local instance")  # fmt: skip
    parser.add_argument("--chunk_frames", "--chunk-frames", type=int | None, default=None, help="split longer scenes into chunks of N frames")
    parser.add_argument("--chunk_overlap", "--chunk-overlap", type=int, default=8, help="frames shared by consecutive chunks")
    parser.add_argument("--overwrite", type=bool, default=False, help="delete the dataset folder's results first")
    parser.add_class_arguments(BootstrapConfig, nested_key=None, as_group=False, skip={"progress_bar"})
    return parser


def _options(args) -> dict:
    """discover()'s options of the chosen source."""
    from ..dataset.sources import READER_SOURCES

    source, scenes = args.source, _names(args.scenes)
    options = {"poses": args.poses}
    if args.reader:
        if source not in READER_SOURCES:
            raise CliError(f"--reader: only for sources {', '.join(READER_SOURCES)} (not {source})")
        options["reader_args"] = dict(args.reader)
    if source == "sintel":
        return {**options, "scenes": scenes}
    if source == "3dpw":
        return {**options, "split": args.split, "sequences": scenes}
    if source == "h36m":
        return {**options, "subjects": tuple(_names(args.subjects) or ()), "actions": scenes}
    return options


def bootstrap_many(argv: list[str]) -> int:
    """``lit-boot bootstrap-many``: discover the tasks, run (or resume) them, print the summary."""
    from .console import dataclass_from

    args = bootstrap_many_parser().parse_args(argv)
    if args.source not in SOURCES:
        raise CliError(f"source {args.source!r}: one of {', '.join(SOURCES)}")
    from ..bootstrap import BootstrapConfig
    from ..dataset import discover, run_dataset

    tasks = discover(args.source, args.path, **_options(args))
    out = args.out or Path("runs") / f"{args.source}_{args.path.resolve().name}"
    config = dataclass_from(args, BootstrapConfig)
    print(f"lit-boot bootstrap-many: {len(tasks)} scene(s) from {args.path} ({args.source}) into {out}", flush=True)
    result = run_dataset(tasks, out, config, engine=args.engine, workers=args.workers, threads=args.threads,
                         retries=args.retries, ray_address=args.ray_address, chunk_frames=args.chunk_frames,
                         chunk_overlap=args.chunk_overlap, overwrite=args.overwrite, progress=True)  # fmt: skip
    print(result.table())
    counts = ", ".join(f"{n} {state}" for state, n in result.counts.items() if n)
    print(f"{counts}; wrote {result.summary_md}, {result.summary_csv} and {out / 'manifest.json'}")
    return 1 if result.counts.get("failed") else 0
