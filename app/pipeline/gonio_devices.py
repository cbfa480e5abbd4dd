"""A gonio session on devices opened by spec: ``tunespec gonio-run``.

The same specs as ``tunespec capture`` (:func:`tunespec.devices.registry.open_bench`):
a light source (``cal1:///dev/ttyUSB0``, ``cal1+socket://H:P``, ``sim``), a camera
(``gphoto2[:PORT]``, or ``sim`` rendering the target under what the light reports),
plus a goniometer (:func:`tunespec.devices.goniometer_registry.open_goniometer`:
``zaber:///dev/ttyUSB0``, ``zaber+socket://H:P``, ``sim``). The sequence is the
simulated session's (:func:`tunespec.app.pipeline.gonio.capture_gonio`, resumable,
then :func:`tunespec.app.pipeline.gonio_process.process_gonio`); what differs:

- the sensitivities come from a calibration (``tunespec calibrate``, absolute units:
  full scale per W sr^-1 m^-2 nm^-1 nm s), so a frame's exposure is in seconds;
  they are sampled onto the working grid (5 nm) the session computes on;
- each LED's spectrum at level 1 is measured once with the light's
  spectroradiometer (``leds_reported.csv``) and the mix chosen from those
  (:func:`tunespec.app.pipeline.gonio_mix.choose_mix`);
- frames come from raw files: :class:`DeviceGonioBench` sets the exposure, reads
  back what the camera really used, keeps the raw file (``raw/``) and stores its
  full-scale planes scaled to the requested exposure, saturated cells at full scale
  (so the HDR merge still flags them).
"""

from __future__ import annotations

from collections.abc import Mapping
from contextlib import closing
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tunespec.app.pipeline.gonio import GonioPlan, capture_gonio
from tunespec.core.io.session import atomic_write_text
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.io.spectral_csv import write_spectra_csv
from tunespec.core.layout import TargetLayout
from tunespec.core.limits import dumps_json, read_json
from tunespec.core.progress import ProgressFn, StopFn, sub_progress
from tunespec.core.spectra import DEFAULT_GRID, Spectra
from tunespec.devices.protocols import DeviceProtocolError

__all__ = ["DeviceGonioBench", "measure_led_spectra", "run_gonio_session"]

#: Where the camera's raw files are kept, one per frame.
RAW_DIR = "raw"
#: The session's own copy of the sample target's layout: a resumed session uses it.
SESSION_LAYOUT = "layout.json"
#: The ISO speed the session's frames are taken at: a resumed session keeps it.
SESSION_CAMERA = "camera.json"
#: A simulated camera's field of view, in widths of the sample target (a gonio
#: camera frames the sample, not the room; ignored for a real camera).
SIM_FIELD = 2.0


class DeviceGonioBench:
    """Light, goniometer and a registry camera as :func:`capture_gonio` drives them."""

    def __init__(self, light: Any, gonio: Any, camera: Any, raw_dir: Path) -> None:
        self.light, self.gonio, self.camera = light, gonio, camera
        self.raw_dir = Path(raw_dir)
        self.raw_dir.mkdir(parents=True, exist_ok=True)

    def capture(self, exposure: float, key: int | None = None) -> NDArray[np.float32]:
        """One frame at ``exposure`` seconds: (3, H/2, W/2) full-scale planes.

        The camera may round the exposure (shutter steps): the planes are scaled by
        requested / used, so Eq. 1 sees the requested exposure; cells saturated in
        the raw file are set to full scale (1.0) after scaling.
        """
        from tunespec.core.io.raw import load_raw

        self.camera.set_exposure(float(exposure))
        used = float(self.camera.exposure_s)
        if not used > 0:
            raise DeviceProtocolError(f"the camera reports an exposure of {used} s")
        stem = self.raw_dir / (f"frame_{key:08x}" if key is not None else "frame")
        raw = load_raw(self.camera.capture(stem))
        planes = raw.planes * np.float32(exposure / used)
        planes[:, raw.saturated] = 1.0
        return planes


