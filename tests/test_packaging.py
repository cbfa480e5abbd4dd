"""The package list in pyproject.toml covers every package folder."""

from __future__ import annotations

import re
import subprocess
import sys
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


#: Dependencies PyPI has no wheels for: installing them needs a C compiler (pidng,
#: which the DNG writer used until issue 13).
SOURCE_ONLY = {"pidng"}


def test_no_dependency_needs_a_compiler_to_install() -> None:
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())
    project = cfg["project"]
    reqs = [*project["dependencies"]]
    for extra in project["optional-dependencies"].values():
        reqs += extra
    names = {re.split(r"[<>=!~;\[ ]", r, maxsplit=1)[0].lower() for r in reqs}
    assert not names & SOURCE_ONLY


def test_the_simulated_camera_writes_dngs_without_pidng(tmp_path) -> None:
    """A fresh interpreter in which pidng cannot be imported writes a DNG that
    rawpy reads back exactly."""
    code = f"""
import sys
from importlib.abc import MetaPathFinder

class NotInstalled(MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in {sorted(SOURCE_ONLY)!r}:
            raise ModuleNotFoundError(name, name=name)

sys.meta_path.insert(0, NotInstalled())
import numpy as np, rawpy
from tunespec.devices.dng import write_dng
mosaic = np.arange(32 * 48, dtype=np.uint16).reshape(32, 48)
path = write_dng({str(tmp_path / "x.dng")!r}, mosaic, exposure_s=0.25, iso=200)
with rawpy.imread(str(path)) as raw:
    assert (raw.raw_image_visible == mosaic).all()
    assert raw.other.iso_speed == 200
print("ok")
"""
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120
    )
    assert out.stdout.strip() == "ok", out.stderr
