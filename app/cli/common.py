"""What the ``tunespec`` commands share: exit codes, argument types, progress bars.

Command modules (``tunespec.app.cli.*_cmds``) import from here, never from the
package itself, so the parser and its commands form no import cycle.
"""

from __future__ import annotations

import argparse
import sys
import time

from tunespec.core.errors import TuneSpecError
from tunespec.core.progress import ProgressFn
from tunespec.core.spectra import DEFAULT_GRID, Grid

__all__ = [
    "EXIT_CANCELLED",
    "EXIT_DEVICE",
    "EXIT_DISK_FULL",
    "EXIT_INPUT",
    "TerminalProgress",
    "add_grid_option",
    "grid_arg",
    "progress_bar",
    "seed_arg",
]

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
