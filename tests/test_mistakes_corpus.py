"""Issue 24: a corpus of mistakes that parse but mean something else.

Every case is a mistake a user makes with good files (a scale, a unit, one typed
value, a truncated range, a missing side file, swapped arguments, another chart,
an option out of range) and must end in a one-line error (exit 2) or a warning line,
never in exit 0 with a wrong number. The good files come from a simulated bench
built once per session (``tools/fuzz_semantic.py``: the shipped camera, LEDs, SG and
CMY target with photon and read noise); the good files give no warning at all.
"""

from __future__ import annotations

import importlib.util
import json
import re
import shutil
import sys
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from tunespec.app.cli import main
from tunespec.core.io.spectral import read_spectral
from tunespec.core.io.spectral_csv import write_spectra_csv
from tunespec.core.spectra import Spectra

_TOOL = Path(__file__).resolve().parents[1] / "tools" / "fuzz_semantic.py"


def _tool():
    spec = importlib.util.spec_from_file_location("tunespec_fuzz_semantic", _TOOL)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


fs = _tool()


@pytest.fixture(scope="session")
def good(tmp_path_factory):
    """The good files (built once) and their estimate's mean dE00."""
    return fs.build_inputs(tmp_path_factory.mktemp("good"))


# -- each case: (good inputs, a folder) -> argv ------------------------------------
def _est(x, **over):
    opts = {"--responses": x.responses, "--illuminants": x.illuminants,
            "--sensitivities": x.sensitivities}  # fmt: skip
    opts.update({"--" + k.replace("_", "-"): v for k, v in over.items()})
    return ["estimate", *[str(a) for kv in opts.items() for a in kv]]


def _cal(x, **over):
    opts = {"--responses": x.chart_responses, "--illuminants": x.chart_illuminants,
            "--reflectances": x.chart}  # fmt: skip
    opts.update({"--" + k.replace("_", "-"): v for k, v in over.items()})
    return ["calibrate", *[str(a) for kv in opts.items() for a in kv]]


def _sens_peak_one(x, d):
    s = read_spectral(x.sensitivities, kind="sensitivity")
    p = fs.scaled_spectra(
        x.sensitivities, d / "s.csv", 1 / s.values.max(), "sensitivity"
    )
    return _est(x, sensitivities=fs.with_side_file(x.sensitivities, p))


def _all_saturated(path, d, share=1.0):
    def sat(r):
        s = np.zeros(r.rgb.shape[:2])
        s.flat[: round(share * s.size)] = 1.0
        return replace(r, saturated=s)

    return fs.edited_responses(path, d / "sat.csv", sat)


def _one_response(x, d, value, patch=2, light=5, channel=1, path=None):
    def edit(r):
        rgb = r.rgb.copy()
        rgb[patch, light, channel] = value
        return replace(r, rgb=rgb)

    return fs.edited_responses(path or x.responses, d / "one.csv", edit)


def _prior_of(x, d, n):
    s = read_spectral(x.chart, kind="reflectance")
    write_spectra_csv(s.select(list(s.names[:n])), d / "prior.csv")
    return _est(x, prior=d / "prior.csv")


def _one_percent_spectrum(path, d):
    s = read_spectral(path, kind="reflectance")
    v = s.values.copy()
    v[int(np.argmax(np.median(v, axis=1)))] *= 100
    write_spectra_csv(Spectra(s.wavelength_nm, v, s.names, {}), d / "mixed.csv")
    return d / "mixed.csv"


def _semicolon(path, d):
    (d / "semi.csv").write_text(path.read_text().replace(",", ";"))
    return d / "semi.csv"


def _shuffled_chart(x, d):
    """Another chart's patches under the same names (the SG's rows shuffled)."""
    s = read_spectral(x.chart, kind="reflectance")
    order = np.random.default_rng(1).permutation(len(s.names))
    write_spectra_csv(Spectra(s.wavelength_nm, s.values[order], s.names, {}),
                      d / "other_chart.csv")  # fmt: skip
    return _cal(x, reflectances=d / "other_chart.csv", method="pca")


