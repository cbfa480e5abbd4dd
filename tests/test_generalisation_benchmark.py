"""The generalisation benchmark in a reduced form (issue 10): one camera per family,
the shipped light-source model, per-LED metering error; nothing the estimator was
tuned on is scored (leave-one-source-out, synthetic families, other reflectances)."""

from __future__ import annotations

import importlib.util
import json
import sys
from contextlib import contextmanager
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "generalisation.py"
CLI_PROTOCOL = BENCH.with_name("cli_protocol.py")
BUDGET_TERMS = BENCH.with_name("budget_terms.py")
#: The colour-science family: the Foveon-type Sigma SD Merrill, outside the camera
#: database's span and the benchmark's hardest camera (docs/validation.md, "colour-science's
#: Nikon was a shipped camera").
FOVEON = "colour-science"


@contextmanager
def _benchmark():
    """``benchmarks/generalisation.py`` as a module (with its data module beside it)."""
    sys.path.insert(0, str(BENCH.parent))
    try:
        spec = importlib.util.spec_from_file_location("generalisation", BENCH)
        mod = importlib.util.module_from_spec(spec)
        sys.modules["generalisation"] = mod  # dataclasses look their module up
        spec.loader.exec_module(mod)
        yield mod
    finally:
        sys.path.remove(str(BENCH.parent))
        sys.modules.pop("generalisation", None)


def _run(tmp_path_factory, *options: str) -> dict:
    """The benchmark, one camera per family, on the shipped light-source model."""
    out = tmp_path_factory.mktemp("gen") / "gen.json"
    argv = ["--per-family", "1", "--lights", "cal1-model", *options]
    with _benchmark() as mod:
        assert mod.main([*argv, "--json", str(out)]) == 0
    return json.loads(out.read_text())


@pytest.fixture(scope="module")
def summary(tmp_path_factory):
    return _run(tmp_path_factory, "--variants", "bayes,nnls,truth")


@pytest.fixture(scope="module")
def lab_conditions(tmp_path_factory):
    """Issue 23's conditions: the light's spectra reported every 10 nm with reading
    noise of 0.3 % of each peak (clipped at zero, two readings averaged), stray light,
    cross-talk and a non-linearity on the responses; estimated on its evaluation's
    grid, 400:700:10."""
    return _run(
        tmp_path_factory,
        "--variants", "bayes,truth-read", "--report-step-nm", "10",
        "--meter-noise", "0.003", "--systematic", "--estimate-grid", "400:700:10",
    )  # fmt: skip


@pytest.mark.slow
def test_every_family_is_accurate_and_never_worse_than_plain_nnls(summary) -> None:
    fams = summary["summary"]
    assert len(fams) == 10
    for fam, per in fams.items():
        bayes, nnls = per["bayes"], per["nnls"]
        assert bayes["de00_mean"] <= 0.15, (fam, bayes["de00_mean"])
        assert bayes["de00_worst_camera"] <= 0.3, (fam, bayes["de00_worst_camera"])
        assert bayes["de00_mean"] <= nnls["de00_mean"] + 0.02, fam
        assert bayes["sens_rms_median"] <= 0.03, fam
        assert 0.90 <= bayes["coverage_reflectance"] <= 0.99, fam


@pytest.mark.slow
def test_fitted_led_offsets_follow_the_injected_ones(summary) -> None:
    fit = [x for s in summary["scores"] for x in s["fitted_shift_nm"]]
    true = [x for s in summary["scores"] for x in s["true_shift_nm"]]
    assert len(fit) == 10 * 22
    assert np.corrcoef(fit, true)[0, 1] > 0.9