def measure_led_spectra(light: Any) -> Spectra:
    """Each channel of ``light`` at level 1, as its spectroradiometer reports it."""
    names = [c.name for c in light.channels()]
    rows = []
    try:
        for j in range(len(names)):
            light.set_levels(np.eye(len(names))[j])
            rows.append(light.measure_spd())
    finally:
        light.all_off()
    return Spectra(rows[0].wavelength_nm, [r.values[0] for r in rows], tuple(names))


def _setup(root: Path, light: Any, sensitivity: Spectra, mix: str) -> np.ndarray:
    """LED spectra and the plan's mix, measured once per folder; the mix levels."""
    from tunespec.app.pipeline.gonio_mix import choose_mix
    from tunespec.core.errors import InputError

    doc_path = root / "mix.json"
    if not doc_path.exists():
        leds = measure_led_spectra(light)
        write_spectra_csv(leds, root / "leds_reported.csv")
        doc = choose_mix(mix, leds, sensitivity, light, root)
        atomic_write_text(doc_path, dumps_json(doc))
    doc = read_json(doc_path)
    if doc.get("mix") != mix:
        raise InputError(
            f"mix.json holds the {doc.get('mix')} mix, the plan asks for {mix}",
            path=doc_path,
        )
    return np.asarray(doc["levels"], dtype=np.float64)


def _session_gain(root: Path, iso: int) -> float:
    """The gain of the session's frames (``core.processing.iso_gain``): ``iso``,
    kept in :data:`SESSION_CAMERA`, whose ISO a resumed session must be given again
    (its frames and those still to take share one scale)."""
    from tunespec.core.errors import InputError
    from tunespec.core.processing import iso_gain

    path = root / SESSION_CAMERA
    if path.exists():
        kept = read_json(path).get("iso")
        if kept != iso:
            raise InputError(
                f"the session's frames are at ISO {kept}: resume it with --iso {kept}, "
                f"not {iso}",
                path=path,
            )
    else:
        atomic_write_text(path, dumps_json({"iso": int(iso)}))
    return iso_gain(iso)


def _session_calibration(
    root: Path,
    sensitivity: Spectra,
    led_correction: Any,
    side: Mapping[str, Any],
) -> tuple[Spectra, Any]:
    """The session's sensitivities and per-LED corrections, kept with it the first
    time (``calibration.csv``, ``led_correction.json``, and the sensor's
    non-linearity that the calibration undid, ``excess_variance.json``: every
    frame of the session is linearised as the chart's were)."""
    from tunespec.core.led_correction import LedCorrection

    cal, corr_path = root / "calibration.csv", root / "led_correction.json"
    excess_path = root / "excess_variance.json"
    if not cal.exists():
        if led_correction is not None:
            atomic_write_text(corr_path, dumps_json(led_correction.as_dict()))
        if "excess_variance" in side:
            doc = side["excess_variance"]
            atomic_write_text(
                excess_path, doc if isinstance(doc, str) else dumps_json(doc)
            )
        write_spectra_csv(sensitivity, cal)
    corr = (
        LedCorrection.from_dict(read_json(corr_path), str(corr_path))
        if corr_path.exists()
        else None
    )
    # the gonio pipeline integrates Eq. 1 on the working grid (the measured SPDs are
    # band-averaged onto it): finer calibrations are abridged to it (ASTM E308)
    S = read_spectra_csv(cal, allow_negative=True).resample(
        DEFAULT_GRID, source=str(cal)
    )
    if excess_path.exists():
        meta = {"excess_variance": dumps_json(read_json(excess_path))}
        S = replace(S, meta={**S.meta, **meta, "meta_path": str(excess_path)})
    return S, corr


