"""Small helpers shared by the tests outside the GUI (``tests/app/helpers.py``)."""

from __future__ import annotations

import re
from pathlib import Path

from tunespec.core.datasets import load_camera, load_colorchecker_sg, load_led_set
from tunespec.core.io.spectral_csv import write_spectra_csv

#: The files :func:`write_shipped_spectra` writes: camera, LEDs, ColorChecker SG.
SHIPPED_SPECTRA = ("cam.csv", "leds.csv", "sg.csv")


def write_shipped_spectra(folder: Path) -> Path:
    """The shipped camera sensitivities, 22 LED spectra and SG reflectances as the
    CSV files ``cam.csv``, ``leds.csv`` and ``sg.csv`` in ``folder`` (returned)."""
    for spectra, name in zip(
        (load_camera(), load_led_set(), load_colorchecker_sg()),
        SHIPPED_SPECTRA,
        strict=True,
    ):
        write_spectra_csv(spectra, folder / name)
    return folder


#: A plain progress line on stderr when it is not a terminal ("capturing: 40% (1.2 s)").
_PROGRESS_LINE = re.compile(r"^.+: \d+% \(\d+\.\d s\)$")


def without_progress(stderr: str) -> str:
    """``stderr`` without its progress lines (they share stderr with the one error
    line, so that stdout holds the results alone)."""
    lines = stderr.strip().splitlines()
    return "\n".join(line for line in lines if not _PROGRESS_LINE.match(line))