@pytest.mark.slow
def test_noisy_coarse_readings_and_sensor_effects_keep_numbers_and_error_bars(
    lab_conditions,
) -> None:
    fams = lab_conditions["summary"]
    assert len(fams) == 10
    for fam, per in fams.items():
        bayes, truth = per["bayes"], per["truth-read"]
        # 0.085-0.097 measured (issue 23 asks at most 0.2 at 0.3 % noise); with the
        # reflectance linear between its 10 nm samples, 0.109-0.137. The Foveon-type
        # Sigma SD Merrill (FOVEON): 0.137
        limit = 0.15 if fam == FOVEON else 0.12
        assert bayes["de00_mean"] <= limit, (fam, bayes["de00_mean"])
        assert bayes["de00_mean"] <= truth["de00_mean"], fam
        # neither too narrow nor too wide. Measured per family: reflectance
        # 0.948-0.959, L* 0.937-0.972, a* 0.950-0.981, b* 0.931-0.969 (with linear
        # hats L* 0.86-0.92, a* 0.68-0.85, b* 0.76-0.90; at 5 nm with the sensor
        # effects unmodelled, 0.982-0.998 and up to 1.0)
        # Against the surfaces' own colour (their 1 nm spectra): L* 0.943-0.981, a*
        # 0.950-0.981, b* 0.940-0.991. The Sigma SD Merrill: 0.945, 0.947, 0.912,
        # 0.937 (surface L* a* b* 0.943, 0.903, 0.950)
        # narrow-01's a* intervals (the narrow-band family's first camera, the one
        # here) are too wide, its calibration's and readings' lines mis-sized (issue
        # 23, open): a* 0.972 over 18 calibrations (coverage_seeds.py, 10 nm, 0.3 %;
        # over the family's six cameras 0.953-0.960), 0.991 in this session since
        # the reflectance is solved past 700 nm (0.987 before)
        foveon, narrow = fam == FOVEON, fam == "synthetic:narrow"
        lo = {"reflectance": 0.93, "L": 0.92, "a": 0.89 if foveon else 0.92, "b": 0.92}
        lo |= {"L_surface": 0.91, "a_surface": 0.88 if foveon else 0.90}
        lo["b_surface"] = 0.92
        hi = {
            "reflectance": 0.975,
            "L": 0.99,
            "a": 0.995 if narrow else 0.99,
            "b": 0.99,
        }
        hi |= {k: 0.995 for k in lo if k.endswith("_surface")}
        for k in lo:
            c = bayes[f"coverage_{k}"]
            assert lo[k] <= c <= hi[k], (fam, k, c)


@pytest.mark.slow
def test_colour_intervals_are_about_the_surface_not_its_10_nm_samples(
    tmp_path_factory,
) -> None:
    """An ideal sensor and exact readings, estimated on 400:700:10. The L*a*b*
    intervals are for the surface's colour; the colour of its 10 nm samples (ASTM
    E308's 10 nm weights) lies 0.018-0.063 dE00 from it per collection on average,
    as much as the estimate's own error here (0.042-0.056), and they do not cover
    it (L*, a*, b* 0.902 / 0.853 / 0.894 over all families)."""
    run = _run(tmp_path_factory, "--variants", "bayes", "--estimate-grid", "400:700:10")
    fams = run["summary"]
    for fam, per in fams.items():
        # measured per family: L* 0.925-0.965, a* 0.868-0.972, b* 0.934-0.978
        for k in ("L", "a", "b"):
            c = per["bayes"][f"coverage_{k}_surface"]
            assert 0.85 <= c <= 0.99, (fam, k, c)
    for k in ("L", "a", "b"):
        # measured over all families 0.951 / 0.940 / 0.959
        pooled = sum(p["bayes"][f"coverage_{k}_surface"] for p in fams.values())
        assert 0.93 <= pooled / len(fams) <= 0.97, (k, pooled / len(fams))


@pytest.mark.slow
def test_a_flat_field_worse_than_nominal_is_measured_not_assumed(
    tmp_path_factory,
) -> None:
    """A lab whose flat field leaves 1 % (not the nominal 0.3 %): the calibration
    fits the residual from the chart, so the intervals still hold. Assuming 0.3 %
    (as before) gave a* 0.849-0.943 and b* 0.865-0.959 per family here."""
    run = _run(
        tmp_path_factory,
        "--variants", "bayes", "--report-step-nm", "10", "--meter-noise", "0.001",
        "--systematic", "--flat-field", "0.01",
    )  # fmt: skip
    for score in run["scores"]:
        # 0.0102 on every camera measured
        assert 0.008 <= score["fitted_flat_field"] <= 0.012, score["camera"]
    for fam, per in run["summary"].items():
        # measured per family: reflectance 0.952-0.963, L* 0.943-0.972, a*
        # 0.950-0.984, b* 0.950-0.994; mean dE00 0.130-0.150 (the Sigma SD Merrill
        # 0.230; coverage 0.931-0.947)
        foveon = fam == FOVEON
        assert per["bayes"]["de00_mean"] <= (0.25 if foveon else 0.17), fam
        for k in ("reflectance", "L", "a", "b"):
            c = per["bayes"][f"coverage_{k}"]
            assert (0.91 if foveon else 0.93) <= c <= 0.999, (fam, k, c)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_curve_that_rings_below_zero_keeps_the_evidences_prior(seed) -> None:
    """The IR-cut camera under the held-out LEDs, with the benchmark's stray light and
    cross-talk: the evidence's prior for its blue channel rings 10-20 % below zero
    (a sharp cut-off). Stiffening that prior until it did not (the rule before)
    took it 1000 times stiffer for these three draws of the sensor effects: the
    curve could no longer follow the cut, H416's gain went to 0.72-0.73 and the
    residuals' relative term to 1.0 % (on the benchmark at 0.3 % reading noise, 0.157
    dE00; 0.105 now)."""
    with _benchmark() as gen:
        gd = sys.modules["generalisation_data"]
        setup = gen.load_setup()
        cam = next(c for c in gd.all_cameras() if c.name == "ircut-01")
        leds = gd.light_sources()["heldout-leds"]
        s = gen.simulate_session(
            cam, leds, setup, np.random.default_rng(0), clean_meter=True,
            report_step_nm=10,
        )  # fmt: skip
        resp = gd.systematic_effects(s.resp, np.random.default_rng(seed))
        est = gen.calibrate("bayes", resp, s.reported, setup[2], setup[4], cam.exclude)
    gain = np.asarray(est.led_correction.gain) * s.gains
    # measured: 0.987-1.041 for the three seeds (0.721-1.110 before)
    assert np.all(np.abs(gain - 1.0) < 0.08), gain.round(3)
    # measured: 0.08-0.11 % (1.02 % before)
    assert est.excess.response_relative < 0.003, est.excess.response_relative


