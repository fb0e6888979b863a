"""RAFT weights: torchvision's own, or original princeton-vl checkpoints converted by key name.

Lookup order for :func:`resolve_weights`:

1. an explicit file path;
2. a known file name in the local checkpoint folders: ``$LIT_BOOT_CHECKPOINTS``, then
   ``./checkpoints`` and the project's ``checkpoints/``;
3. torchvision's download of a weights name (``C_T_V1`` ...) into the first checkpoint folder,
   with its hash check.

Offline with nothing local, the error names the file to place and where. A file whose name is
in :data:`KNOWN_SHA256` is checked against that hash before it is loaded (once per file, size
and mtime per process); a mismatch raises :class:`WeightsHashError`.
"""

from __future__ import annotations

import hashlib
import os
import re
import warnings
from pathlib import Path

import torch
from torchvision.models.optical_flow import Raft_Large_Weights, Raft_Small_Weights

__all__ = [
    "ARCHS",
    "WEIGHT_ENUMS",
    "ORIGINAL_FILES",
    "KNOWN_SHA256",
    "WeightsHashError",
    "check_known_hash",
    "file_sha256",
    "checkpoint_dirs",
    "convert_original_state_dict",
    "load_state_dict_file",
    "resolve_weights",
]

ARCHS = ("raft_small", "raft_large")
WEIGHT_ENUMS = {"raft_small": Raft_Small_Weights, "raft_large": Raft_Large_Weights}
#: Original princeton-vl file names and the torchvision weights they equal.
ORIGINAL_FILES = {
    ("raft_small", "C_T_V1"): "raft-small.pth",
    ("raft_large", "C_T_V1"): "raft-things.pth",
    ("raft_large", "C_T_SKHT_V1"): "raft-sintel.pth",
    ("raft_large", "C_T_SKHT_K_V1"): "raft-kitti.pth",
}

#: The sha256 of known weight files by file name: torchvision's carry the start of theirs in the
#: name (8 hex digits, all that is known here), the original files' is given whole.
#: checkpoints/README.md lists the same (a test compares them).
KNOWN_SHA256 = {
    "raft_small_C_T_V1-ad48884c.pth": "ad48884c",
    "raft_small_C_T_V2-01064c6d.pth": "01064c6d",
    "raft_large_C_T_V1-22a6c225.pth": "22a6c225",
    "raft_large_C_T_V2-1bb1363a.pth": "1bb1363a",
    "raft_large_C_T_SKHT_V1-0b8c9e55.pth": "0b8c9e55",
    "raft_large_C_T_SKHT_V2-ff5fadd5.pth": "ff5fadd5",
    "raft_large_C_T_SKHT_K_V1-4a6a5039.pth": "4a6a5039",
    "raft_large_C_T_SKHT_K_V2-b5c70766.pth": "b5c70766",
    "raft-small.pth": "c7d41b9cc88442bb8aa911dbb33086dac55a226394b142937ff22d5578717332",
}

_PROJECT_CHECKPOINTS = Path(__file__).resolve().parents[2] / "checkpoints"

# (pattern, replacement) applied in order to an original key without its "module." prefix.
_RULES = [
    (r"^fnet\.", "feature_encoder."),
    (r"^cnet\.", "context_encoder."),
    (r"^(feature_encoder|context_encoder)\.conv1\.", r"\1.convnormrelu.0."),
    (r"^(feature_encoder|context_encoder)\.norm1\.", r"\1.convnormrelu.1."),
    (r"^(feature_encoder|context_encoder)\.conv2\.", r"\1.conv."),
    (r"\.(layer\d\.\d)\.conv(\d)\.", r".\1.convnormrelu\2.0."),
    (r"\.(layer\d\.\d)\.norm(\d)\.", r".\1.norm\2."),  # resolved per block below
    (r"^update_block\.encoder\.convc(\d)\.", r"update_block.motion_encoder.convcorr\1.0."),
    (r"^update_block\.encoder\.convf(\d)\.", r"update_block.motion_encoder.convflow\1.0."),
    (r"^update_block\.encoder\.conv\.", "update_block.motion_encoder.conv.0."),
    (r"^update_block\.gru\.conv([zrq])(\d)\.", r"update_block.recurrent_block.convgru\2.conv\1."),
    (r"^update_block\.gru\.conv([zrq])\.", r"update_block.recurrent_block.convgru1.conv\1."),
    (r"^update_block\.mask\.0\.", "mask_predictor.convrelu.0."),
    (r"^update_block\.mask\.2\.", "mask_predictor.conv."),
]