def _rewritten(src, dst, change):
    """``src``'s spectra with ``(wavelength_nm, values) = change(...)``; a
    sensitivities file keeps its side file."""
    s = read_spectral(src)
    w, v = change(s.wavelength_nm, s.values)
    write_spectra_csv(Spectra(w, v, s.names, {}), dst)
    return fs.with_side_file(src, dst)


def _copy(src, dst):
    shutil.copyfile(src, dst)
    return dst


#: (case id, argv builder, "refused" | "flagged", a fragment of the message).
CASES: list[tuple[str, Callable, str, str]] = [
    # issue 24's table
    ("responses x100", lambda x, d: _est(x, responses=fs.scaled_responses(
        x.responses, d / "r.csv", 100.0)), "refused", "perfect white"),
    ("illuminants x1e6", lambda x, d: _est(x, illuminants=fs.scaled_spectra(
        x.illuminants, d / "i.csv", 1e6, "illuminant")), "refused", "perfect white"),
    ("sensitivities peak 1", _sens_peak_one, "refused", "normalised to peak 1"),
    ("sensitivities as CGATS", lambda x, d: _est(x, sensitivities=fs.cgats_sensitivities(
        x.sensitivities, d / "s.ti3")), "refused", "perfect white"),
    ("every response saturated", lambda x, d: _est(
        x, responses=_all_saturated(x.responses, d)), "refused", "saturated"),
    ("prior of 3 spectra", lambda x, d: _prior_of(x, d, 3), "refused", "--prior has 3"),
    ("--spd-shift-nm 500", lambda x, d: _est(x, spd_shift_nm=500), "refused",
     "--spd-shift-nm 500"),
    ("one response -0.2", lambda x, d: _est(x, responses=_one_response(x, d, -0.2)),
     "refused", "below zero"),
    # the bullet list
    ("chart typo 3.0", lambda x, d: _cal(x, reflectances=fs.typo_spectra(
        x.chart, d / "c.csv", 40, 20, 3.0)), "refused", "3 in a file of fractions"),
    ("chart 450-650 nm", lambda x, d: _cal(x, reflectances=fs.truncated_spectra(
        x.chart, d / "c.csv", 450, 650, "reflectance")), "refused", "covers 450-650"),
    ("sensitivities without side file", lambda x, d: _est(
        x, sensitivities=_copy(x.sensitivities, d / "S.csv")), "refused",
     "--no-corrections"),
    ("-o equal to --responses", lambda x, d: [*_est(x, responses=_copy(
        x.responses, d / "r.csv")), "-o", str(d / "r.csv")], "refused",
     "overwrite an input"),
    ("calibrate --grid 400:700:20", lambda x, d: _cal(x, grid="400:700:20",
                                                      method="pca"),
     "flagged", "coarser than calibration needs"),
    ("--hold-out-every 0", lambda x, d: _cal(x, hold_out_every=0), "refused",
     "--hold-out-every 0"),
    ("--hdr-from -5", lambda x, d: ["gonio-plan", "-o", str(d / "p.json"),
                                    "--hdr-from", "-5"], "refused", "--hdr-from"),
    ("gonio-demo --resume on an empty folder", lambda x, d: [
        "gonio-demo", "--out", str(d / "empty"), "--resume"], "refused", "--resume"),
    ("semicolon responses", lambda x, d: _est(x, responses=_semicolon(x.responses, d)),
     "refused", "separated by ';'"),
    # more scales
    ("responses x1e-2", lambda x, d: _est(x, responses=fs.scaled_responses(
        x.responses, d / "r.csv", 1e-2)), "refused", "perfect white"),
    ("responses x3", lambda x, d: _est(x, responses=fs.scaled_responses(
        x.responses, d / "r.csv", 3.0)), "refused", "perfect white"),
    ("responses x1e6", lambda x, d: _est(x, responses=fs.scaled_responses(
        x.responses, d / "r.csv", 1e6)), "refused", "perfect white"),
    ("illuminants x100", lambda x, d: _est(x, illuminants=fs.scaled_spectra(
        x.illuminants, d / "i.csv", 100.0, "illuminant")), "refused", "perfect white"),
    ("illuminants x1e-2", lambda x, d: _est(x, illuminants=fs.scaled_spectra(
        x.illuminants, d / "i.csv", 1e-2, "illuminant")), "refused", "perfect white"),
    ("sensitivities x100", lambda x, d: _est(x, sensitivities=fs.with_side_file(
        x.sensitivities, fs.scaled_spectra(x.sensitivities, d / "s.csv", 100.0,
                                           "sensitivity"))), "refused", "perfect white"),
    ("sensitivities x1e-2", lambda x, d: _est(x, sensitivities=fs.with_side_file(
        x.sensitivities, fs.scaled_spectra(x.sensitivities, d / "s.csv", 1e-2,
                                           "sensitivity"))), "refused", "perfect white"),
    ("one LED x10", lambda x, d: _est(x, illuminants=fs.scaled_spectra(
        x.illuminants, d / "i.csv", 10.0, "illuminant", slice(4, 5))), "refused",
     "light LED465"),
    ("one LED x1/3", lambda x, d: _est(x, illuminants=fs.scaled_spectra(
        x.illuminants, d / "i.csv", 1 / 3, "illuminant", slice(9, 10))), "refused",
     "light LED540"),
    ("one light's responses x100", lambda x, d: _est(x, responses=fs.scaled_responses(
        x.responses, d / "r.csv", 100.0, lambda p, i: i == 7)), "refused",
     "light LED510"),
    # a scale that darker or brighter samples have too: only the white background
    # against the chart session's tells it (before: exit 0, reflectances 0.5x, 1.4x)
    ("the sample's illuminants x2 (exposure in another unit)", lambda x, d: _est(
        x, illuminants=fs.scaled_spectra(x.illuminants, d / "i.csv", 2.0,
                                         "illuminant")), "refused",
     "white background reflects 0.5x"),
    ("the sample half a stop brighter than recorded (ISO, aperture)", lambda x, d: _est(
        x, responses=fs.scaled_responses(x.responses, d / "r.csv", 1.4,
                                         white_too=True)), "refused",
     "white background reflects 1.4x"),
    ("sensitivities x2 (another calibration's scale)", lambda x, d: _est(
        x, sensitivities=fs.with_side_file(x.sensitivities, fs.scaled_spectra(
            x.sensitivities, d / "s.csv", 2.0, "sensitivity"))), "refused",
     "white background reflects 0.5x"),
    ("one LED's exposure typed x1.25", lambda x, d: _est(x, illuminants=fs.scaled_spectra(
        x.illuminants, d / "i.csv", 1.25, "illuminant", slice(9, 10))), "refused",
     "light LED540: the sample's white background"),
    ("responses without their white level", lambda x, d: _est(
        x, responses=fs.edited_responses(x.responses, d / "r.csv", lambda r: replace(
            r, white_rgb=None))), "flagged", "no white-background level"),
    # units and typos
    ("prior typo 5.0", lambda x, d: _est(x, prior=fs.typo_spectra(
        x.chart, d / "p.csv", 7, 3, 5.0)), "refused", "a typo?"),
    ("reference typo 3.0", lambda x, d: ["evaluate", "--estimated",
                                         str(x.folder / "good_estimate.csv"),
                                         "--reference", str(fs.typo_spectra(
                                             x.reference, d / "r.csv", 2, 30, 3.0))],
     "refused", "a typo?"),
    ("reference one spectrum in percent", lambda x, d: [
        "evaluate", "--estimated", str(x.folder / "good_estimate.csv"), "--reference",
        str(_one_percent_spectrum(x.reference, d))], "refused", "mixed units"),
    ("chart one spectrum in percent", lambda x, d: _cal(
        x, reflectances=_one_percent_spectrum(x.chart, d)), "refused", "mixed units"),
    ("chart in percent with a typo", lambda x, d: _cal(
        x, reflectances=_percent_with_typo(x.chart, d)), "refused",
     "300 in a file of percent"),
    ("chart typo 1.6 on a white", lambda x, d: _cal(x, reflectances=_typo_on_white(
        x.chart, d, 1.6)), "refused", "1.6 in a file of fractions"),
    ("one response 5 (full scale is 1)", lambda x, d: _est(
        x, responses=_one_response(x, d, 5.0, channel=0)), "refused", "full scale"),
    # a chart on another response curve than a raw sensor's: every patch is off,
    # which a calibration with free per-LED gains half absorbs (before: exit 0 with
    # warnings, and the sample's estimate 2.4 dE00 off without one)
    ("chart from a TIFF with a tone curve (gamma 1/1.2)", lambda x, d: _cal(
        x, responses=_toned(x.chart_responses, d, 1 / 1.2)), "refused",
     "bend as response^(1 + gamma) with gamma -0.1"),
    # the paper's estimators, with no error model to take a bend up, refuse it too
    # (before: exit 0 with Table 1's warning)
    ("chart on a tone curve (gamma 1/1.2), method smooth", lambda x, d: _cal(
        x, responses=_toned(x.chart_responses, d, 1 / 1.2), method="smooth"),
     "refused", "bend as response^(1 + gamma) with gamma -0.2"),
    ("chart on a tone curve (x^1.1), method pca", lambda x, d: _cal(
        x, responses=_toned(x.chart_responses, d, 1.1), method="pca"),
     "refused", "bend as response^(1 + gamma) with gamma +0.0"),
    # a sample on a tone curve, with sensitivities that carry no covariance (no Eq. 1
    # check of the targets): its white background's channels tilt (before: exit 0,
    # 3.0 dE00 at x^1.1)
    ("sample on a tone curve (x^1.1), curves without a covariance", lambda x, d: _est(
        x, responses=_toned(x.responses, d, 1.1)), "flagged",
     "white background's channels bend as response^(1 + gamma) with gamma +0.10"),
    ("chart not dark-subtracted (+0.5 % of full scale)", lambda x, d: _cal(
        x, responses=fs.edited_responses(x.chart_responses, d / "r.csv", lambda r: replace(
            r, rgb=r.rgb + 0.005))), "refused", "black level not subtracted"),
    ("chart responses x100", lambda x, d: _cal(x, responses=fs.scaled_responses(
        x.chart_responses, d / "r.csv", 100.0)), "refused", "above full scale"),
    # coverage
    ("illuminants 450-650 nm", lambda x, d: _est(x, illuminants=fs.truncated_spectra(
        x.illuminants, d / "i.csv", 450, 650)), "refused", "covers 450-650"),
    ("sensitivities 420-680 nm", lambda x, d: _est(x, sensitivities=fs.with_side_file(
        x.sensitivities, fs.truncated_spectra(x.sensitivities, d / "s.csv", 420, 680))),
     "refused", "covers 420-680"),
    ("prior 400-600 nm", lambda x, d: _est(x, prior=fs.truncated_spectra(
        x.chart, d / "p.csv", 400, 600, "reflectance")), "refused", "covers 400-600"),
    ("estimate --grid 450:650:5", lambda x, d: _est(x, grid="450:650:5"), "refused",
     "widen --grid"),
    ("reference 450-650 nm", lambda x, d: [
        "evaluate", "--estimated", str(x.folder / "good_estimate.csv"), "--reference",
        str(fs.truncated_spectra(x.reference, d / "r.csv", 450, 650, "reflectance"))],
     "refused", "covers 450-650"),
    # responses
    ("25 % saturated", lambda x, d: _est(x, responses=_all_saturated(
        x.responses, d, 0.25)), "refused", "25% of the patch/light pairs"),
    ("chart all saturated", lambda x, d: _cal(x, responses=_all_saturated(
        x.chart_responses, d)), "refused", "saturated"),
    ("chart response -0.2", lambda x, d: _cal(x, responses=_one_response(
        x, d, -0.2, patch=30, path=x.chart_responses)), "refused", "below zero"),
    # swapped arguments, wrong files
    ("--responses and --illuminants swapped", lambda x, d: _est(
        x, responses=x.illuminants, illuminants=x.responses), "refused",
     "missing column"),
    ("--sensitivities given the illuminants", lambda x, d: _est(
        x, sensitivities=_copy(x.illuminants, d / "S.csv")), "refused", "channel"),
    ("--prior given the sensitivities", lambda x, d: _est(
        x, prior=x.sensitivities), "refused", "in a file of fractions"),
    ("--reflectances given the sample's reference", lambda x, d: _cal(
        x, reflectances=x.reference), "refused", "not columns here"),
    ("sensitivities' R and B swapped", lambda x, d: _est(x, sensitivities=_rewritten(
        x.sensitivities, d / "s.csv", lambda w, v: (w, v[::-1]))), "refused",
     "do not match each other"),
    ("responses' R and B swapped", lambda x, d: _est(x, responses=fs.edited_responses(
        x.responses, d / "r.csv", lambda r: replace(
            r, rgb=r.rgb[..., ::-1], rgb_std=r.rgb_std[..., ::-1]))), "refused", "do not match each other"),
    ("illuminant columns in another order", lambda x, d: _est(x, illuminants=_rewritten(
        x.illuminants, d / "i.csv", lambda w, v: (w, v[np.random.default_rng(0)
                                                      .permutation(len(v))]))),
     "refused", "do not match each other"),
    # found by the estimate itself: with a calibration's covariance, the responses
    # must fit a reflectance through Eq. 1
    ("two neighbouring LEDs' spectra swapped", lambda x, d: _est(
        x, sensitivities=_with_covariance(x, d), illuminants=_rewritten(
            x.illuminants, d / "i.csv", lambda w, v: (
                w, v[[*range(9), 10, 9, *range(11, len(v))]]))), "refused",
     "fit no reflectance through Eq. 1"),
    ("responses not dark-subtracted (+1 % of full scale)", lambda x, d: _est(
        x, sensitivities=_with_covariance(x, d), responses=fs.edited_responses(
            x.responses, d / "r.csv", lambda r: replace(
                r, rgb=r.rgb + 0.01))), "refused", "fit no reflectance through Eq. 1"),
    ("illuminants 10 nm off", lambda x, d: _est(x, illuminants=_rewritten(
        x.illuminants, d / "i.csv", lambda w, v: (w + 10, v))), "refused",
     "off by more than 2x"),
    ("illuminant wavelengths in um", lambda x, d: _est(x, illuminants=_rewritten(
        x.illuminants, d / "i.csv", lambda w, v: (w / 1000, v))), "refused",
     "0.38-0.73 nm"),
    ("responses in 16-bit counts", lambda x, d: _est(x, responses=fs.scaled_responses(
        x.responses, d / "r.csv", 65535.0)), "refused", "perfect white"),
    ("responses in percent of full scale", lambda x, d: _est(
        x, responses=fs.scaled_responses(x.responses, d / "r.csv", 100.0)), "refused",
     "x100?"),
    # Eq. 1 misfits every patch in a pattern no sensor has (pca: gamma -17.8)
    ("another chart under the same names", _shuffled_chart, "refused",
     "reflectances that are not this chart's"),
    # options out of range
    ("--noise-std -1", lambda x, d: _est(x, noise_std=-1), "refused", "--noise-std"),
    ("--noise-std 1e300", lambda x, d: _est(x, noise_std=1e300), "refused",
     "--noise-std"),
    ("--noise-std 0.5", lambda x, d: _est(x, noise_std=0.5), "refused",
     "50% of full scale"),
    ("--spd-shift-nm -12", lambda x, d: _est(x, spd_shift_nm=-12), "refused",
     "--spd-shift-nm -12"),
    ("--hold-out-every 1", lambda x, d: _cal(x, hold_out_every=1), "refused",
     "--hold-out-every 1"),
    ("capture --max-exposure 0", lambda x, d: [
        "capture", "--out", str(d / "s"), "--max-exposure", "0"], "refused",
     "--max-exposure"),
]  # fmt: skip


