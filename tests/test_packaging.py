"""The package list in pyproject.toml covers every package folder."""

from __future__ import annotations

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TOPS = {
    "app": "tunespec.app",
    "core": "tunespec.core",
    "devices": "tunespec.devices",
    "resources": "tunespec.resources",
}


def test_every_package_folder_is_listed() -> None:
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())
    listed = set(cfg["tool"]["setuptools"]["packages"])
    found = set()
    for folder, dotted in TOPS.items():
        for init in (ROOT / folder).rglob("__init__.py"):
            rel = init.parent.relative_to(ROOT / folder)
            if "__pycache__" in rel.parts:
                continue
            found.add(".".join([dotted, *rel.parts]))
    assert found == listed, f"missing {found - listed}, stale {listed - found}"


def test_core_and_devices_never_import_qt() -> None:
    for folder in ("core", "devices"):
        for py in (ROOT / folder).rglob("*.py"):
            text = py.read_text()
            for bad in ("PySide6", "pyqtgraph", "shiboken6"):
                assert f"import {bad}" not in text and f"from {bad}" not in text, py
