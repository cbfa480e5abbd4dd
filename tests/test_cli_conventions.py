"""One set of CLI habits, enforced on every subcommand by walking the parser.

A command added later is covered without touching this file:

- a file output is ``-o/--output``, a folder output ``-o/--out``; ``-o`` means
  nothing else; other outputs end in ``-out`` (``--illuminants-out``);
- every output option is declared (``set_defaults(output_files=..., output_dirs=...)``)
  so :func:`tunespec.app.cli.check_outputs` checks it before any work, and an
  unusable path ends in exit 2 without the command running;
- every command takes ``-q/--quiet`` and ``--json`` unless it is listed in
  :data:`PRINTS_NO_NUMBERS` with the reason;
- ``tunespec --help`` lists the exit codes; progress lines go to stderr.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from tunespec.app import cli
from tunespec.app.cli import build_parser, check_outputs
from tunespec.app.cli.common import (
    EXIT_CANCELLED,
    EXIT_DEVICE,
    EXIT_DISK_FULL,
    EXIT_INPUT,
    grid_arg,
    resolution_arg,
    seed_arg,
)
from tunespec.core.errors import InputError

#: Commands that report no numbers, and why (prefixes: ``emulate`` covers its
#: devices).
PRINTS_NO_NUMBERS = {
    "emulate": "serves a device protocol on a port until Ctrl-C; prints its address",
}


def _subcommands(
    parser: argparse.ArgumentParser, prefix: tuple[str, ...] = ()
) -> dict[str, argparse.ArgumentParser]:
    """Every leaf command (``emulate cal1`` included), by its words."""
    found: dict[str, argparse.ArgumentParser] = {}
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        return {" ".join(prefix): parser}
    for action in subs:
        for name, sp in action.choices.items():
            found.update(_subcommands(sp, (*prefix, name)))
    return found


COMMANDS = _subcommands(build_parser())


def _options(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    return [a for a in parser._actions if a.option_strings]


def _is_output(action: argparse.Action) -> bool:
    return action.dest in ("output", "out") or action.dest.endswith(("_out", "_output"))


def test_the_walk_finds_every_command() -> None:
    assert len(COMMANDS) >= 20
    for name in ("demo", "estimate-image", "match-illuminant", "gonio-run", "report"):
        assert name in COMMANDS


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_output_options_follow_one_spelling(name: str) -> None:
    parser = COMMANDS[name]
    defaults = parser._defaults
    files = tuple(defaults.get("output_files", ()))
    dirs = tuple(defaults.get("output_dirs", ()))
    dests = {a.dest for a in parser._actions}
    assert set(files + dirs) <= dests, f"{name}: declares outputs it does not take"
    for a in _options(parser):
        opts = set(a.option_strings)
        if "-o" in opts:
            assert a.dest in ("output", "out"), f"{name}: -o is {a.option_strings}"
        if a.dest == "output":
            assert {"-o", "--output"} <= opts and "output" in files, (
                f"{name}: a file output is -o/--output, declared in output_files"
            )
        if a.dest == "out":
            assert {"-o", "--out"} <= opts and "out" in dirs, (
                f"{name}: a folder output is -o/--out, declared in output_dirs"
            )
        if _is_output(a):
            assert a.dest in files + dirs, (
                f"{name}: {a.option_strings} is not checked before the work starts"
            )


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_commands_that_print_numbers_take_quiet_and_json(name: str) -> None:
    if any(name == k or name.startswith(k + " ") for k in PRINTS_NO_NUMBERS):
        return
    opts = {s for a in _options(COMMANDS[name]) for s in a.option_strings}
    assert {"-q", "--quiet", "--json"} <= opts, f"{name}: no --quiet/--json"


def test_help_lists_the_exit_codes() -> None:
    epilog = build_parser().format_help()
    for code, what in (
        (0, "done"),
        (EXIT_INPUT, "bad input"),
        (EXIT_DEVICE, "device"),
        (EXIT_DISK_FULL, "disk full"),
        (EXIT_CANCELLED, "interrupted"),
    ):
        assert f"{code} {what}" in " ".join(epilog.split()), code


def _value(action: argparse.Action) -> str:
    """A value argparse accepts for a required argument (the check of the outputs
    comes before anything reads it): the first candidate its type takes."""
    if action.choices:
        return str(next(iter(action.choices)))
    known = {grid_arg: "400:700:10", seed_arg: "0", resolution_arg: "64x48"}
    if action.type in known:
        return known[action.type]
    for candidate in ("input.csv", "1", "0.5", "400:700:10", "64x48", "sim"):
        try:
            if action.type is not None:
                action.type(candidate)  # type: ignore[operator]
        except (ValueError, TypeError, argparse.ArgumentTypeError, InputError):
            continue
        return candidate
    raise AssertionError(f"no test value for {action.dest}: add one to _value")


def _argv(name: str, parser: argparse.ArgumentParser, blocked: Path) -> list[str]:
    """The command with its required arguments and every output under ``blocked``
    (a regular file, so no path under it can be written)."""
    files = tuple(parser._defaults.get("output_files", ()))
    dirs = tuple(parser._defaults.get("output_dirs", ()))
    argv = name.split()
    for a in parser._actions:
        if isinstance(a, argparse._HelpAction | argparse._SubParsersAction):
            continue
        if a.dest in files + dirs:
            argv += [a.option_strings[-1], str(blocked / "sub" / f"{a.dest}.out")]
        elif not a.option_strings:
            argv.append(_value(a))
        elif a.required:
            argv += [a.option_strings[-1], _value(a)]
    return argv


OUTPUT_COMMANDS = sorted(
    n
    for n, p in COMMANDS.items()
    if p._defaults.get("output_files") or p._defaults.get("output_dirs")
)


@pytest.mark.parametrize("name", OUTPUT_COMMANDS)
def test_unwritable_outputs_fail_before_the_work(
    name: str, tmp_path, monkeypatch, capsys
) -> None:
    blocked = tmp_path / "a-file"
    blocked.write_text("")
    ran: list[str] = []
    parser = build_parser()
    leaf = _subcommands(parser)[name]
    leaf.set_defaults(func=lambda args: ran.append(name) or 0)
    monkeypatch.setattr(cli, "build_parser", lambda: parser)
    argv = _argv(name, leaf, blocked)
    with pytest.raises(InputError, match="is a file"):
        check_outputs(parser.parse_args(argv))
    assert cli.main(argv) == EXIT_INPUT
    assert ran == [], f"{name} ran with an unwritable output"
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "a-file" in err


def test_folder_outputs_take_dash_o(tmp_path) -> None:
    """The spellings issue 28 found missing: ``demo -o`` was unrecognised."""
    parser = build_parser()
    for argv in (
        ["demo", "-o", "d"],
        ["capture", "-o", "d"],
        ["gonio-demo", "-o", "d"],
        ["estimate-image", "s", "--sensitivities", "S.csv", "-o", "d"],
    ):
        assert parser.parse_args(argv).out == Path("d"), argv
    for argv in (["demo", "--out", "d"], ["gonio-demo", "--out", "d"]):
        assert parser.parse_args(argv).out == Path("d"), argv  # the old spelling


def test_progress_goes_to_stderr(capsys) -> None:
    import argparse as ap

    from tunespec.app.cli.common import Console

    for flags in ({}, {"json": True}):
        progress = Console(ap.Namespace(quiet=False, **flags)).progress("work")
        assert progress is not None
        progress(0.5)
        progress(1.0)
        cap = capsys.readouterr()
        assert cap.out == "" and "work: 50%" in cap.err
    assert Console(ap.Namespace(quiet=True)).progress("work") is None
