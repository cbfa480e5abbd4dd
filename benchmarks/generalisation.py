"""Generalisation benchmark of the camera calibration: scored only on what it never saw.

For every camera of :mod:`generalisation_data` (leave-one-*source*-out over the
shipped rawtoaces-data cameras, colour-science's NPL cameras and six synthetic
families outside the database's span), under both light sources (the shipped CAL1
model and a held-out LED set):

1. the ColorChecker SG is captured under every LED (1 nm rendering, exposure per LED
   to 80 % of full scale, photon + read noise of 400 ROI pixels, 0.3 % flat-field
   residual) and the spectroradiometer reports every LED with its *own* error:
   a wavelength offset drawn from U(-1, +1) nm and a gain from N(1, 1 %)
   (``--no-metering-error`` turns both off);
2. each estimator calibrates on the 380-730 nm / 2 nm grid (the product's
   ``CALIBRATION_GRID``) from the reported SPDs,
   with the camera's whole measuring source removed from the database;
3. 318 test reflectances (:func:`generalisation_data.test_reflectances`: not the
   chart, not the Wiener prior) are captured the same way and estimated by Wiener
   (Eq. 5-6, SG prior, 400-700 nm / 5 nm) with each calibration, its light-source
   corrections and, for ``bayes``, the propagated uncertainty.

Scores per camera: sensitivity RMS (peak-normalised), Table 1 RGB mean, mean and worst
CIEDE2000 (D50) and mean spectral RMS on the test reflectances, and for ``bayes`` the
coverage of its 95 % intervals (reflectance samples, L*, a*, b*). Summaries per family.

Estimators: ``bayes`` (default: empirical Bayes, per-LED self-calibration),
``bayes-noselfcal`` (same, one common wavelength offset only), ``smooth`` (the previous
default, fixed database weight), ``pca`` (the paper's Eq. 4) and ``nnls`` (plain
non-negative least squares with a fixed second-difference penalty, no database, no
shift: the reference every family must beat or match); ``truth`` is Wiener with the
true sensitivities and the true spectra, the floor that no calibration can beat.

Usage::

    python benchmarks/generalisation.py                  # everything (~20 min, 2 cores)
    python benchmarks/generalisation.py --quick          # 2 cameras per family, one light
    python benchmarks/generalisation.py --no-metering-error --variants bayes,bayes-noselfcal
    python benchmarks/generalisation.py --json out.json
    python benchmarks/generalisation.py --grid 380:730:5  # calibrate on another grid
    python benchmarks/generalisation.py --meter-noise 0.001 --report-step-nm 10  # noisy SPDs
    python benchmarks/generalisation.py --systematic  # stray light, cross-talk, non-linearity
    python benchmarks/generalisation.py --variants bayes,pca,smooth --chart-tone 0.8333

After the table it prints the leave-one-reflectance-collection-out choice of
``core.uncertainty.PRIOR_MISMATCH_SCALE`` (:func:`tune_prior_scales`), with
``BLIND_EDGE_SCALE`` as shipped or, with ``--tune-edge``, chosen with it, and per
variant the bends the chart's residuals showed and how many the product refuses
(:func:`print_bends`; ``--chart-tone`` puts the chart on a tone curve).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse
import json
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

sys.path.insert(0, str(Path(__file__).resolve().parent))

import generalisation_data as gd

from tunespec.core.colorimetry import delta_e_2000, lab_d50, reflectance_stats
from tunespec.core.datasets import load_camera_database, load_colorchecker_sg
from tunespec.core.excess import bend_verdict, linearise
from tunespec.core.metering import suppress_meter_floor
from tunespec.core.responses import Responses
from tunespec.core.selfcheck import self_check
from tunespec.core.sensitivity import (
    SensitivityEstimate,
    estimate_camera_sensitivity,
)
from tunespec.core.sensitivity_bayes import (
    _data,
    _nnls_quadratic,
    _normal,
    _smoothness_penalty,
)
from tunespec.core.simulate import NoiseModel, scale_to_exposure, simulate_responses
from tunespec.core.spectra import CALIBRATION_GRID, Grid, Spectra
from tunespec.core.stats import calibration_report, sensitivity_rms
from tunespec.core.uncertainty import (
    BLIND_EDGE_SCALE,
    PRIOR_MISMATCH_SCALE,
    reflectance_uncertainty,
    wiener_with_uncertainty,
)
from tunespec.core.wiener import on_integration_grid

WORK = CALIBRATION_GRID
EST = Grid(400.0, 700.0, 5.0)
VARIANTS = ("bayes", "bayes-noselfcal", "smooth", "pca", "nnls", "truth", "truth-read")
#: Smoothness weight of the ``nnls`` reference (relative to the data's mean diagonal).
NNLS_LAMBDA = 1e-3
Z95 = 1.959964


@dataclass
class Score:
    camera: str
    family: str
    light: str
    variant: str
    sens_rms: float
    table1_rgb_mean: float
    de00_mean: float
    de00_max: float
    spec_rms_mean: float
    coverage: dict[str, float] = field(default_factory=dict)
    # per reflectance collection, per KAPPAS: reflectance samples inside at each
    # wavelength, L*, a*, b* inside, targets (for tune_prior_scales)
    coverage_counts: dict[str, list[list[float]]] = field(default_factory=dict)
    # the same at each blind-edge scale gamma of --tune-edge (keys: gamma)
    edge_counts: dict[str, dict[str, list[list[float]]]] = field(default_factory=dict)
    fitted_shift_nm: list[float] = field(default_factory=list)
    fitted_gain: list[float] = field(default_factory=list)
    true_shift_nm: list[float] = field(default_factory=list)
    true_gain: list[float] = field(default_factory=list)
    # |estimate - truth| / standard uncertainty of the sensitivities, every sample
    # where the true curve is above 1 % of its channel's peak (the report's bands)
    sens_z: list[float] = field(default_factory=list)
    # the flat-field residual the calibration fitted, and all its systematic terms
    fitted_flat_field: float | None = None
    fitted_excess: dict[str, Any] = field(default_factory=dict)
    # what the product's self-check (without its held-out refit) finds
    self_check_warnings: list[str] = field(default_factory=list)
    # the chart's bend c^(1 + gamma) and its standard error, where the fit found one
    bend: tuple[float, float] | None = None
    seconds: float = 0.0


def nnls_reference(responses, reported: Spectra, chart: Spectra) -> SensitivityEstimate:
    """Plain smoothness-penalised NNLS (fixed ``NNLS_LAMBDA``), no database, no shift."""
    var = (
        1e-8
        + responses.rgb_std**2 / responses.n_pixels[..., None]
        + (0.005 * responses.rgb) ** 2
    )
    data = _data(
        chart.select(responses.patches).values, responses.rgb, var, chart.step_nm
    )
    G, b = _normal(data, reported.select(responses.illuminants).values)
    Om = _smoothness_penalty(chart.wavelength_nm.size)
    S = np.stack(
        [
            _nnls_quadratic(G[k] + NNLS_LAMBDA * np.trace(G[k]) / G.shape[1] * Om, b[k])
            for k in range(3)
        ]
    )
    sens = Spectra(chart.wavelength_nm, S, ("R", "G", "B"), {"source": "nnls"})
    return SensitivityEstimate(sens, "nnls")


def calibrate(
    variant, responses, reported, chart, database, exclude, truth=None
) -> SensitivityEstimate:
    if variant in ("truth", "truth-read"):  # the floor: true sensitivities
        return SensitivityEstimate(truth, variant)
    if variant == "nnls":
        return nnls_reference(responses, reported, chart)
    method = variant.split("-")[0]
    db = {n: s for n, s in database.items() if n not in set(exclude)}
    kw: dict[str, Any] = {}
    if variant == "bayes-noselfcal":
        kw["self_calibrate"] = False
    return estimate_camera_sensitivity(
        responses, reported, chart, method=method, database=db, **kw
    )


def with_true_sensitivities(
    est: SensitivityEstimate, truth: Spectra
) -> SensitivityEstimate:
    """A ``"bayes"`` calibration with the camera's true curves (on :data:`WORK`) in
    its sensitivities' place: no metering corrections, and a covariance shrunk to
    nothing, so that Eq. 5 keeps the error model's ``K_e`` and the budget keeps its
    other lines (``budget_terms.py``, ``colour_bias.py``)."""
    return replace(
        est, sensitivity=truth.resample(WORK), led_correction=None, spd_shift_nm=0.0,
        covariance=est.covariance * 1e-12, readings=None,
    )  # fmt: skip


#: Candidate prior-mismatch scales (``core.uncertainty.PRIOR_MISMATCH_SCALE``).
KAPPAS = np.round(np.arange(0.6, 3.01, 0.05), 2)
#: Blind-edge scales tried with them by ``--tune-edge``.
EDGE_SCALES = (0.0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 2.0)


def collection(name: str) -> str:
    """Which reflectance collection a test reflectance comes from."""
    for prefix, label in (("CES", "CIE 2017"), ("TCS", "CIE 1995"), ("VS", "NIST CQS")):
        if name.startswith(prefix):
            return label
    return "rawtoaces 190"


def coverage_counts(w, unc, truth_r, lab_true, names) -> dict[str, list[list[float]]]:
    """Inside-the-95 %-interval counts per collection at every ``KAPPAS`` value: the
    reflectance samples inside at each wavelength, then L*, a*, b* inside (against
    ``lab_true``, the surfaces' own colour as :func:`surface_lab` gives it) and the
    number of targets.

    The prior-mismatch share of each variance scales with ``kappa^2`` (the rest does
    not), so one uncertainty computation gives them all.
    """
    k0 = PRIOR_MISMATCH_SCALE**2
    var_r = unc.covariance.diagonal(axis1=1, axis2=2)
    rest_r, prior_r = var_r - unc.prior_part_variance, unc.prior_part_variance / k0
    lab_var = unc.lab_std**2
    rest_l, prior_l = (
        lab_var - unc.lab_prior_part_variance,
        unc.lab_prior_part_variance / k0,
    )
    err_r = np.abs(w.reflectance.values - truth_r)
    err_l = np.abs(unc.lab - lab_true)
    groups = np.array([collection(n) for n in names])
    out: dict[str, list[list[float]]] = {}
    for g in sorted(set(groups)):
        m = groups == g
        rows = []
        for kappa in KAPPAS:
            std_r = np.minimum(
                np.sqrt(np.maximum(rest_r[m] + kappa**2 * prior_r[m], 0)), 0.5
            )
            std_l = np.sqrt(np.maximum(rest_l[m] + kappa**2 * prior_l[m], 0))
            rows.append(
                np.sum(err_r[m] <= Z95 * std_r, axis=0).astype(float).tolist()
                + [float(np.sum(err_l[m, j] <= Z95 * std_l[:, j])) for j in range(3)]
                + [float(m.sum())]
            )
        out[g] = rows
    return out


def _coverage_miss(counts: np.ndarray) -> np.ndarray:
    """Per ``KAPPAS`` row: the mean squared distance from 95 % of the reflectance
    coverage at each wavelength, and of the L*, a*, b* coverages, the four averaged
    (the intervals are to hold at every wavelength, not only on average)."""
    n = counts[:, -1:]
    refl = np.mean((counts[:, :-4] / n - 0.95) ** 2, axis=1)
    lab = np.sum((counts[:, -4:-1] / n - 0.95) ** 2, axis=1)
    return (refl + lab) / 4


def _describe_coverage(c: np.ndarray) -> str:
    n = c[-1]
    r = c[:-4] / n
    return (
        f"reflectance {np.mean(r):.3f} (per wavelength {r.min():.3f}-{r.max():.3f}), "
        f"L* {c[-4] / n:.3f}, a* {c[-3] / n:.3f}, b* {c[-2] / n:.3f}"
    )


def tune_prior_scales(scores: list[Score]) -> None:
    """Leave-one-collection-out over ``kappa`` and the blind-edge scale ``gamma``
    (the shipped one alone without ``--tune-edge``): the pair :func:`_coverage_miss`
    likes best on the other collections, scored on the one left out, as
    ``PRIOR_MISMATCH_SCALE`` and ``BLIND_EDGE_SCALE`` are chosen."""
    ss = [s for s in scores if s.coverage_counts]
    if not ss:
        return
    counts = [{repr(BLIND_EDGE_SCALE): s.coverage_counts} | s.edge_counts for s in ss]
    gammas = sorted(counts[0], key=float)
    groups = sorted(ss[0].coverage_counts)
    # (gamma, kappa) x collection: the counts summed over the calibrations
    tot = {
        g: np.stack([np.sum([c[e][g] for c in counts], axis=0) for e in gammas])
        for g in groups
    }
    print("\nprior-mismatch and blind-edge scales, chosen without the collection:")

    def best(c: np.ndarray) -> tuple[int, int]:
        miss = np.stack([_coverage_miss(x) for x in c])
        e, k = np.unravel_index(int(np.argmin(miss)), miss.shape)
        return int(e), int(k)

    def show(label: str, train: np.ndarray, scored: np.ndarray) -> None:
        e, k = best(train)
        print(
            f"  {label:<15} kappa {KAPPAS[k]:.2f} gamma {float(gammas[e]):.2f}: "
            + _describe_coverage(scored[e, k])
        )

    for g in groups:
        show(g, np.sum([tot[h] for h in groups if h != g], axis=0), tot[g])
    allc = np.sum([tot[g] for g in groups], axis=0)
    show("all", allc, allc)


def surface_lab(test_fine: Spectra) -> NDArray[np.float64]:
    """CIELAB of the test surfaces themselves: their 1 nm spectra over the estimation
    grid's range. The colour of their samples on a coarse grid (``lab_d50`` of the
    10 nm samples, ASTM E308's 10 nm weights) differs from it where a spectrum has
    detail between the samples (:func:`print_tabulation_error`)."""
    return lab_d50(test_fine.resample(Grid(EST.start_nm, EST.end_nm, 1.0)))


def print_tabulation_error(test_fine: Spectra, test_est: Spectra) -> None:
    """CIEDE2000 between the colour of each test surface and the colour of its
    samples on the estimation grid, per collection: how far the two measurands of
    the L*a*b* coverage lie apart."""
    de = delta_e_2000(lab_d50(test_est), surface_lab(test_fine))
    groups = np.array([collection(n) for n in test_est.names])
    print(
        f"\ncolour of the {EST.step_nm:g} nm samples vs the surface's, dE00 mean/max:"
    )
    for g in sorted(set(groups)):
        d = de[groups == g]
        print(f"  {g:<15} {d.mean():.3f} / {d.max():.3f}")


def coverage(
    est_r, std_r, lab_est, lab_std, truth_r, lab_true, lab_surface
) -> dict[str, float]:
    """Coverage of the 95 % intervals: the reflectance samples, L*a*b* against the
    colour of the truth's samples on the estimation grid (``L``, ``a``, ``b``) and
    against the surface's own colour (``L_surface``, ...)."""
    cov = {"reflectance": float(np.mean(np.abs(est_r - truth_r) <= Z95 * std_r))}
    for ref, suffix in ((lab_true, ""), (lab_surface, "_surface")):
        for j, name in enumerate(("L", "a", "b")):
            cov[name + suffix] = float(
                np.mean(np.abs(lab_est[:, j] - ref[:, j]) <= Z95 * lab_std[:, j])
            )
    return cov


def sensitivity_z(est: SensitivityEstimate, truth: Spectra) -> list[float]:
    """``|s_est - s_true| / u(s)`` where the true curve exceeds 1 % of its peak."""
    t = truth.values
    inside = t > 0.01 * t.max(axis=1, keepdims=True)
    std = np.maximum(est.std, 1e-300)
    return (np.abs(est.sensitivity.values - t) / std)[inside].tolist()


def tune_band_scale(scores: list[Score]) -> None:
    """Coverage of the sensitivities' 95 % bands, and the scale of their standard
    uncertainty that would make it 95 %, chosen with each family left out in turn."""
    ss = [s for s in scores if s.sens_z]
    if not ss:
        return
    z = {f: np.concatenate([s.sens_z for s in ss if s.family == f]) for f in
         sorted({s.family for s in ss})}  # fmt: skip
    every = np.concatenate(list(z.values()))
    print(
        f"\nsensitivity 95 % bands: coverage {np.mean(every <= Z95):.3f} "
        f"({every.size} samples); scale for 95 %: {np.quantile(every, 0.95) / Z95:.2f}"
    )
    for f, zf in z.items():
        rest = np.concatenate([v for g, v in z.items() if g != f])
        c = float(np.quantile(rest, 0.95) / Z95)
        print(
            f"  {f:<26} coverage {np.mean(zf <= Z95):.3f}; scale from the others "
            f"{c:.2f} -> coverage {np.mean(zf <= Z95 * c):.3f}"
        )


@dataclass
class Session:
    """One camera's simulated session under a light: the chart's and the test
    reflectances' responses, the exposure-scaled true spectra, the spectra as the
    light reported them at its own sampling and on the calibration's grid, and the
    per-LED metering errors it drew."""

    scaled: Spectra
    resp: Responses
    resp_t: Responses
    reported_native: Spectra
    reported: Spectra
    shifts: NDArray[np.float64]
    gains: NDArray[np.float64]


def simulate_session(
    cam: gd.Camera,
    leds: Spectra,
    setup,
    rng,
    *,
    metering: bool = True,
    meter_noise: float = 0.0,
    meter_reads: int = 2,
    clean_meter: bool = False,
    report_step_nm: float = 1.0,
    report_slit: bool = False,
    systematic: bool = False,
    flat_field: float = NoiseModel.flat_field_residual,
    chart_tone: float = 1.0,
) -> Session:
    """Eq. 1 for the chart and the test reflectances, with the light's readings as
    an instrument reports them (the options as :func:`main`'s flags)."""
    chart_fine, test_fine = setup[0], setup[1]
    scaled = scale_to_exposure(chart_fine, leds, cam.truth, target=0.8)
    noise = NoiseModel(flat_field_residual=flat_field)
    resp = simulate_responses(chart_fine, scaled, cam.truth, noise=noise, rng=rng)
    resp_t = simulate_responses(test_fine, scaled, cam.truth, noise=noise, rng=rng)
    if metering:
        reported_fine, shifts, gains = gd.metering_error(scaled, rng)
    else:
        reported_fine, shifts, gains = scaled, np.zeros(len(leds)), np.ones(len(leds))
    if systematic:
        resp = gd.systematic_effects(resp, rng)
        resp_t = gd.systematic_effects(resp_t, rng)
    resp = linearise(resp, 1.0 / chart_tone - 1.0)  # c^chart_tone: a rendered file
    # the instrument's own sampling, then its reading noise on what it reports
    reported_native = gd.report_at(reported_fine, report_step_nm, slit=report_slit)
    if meter_noise:
        reported_native = gd.metering_noise(
            reported_native, rng, meter_noise, reads=meter_reads
        )
    if clean_meter:
        reported_native = suppress_meter_floor(reported_native)
    reported = reported_native.resample(WORK, average=True)
    return Session(scaled, resp, resp_t, reported_native, reported, shifts, gains)


def estimate_tests(
    est: SensitivityEstimate, resp_t: Responses, used: Spectra, reported: Spectra, setup
):
    """The product's estimate chain for the test reflectances: Eq. 1 integrated on
    the calibration's grid, the reflectance solved for wherever it integrates and
    reported on EST (as `tunespec estimate` does), Eq. 5 with the error model as
    K_e where the calibration carries one, and its uncertainty. ``used``: the
    spectra Eq. 1 takes (corrected as the calibration found); ``reported``: as the
    light reported them. The responses are linearised as the calibration's chart
    was (``est.linearise``)."""
    illum, sens, _ = on_integration_grid(
        est.correct_illuminants(used), est.sensitivity, EST
    )
    return wiener_with_uncertainty(
        est.linearise(resp_t), illum, sens, setup[3], reported, est, grid=EST
    )


def run_camera(
    cam: gd.Camera,
    light: str,
    leds: Spectra,
    variants,
    rng,
    *,
    setup,
    edge_scales: tuple[float, ...] = (),
    **conditions: Any,
) -> list[Score]:
    """Every variant's calibration and test estimate for one camera and light
    (``conditions``: :func:`simulate_session`'s options; ``edge_scales``: the
    blind-edge scales whose coverage counts :func:`tune_prior_scales` takes)."""
    _, test_fine, chart_work, _, db, test_est = setup
    session = simulate_session(cam, leds, setup, rng, **conditions)
    resp, resp_t, reported = session.resp, session.resp_t, session.reported
    truth_work = cam.truth.resample(WORK)
    lab_true, lab_surface = lab_d50(test_est), surface_lab(test_fine)
    out = []
    for variant in variants:
        t0 = time.perf_counter()
        est = calibrate(
            variant, resp, reported, chart_work, db, cam.exclude, truth_work
        )
        secs = time.perf_counter() - t0
        # ``truth``: the true spectra; ``truth-read``: the true sensitivities with
        # the light's readings as reported (what no calibration can beat with them)
        used = (
            session.scaled.resample(WORK, average=True)
            if variant == "truth"
            else reported
        )
        t1 = calibration_report(est, resp, used, chart_work).training
        w, unc = estimate_tests(est, resp_t, used, reported, setup)
        st = reflectance_stats(w.reflectance, test_est)
        sc = Score(
            cam.name,
            cam.family,
            light,
            variant,
            sensitivity_rms(est.sensitivity, truth_work),
            float(t1.mean[3]),
            st.mean_delta_e00,
            st.max_delta_e00,
            st.mean_spectral_rms,
            seconds=secs,
        )
        if "linearity_gamma_found" in est.params:
            sc.bend = (
                est.params["linearity_gamma_found"],
                est.params["linearity_gamma_se"],
            )
        if est.excess is not None:
            sc.fitted_flat_field = est.excess.flat_field_relative
            sc.fitted_excess = est.excess.as_dict()
            sc.self_check_warnings = list(
                self_check(
                    est,
                    resp,
                    used,
                    chart_work,
                    reported_illuminants=session.reported_native,
                ).warnings
            )
        if est.covariance is not None:
            sc.sens_z = sensitivity_z(est, truth_work)
            sc.coverage_counts = coverage_counts(
                w, unc, test_est.values, lab_surface, test_est.names
            )
            # the shipped scale's counts are coverage_counts' own
            for gamma in set(edge_scales) - {BLIND_EDGE_SCALE}:
                unc_g = reflectance_uncertainty(
                    w, resp_t, reported, est, edge_scale=gamma
                )
                sc.edge_counts[repr(gamma)] = coverage_counts(
                    w, unc_g, test_est.values, lab_surface, test_est.names
                )
            sc.coverage = coverage(
                w.reflectance.values,
                unc.reflectance_std,
                unc.lab,
                unc.lab_std,
                test_est.values,
                lab_true,
                lab_surface,
            )
        if est.led_correction is not None and est.led_correction.gain_std:
            sc.fitted_shift_nm = list(est.led_correction.shift_nm)
            sc.fitted_gain = list(est.led_correction.gain)
            sc.true_shift_nm = [float(x) for x in session.shifts]
            sc.true_gain = [float(x) for x in session.gains]
        out.append(sc)
    return out


def load_setup():
    return (
        gd.chart(),
        gd.test_reflectances(),
        load_colorchecker_sg(WORK),
        load_colorchecker_sg(),  # the prior, reported on EST
        load_camera_database(WORK),
        gd.test_reflectances().resample(EST),
    )


def summarise(scores: list[Score]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    keys = sorted({(s.family, s.variant) for s in scores})
    for fam, var in keys:
        ss = [s for s in scores if s.family == fam and s.variant == var]
        d = {
            "n": len(ss),
            "sens_rms_median": float(np.median([s.sens_rms for s in ss])),
            "table1_rgb_mean": float(np.mean([s.table1_rgb_mean for s in ss])),
            "de00_mean": float(np.mean([s.de00_mean for s in ss])),
            "de00_worst_camera": float(np.max([s.de00_mean for s in ss])),
            "de00_max": float(np.max([s.de00_max for s in ss])),
            "spec_rms_mean": float(np.mean([s.spec_rms_mean for s in ss])),
        }
        if ss[0].coverage:
            for k in ss[0].coverage:
                d[f"coverage_{k}"] = float(np.mean([s.coverage[k] for s in ss]))
        out.setdefault(fam, {})[var] = d
    return out


def shift_correlation(scores: list[Score]) -> float | None:
    fit = [x for s in scores for x in s.fitted_shift_nm]
    true = [x for s in scores for x in s.true_shift_nm]
    if len(fit) < 3 or np.std(true) == 0:
        return None
    # the common offset is absorbed by the sensitivities' shape; compare deviations
    return float(np.corrcoef(fit, true)[0, 1])


def print_bends(scores: list[Score]) -> None:
    """Per variant, the bend ``gamma`` the chart's residuals showed (the product's
    linearity check, ``core.plausibility.check_chart_linearity``) and how many
    calibrations it would refuse."""
    for variant in sorted({s.variant for s in scores if s.bend is not None}):
        bends = np.array([s.bend for s in scores if s.variant == variant and s.bend])
        refused = sum(bend_verdict(g, se) == "refuse" for g, se in bends)
        print(
            f"\n{variant}: the chart's bend gamma {bends[:, 0].min():+.4f} to "
            f"{bends[:, 0].max():+.4f} (|gamma| / s.e. up to "
            f"{np.max(np.abs(bends[:, 0]) / bends[:, 1]):.1f}), refused "
            f"{refused} of {len(bends)}"
        )


def print_summary(summary: dict[str, Any], variants) -> None:
    cols = ("sens_rms_median", "de00_mean", "de00_worst_camera", "spec_rms_mean")
    print(
        f"{'family':<26}{'variant':<17}{'n':>4}"
        + "".join(f"{c:>19}" for c in cols)
        + "   coverage R/L/a/b (L/a/b against the surface's colour)"
    )
    for fam, per in summary.items():
        for var in variants:
            if var not in per:
                continue
            d = per[var]
            cov = ""
            if "coverage_reflectance" in d:
                keys = ("reflectance", "L", "a", "b")
                cov = "   " + "/".join(f"{d[f'coverage_{k}']:.3f}" for k in keys)
                cov += (
                    " (surface "
                    + "/".join(f"{d[f'coverage_{k}_surface']:.3f}" for k in keys[1:])
                    + ")"
                )
            print(
                f"{fam:<26}{var:<17}{d['n']:>4}"
                + "".join(f"{d[c]:>19.4f}" for c in cols)
                + cov
            )


def main(argv: list[str] | None = None) -> int:
    global WORK, EST
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--quick", action="store_true", help="2 cameras per family, CAL1 model only"
    )
    ap.add_argument(
        "--per-family", type=int, default=None, help="at most N cameras per family"
    )
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--lights", default="cal1-model,heldout-leds")
    ap.add_argument("--no-metering-error", action="store_true")
    ap.add_argument(
        "--meter-noise",
        type=float,
        default=0.0,
        help="noise of the reported spectra, a fraction of each one's peak, clipped at "
        "0 and averaged over --meter-reads readings (the simulated CAL1: 0.001)",
    )
    ap.add_argument(
        "--meter-reads",
        type=int,
        default=2,
        help="readings averaged per reported spectrum, each clipped at 0 (default 2, "
        "as capture averages the readings before and after a frame)",
    )
    ap.add_argument(
        "--raw-meter",
        action="store_true",
        help="leave the noise floor in the reported spectra (by default they are "
        "cleaned at their own sampling, core.metering.suppress_meter_floor, as the "
        "product's readers and processing do)",
    )
    ap.add_argument(
        "--report-step-nm",
        type=float,
        default=1.0,
        help="the spectroradiometer reports every STEP nm (1: the 1 nm rendering "
        "itself); its noise is on those samples",
    )
    ap.add_argument(
        "--report-slit",
        action="store_true",
        help="each reported sample through a triangular slit as wide as the step "
        "(default: the spectrum's value there)",
    )
    ap.add_argument(
        "--systematic",
        action="store_true",
        help="stray light and cross-talk (0.2 %% per patch and LED) and a "
        "non-linearity (signal^1.003) on the responses, beside the flat-field residual",
    )
    ap.add_argument(
        "--flat-field",
        type=float,
        default=NoiseModel.flat_field_residual,
        help="the flat field's residual (relative, one draw per patch and LED) in the "
        "simulated responses (default %(default)s; the calibration fits its size)",
    )
    ap.add_argument(
        "--chart-tone",
        type=float,
        default=1.0,
        help="the chart's responses through c^E, a rendered file's tone curve (the "
        "linearity check's refusals: the bends printed at the end)",
    )
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--grid",
        type=Grid.parse,
        default=WORK,
        help=f"calibration grid START:END:STEP (default {WORK})",
    )
    ap.add_argument(
        "--estimate-grid",
        type=Grid.parse,
        default=EST,
        help=f"estimation grid START:END:STEP (default {EST})",
    )
    ap.add_argument(
        "--tune-edge",
        action="store_true",
        help="also choose the blind-edge scale with the prior-mismatch scale "
        f"(gamma in {EDGE_SCALES}; shipped {BLIND_EDGE_SCALE})",
    )
    ap.add_argument("--json")
    args = ap.parse_args(argv)
    WORK, EST = args.grid, args.estimate_grid
    variants = [v for v in args.variants.split(",") if v]
    lights = args.lights.split(",")
    per_family = args.per_family
    if args.quick:
        per_family = per_family or 2
        lights = lights[:1]
    cams = gd.cameras_per_family(per_family) if per_family else gd.all_cameras()
    setup = load_setup()
    print_tabulation_error(setup[1], setup[5])
    light_spectra = gd.light_sources()
    rng = np.random.default_rng(args.seed)
    scores: list[Score] = []
    t0 = time.perf_counter()
    for light in lights:
        for cam in cams:
            scores += run_camera(
                cam,
                light,
                light_spectra[light],
                variants,
                rng,
                metering=not args.no_metering_error,
                setup=setup,
                meter_noise=args.meter_noise,
                meter_reads=args.meter_reads,
                clean_meter=not args.raw_meter,
                report_step_nm=args.report_step_nm,
                report_slit=args.report_slit,
                systematic=args.systematic,
                flat_field=args.flat_field,
                chart_tone=args.chart_tone,
                edge_scales=EDGE_SCALES if args.tune_edge else (),
            )
    summary = summarise(scores)
    print_summary(summary, variants)
    tune_prior_scales([s for s in scores if s.variant == "bayes"])
    tune_band_scale([s for s in scores if s.variant == "bayes"])
    flagged = [s for s in scores if s.self_check_warnings]
    print(f"\nself-check findings: {len(flagged)} of {len(scores)} calibrations")
    for s in flagged:
        for w in s.self_check_warnings:
            print(f"  {s.family} ({s.variant}): {w[:110]}")
    print_bends(scores)
    corr = shift_correlation([s for s in scores if s.variant == "bayes"])
    if corr is not None:
        print(
            f"\nbayes: correlation of fitted and injected per-LED offsets: {corr:.3f}"
        )
    print(
        f"\n{len(cams)} cameras x {len(lights)} light source(s) in {time.perf_counter() - t0:.0f} s, seed {args.seed}"
    )
    if args.json:
        Path(args.json).write_text(
            json.dumps(
                {"summary": summary, "scores": [s.__dict__ for s in scores]}, indent=1
            )
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
