"""What the ``tunespec`` commands share: exit codes, argument types, progress bars.

Command modules (``tunespec.app.cli.*_cmds``) import from here, never from the
package itself, so the parser and its commands form no import cycle.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TextIO

from tunespec.core.errors import InputError, TuneSpecError
from tunespec.core.progress import ProgressFn
from tunespec.core.spectra import Grid, Spectra

__all__ = [
    "EXIT_CANCELLED",
    "EXIT_CODES_HELP",
    "EXIT_DEVICE",
    "EXIT_DISK_FULL",
    "EXIT_INPUT",
    "Console",
    "TerminalProgress",
    "add_bench_options",
    "add_force_option",
    "add_grid_option",
    "add_output_options",
    "add_scheduler_option",
    "add_sensitivities_option",
    "close_progress",
    "grid_arg",
    "plausibility_checks",
    "progress_bar",
    "resolution_arg",
    "resolve_grid",
    "seed_arg",
    "serve_until_stopped",
]

EXIT_INPUT = 2
EXIT_DEVICE = 3
EXIT_DISK_FULL = 4
EXIT_CANCELLED = 130
#: The exit codes, as ``tunespec --help`` lists them.
EXIT_CODES_HELP = (
    "exit codes: 0 done; 2 bad input (a file, option or value: the one error line "
    "names it); 3 device error (light source, camera, goniometer); 4 disk full; "
    "130 interrupted (Ctrl-C or cancelled). Results go to stdout, progress, notes "
    "and errors to stderr."
)


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


def resolution_arg(text: str) -> tuple[int, int]:
    """argparse type for ``--resolution WxH`` (a simulated camera's size)."""
    from tunespec.devices.registry import parse_resolution

    try:
        return parse_resolution(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_grid_option(
    parser: argparse.ArgumentParser,
    help: str = "working wavelength grid in nm (default: from the data, the widest "
    "range every input covers at the finest step of the chart, prior and sensitivity "
    "data, at most 10 nm; printed and kept in the outputs' metadata)",
) -> None:
    """The shared ``--grid`` option (default ``None``: the command decides, e.g. from
    the data with :func:`resolve_grid`)."""
    parser.add_argument(
        "--grid", type=grid_arg, default=None, metavar="START:END:STEP", help=help
    )


def add_sensitivities_option(
    parser: argparse.ArgumentParser,
    help: str = "sensitivities with R, G, B: the CSV of 'tunespec calibrate' or its "
    "rawtoaces JSON ('export-rawtoaces', the demo's sensitivities.json), CGATS",
    *,
    required: bool = True,
) -> None:
    """``--sensitivities``: a camera's R, G, B sensitivities (any format
    :func:`tunespec.core.datasets.read_sensitivities` reads)."""
    parser.add_argument("--sensitivities", required=required, type=Path, help=help)


def add_scheduler_option(
    parser: argparse.ArgumentParser,
    help: str = "a dask.distributed scheduler (tcp://host:8786); default: local threads",
) -> None:
    """``--scheduler``: where the Dask steps compute
    (:func:`tunespec.app.pipeline.engine.connect`)."""
    parser.add_argument("--scheduler", default=None, metavar="ADDRESS", help=help)


def add_bench_options(parser: argparse.ArgumentParser) -> None:
    """``--light``, ``--camera``, ``--resolution`` and ``--seed``: the devices by spec
    (:func:`tunespec.devices.registry.open_bench`), as ``capture`` and ``gonio-run``
    take them."""
    parser.add_argument(
        "--light",
        default="sim",
        help="sim | cal1:///dev/ttyUSB0 | cal1+socket://HOST:PORT",
    )
    parser.add_argument(
        "--camera",
        default=None,
        help="sim[?realtime=1] | gphoto2 | gphoto2:usb:BUS,DEV (default: sim with a "
        "simulated light, gphoto2 otherwise)",
    )
    parser.add_argument(
        "--resolution",
        type=resolution_arg,
        default=None,
        metavar="WxH",
        help="simulated camera resolution",
    )
    parser.add_argument("--seed", type=seed_arg, default=0, help="simulation seed")


def add_output_options(parser: argparse.ArgumentParser) -> None:
    """``--quiet`` and ``--json``, on every command that reports numbers."""
    parser.add_argument(
        "-q",
        "--quiet",
        action="store_true",
        help="print nothing but warnings and errors (no progress, no tables)",
    )
    parser.add_argument(
        "--json",
        action="store_true",
        help="print one JSON object with the numbers on stdout instead of the text "
        "(progress and notes go to stderr)",
    )


def add_force_option(parser: argparse.ArgumentParser) -> None:
    """``--force``: accept inputs the plausibility checks refuse
    (:mod:`tunespec.core.plausibility`); each override is a warning and is listed in
    the outputs' metadata (``forced``)."""
    parser.add_argument(
        "--force",
        action="store_true",
        help="accept inputs that look implausible (a scale, coverage or size "
        "mistake); each override is warned about and recorded in the outputs",
    )


def plausibility_checks(args: argparse.Namespace, out: Console) -> Any:
    """The :class:`~tunespec.core.plausibility.Checks` of a command (``--force``)."""
    from tunespec.core.plausibility import Checks

    return Checks(force=bool(getattr(args, "force", False)), warn=out.warn)


class Console:
    """Where a command's text goes, after ``--quiet`` and ``--json``.

    ``say``: the text report on stdout (neither option); ``note``: what was
    converted or chosen, on stderr (not with ``--quiet``); ``warn``: always, on
    stderr; ``summary``: the machine-readable result, on stdout with ``--json``.
    """

    def __init__(self, args: argparse.Namespace) -> None:
        self.quiet = bool(getattr(args, "quiet", False))
        self.json = bool(getattr(args, "json", False))

    def say(self, text: str = "") -> None:
        if not (self.quiet or self.json):
            print(text)

    def note(self, text: str) -> None:
        if not self.quiet:
            print(f"note: {text}", file=sys.stderr)

    def warn(self, text: str) -> None:
        print(f"warning: {text}", file=sys.stderr)

    def inputs(self, *spectra: Spectra) -> None:
        """Report what the readers converted (percent, absolute scale) per file."""
        for s in spectra:
            if "note" in s.meta:
                self.note(f"{s.meta.get('source', '')}: {s.meta['note']}")

    def summary(self, doc: dict[str, Any]) -> None:
        if self.json:
            from tunespec.core.limits import dumps_json

            print(dumps_json(doc))

    def progress(self, label: str) -> ProgressFn | None:
        """A progress callback (none with ``--quiet``)."""
        if self.quiet:
            return None
        return progress_bar(label)


def resolve_grid(
    args: argparse.Namespace,
    inputs: Sequence[tuple[Spectra, bool]],
    out: Console,
    *,
    max_step_nm: float | None = None,
) -> Grid:
    """The working grid: ``--grid``, else from the data (printed).

    ``inputs``: each spectral input with whether its step counts
    (:func:`~tunespec.core.spectra.grid_from_data`; light spectra are band-averaged
    and pass ``False``); ``max_step_nm`` caps the step (calibration:
    :data:`~tunespec.core.spectra.CALIBRATION_MAX_STEP_NM`).
    """
    from tunespec.core.spectra import MAX_DATA_GRID_STEP_NM, grid_from_data

    if args.grid is not None:
        out.say(f"working grid {args.grid} nm (--grid)")
        return args.grid
    grid = grid_from_data(
        [s for s, _ in inputs],
        sets_step=[k for _, k in inputs],
        max_step_nm=max_step_nm or MAX_DATA_GRID_STEP_NM,
    )
    out.say(
        f"working grid {grid} nm (from the data: the range every input covers; "
        "--grid overrides)"
    )
    return grid


_OPEN_BARS: list[TerminalProgress] = []


class TerminalProgress:
    """A progress callback (:data:`ProgressFn`) on stderr.

    On a terminal a real progress bar on stderr (``rich``: bar, percentage, elapsed
    and remaining time); otherwise (logs, CI) a plain line at every 10 % on
    ``lines_to`` (default stderr: stdout holds the results alone, so a table or a
    JSON document can be piped), so a log shows how far the work got.
    :func:`close_progress` stops bars left open by an error.
    """

    def __init__(
        self, label: str, *, force: bool = False, lines_to: TextIO | None = None
    ) -> None:
        self.label = label
        self._tty = sys.stderr.isatty() or force
        self._lines_to = lines_to
        self._t0 = time.monotonic()
        self._last_decile = -1
        self._bar: Any = None
        self._task: Any = None

    def _start(self) -> None:
        from rich.console import Console as RichConsole
        from rich.progress import (
            BarColumn,
            Progress,
            TaskProgressColumn,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

        self._bar = Progress(
            TextColumn("{task.description:<14}"),
            BarColumn(),
            TaskProgressColumn(),
            TimeElapsedColumn(),
            TimeRemainingColumn(),
            console=RichConsole(file=sys.stderr),
        )
        self._bar.start()
        self._task = self._bar.add_task(self.label, total=1.0)
        _OPEN_BARS.append(self)

    def __call__(self, fraction: float) -> None:
        fraction = min(max(float(fraction), 0.0), 1.0)
        if self._tty:
            if self._bar is None:
                self._start()
            self._bar.update(self._task, completed=fraction)
            if fraction >= 1.0:
                self.close()
            return
        decile = int(fraction * 10)
        if decile > self._last_decile:
            self._last_decile = decile
            elapsed = time.monotonic() - self._t0
            stream = self._lines_to or sys.stderr
            stream.write(f"{self.label}: {fraction:.0%} ({elapsed:.1f} s)\n")
            stream.flush()

    def close(self) -> None:
        if self._bar is not None:
            self._bar.stop()
            self._bar = None
            if self in _OPEN_BARS:
                _OPEN_BARS.remove(self)


def close_progress() -> None:
    """Stop every progress bar still drawing (a command ended early)."""
    for bar in list(_OPEN_BARS):
        bar.close()


def progress_bar(label: str, *, lines_to: TextIO | None = None) -> ProgressFn:
    """A progress callback for ``label`` (:class:`TerminalProgress`)."""
    return TerminalProgress(label, lines_to=lines_to)


def serve_until_stopped(stop: threading.Event, out: TextIO) -> None:
    """An emulator's foreground loop: wait until ``stop`` is set or Ctrl-C (then
    ``stopped`` is written to ``out``)."""
    out.flush()
    try:
        while not stop.wait(0.5):
            pass
    except KeyboardInterrupt:
        out.write("stopped\n")
