"""The command line starts fast: what it imports before a command needs it.

No wall-clock asserts (``benchmarks/bench_cli_startup.py`` measures the time); these
tests check the cause instead: ``tunespec --help``, ``--version`` and the errors of
the commands must not import plotting (matplotlib, colour-science, which imports
``colour.plotting``) or scipy's estimators. Each runs in a fresh interpreter, since
this one has long imported everything.
"""

from __future__ import annotations

import json
import subprocess
import sys
from importlib.metadata import version

import pytest

from tunespec.app.cli import main

#: Modules that take a start-up from ~0.15 s to 0.5-2 s.
HEAVY = ("matplotlib", "colour", "scipy", "cv2", "rawpy", "PySide6")

_PROBE = """
import json, sys
from tunespec.app.cli import main
try:
    code = main(sys.argv[1:])
except SystemExit as exc:
    code = exc.code
loaded = sorted({m.split(".")[0] for m in sys.modules} & set(HEAVY))
sys.stdout.write("\\n" + json.dumps({"code": code, "loaded": loaded}))
"""


def _probe(*argv: str, cwd) -> dict:
    """Run ``main(argv)`` in a fresh interpreter; its exit code and heavy imports."""
    code = _PROBE.replace("HEAVY", repr(HEAVY))
    out = subprocess.run(
        [sys.executable, "-c", code, *argv],
        capture_output=True,
        text=True,
        cwd=cwd,
        check=False,
        timeout=120,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_importing_the_cli_entry_imports_no_plotting(tmp_path) -> None:
    out = subprocess.run(
        [
            sys.executable,
            "-c",
            "import sys, tunespec.app.cli as c; c.build_parser(); "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in "
            f"{HEAVY!r}))",
        ],
        capture_output=True,
        text=True,
        check=True,
        cwd=tmp_path,
        timeout=120,
    )
    assert out.stdout.strip() == "[]"


@pytest.mark.parametrize(
    "argv",
    [
        ["--help"],
        ["--version"],
        ["calibrate", "--help"],
        ["bogus-command"],
        ["calibrate", "--responses", "no.csv", "--illuminants", "no.csv"],
        [
            "calibrate",
            *("--responses", "no.csv", "--illuminants", "no.csv"),
            *("--reflectances", "no.csv", "-o", "s.csv"),
        ],
        [
            "estimate",
            *("--responses", "no.csv", "--illuminants", "no.csv"),
            *("--sensitivities", "no.csv", "-o", "r.csv"),
        ],
        ["evaluate", "--estimated", "no.csv", "--reference", "no.csv"],
        ["run", "no.toml"],
        ["process", "no-session", "-o", "r.csv"],
    ],
    ids=lambda a: " ".join(a[:2]),
)
def test_help_version_and_errors_import_no_heavy_module(argv, tmp_path) -> None:
    got = _probe(*argv, cwd=tmp_path)
    assert got["code"] in (0, 2), got
    assert got["loaded"] == [], got


def test_version_prints_the_package_version(capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out == f"tunespec {version('tunespec')}\n"


def test_the_cli_offers_every_sensitivity_method() -> None:
    from tunespec.app.cli.core_cmds import METHOD_CHOICES
    from tunespec.core.sensitivity import SENSITIVITY_METHODS

    assert sorted(METHOD_CHOICES) == sorted(SENSITIVITY_METHODS)
    from tunespec.app.pipeline.plan import METHOD_CHOICES as WORKFLOW_METHODS

    assert sorted(WORKFLOW_METHODS) == sorted(SENSITIVITY_METHODS)