def _with_covariance(x, d):
    """The good sensitivities with a covariance in their side file, as a ``"bayes"``
    calibration writes one (0.2 % of the peak per sample, independent): the
    estimate then has its error model and its uncertainties."""
    from tunespec.core.io.export import write_sensitivities_csv

    s = read_spectral(x.sensitivities, kind="sensitivity")
    n = s.values.size
    return write_sensitivities_csv(
        d / "S.csv", s, (0.002 * s.values.max()) ** 2 * np.eye(n)
    )


def _toned(path, d, exponent):
    """The responses (their noise and white level too) through ``c^exponent``: a
    rendered file's tone curve."""
    d.mkdir(exist_ok=True)

    def tone(r):
        c = np.clip(r.rgb, 1e-6, None)
        return replace(r, rgb=c**exponent, rgb_std=r.rgb_std * exponent
                       * c ** (exponent - 1), white_rgb=r.white_rgb**exponent)  # fmt: skip

    return fs.edited_responses(path, d / "toned.csv", tone)


def _typo_on_white(path, d, value):
    """``value`` typed in the brightest spectrum at 530 nm (its neighbours near 0.9)."""
    s = read_spectral(path, kind="reflectance")
    k = int(np.argmax(np.median(s.values, axis=1)))
    j = int(np.argmin(np.abs(s.wavelength_nm - 530)))
    return fs.typo_spectra(path, d / "white_typo.csv", k, j, value)


