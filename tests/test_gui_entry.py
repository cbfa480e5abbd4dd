"""``tunespec-gui`` without the ``gui`` extra: one line saying what to install.

Runs in a fresh interpreter where importing PySide6 and pyqtgraph fails as it does
after ``pip install tunespec`` (an import hook stands in for the missing packages),
so it also runs, and matters most, where Qt is not installed at all.
"""

from __future__ import annotations

import subprocess
import sys

import pytest

_WITHOUT = """
import sys
from importlib.abc import MetaPathFinder

class NotInstalled(MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in BLOCKED:
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None

sys.meta_path.insert(0, NotInstalled())
sys.argv = ["tunespec-gui", *ARGS]
from tunespec.app.__main__ import main
sys.exit(main())
"""


def _gui(blocked: tuple[str, ...], *args: str) -> subprocess.CompletedProcess[str]:
    code = _WITHOUT.replace("BLOCKED", repr(blocked)).replace("ARGS", repr(args))
    return subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        check=False,
        timeout=120,
    )


@pytest.mark.parametrize(
    ("blocked", "named"),
    [
        (("PySide6", "shiboken6", "pyqtgraph"), "PySide6"),
        (("pyqtgraph",), "pyqtgraph"),
    ],
)
def test_missing_gui_packages_give_one_line_to_install_the_extra(
    blocked, named
) -> None:
    out = _gui(blocked)
    assert out.returncode == 1
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1, out.stderr
    assert "Traceback" not in out.stderr
    assert named in lines[0]
    assert "pip install 'tunespec[gui]'" in lines[0]


def test_help_works_without_the_gui_packages() -> None:
    out = _gui(("PySide6", "shiboken6", "pyqtgraph"), "--help")
    assert out.returncode == 0, out.stderr
    assert "tunespec-gui" in out.stdout
