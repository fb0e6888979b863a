"""What the ``lit-boot`` command prints: its own lines, progress bars, and errors as one line;
and the parsers' shared pieces.

Cheap to import (no torch, no Lightning): the command line parses, and answers ``--help``, first.

- :class:`ArgumentParser`: jsonargparse's parser with the command line's defaults (no abbreviated
  options, "did you mean" for an unknown one; a bad argument raises instead of printing the whole
  usage); :func:`normalize_options`: ``--flow-epochs`` is ``--flow_epochs`` (every command takes
  both spellings); :func:`dataclass_from`
  builds a settings dataclass from the options its fields made; :func:`set_help` fills or
  replaces the help of options made from a signature; :func:`refuse_to_overwrite` guards ``--out``;
- :func:`command_output`: around each command: lit-boot's log records (``lit_boot.*``) to stdout
  as plain lines; Lightning's info lines (accelerator summary, tips, model summary, "Seed set
  to") and the known dependency warnings off; ``lit-boot --verbose`` (or ``LIT_BOOT_VERBOSE=1``)
  keeps everything;
- :func:`error_line`: an exception (jsonargparse's multi-line ones included) as one line;
- :func:`drop_native_noise`: MediaPipe's native start-up lines removed from stderr.
"""

from __future__ import annotations

import argparse
import dataclasses
import difflib
import logging
import os
import re
import sys
import threading
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any, get_type_hints

import jsonargparse

from ..quiet import keep_lightning, quiet_lightning

__all__ = ["ArgumentParser", "CliError", "HelpFormatter", "Suggesting", "command_output", "dataclass_from",
           "drop_native_noise", "error_line", "is_user_error", "normalize_options", "plain", "refuse_to_overwrite",
           "set_help", "suggest_options", "verbose_requested"]

#: MediaPipe's native (C++) start-up lines on stderr: TFLite's delegate notice, absl's pre-init note
#: and its feedback-tensor warning (once per model).
NATIVE_NOISE = re.compile(
    r"INFO: Created TensorFlow Lite XNNPACK delegate for CPU\."
    r"|WARNING: All log messages before absl::InitializeLog\(\) is called are written to STDERR"
    r"|W\d{4} [\d:.]+ +\d+ inference_feedback_manager\.cc:\d+\] Feedback manager requires a model with a single"
)


class CliError(Exception):
    """A user error: printed as one line, exit status 2."""


def plain(text: str) -> str:
    """``text`` without reST markup: ``x`` -> x, :func:`~a.b` -> b, :class:`a.X` -> a.X."""
    text = re.sub(r":\w+:`(~?)([^`]+)`", lambda m: m.group(2).rsplit(".", 1)[-1] if m.group(1) else m.group(2), text)
    return re.sub(r"``([^`]+)``", r"\1", text)


class HelpFormatter(jsonargparse.DefaultHelpFormatter):
    """jsonargparse's help as plain text (docstrings' reST markup removed), with a class type shown
    by name (``Path``, not ``<class 'Path'>``)."""

    def _get_type_str(self, action: argparse.Action) -> str | None:
        hint = action.type if action.type is not None else getattr(action, "_typehint", None)
        return hint.__name__ if isinstance(hint, type) else super()._get_type_str(action)

    def _expand_help(self, action: argparse.Action) -> str:
        return plain(super()._expand_help(action))

    def _format_text(self, text: str) -> str:
        return super()._format_text(plain(text))

    def start_section(self, heading: str | None) -> None:
        super().start_section(plain(heading) if heading else heading)


def normalize_options(argv: Sequence[str]) -> list[str]:
    """``argv`` with ``-`` in option names spelled ``_`` (``--flow-epochs 2`` ->
    ``--flow_epochs 2``, ``--data.max-frames=3`` -> ``--data.max_frames=3``): every lit-boot
    option is spelled with underscores, and both spellings are taken. Values, and everything
    after a bare ``--``, are left as they are."""
    out, rest = [], False
    for arg in argv:
        if arg == "--":
            rest = True
        elif not rest and arg.startswith("--") and len(arg) > 2 and not arg[2].isdigit():
            name, sep, value = arg[2:].partition("=")
            arg = "--" + name.replace("-", "_") + sep + value
        out.append(arg)
    return out


def suggest_options(message: str, known: Iterable[str]) -> str:
    """``message`` ("unrecognized arguments: --flow_epoch 2") with the closest known option of
    each unknown one added ("; did you mean --flow_epochs?"); as it is when none is close."""
    match = re.match(r"unrecognized arguments: (.*)$", message, re.S)
    if not match or "; did you mean" in message:  # a nested parser's error passes through its parent's
        return message
    known = sorted({k for k in known if k.startswith("--")})
    hints = []
    for arg in match.group(1).split():
        name = arg.split("=", 1)[0]
        if name.startswith("--") and name not in known:
            close = difflib.get_close_matches(name, known, n=1, cutoff=0.75)
            hints += [(close[0], name)] if close else []
    if len(hints) > 1:
        return message + "; did you mean " + ", ".join(f"{option} (for {name})" for option, name in hints) + "?"
    return message + (f"; did you mean {hints[0][0]}?" if hints else "")