def _percent_with_typo(path, d):
    s = read_spectral(path, kind="reflectance")
    v = s.values * 100
    v[3, 10] = 300.0
    write_spectra_csv(Spectra(s.wavelength_nm, v, s.names, {}), d / "pct.csv")
    return d / "pct.csv"


def _run(argv, capsys) -> tuple[int, list[str]]:
    try:
        quiet = argv[0] in ("estimate", "calibrate", "evaluate", "capture", "demo")
        code = main([*argv, "-q"] if quiet else argv)
    except SystemExit as exc:  # argparse's usage error: exit 2 with its message
        code = int(exc.code or 0)
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    return code, [ln for ln in err.splitlines() if ln.strip()]


@pytest.mark.parametrize(
    ("argv_of", "expect", "fragment"),
    [pytest.param(b, e, f, id=i) for i, b, e, f in CASES],
)
def test_mistake_is_refused_or_flagged(
    good, tmp_path, capsys, argv_of, expect, fragment
):
    argv = argv_of(good, tmp_path)
    if "-o" not in argv and argv[0] in ("estimate", "calibrate"):
        argv = [*argv, "-o", str(tmp_path / "out.csv")]
    code, lines = _run(argv, capsys)
    if expect == "refused":
        assert code == 2, lines
        assert fragment in lines[-1], lines
        if argv[0] in ("estimate", "calibrate", "evaluate"):
            assert len(lines) == 1, lines  # one line: what, how much, what to do
        assert not (tmp_path / "out.csv").exists()
    else:
        assert code == 0, lines
        assert any(ln.startswith("warning:") and fragment in ln for ln in lines), lines


