"""The import contracts of pyproject.toml hold (not only in CI).

import-linter (grimp) cannot follow setuptools' editable finder for the mapped
``tunespec`` namespace, so the test gives it a plain tree of links,
``tunespec/{app,core,devices,resources}``, as ``tools/lint_imports.sh`` does.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TOPS = ("app", "core", "devices", "resources")


def test_import_contracts_are_kept(tmp_path) -> None:
    pytest.importorskip("importlinter")
    tree = tmp_path / "tunespec"
    tree.mkdir()
    for top in TOPS:
        (tree / top).symlink_to(ROOT / top, target_is_directory=True)
    env = {**os.environ, "PYTHONPATH": str(tmp_path)}
    out = subprocess.run(
        [
            sys.executable,
            "-c",
            "import sys; from importlinter.cli import lint_imports_command; "
            "sys.exit(lint_imports_command())",
            "--no-cache",
        ],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        check=False,
        timeout=300,
    )
    assert out.returncode == 0, out.stdout + out.stderr
    assert "0 broken" in out.stdout
