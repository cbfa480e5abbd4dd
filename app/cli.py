"""The ``tunespec`` command line.

Subcommands live in ``tunespec.app.commands.*`` modules, each with a
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
import importlib
import sys
import time
from collections.abc import Sequence

from tunespec.core.errors import DiskFullError, TuneSpecError
from tunespec.core.progress import Cancelled, ProgressFn
from tunespec.core.spectra import DEFAULT_GRID, Grid

COMMAND_MODULES = (
    "tunespec.app.commands.core_cmds",
    "tunespec.app.commands.device_cmds",
    "tunespec.app.commands.session_cmds",
    "tunespec.app.commands.export_cmds",
)

EXIT_INPUT = 2
EXIT_DEVICE = 3
EXIT_DISK_FULL = 4
EXIT_CANCELLED = 130


def grid_arg(text: str) -> Grid:
    """argparse type for ``--grid START:END:STEP``."""
    try:
        return Grid.parse(text)
    except TuneSpecError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def seed_arg(text: str) -> int:
    """argparse type for ``--seed``: an integer in ``[0, 2**32 - 1]``."""
    from tunespec.core.limits import valid_seed

    try:
        return valid_seed(int(text), "--seed")
    except (ValueError, TuneSpecError) as exc:
        raise argparse.ArgumentTypeError(
            f"expected an integer from 0 to 4294967295, got {text!r}"
        ) from exc


def add_grid_option(parser: argparse.ArgumentParser) -> None:
    """The shared ``--grid`` option."""
    parser.add_argument(
        "--grid",
        type=grid_arg,
        default=DEFAULT_GRID,
        metavar="START:END:STEP",
        help=f"working wavelength grid in nm (default {DEFAULT_GRID})",
    )


class TerminalProgress:
    """A one-line progress bar on stderr, usable as a :data:`ProgressFn`.

    Redraws at most 10 times a second, shows elapsed and remaining time, and stays
    silent when stderr is not a terminal unless ``force`` (then it prints a line per
    10 % so logs still show progress).
    """

    def __init__(self, label: str, *, width: int = 30, force: bool = False) -> None:
        self.label = label
        self.width = width
        self._tty = sys.stderr.isatty()
        self._force = force
        self._t0 = time.monotonic()
        self._last_draw = 0.0
        self._last_decile = -1

    def __call__(self, fraction: float) -> None:
        now = time.monotonic()
        elapsed = now - self._t0
        if self._tty:
            if fraction < 1.0 and now - self._last_draw < 0.1:
                return
            self._last_draw = now
            filled = round(self.width * fraction)
            eta = elapsed / fraction * (1 - fraction) if fraction > 0 else float("nan")
            eta_s = f"{eta:5.0f}s left" if eta == eta else "   ?s left"
            bar = "#" * filled + "-" * (self.width - filled)
            sys.stderr.write(f"\r{self.label:<28} [{bar}] {fraction:6.1%} {eta_s}")
            if fraction >= 1.0:
                sys.stderr.write(
                    f"\r{self.label:<28} [{bar}] done in {elapsed:.1f}s   \n"
                )
            sys.stderr.flush()
        elif self._force:
            decile = int(fraction * 10)
            if decile > self._last_decile:
                self._last_decile = decile
                sys.stderr.write(f"{self.label}: {fraction:.0%} ({elapsed:.1f}s)\n")


def progress_bar(label: str) -> ProgressFn:
    """A terminal progress callback for ``label``."""
    return TerminalProgress(label)


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
        from tunespec.core.export import tunespec_version

        print(f"{parser.prog} {tunespec_version()}")
        parser.exit()


def build_parser() -> argparse.ArgumentParser:
    """The ``tunespec`` parser with every subcommand.

    Builds fast: command modules import what a command needs when it runs, so that
    ``--help``, ``--version`` and argument errors answer at once (no scipy,
    colour-science or matplotlib).
    """
    parser = argparse.ArgumentParser(
        prog="tunespec",
        description="Spectral reflectance from an RGB camera and a tunable LED source.",
    )
    parser.add_argument("--version", action=_VersionAction)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``tunespec``; returns the exit code."""
    from tunespec.devices.protocols import DeviceError

    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        check_outputs(args)
        return int(args.func(args) or 0)
    except DiskFullError as exc:
        print(f"tunespec {args.command}: disk full: {exc}", file=sys.stderr)
        return EXIT_DISK_FULL
    except TuneSpecError as exc:
        print(f"tunespec {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_INPUT
    except DeviceError as exc:
        print(f"tunespec {args.command}: device error: {exc}", file=sys.stderr)
        return EXIT_DEVICE
    except (Cancelled, KeyboardInterrupt):
        print(f"tunespec {args.command}: cancelled", file=sys.stderr)
        return EXIT_CANCELLED
    except OSError as exc:
        # the last net: a file the checks could not foresee (a full disk while
        # writing, a permission changed meanwhile) still ends in one line
        if exc.errno == errno.ENOSPC:
            err = DiskFullError.from_os_error(exc)
            print(f"tunespec {args.command}: disk full: {err}", file=sys.stderr)
            return EXIT_DISK_FULL
        where = f"{exc.filename}: " if exc.filename else ""
        print(
            f"tunespec {args.command}: error: {where}{exc.strerror or exc}",
            file=sys.stderr,
        )
        return EXIT_INPUT


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
    for attr in getattr(args, "output_dirs", ()):
        value = getattr(args, attr, None)
        if value is not None:
            check_output_dir(value, "--" + attr.replace("_", "-"))


if __name__ == "__main__":
    sys.exit(main())
