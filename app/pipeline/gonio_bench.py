"""A gonio session end to end on the simulated bench (``tunespec gonio-demo``).

1. Calibrate the camera on the ColorChecker SG under the 22 LEDs at 0/45 (patch
   level: Eq. 1 with the bench's true camera and the light's emitted spectra, photon
   and read noise; estimated from the spectra the light *reports*,
   :func:`tunespec.core.sensitivity.estimate_camera_sensitivity`);
2. match the LEDs to D50 with the spectra the light reports for each channel
   (:func:`tunespec.core.illuminant_match.match_illuminant`), tuned for the camera
   when the plan's ``mix`` is ``camera`` (:mod:`tunespec.app.pipeline.gonio_mix`);
3. capture the plan (:func:`tunespec.app.pipeline.gonio.capture_gonio`; resumable);
4. process and fuse (:func:`tunespec.app.pipeline.gonio_process.process_gonio`),
   write the data set and score it against the bench's truth (``summary.json``).

Calibration and mix are kept in the folder (``calibration.csv``, ``mix.json``), so a
resumed session uses the same ones.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from tunespec.app.pipeline.gonio import GonioPlan, capture_gonio, default_plan
from tunespec.core.io.session import atomic_write_text
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.io.spectral_csv import write_spectra_csv
from tunespec.core.limits import dumps_json, read_json
from tunespec.core.progress import ProgressFn, StopFn, sub_progress
from tunespec.core.spectra import DEFAULT_GRID, Spectra

__all__ = ["open_gonio_bench", "run_gonio_demo"]


def open_gonio_bench(seed: int = 0, fail_after_moves: int | None = None) -> Any:
    """The simulated bench: a warm CAL1-model light, a goniometer, the glossy target."""
    from tunespec.devices.sim.gonio import GonioBench, SimGoniometer
    from tunespec.devices.sim.light import open_sim_light

    light = open_sim_light("sim", seed=seed, warm=True)
    gonio = SimGoniometer(fail_after_moves=fail_after_moves, seed=seed)
    return GonioBench(light, gonio, seed=seed)


def _led_spectra(bench: Any) -> tuple[Spectra, np.ndarray]:
    """Each LED as the light reports it, and what it emits right after (the truth)."""
    light = bench.light
    names = [c.name for c in light.channels()]
    reported, emitted = [], []
    for j in range(len(names)):
        light.set_levels(np.eye(len(names))[j])
        reported.append(light.measure_spd())
        emitted.append(light.emitted_spd().resample(bench.grid, average=True).values[0])
    light.all_off()
    rep = Spectra(
        reported[0].wavelength_nm, [r.values[0] for r in reported], tuple(names)
    )
    return rep, np.array(emitted)


def calibrate_on_bench(bench: Any, seed: int) -> tuple[Any, Spectra]:
    """Sensitivities from the SG under every LED (see the module docstring).

    Returns the estimate (default estimator: sensitivities and per-LED metering
    corrections) and the LED spectra the light reported.
    """
    from tunespec.core.datasets import load_colorchecker_sg
    from tunespec.core.sensitivity import estimate_camera_sensitivity
    from tunespec.core.simulate import simulate_responses

    reported, emitted = _led_spectra(bench)
    true = emitted * bench.gain
    t = 0.8 / (true @ bench.sensitivity.values.T).max(axis=1)  # white at 80 %
    sg = load_colorchecker_sg(bench.grid)
    truth = Spectra(bench.grid.wavelength_nm, true * t[:, None], reported.names)
    resp = simulate_responses(sg, truth, bench.sensitivity, rng=seed)
    rep = reported.resample(DEFAULT_GRID, average=True)
    rep = rep.with_values(rep.values * t[:, None])  # the exposure scale of Eq. 1
    est = estimate_camera_sensitivity(resp, rep, load_colorchecker_sg())
    return est, reported


def _setup(
    bench: Any, root: Path, seed: int, mix_kind: str = "d50"
) -> tuple[Spectra, Any, np.ndarray]:
    """Calibration, its corrections and the plan's mix: made once per folder, reused."""
    from tunespec.app.pipeline.gonio_mix import choose_mix

    cal, mix, leds = (
        root / "calibration.csv",
        root / "mix.json",
        root / "leds_reported.csv",
    )
    if not (cal.exists() and mix.exists() and leds.exists()):
        est, reported = calibrate_on_bench(bench, seed)
        doc = choose_mix(mix_kind, reported, est.sensitivity, bench.light, root)
        write_spectra_csv(est.sensitivity, cal)
        write_spectra_csv(reported, leds)
        atomic_write_text(mix, dumps_json({**doc, **_led_correction_doc(est)}))
    return _load_setup(root, mix_kind)