def convert_original_state_dict(state: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """Rename an original princeton-vl RAFT state dict (``module.fnet.*`` ...) to torchvision's
    names, by key name, for raft_small and raft_large.

    A residual block's norms follow its convs (``normK`` -> ``convnormreluK.1``); a norm with no
    conv of its number is the downsample norm (``downsample.1``), which the original saves
    under both names.
    """
    renamed: dict[str, torch.Tensor] = {}
    for key, value in state.items():
        key = key.removeprefix("module.")
        for pattern, repl in _RULES:
            key = re.sub(pattern, repl, key)
        renamed[key] = value
    out: dict[str, torch.Tensor] = {}
    for key, value in renamed.items():
        m = re.match(r"^(.*\.layer\d\.\d)\.norm(\d)\.(.*)$", key)
        if m is None:
            out[key] = value
            continue
        block, k, rest = m.groups()
        if any(name.startswith(f"{block}.convnormrelu{k}.0.") for name in renamed):
            out[f"{block}.convnormrelu{k}.1.{rest}"] = value
        else:
            out.setdefault(f"{block}.downsample.1.{rest}", value)
    return out


class WeightsHashError(ValueError):
    """A weights file under a known name does not have that file's sha256."""


_HASHES: dict[tuple[str, int, int], str] = {}


def file_sha256(path: str | Path) -> str:
    """The sha256 (hex) of a file, computed once per process for each (path, size, mtime)."""
    path = Path(path)
    info = path.stat()
    key = (str(path.resolve()), info.st_size, info.st_mtime_ns)
    if key not in _HASHES:
        digest = hashlib.sha256()
        with open(path, "rb") as f:
            for chunk in iter(lambda: f.read(1 << 20), b""):
                digest.update(chunk)
        _HASHES[key] = digest.hexdigest()
    return _HASHES[key]


def check_known_hash(path: str | Path) -> None:
    """Raise :class:`WeightsHashError` when ``path``'s name is in :data:`KNOWN_SHA256` and its
    sha256 differs (torchvision's names: does not start with the 8 digits). Other names pass."""
    path = Path(path)
    expected = KNOWN_SHA256.get(path.name)
    if expected is None:
        return
    found = file_sha256(path)
    if not found.startswith(expected):
        what = "starts with" if len(expected) < 64 else "is"
        raise WeightsHashError(
            f"{path}: sha256 {found}, but the sha256 of {path.name} {what} {expected} (checkpoints/README.md): a "
            "corrupted or different file under a known name; download it again, or rename your own weights"
        )


def _unloadable(path: Path, err: Exception) -> str:
    """One line for a file torch.load(weights_only=True) refused (torch's own message, with its
    advice to load untrusted pickles, is left out)."""
    expected = "expected a torch.save'd RAFT state dict such as raft-small.pth"
    if "Unsupported global" in str(err):  # a pickle of Python objects, e.g. a whole model
        return f"{path}: holds pickled Python objects, not only tensors ({expected}: save model.state_dict())"
    return f"{path}: not a PyTorch weights file ({expected}; torch.load failed with {type(err).__name__})"


def load_state_dict_file(path: str | Path, arch: str) -> dict[str, torch.Tensor]:
    """Read a RAFT weights file in torchvision's or the original format; returns torchvision
    names. A file of neither format raises ``ValueError`` saying what was found; a known file
    name with other bytes raises :class:`WeightsHashError` (a ValueError)."""
    path = Path(path)
    if path.is_file():
        check_known_hash(path)
    try:
        with warnings.catch_warnings():  # torch's note on a pickle protocol it did not write
            warnings.filterwarnings("ignore", message="Detected pickle protocol", category=UserWarning)
            state = torch.load(path, map_location="cpu", weights_only=True)
    except FileNotFoundError:
        raise FileNotFoundError(f"RAFT weights file {path} does not exist") from None
    except Exception as err:  # noqa: BLE001 - any unpickling failure is a bad file
        raise ValueError(_unloadable(path, err)) from None
    if isinstance(state, dict) and "state_dict" in state and isinstance(state["state_dict"], dict):
        state = state["state_dict"]
    if not isinstance(state, dict) or not all(isinstance(v, torch.Tensor) for v in state.values()):
        raise ValueError(f"{path}: expected a state dict of tensors, found {type(state).__name__}")
    keys = list(state)
    if any(k.removeprefix("module.").startswith(("fnet.", "cnet.")) for k in keys):
        state = convert_original_state_dict(state)
    elif not any(k.startswith("feature_encoder.") for k in keys):
        raise ValueError(
            f"{path}: neither a torchvision RAFT state dict (feature_encoder.*) nor an original "
            f"princeton-vl checkpoint (module.fnet.*); found keys like {keys[:4]}"
        )
    large = any(k.startswith("mask_predictor.") for k in state)
    if large != (arch == "raft_large"):
        found = "raft_large" if large else "raft_small"
        raise ValueError(f"{path}: holds {found} weights, but {arch} was asked for")
    return state


def _default_dirs() -> list[Path]:
    """The folders searched after ``$LIT_BOOT_CHECKPOINTS``: ``./checkpoints``, then the project's."""
    return [Path.cwd() / "checkpoints", _PROJECT_CHECKPOINTS]


def checkpoint_dirs() -> list[Path]:
    """Local folders searched for weight files, in order."""
    dirs = []
    if os.environ.get("LIT_BOOT_CHECKPOINTS"):
        dirs.append(Path(os.environ["LIT_BOOT_CHECKPOINTS"]))
    dirs += _default_dirs()
    seen: list[Path] = []
    for d in dirs:
        if d.resolve() not in [s.resolve() for s in seen]:
            seen.append(d)
    return seen


def resolve_weights(arch: str, weights: str | Path) -> Path:
    """The local file holding ``weights`` for ``arch`` (see the module docstring for the order);
    downloads torchvision's file when it is nowhere local."""
    if arch not in ARCHS:
        raise ValueError(f"arch: expected one of {ARCHS}, got {arch!r}")
    as_path = Path(weights)
    if as_path.suffix in (".pth", ".pt", ".ckpt") or as_path.exists():
        if not as_path.exists():
            raise FileNotFoundError(f"RAFT weights file {as_path} does not exist")
        return as_path
    enum = WEIGHT_ENUMS[arch]
    name = str(weights)
    if name not in enum.__members__:
        raise ValueError(
            f"weights: {name!r} is neither a file nor a torchvision {enum.__name__} name "
            f"({', '.join(enum.__members__)})"
        )
    member = enum[name]
    names = [Path(member.url).name]
    original = ORIGINAL_FILES.get((arch, member.name))
    if original:
        names.append(original)
    for folder in checkpoint_dirs():
        for file in names:
            if (folder / file).is_file():
                return folder / file
    target = checkpoint_dirs()[0]
    try:
        from torch.hub import load_state_dict_from_url

        target.mkdir(parents=True, exist_ok=True)
        load_state_dict_from_url(member.url, model_dir=str(target), check_hash=True, progress=True)
    except Exception as err:  # noqa: BLE001 - offline, refused, bad hash: all end the same way
        where = " or ".join(str(d) for d in checkpoint_dirs())
        raise FileNotFoundError(
            f"RAFT weights {arch} {name} are not available locally and could not be downloaded "
            f"({type(err).__name__}: {err}). Place {' or '.join(names)} in {where} "
            f"(or set LIT_BOOT_CHECKPOINTS), or pass the file path."
        ) from None
    return target / names[0]