class Suggesting:
    """A parser mixin: an unknown option's error names the closest known one
    (:func:`suggest_options`)."""

    def error(self, message: str, ex: Exception | None = None):
        return super().error(suggest_options(message, self._option_string_actions), ex)


class ArgumentParser(Suggesting, jsonargparse.ArgumentParser):
    """jsonargparse's ArgumentParser, but ``--epoch`` is not taken for ``--epochs`` (it is an
    error that suggests ``--epochs``) and a bad argument raises :class:`argparse.ArgumentError`
    (``main()`` prints it as one line)."""

    def __init__(self, *args, allow_abbrev: bool = False, exit_on_error: bool = False, **kwargs) -> None:
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, allow_abbrev=allow_abbrev, exit_on_error=exit_on_error, **kwargs)


def dataclass_from(args: jsonargparse.Namespace, cls: type) -> Any:
    """An instance of the dataclass ``cls`` from parsed options named after its fields (added by
    ``add_class_arguments(cls, nested_key=None)``); a nested dataclass field's options
    (``--estimates.mpjpe_mm``) make that field's instance. Fields without an option (skipped
    when the parser was built) keep their defaults."""
    hints = get_type_hints(cls)

    def value(name: str) -> Any:
        given, hint = args[name], hints[name]
        nested = isinstance(hint, type) and dataclasses.is_dataclass(hint) and isinstance(given, jsonargparse.Namespace)
        return dataclass_from(given, hint) if nested else given

    return cls(**{f.name: value(f.name) for f in dataclasses.fields(cls) if f.init and f.name in args})


def set_help(parser: jsonargparse.ArgumentParser, helps: dict[str, str], replace: bool = False) -> None:
    """Give the options ``helps`` names (by destination) that help text: only where they have none
    (jsonargparse takes help from "Args:" docstrings), or always with ``replace``."""
    for action in parser._actions:
        if action.dest in helps and (replace or action.help is None):
            action.help = helps[action.dest]


def refuse_to_overwrite(out: Path, overwrite: bool, what: str = "it") -> None:
    """Raise :class:`CliError` when ``--out`` ``out`` exists and is not an empty folder, unless
    ``overwrite``; the message says to pass ``--overwrite true`` to replace ``what``."""
    if out.exists() and not overwrite and (not out.is_dir() or any(out.iterdir())):
        raise CliError(f"--out {out}: exists and is not empty (pass --overwrite true to replace {what})")


def verbose_requested() -> bool:
    """True when ``LIT_BOOT_VERBOSE`` is set to anything but ``""``/``0``."""
    return os.environ.get("LIT_BOOT_VERBOSE", "") not in ("", "0")


_verbose = False  # inside command_output(verbose=True): drop_native_noise keeps everything


class _Stdout(logging.StreamHandler):
    """A handler writing to the current ``sys.stdout`` (a redirect or pytest's capture included)."""

    @property
    def stream(self):
        return sys.stdout

    @stream.setter
    def stream(self, value) -> None:
        pass


@contextmanager
def command_output(verbose: bool = False) -> Iterator[None]:
    """Within the block (one command): lit-boot's log records (``lit_boot.*``, INFO and up; DEBUG
    too with ``verbose``) go to stdout as plain lines, and only there (not on to the root
    logger's handlers); unless ``verbose``, Lightning's info lines and the known dependency
    warnings are dropped and every other warning from Lightning or torch* shows once per message
    (:func:`lit_boot.quiet.quiet_lightning`). The handler is removed and the levels restored after."""
    global _verbose
    ours = logging.getLogger("lit_boot")
    handler = _Stdout()
    handler.setFormatter(logging.Formatter("%(message)s"))
    level, propagate = ours.level, ours.propagate
    ours.addHandler(handler)
    ours.setLevel(logging.DEBUG if verbose else logging.INFO)
    ours.propagate = False
    was_verbose, _verbose = _verbose, verbose
    with keep_lightning() if verbose else quiet_lightning():
        try:
            yield
        finally:
            _verbose = was_verbose
            ours.removeHandler(handler)
            ours.propagate = propagate
            ours.setLevel(level)


_PARSER_KEY = re.compile(r'Parser key "([^"]+)":\s*')
_EXPECTED = re.compile(r"Expected a <class '(\w+)'>")
_LITERAL = re.compile(r"Expected a typing\.Literal\[(.+)\]")
_UNION = "Does not validate against any of the Union subtypes"