def test_the_good_files_give_no_warning(good, tmp_path, capsys) -> None:
    x = good
    assert x.base_de00 < 0.5
    code, lines = _run([*_est(x), "-o", str(tmp_path / "e.csv")], capsys)
    assert code == 0 and lines == [], lines
    code, lines = _run(["evaluate", "--estimated", str(tmp_path / "e.csv"),
                        "--reference", str(x.reference)], capsys)  # fmt: skip
    assert code == 0 and lines == [], lines


def test_the_good_files_fit_eq1(good, tmp_path, capsys) -> None:
    """With a covariance the estimate checks its responses against Eq. 1: the good
    files' chi-square per response is about 1, and nothing is said."""
    argv = [*_est(good, sensitivities=_with_covariance(good, tmp_path)), "--json",
            "-o", str(tmp_path / "e.csv")]  # fmt: skip
    code = main(argv)
    out, err = capsys.readouterr()
    assert code == 0 and err == "", err
    chi2 = np.array(json.loads(out)["chi2_per_response"])
    assert chi2.size == 8 and 0.3 < np.median(chi2) < 2.0 and chi2.max() < 4.0, chi2


def test_force_overrides_and_is_recorded(good, tmp_path, capsys) -> None:
    x = good
    argv = _est(x, spd_shift_nm=8, prior=fs.truncated_spectra(
        x.chart, tmp_path / "p.csv", 400, 700, "reflectance"))  # fmt: skip
    code, lines = _run([*argv, "-o", str(tmp_path / "e.csv"), "--force"], capsys)
    assert code == 0, lines
    assert any(
        "accepted with --force" in ln and "--spd-shift-nm 8" in ln for ln in lines
    )
    # each override is a warning line and is listed in the output's metadata (an
    # 8 nm shift also moves two narrow LEDs' signal off the others': a second one)
    meta = json.loads((tmp_path / "e.csv.meta.json").read_text())
    forced = [ln for ln in lines if "accepted with --force" in ln]
    assert len(meta["forced"]) == len(forced) >= 1
    assert "--spd-shift-nm 8" in meta["forced"][0]


