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


#: What the front ends may not import themselves (issue 26): they run pipeline jobs.
FRONT_END_FORBIDDEN = {
    "tunespec.core.sensitivity",
    "tunespec.core.sensitivity_bayes",
    "tunespec.core.wiener",
    "tunespec.core.uncertainty",
    "tunespec.core.processing",
    "tunespec.devices.capture",
}


def test_the_front_end_contracts_are_in_the_configuration() -> None:
    """The contracts the first test checks include the front ends' and the
    pipeline's acyclic one (dropping one from pyproject.toml fails here)."""
    import tomllib

    doc = tomllib.loads((ROOT / "pyproject.toml").read_text())
    contracts = doc["tool"]["importlinter"]["contracts"]
    forbidden: dict[tuple[str, ...], set[str]] = {}
    for c in contracts:
        if c["type"] == "forbidden":
            forbidden.setdefault(tuple(c["source_modules"]), set()).update(
                c["forbidden_modules"]
            )
    assert forbidden[("tunespec.app.cli",)] >= FRONT_END_FORBIDDEN
    assert forbidden[("tunespec.app.gui",)] >= FRONT_END_FORBIDDEN | {
        "tunespec.app.pipeline.steps"
    }
    acyclic = [c for c in contracts if c["type"] == "acyclic_siblings"]
    assert any("tunespec.app.pipeline" in c["ancestors"] for c in acyclic)