def error_line(err: BaseException) -> str:
    """``err`` as one line: jsonargparse's ``Parser key "x":`` as ``--x:``, its union reports as the
    reasons that are not "expected None", no ``Namespace(...)`` dumps; an OSError as "path:
    reason" (no errno)."""
    text = str(err).strip()
    if isinstance(err, OSError) and err.filename is not None and err.strerror:  # not "[Errno 13] ..."
        text = f"{err.filename}: {err.strerror}" + (f" ({err.filename2})" if err.filename2 else "")
    if _UNION in text:
        text = _union_reasons(text)
    text = _PARSER_KEY.sub(lambda m: f"--{m.group(1)}: ", text)
    text = re.sub(r"Key \"([^\"]+)\" is required but not included in config object or its value is None\.?",
                  r"--\1 is required", text)  # fmt: skip
    text = re.sub(r"Expected a <class '(\w+)'>\. Got value: (.+)$", r"expected \1, got '\2'", text, flags=re.M)
    text = _EXPECTED.sub(r"expected \1", text)
    return " ".join(line.strip() for line in text.splitlines() if line.strip())


def _union_reasons(text: str) -> str:
    """A jsonargparse union report as its head (``Parser key "x":``) and the subtypes' reasons."""
    head, _, rest = text.partition(_UNION)
    key = match.group(1) if (match := _PARSER_KEY.search(head)) else None
    errors = rest.partition("Errors:")[2].partition("Given value type:")[0]
    indent = match.group(1) if (match := re.search(r"^([ \t]*)- ", errors, re.M)) else ""
    items = [" ".join(item.split()) for item in re.split(rf"^{indent}- ", errors, flags=re.M) if item.strip()]
    items = [item for item in items if item != "Expected a <class 'NoneType'>"]
    expected = [match.group(1) for item in items if (match := _EXPECTED.fullmatch(item) or _LITERAL.fullmatch(item))]
    real = [_class_problem(item, key) for item in items if not (_EXPECTED.fullmatch(item) or _LITERAL.fullmatch(item))]
    if real:  # a class's problem names its options in full (--data.scene): the head (--data) adds nothing
        named = key is not None and any(item.startswith("Problem with given class_path") for item in items)
        return ("" if named else head) + "; ".join(real)
    got = match.group(1).strip() if (match := re.search(r"Given value: (.*)$", text, re.S)) else ""
    return head + f"expected {' or '.join(expected)}" + (f", got {got!r}" if got else "") if expected else text


def _class_problem(item: str, key: str | None) -> str:
    """``Problem with given class_path 'C': <reason>`` as ``C: <reason>``, the options in the reason
    named in full (``--data.scene``)."""
    match = re.fullmatch(r"Problem with given class_path '([\w.]+)':\s*(.*)", item)
    if match is None or key is None:
        return item
    cls, reason = match.groups()
    reason = _PARSER_KEY.sub(lambda m: f"--{key}.{m.group(1)}: ", reason)
    missing = re.fullmatch(r"the following arguments are required: (.+)", reason)
    if missing:
        names = [f"--{key}.{name.strip()}" for name in missing.group(1).split(",")]
        reason = " and ".join(names) + (" is" if len(names) == 1 else " are") + " required"
    return f"{cls}: {reason}"


def is_user_error(err: BaseException) -> bool:
    """Whether ``main()`` reports ``err`` as one line with exit status 2 (no traceback)."""
    return isinstance(err, (CliError, argparse.ArgumentError, ValueError, OSError))


@contextmanager
def drop_native_noise(pattern: re.Pattern[str] = NATIVE_NOISE) -> Iterator[None]:
    """Within the block, stderr (file descriptor 2, where native libraries write) goes through a
    pipe; lines matching ``pattern`` are dropped, everything else is passed on as it comes.
    Does nothing within ``command_output(verbose=True)``."""
    if _verbose:
        yield
        return
    sys.stderr.flush()
    saved = os.dup(2)
    read_end, write_end = os.pipe()
    os.dup2(write_end, 2)
    os.close(write_end)
    thread = threading.Thread(target=_pass_on, args=(read_end, saved, pattern), daemon=True)
    thread.start()
    try:
        yield
    finally:
        sys.stderr.flush()
        os.dup2(saved, 2)  # closes the pipe's last write end: the thread reads to the end and stops
        thread.join(timeout=10)
        os.close(saved)


def _pass_on(read_end: int, out: int, pattern: re.Pattern[str]) -> None:
    """Copy lines (ending in \\n or \\r, so progress bars move) from ``read_end`` to ``out``, but
    those matching ``pattern``."""
    pending = b""
    with os.fdopen(read_end, "rb", buffering=0) as pipe:
        while chunk := pipe.read(65536):
            pending += chunk
            *lines, pending = re.split(rb"(?<=[\r\n])", pending)
            for line in lines:
                if not pattern.match(line.decode(errors="replace")):
                    os.write(out, line)
    if pending and not pattern.match(pending.decode(errors="replace")):
        os.write(out, pending)