def test_no_corrections_proceeds_and_says_so(good, tmp_path, capsys) -> None:
    x = good
    bare = _copy(x.sensitivities, tmp_path / "S.csv")
    argv = [*_est(x, sensitivities=bare), "-o", str(tmp_path / "e.csv")]
    code, lines = _run([*argv, "--no-corrections"], capsys)
    assert code == 0 and len(lines) == 1 and "--no-corrections" in lines[0], lines
    meta = json.loads((tmp_path / "e.csv.meta.json").read_text())
    assert meta["corrections"] == "none (--no-corrections)"


def test_a_toned_sample_without_side_file_is_flagged(good, tmp_path, capsys) -> None:
    """Without the side file no chart's white background checks the sample's scale;
    its own board's channels still show a tone curve (1/1.2: gamma -0.17)."""
    x = good
    bare = _copy(x.sensitivities, tmp_path / "S.csv")
    toned = _toned(x.responses, tmp_path, 1 / 1.2)
    argv = [
        *_est(x, sensitivities=bare, responses=toned),
        "-o",
        str(tmp_path / "e.csv"),
    ]
    code, lines = _run([*argv, "--no-corrections"], capsys)
    bends = [ln for ln in lines if "channels bend" in ln]
    assert code == 0 and len(bends) == 1 and "gamma -0.1" in bends[0], lines
    # the Python API says it too (the good side file: no covariance)
    from tunespec.app import api

    with pytest.warns(UserWarning, match="^the white background's channels bend"):
        api.estimate(_toned(x.responses, tmp_path / "api", 1.1), x.illuminants,
                     x.sensitivities)  # fmt: skip