@pytest.mark.slow
@pytest.mark.parametrize("camera", ["ircut-01", "Nikon D5100"])
def test_the_command_line_gives_what_the_benchmark_scores(camera) -> None:
    """An evaluation runs files through ``tunespec calibrate`` and ``tunespec
    estimate``; the benchmark calls functions. On the same session (the readings
    every 10 nm with 0.3 % noise, one reading, the sensor effects on) both give the
    same estimate and the same intervals. Before, here, the command line's
    intervals covered 0.97-1.00 (the calibration's own readings, read again at 10
    nm, were taken for other readings) and the IR-cut camera's mean dE00 was 0.300
    against 0.108 (its per-LED corrections applied to the 10 nm samples)."""
    with _benchmark() as gen:
        gd = sys.modules["generalisation_data"]
        spec = importlib.util.spec_from_file_location("cli_protocol", CLI_PROTOCOL)
        protocol = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(protocol)
        gen.EST = protocol.EST
        setup = gen.load_setup()
        cam = next(c for c in gd.all_cameras() if c.name == camera)
        via_cli, via_fn = protocol.compare(
            cam, gd.light_sources()["cal1-model"], setup, np.random.default_rng(0),
            meter_noise=0.003, meter_reads=1, systematic=True, report_step_nm=10,
        )  # fmt: skip
    assert via_cli["de00"] == pytest.approx(via_fn["de00"], abs=1e-5), (via_cli, via_fn)
    for k in "RLab":
        assert via_cli[k] == pytest.approx(via_fn[k], abs=0.004), (k, via_cli, via_fn)
    # and what the benchmark scores holds (measured: dE00 0.097 / 0.089, L* 0.909 / 0.940)
    assert via_cli["de00"] < 0.12
    assert 0.9 <= via_cli["L"] <= 0.985, via_cli


def test_no_camera_is_scored_with_its_own_measurement_in_the_database() -> None:
    """Every camera the benchmark scores differs from every database camera the
    estimator may use. colour-science's "Nikon 5100 (NPL)" was the shipped "Nikon
    D5100" (equal to 5e-10) and was scored with the whole database."""
    with _benchmark():
        gd = sys.modules["generalisation_data"]
        shipped = gd.shipped_cameras()
        for cam in gd.all_cameras():
            for db in shipped:
                if db.name not in cam.exclude:
                    difference = np.abs(cam.truth.values - db.truth.values).max()
                    assert difference > 0.01, (cam.name, db.name)


@pytest.mark.slow
def test_the_budgets_random_lines_predict_the_spread_of_new_responses() -> None:
    """``benchmarks/budget_terms.py`` on one session (narrow-band camera, CAL1 model,
    the sensor effects without the non-linearity, 0.3 % readings): the response
    noise, flat-field, stray-light and cross-talk lines against the spread of L*a*b*
    over six new draws of the test responses (measured 1.00 / 0.97 / 1.10; 0.91-1.10
    on four cameras and both lights)."""
    spec = importlib.util.spec_from_file_location("budget_terms", BUDGET_TERMS)
    with _benchmark():
        bt = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(bt)
        bt.gen.EST = bt.cp.EST
        setup = bt.gen.load_setup()
        cam = next(c for c in bt.gd.all_cameras() if c.name == "narrow-01")
        args = SimpleNamespace(
            draws=6, seed=100, meter_noise=0.003, report_step_nm=10.0,
            systematic=True, linear=True, true_sensitivities=False,
        )  # fmt: skip
        parts = bt.run_camera(cam, bt.gd.light_sources()["cal1-model"], setup, args)
    assert np.all((parts["random"] > 0.8) & (parts["random"] < 1.25)), parts["random"]
