"""The ``tunespec`` command line.

Subcommands live in the ``tunespec.app.cli.*_cmds`` modules, each with a
``register(subparsers)`` function that adds its parsers and sets ``func`` (called with
the parsed namespace, returns an exit code). This module owns error handling: any
:class:`~tunespec.core.errors.TuneSpecError` or
:class:`~tunespec.devices.protocols.DeviceError` becomes one line on stderr and exit
code 2 (input), 3 (device) or 4 (disk full); ``Cancelled``/Ctrl-C exit with 130; output
paths declared by a command are checked before it runs. No Qt is imported.
"""

from __future__ import annotations

import argparse
import errno
import sys
from collections.abc import Sequence
from typing import NoReturn

from tunespec.app.cli import (
    core_cmds,
    device_cmds,
    export_cmds,
    extract_cmds,
    gonio_cmds,
    image_cmds,
    session_cmds,
)
from tunespec.app.cli.common import (
    EXIT_CANCELLED,
    EXIT_CODES_HELP,
    EXIT_DEVICE,
    EXIT_DISK_FULL,
    EXIT_INPUT,
    TerminalProgress,
    add_grid_option,
    close_progress,
    grid_arg,
    progress_bar,
    seed_arg,
)
from tunespec.core.errors import DiskFullError, TuneSpecError
from tunespec.core.progress import Cancelled

__all__ = [
    "EXIT_CANCELLED",
    "EXIT_DEVICE",
    "EXIT_DISK_FULL",
    "EXIT_INPUT",
    "TerminalProgress",
    "add_grid_option",
    "build_parser",
    "check_outputs",
    "grid_arg",
    "main",
    "progress_bar",
    "seed_arg",
]

#: The command modules, in the order ``--help`` lists them. Imported statically: each
#: imports only what its commands need when they run (``tunespec --help`` stays light).
COMMAND_MODULES = (
    core_cmds,
    device_cmds,
    session_cmds,
    export_cmds,
    gonio_cmds,
    image_cmds,
    extract_cmds,
)


class _VersionAction(argparse.Action):
    """``--version``: the installed version, looked up only when asked for."""

    def __init__(self, option_strings: Sequence[str], dest: str, **kwargs: object):
        super().__init__(
            option_strings,
            dest,
            nargs=0,
            default=argparse.SUPPRESS,
            help="print the TuneSpec version and exit",
        )

    def __call__(self, parser: argparse.ArgumentParser, *_args: object) -> None:
        from tunespec.core.io.export import tunespec_version

        print(f"{parser.prog} {tunespec_version()}")
        parser.exit()


class _Parser(argparse.ArgumentParser):
    """argparse, its error line cut as every other error (argparse quotes a bad
    value whole: a 5,000-digit number filled the terminal). Subcommands' parsers
    are of this class too (``add_subparsers`` takes the parent's)."""

    def error(self, message: str) -> NoReturn:
        super().error(_line(message))


def build_parser() -> argparse.ArgumentParser:
    """The ``tunespec`` parser with every subcommand.

    Builds fast: command modules import what a command needs when it runs, so that
    ``--help``, ``--version`` and argument errors answer at once (no scipy,
    colour-science or matplotlib).
    """
    parser = _Parser(
        prog="tunespec",
        description="Spectral reflectance from an RGB camera and a tunable LED source.",
        epilog=EXIT_CODES_HELP,
    )
    parser.add_argument("--version", action=_VersionAction)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for module in COMMAND_MODULES:
        module.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``tunespec``; returns the exit code."""
    from tunespec.devices.protocols import DeviceError

    parser = build_parser()
    args = parser.parse_args(argv)
    from tunespec.app.pipeline.engine import limit_blas_threads

    limit_blas_threads()
    try:
        check_outputs(args)
        return int(args.func(args) or 0)
    except DiskFullError as exc:
        print(f"tunespec {args.command}: disk full: {_line(exc)}", file=sys.stderr)
        return EXIT_DISK_FULL
    except TuneSpecError as exc:
        print(f"tunespec {args.command}: error: {_line(exc)}", file=sys.stderr)
        return EXIT_INPUT
    except DeviceError as exc:
        print(f"tunespec {args.command}: device error: {_line(exc)}", file=sys.stderr)
        return EXIT_DEVICE
    except (Cancelled, KeyboardInterrupt):
        print(f"tunespec {args.command}: cancelled", file=sys.stderr)
        return EXIT_CANCELLED
    except OSError as exc:
        # the last net: a file the checks could not foresee (a full disk while
        # writing, a permission changed meanwhile) still ends in one line
        if exc.errno == errno.ENOSPC:
            err = DiskFullError.from_os_error(exc)
            print(f"tunespec {args.command}: disk full: {_line(err)}", file=sys.stderr)
            return EXIT_DISK_FULL
        where = f"{exc.filename}: " if exc.filename else ""
        print(
            f"tunespec {args.command}: error: {_line(where + str(exc.strerror or exc))}",
            file=sys.stderr,
        )
        return EXIT_INPUT
    finally:
        close_progress()


#: Longest error line printed: a value typed (or read) with thousands of characters
#: is cut in the middle rather than flooding the terminal.
MAX_ERROR_CHARS = 600


def _line(exc: object) -> str:
    """An error as one line of at most :data:`MAX_ERROR_CHARS` characters."""
    text = " ".join(str(exc).splitlines())
    if len(text) <= MAX_ERROR_CHARS:
        return text
    return text[: MAX_ERROR_CHARS - 160] + " ... " + text[-150:]


def check_outputs(args: argparse.Namespace) -> None:
    """Check the output paths a command declared, before it does any work.

    Commands list them with ``set_defaults(output_files=(...), output_dirs=(...))``
    (argparse destinations).
    """
    from tunespec.core.limits import check_output_dir, check_output_file

    for attr in getattr(args, "output_files", ()):
        value = getattr(args, attr, None)
        if value is not None:
            check_output_file(value, "--" + attr.replace("_", "-"))
    _outputs_are_not_inputs(args)
    for attr in getattr(args, "output_dirs", ()):
        value = getattr(args, attr, None)
        if value is not None:
            check_output_dir(value, "--" + attr.replace("_", "-"))


def _outputs_are_not_inputs(args: argparse.Namespace) -> None:
    """An output file that is also one of the command's input files is refused
    (``-o`` equal to ``--responses`` would overwrite the measurement)."""
    import os
    from pathlib import Path

    from tunespec.core.errors import InputError

    outputs = set(getattr(args, "output_files", ())) | set(
        getattr(args, "output_dirs", ())
    )
    inputs = {
        k: os.path.realpath(v)
        for k, v in vars(args).items()
        if isinstance(v, Path) and k not in outputs
    }
    for attr in getattr(args, "output_files", ()):
        value = getattr(args, attr, None)
        if value is None:
            continue
        real = os.path.realpath(value)
        for k, v in inputs.items():
            if v == real:
                flag = "-o" if attr == "output" else "--" + attr.replace("_", "-")
                raise InputError(
                    f"{flag} {value} is also --{k.replace('_', '-')}: writing it would "
                    "overwrite an input; choose another output file"
                )