def test_a_single_typo_no_longer_decides_the_unit(good, tmp_path) -> None:
    """Before: one 3.0 made the whole SG file percent (a 100x scale, 52.6 dE00)."""
    from tunespec.core.errors import InputError

    p = fs.typo_spectra(good.chart, tmp_path / "c.csv", 40, 20, 3.0)
    with pytest.raises(InputError) as err:
        read_spectral(p, kind="reflectance")
    msg = str(err.value)
    # the line of 480 nm (a header, then 380 nm at line 2, 5 nm steps) and the column
    assert msg.startswith(f"{p}:22: 3 in a file of fractions (0..1.05): a typo?"), msg
    assert "column 42: " in msg


def test_demo_seed_of_another_folder_is_refused(tmp_path, capsys) -> None:
    truth = tmp_path / "demo" / "truth"
    truth.mkdir(parents=True)
    (truth / "truth.json").write_text(json.dumps({"camera": {"seed": 0}}))
    code, lines = _run(["demo", "--out", str(tmp_path / "demo"), "--seed", "5"], capsys)
    assert code == 2 and "holds a demo of seed 0" in lines[-1], lines


@pytest.mark.slow
def test_the_demos_files_give_no_warning(tmp_path, capsys) -> None:
    """The demo's own exports through estimate and calibrate: exit 0, no warning
    (no false alarm on good data)."""
    x = fs.build_inputs(tmp_path / "demo", source="demo")
    assert x.base_de00 < 0.3
    capsys.readouterr()
    code, lines = _run([*_cal(x), "-o", str(tmp_path / "S.csv")], capsys)
    assert code == 0 and lines == [], lines
    code, lines = _run([*_est(x), "-o", str(tmp_path / "e.csv")], capsys)
    assert code == 0 and lines == [], lines


def test_config_force_key_is_checked() -> None:
    """``force = true`` (top level of run.toml) is the configuration's --force."""
    from tunespec.app.pipeline.plan import check_config
    from tunespec.core.errors import InputError

    check_config({"force": True})
    with pytest.raises(InputError, match="force: expected true or false"):
        check_config({"force": "yes"})


def test_force_on_calibrate_is_recorded_beside_the_sensitivities(
    good, tmp_path, capsys
) -> None:
    x = good
    chart = fs.truncated_spectra(x.chart, tmp_path / "c.csv", 420, 680, "reflectance")
    argv = [*_cal(x, reflectances=chart, method="pca"), "-o", str(tmp_path / "S.csv")]
    code, lines = _run([*argv, "--force", "--stats", str(tmp_path / "t1.json")], capsys)
    assert code == 0, lines
    assert any("accepted with --force" in ln and "covers 420-680" in ln for ln in lines)
    side = json.loads((tmp_path / "S.csv.meta.json").read_text())
    stats = json.loads((tmp_path / "t1.json").read_text())
    assert side["forced"] == stats["forced"] and "covers 420-680" in side["forced"][0]