def _led_correction_doc(estimate: Any) -> dict[str, Any]:
    """The calibration's per-LED corrections, JSON-ready (kept in ``mix.json``)."""
    c = estimate.led_correction
    return {"led_correction": {
        "names": list(c.names), "gain": list(c.gain), "shift_nm": list(c.shift_nm),
        "common_shift_nm": c.common_shift_nm}}  # fmt: skip


def _load_setup(root: Path, mix_kind: str) -> tuple[Spectra, Any, np.ndarray]:
    """Sensitivities, the illuminant correction and the mix levels kept in ``root``."""
    from tunespec.app.pipeline.gonio_process import calibration_correction
    from tunespec.core.errors import InputError
    from tunespec.core.led_correction import LedCorrection

    doc = read_json(root / "mix.json")
    if doc.get("mix", "d50") != mix_kind:
        raise InputError(
            f"mix.json holds the {doc.get('mix', 'd50')} mix, the plan asks for "
            f"{mix_kind}: start a new session folder",
            path=root / "mix.json",
        )
    c = doc["led_correction"]
    corr = LedCorrection(tuple(c["names"]), tuple(c["gain"]), tuple(c["shift_nm"]),
                         float(c["common_shift_nm"]))  # fmt: skip
    levels = np.array(doc["levels"])
    leds = read_spectra_csv(root / "leds_reported.csv")
    correct = calibration_correction(corr, leds, levels)
    sens = read_spectra_csv(root / "calibration.csv", allow_negative=True)
    return sens, correct, levels


def _truth(bench: Any, plan: GonioPlan) -> np.ndarray:
    n = bench.layout.n_patches
    rows = []
    for step in plan.steps:
        R = bench.reflectance_factors(step.geometry)[:n]
        rows.append(Spectra(bench.grid.wavelength_nm, R, bench.layout.patch_names)
                    .resample(DEFAULT_GRID).values)  # fmt: skip
    return np.stack(rows, axis=1)


def run_gonio_demo(
    out: str | Path,
    *,
    n_geometries: int = 14,
    mix: str = "d50",
    seed: int = 0,
    fail_after_moves: int | None = None,
    scheduler: str | None = None,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
) -> dict[str, Any]:
    """Run (or resume) the simulated gonio session in ``out``; return the summary.

    ``mix``: the single-shot mix of a new session's default plan (``d50`` or
    ``camera``, :mod:`~tunespec.app.pipeline.gonio_mix`); a plan in ``out`` keeps
    its own. ``scheduler``: see
    :func:`~tunespec.app.pipeline.gonio_process.process_gonio`.
    """
    from tunespec.app.pipeline.gonio_output import write_gonio_outputs
    from tunespec.app.pipeline.gonio_process import process_gonio, result_summary
    from tunespec.core.datasets import load_colorchecker_sg

    root = Path(out)
    root.mkdir(parents=True, exist_ok=True)
    plan_path = root / "plan.json"
    plan = (
        GonioPlan.load(plan_path)
        if plan_path.exists()
        else default_plan(n_geometries, mix=mix)
    )
    bench = open_gonio_bench(seed, fail_after_moves)
    S, correct, levels = _setup(bench, root, seed, plan.mix)
    capture_gonio(plan, root, bench, S, levels, should_stop=should_stop,
                  progress=sub_progress(progress, 0.0, 0.6))  # fmt: skip
    result = process_gonio(root, S, bench.layout, load_colorchecker_sg(),
                           correct=correct, scheduler=scheduler, progress=sub_progress(progress, 0.6, 0.95),
                           should_stop=should_stop)  # fmt: skip
    files = write_gonio_outputs(result, root)
    summary = {"mix": plan.mix, **result_summary(result, _truth(bench, plan))}
    summary["warnings"] = list(result.warnings)
    summary["files"] = [str(p.relative_to(root)) for p in files[:1] + files[-1:]]
    atomic_write_text(root / "summary.json", dumps_json(summary))
    return summary