def run_gonio_session(
    out: str | Path,
    *,
    light: str,
    camera: str | None,
    gonio: str,
    sensitivity: Spectra,
    layout: TargetLayout,
    led_correction: Any = None,
    sensitivity_meta: Mapping[str, Any] | None = None,
    layout_path: str | Path | None = None,
    resolution: tuple[int, int] | None = None,
    iso: int = 100,
    seed: int = 0,
    scheduler: str | None = None,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
) -> dict[str, Any]:
    """Capture (or resume) and process the plan in ``out`` on the named devices.

    ``out/plan.json`` must exist (the CLI writes it). The sensitivities and the
    calibration's per-LED corrections (``led_correction``, a
    :class:`~tunespec.core.led_correction.LedCorrection`: metering errors of the
    light's spectroradiometer that the calibration separated from the sensitivities)
    are saved with the session (``calibration.csv``, ``led_correction.json``) and a
    resumed session uses those (``sensitivity_meta``, the sensitivities' side file
    as ``core.io.export.read_sensitivity_meta`` reads it, gives them when
    ``led_correction`` is not given); the corrections are applied to every illuminant of
    Eq. 1, the mix's through its LEDs
    (:func:`~tunespec.app.pipeline.gonio_process.calibration_correction`). The
    layout is kept as ``layout.json`` (:data:`SESSION_LAYOUT`), which a resumed
    session is given back (``gonio-run --resume`` without ``--layout``). Returns
    the summary written to ``summary.json``: geometries, the goniometer's read-back
    positions, the mix and per geometry the mean single-shot XYZ uncertainty.
    """
    from tunespec.app.pipeline.gonio_output import write_gonio_outputs
    from tunespec.app.pipeline.gonio_process import (
        calibration_correction,
        process_gonio,
    )
    from tunespec.core.datasets import load_colorchecker_sg
    from tunespec.core.led_correction import LedCorrection
    from tunespec.devices.goniometer_registry import open_goniometer
    from tunespec.devices.registry import open_bench

    side = sensitivity_meta or {}
    if led_correction is None and "led_correction" in side:
        led_correction = LedCorrection.from_dict(
            side["led_correction"], side.get("meta_path")
        )
    root = Path(out)
    plan = GonioPlan.load(root / "plan.json")
    if not (root / SESSION_LAYOUT).exists():
        layout.save(root / SESSION_LAYOUT)
    if layout_path is None:
        layout_path = root / SESSION_LAYOUT
    S, corr = _session_calibration(root, sensitivity, led_correction, side)
    # the calibration counts its light at ISO 100 (core.processing.iso_gain): at
    # this session's gain the camera gives that much more per unit of light
    S = S.with_values(S.values * _session_gain(root, iso))
    with (
        open_bench(light, camera, layout=layout.with_corners(None),
                   layout_path=layout_path, resolution=resolution, seed=seed,
                   scene_options={"field_width_mm": SIM_FIELD * layout.width_mm},
                   ) as bench,
        closing(open_goniometer(gonio)) as stage,
    ):  # fmt: skip
        bench.camera.set_iso(iso)
        levels = _setup(root, bench.light, S, plan.mix)
        devices = DeviceGonioBench(bench.light, stage, bench.camera, root / RAW_DIR)
        taken = capture_gonio(plan, root, devices, S, levels, should_stop=should_stop,
                              progress=sub_progress(progress, 0.0, 0.7))  # fmt: skip
    correct = (
        calibration_correction(
            corr, read_spectra_csv(root / "leds_reported.csv"), levels
        )
        if corr is not None
        else None
    )
    result = process_gonio(root, S, layout, load_colorchecker_sg(), correct=correct,
                           scheduler=scheduler,
                           progress=sub_progress(progress, 0.7, 0.95),
                           should_stop=should_stop)  # fmt: skip
    files = write_gonio_outputs(result, root)
    summary = {
        "n_geometries": len(plan.steps),
        "n_spectral": int(result.spectral.sum()),
        "mix": plan.mix,
        "frames_taken_now": len(taken),
        "positions": result.positions,
        "u_xyz_mean": [float(v) for v in np.nanmean(result.u_xyz, axis=(0, 2))],
        "warnings": list(result.warnings),
        "files": [str(p.relative_to(root)) for p in files[:1] + files[-1:]],
    }
    atomic_write_text(root / "summary.json", dumps_json(summary))
    return summary