def test_force_keeps_a_toned_chart_as_fitted_and_says_so(good, tmp_path, capsys):
    """``--force`` on a bend no sensor has: the fit without linearising (as before
    the check), the override beside the sensitivities."""
    argv = [*_cal(good, responses=_toned(good.chart_responses, tmp_path, 1 / 1.2)),
            "-o", str(tmp_path / "S.csv"), "--force"]  # fmt: skip
    code, lines = _run(argv, capsys)
    assert code == 0, lines
    assert any("accepted with --force" in ln and "gamma -0.1" in ln for ln in lines)
    side = json.loads((tmp_path / "S.csv.meta.json").read_text())
    assert "gamma -0.1" in side["forced"][0]
    assert side["excess_variance"]["linearity_gamma"] == 0.0


def test_an_estimate_repeats_what_its_calibration_warned(good, tmp_path, capsys):
    """A calibration's warnings (here the self-check's: a chart bent as
    ``c^(1/1.05)``, undone, but more than a sensor bends) travel in its side file;
    every estimate with it repeats them, so a script that calls the two commands
    does not lose them."""
    chart = _toned(good.chart_responses, tmp_path, 1 / 1.05)
    cal = [*_cal(good, responses=chart), "-o", str(tmp_path / "S.csv")]
    code, lines = _run(cal, capsys)
    assert code == 0 and any("non-linearity" in ln for ln in lines), lines
    side = json.loads((tmp_path / "S.csv.meta.json").read_text())
    assert side["warnings"] == [ln.removeprefix("warning: ") for ln in lines]
    sample = _toned(good.responses, tmp_path / "sample", 1 / 1.05)
    est = [*_est(good, sensitivities=tmp_path / "S.csv", responses=sample),
           "-o", str(tmp_path / "e.csv")]  # fmt: skip
    code, lines = _run(est, capsys)
    assert code == 0, lines
    assert lines[0].startswith(
        f"warning: the calibration {tmp_path / 'S.csv'} warned: self-check: "
    ), lines
    # the Python API says them too, as warnings
    from tunespec.app import api

    said = "^" + re.escape(f"the calibration {tmp_path / 'S.csv'} warned: self-check: ")
    with pytest.warns(UserWarning, match=said):
        api.estimate(sample, good.illuminants, tmp_path / "S.csv")


def test_the_python_api_keeps_the_white_background_and_checks_the_scale(
    good, tmp_path
) -> None:
    """``Calibration.load``/``save`` keep the chart session's white background
    (before: dropped, so ``api.estimate`` checked no scale), and ``api.estimate``
    refuses a sample on another scale as the command does."""
    from tunespec.app import api
    from tunespec.core.calibration import Calibration
    from tunespec.core.plausibility import Implausible

    side = json.loads(Path(f"{good.sensitivities}.meta.json").read_text())
    cal = Calibration.load(good.sensitivities)
    assert cal.white_background == side["white_background"]
    again = Calibration.load(cal.save(tmp_path / "cal.json"))
    assert again.white_background == cal.white_background
    doubled = fs.scaled_spectra(good.illuminants, tmp_path / "i.csv", 2.0, "illuminant")
    with pytest.raises(Implausible, match=r"white background reflects 0\.5x"):
        api.estimate(good.responses, doubled, again)
    done = api.estimate(good.responses, doubled, again, force=True)
    assert any("white background reflects 0.5x" in f for f in done.forced)


@pytest.mark.slow
def test_semantic_fuzz_seeded() -> None:
    """A seeded part of ``tools/fuzz_inputs.py --semantic``: no traceback, no hang,
    nothing accepted without a warning and wrong by more than 1 dE00."""
    counts, bugs = fs.fuzz_semantic(200, seed=5)
    assert not bugs, bugs[:5]
    assert sum(counts[o] for o in fs.OUTCOMES) == 200
    assert counts["refused"] > 150  # the mutations are mistakes: mostly refused
