"""The single-shot LED mix of a gonio session: plain D50 match or camera-tuned.

``d50`` (the default): the LED levels whose mix reproduces CIE D50 for the eye
(:func:`tunespec.core.illuminant_match.match_illuminant`: chromaticity pinned,
metamerism of the ColorChecker SG minimised). ``camera``: that match re-optimised for
the calibrated camera (:func:`tunespec.core.single_shot.optimise_mix_for_camera`: the
camera x mix as close to colorimetric as the LEDs allow, D50's u'v' kept and the SG's
metamerism within CIE 51.2 category B), the "go beyond" of the paper's single shot.

Either way the light is driven to the levels once and the spectrum its
spectroradiometer reports is kept (``mix_measured.csv``) with the levels and the
metrics (``mix.json``); every geometry keeps its own reported mix SPD too
(``spd_mix.csv``), which is what the single-shot transform uses.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from tunespec.app.pipeline.gonio import MIX_KINDS
from tunespec.core.errors import InputError
from tunespec.core.io.spectral_csv import write_spectra_csv
from tunespec.core.spectra import Spectra

__all__ = ["MEASURED_MIX_CSV", "choose_mix"]

#: The mix's SPD as the light source reported it at the chosen levels.
MEASURED_MIX_CSV = "mix_measured.csv"


def choose_mix(
    kind: str,
    leds: Spectra,
    sensitivity: Spectra,
    light: Any,
    folder: str | Path,
) -> dict[str, Any]:
    """Levels of the ``kind`` mix, driven once on ``light`` and measured.

    Parameters
    ----------
    kind
        One of :data:`~tunespec.app.pipeline.gonio.MIX_KINDS`.
    leds
        Each channel's spectrum at level 1 as the light reports it (in the light's
        channel order).
    sensitivity
        The calibrated camera sensitivities (used by ``camera`` only).
    light
        A :class:`~tunespec.devices.protocols.LightSource`; left with every LED off.
    folder
        Where :data:`MEASURED_MIX_CSV` is written.

    Returns
    -------
    dict
        JSON-ready: ``mix`` (the kind), ``levels``, ``channels``, ``d50_match`` (the
        plain match's levels and metrics), ``camera_mix`` (``camera`` only: the
        camera's RMS CIELAB error over the SG under the plain and the tuned mix, the
        tuned mix's metamerism and Delta u'v'), ``measured`` (Delta u'v' to D50, CIE
        Ra and TM-30 Rf of the reported SPD) and ``measured_spd`` (the CSV's name).
    """
    from tunespec.core.datasets import load_colorchecker_sg
    from tunespec.core.illuminant_match import (
        colour_rendering,
        illuminant_spd,
        match_illuminant,
        spd_delta_uv,
    )
    from tunespec.core.single_shot import optimise_mix_for_camera

    if kind not in MIX_KINDS:
        raise InputError(f"mix: expected one of {', '.join(MIX_KINDS)}, got {kind!r}")
    d50, sg = illuminant_spd("D50"), load_colorchecker_sg()
    match = match_illuminant(leds, d50, sg)
    levels = match.levels
    doc: dict[str, Any] = {"mix": kind, "d50_match": match.as_dict()}
    if kind == "camera":
        tuned = optimise_mix_for_camera(leds, sensitivity, sg, levels)
        levels = tuned.levels
        doc["camera_mix"] = {
            "camera_rms_deab_d50_match": tuned.start_camera_rms_deab,
            "camera_rms_deab": tuned.camera_rms_deab,
            "metamerism_de00": tuned.metamerism_de00,
            "delta_uv": tuned.delta_uv,
        }
    channels = [c.name for c in light.channels()]
    if tuple(channels) != leds.names:
        raise InputError(
            "the LED spectra's channels differ from the light's: "
            f"{list(leds.names)[:3]}... vs {channels[:3]}..."
        )
    try:
        light.set_levels(np.asarray(levels, dtype=np.float64))
        spd = light.measure_spd()
    finally:
        light.all_off()
    write_spectra_csv(spd, Path(folder) / MEASURED_MIX_CSV)
    ra, rf = colour_rendering(spd)
    doc.update(
        channels=channels,
        levels=[float(v) for v in levels],
        measured={"delta_uv": spd_delta_uv(spd, d50), "cri_ra": ra, "tm30_rf": rf},
        measured_spd=MEASURED_MIX_CSV,
    )
    return doc
