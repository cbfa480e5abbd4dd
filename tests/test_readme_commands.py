"""Every command the README's command table names exists, with every option it shows.

The table is what a user reads first; a command renamed or an option dropped without
the README following is caught here (the issue's "every CLI command in the README
works"). Each command's ``--help`` must also print and exit 0.
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import pytest

from tunespec.app.cli import build_parser, main

README = Path(__file__).resolve().parents[1] / "README.md"


def _table_usages() -> list[str]:
    """The backticked ``tunespec ...`` usages of the README's command table."""
    rows = [
        r
        for r in README.read_text(encoding="utf-8").splitlines()
        if r.startswith("| `tunespec")
    ]
    return [u for r in rows for u in re.findall(r"`(tunespec [^`]+)`", r.split(" | ")[0])]  # fmt: skip


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _command(usage: str) -> tuple[list[str], argparse.ArgumentParser]:
    """The command words of ``usage`` (``emulate cal1``) and their parser."""
    words, parser = [], build_parser()
    for word in usage.split()[1:]:
        sub = _subparsers(parser)
        if word not in sub:
            break
        words.append(word)
        parser = sub[word]
    return words, parser


USAGES = [u for u in _table_usages() if u != "tunespec --version"]


def test_the_table_is_read() -> None:
    assert len(USAGES) >= 18
    assert "tunespec run CONFIG.toml" in USAGES


@pytest.mark.parametrize("usage", USAGES)
def test_every_command_and_option_of_the_table_exists(usage: str, capsys) -> None:
    words, parser = _command(usage)
    assert words, f"{usage}: no such command"
    known = set(parser._option_string_actions)
    shown = set(re.findall(r"(?<![\w-])(--?[a-z][\w-]*)", usage))
    assert shown <= known, f"{usage}: unknown {sorted(shown - known)}"
    with pytest.raises(SystemExit) as info:
        build_parser().parse_args([*words, "--help"])
    assert info.value.code == 0
    assert words[-1] in capsys.readouterr().out


def test_version(capsys) -> None:
    with pytest.raises(SystemExit) as info:
        main(["--version"])
    assert info.value.code == 0
    assert capsys.readouterr().out.strip()
