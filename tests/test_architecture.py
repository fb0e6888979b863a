"""The package's import contract (issue 14): the layers, a light core, no cycles.

The contracts live in pyproject.toml (``[tool.importlinter]``) and are checked by import-linter
(the dev extra), here as ``lint-imports`` would be run by hand; importing the core is checked in a
fresh interpreter.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

from importlinter.api import read_configuration

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = ROOT / "pyproject.toml"


def test_the_import_contracts_are_all_kept() -> None:
    contracts = read_configuration(str(PYPROJECT))["contracts_options"]
    assert {c["type"] for c in contracts} == {"layers", "forbidden", "acyclic_siblings"}
    layers = next(c for c in contracts if c["type"] == "layers")["layers"]
    assert layers[0] == "lit_boot.cli" and layers[-1] == "lit_boot.core"
    lint = Path(sys.executable).parent / "lint-imports"  # reads pyproject.toml in its working directory
    env = {**os.environ, "COLUMNS": "300"}  # one line per contract
    done = subprocess.run([str(lint), "--no-cache"], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    report = re.sub(r"\x1b\[[0-9;]*m", "", done.stdout)  # some versions colour even a pipe
    assert done.returncode == 0, report + done.stderr
    for contract in contracts:
        assert f"{contract['name']} KEPT" in report, (contract["name"], report)
    assert f"Contracts: {len(contracts)} kept, 0 broken." in report


def test_importing_the_core_loads_neither_lightning_nor_opencv() -> None:
    heavy = ("lightning", "cv2", "kornia", "matplotlib")
    code = f"import sys\nimport lit_boot.core\nprint(sorted(m for m in {heavy!r} if m in sys.modules))"
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == "[]"
