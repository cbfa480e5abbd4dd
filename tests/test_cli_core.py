"""The core commands end to end on files, and their one-line errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.helpers import SHIPPED_SPECTRA, write_shipped_spectra
from tunespec.app.cli import main
from tunespec.core.datasets import (
    load_camera,
    resource_path,
)
from tunespec.core.io.export import COLORIMETRY_COLUMNS
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.io.spectral_csv import write_spectra_csv
from tunespec.core.spectra import Grid


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    return write_shipped_spectra(tmp_path_factory.mktemp("cli"))


def _simulate(sensitivities, illuminants, reflectances, *options) -> int:
    """``tunespec simulate-responses`` on three files, with further options."""
    return main(
        [
            "simulate-responses",
            "--sensitivities",
            str(sensitivities),
            "--illuminants",
            str(illuminants),
            "--reflectances",
            str(reflectances),
            *map(str, options),
        ]
    )


def test_simulate_calibrate_estimate_evaluate(files, capsys) -> None:
    d = files
    assert (
        _simulate(
            str(d / "cam.csv"),
            str(d / "leds.csv"),
            str(d / "sg.csv"),
            "--exposure-target",
            "0.8",
            "--illuminants-out",
            str(d / "L.csv"),
            "-o",
            str(d / "R.csv"),
        )
        == 0
    )
    assert (
        main(
            [
                "calibrate",
                "--responses",
                str(d / "R.csv"),
                "--illuminants",
                str(d / "L.csv"),
                "--reflectances",
                str(d / "sg.csv"),
                "--hold-out-every",
                "5",
                "-o",
                str(d / "S.csv"),
                "--stats",
                str(d / "cal.json"),
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "RGB" in out
    stats = json.loads((d / "cal.json").read_text())
    # Simulated at the 5D Mark III's noise: the paper's Table 1 level (0.24 % mean RGB)
    assert stats["training"]["RGB"]["mean"] < 0.0024
    assert stats["held_out"]["RGB"]["mean"] < 0.0030
    # the self-check predicts the calibration's own held-aside patches (no second fit)
    checked = stats["self_check"]
    assert "Self-check:" in out and checked["passed"] is True
    assert checked["held_out"]["prediction"] == stats["held_out"]
    assert checked["held_out"]["every"] == 5
    assert min(checked["residual_chi_square"]["reduced"].values()) > 0.8
    assert max(checked["residual_chi_square"]["reduced"].values()) < 1.3
    meta = json.loads((d / "S.csv.meta.json").read_text())
    # simulate-responses writes the true SPDs: the fitted shift is near zero
    assert abs(meta["spd_shift_nm"]) < 0.3
    assert stats["params"]["spd_shift_fitted"] is True
    sens = read_spectra_csv(d / "S.csv")
    assert stats["grid"] == "380:730:2"  # calibration at CALIBRATION_MAX_STEP_NM
    true = load_camera(grid=Grid(380.0, 730.0, 2.0)).values
    est = sens.values / sens.values.max(axis=1, keepdims=True)
    true = true / true.max(axis=1, keepdims=True)
    assert np.sqrt(np.mean((est - true) ** 2)) < 0.03
    target = resource_path("charts", "neugebauer_cmy_model.csv")
    assert (
        _simulate(
            str(d / "cam.csv"),
            str(d / "L.csv"),
            str(target),
            "--seed",
            "3",
            "-o",
            str(d / "T.csv"),
        )
        == 0
    )
    assert (
        main(
            [
                "estimate",
                "--responses",
                str(d / "T.csv"),
                "--illuminants",
                str(d / "L.csv"),
                "--sensitivities",
                str(d / "S.csv"),
                "-o",
                str(d / "E.csv"),
            ]
        )
        == 0
    )
    # a grid past the light is refused by the grid asked for, not the one Eq. 1
    # would integrate on (wider, finer)
    capsys.readouterr()
    estimate = ["estimate", "--responses", str(d / "T.csv"), "--illuminants"]
    past = [str(d / "L.csv"), "--sensitivities", str(d / "S.csv"), "--grid"]
    assert main([*estimate, *past, "400:760:10", "-o", str(d / "X.csv")]) == 2
    err = capsys.readouterr().err
    assert (
        "S.csv: wavelength range 380-730 nm is too short for the grid 400:760:10" in err
    )
    assert len(err.strip().splitlines()) == 1 and not (d / "X.csv").exists()
    # the 'bayes' calibration carries a covariance: uncertainties beside the estimate
    assert len(meta["led_correction"]["leds"]) == 22
    unc = read_spectra_csv(d / "E_uncertainty.csv")
    assert unc.names == read_spectra_csv(d / "E.csv").names
    assert np.all(unc.values > 0) and np.all(unc.values < 0.2)
    rows = (d / "E_colorimetry.csv").read_text().splitlines()
    assert rows[0].split(",") == list(COLORIMETRY_COLUMNS)
    assert len(rows) == 1 + len(unc.names)
    u_lab = np.array([[float(x) for x in r.split(",")[10:13]] for r in rows[1:]])
    assert np.all(u_lab > 0.005) and np.all(u_lab < 3.0)
    assert (
        main(
            [
                "evaluate",
                "--estimated",
                str(d / "E.csv"),
                "--reference",
                str(target),
                "--stats",
                str(d / "t2.json"),
            ]
        )
        == 0
    )
    t2 = json.loads((d / "t2.json").read_text())
    assert t2["average"]["delta_e00"] < 2.0


@pytest.mark.parametrize(
    ("mutate", "fragment"),
    [
        (lambda t: t.replace("patch,illuminant", "pach,illuminant"), "missing column"),
        (lambda t: t.replace(",LED450,", ",LED999,"), "LED999"),
        (lambda t: t.replace("\nA1,", "\nZZ9,"), "ZZ9"),
    ],
)
def test_bad_input_is_one_line_exit_2(files, capsys, mutate, fragment) -> None:
    d = files
    _simulate(
        *(d / f for f in SHIPPED_SPECTRA),
        "--no-noise",
        "-o",
        str(d / "ok.csv"),
    )
    capsys.readouterr()
    bad = d / "bad.csv"
    bad.write_text(mutate((d / "ok.csv").read_text()))
    code = main(
        [
            "calibrate",
            "--responses",
            str(bad),
            "--illuminants",
            str(d / "leds.csv"),
            "--reflectances",
            str(d / "sg.csv"),
            "-o",
            str(d / "never.csv"),
        ]
    )
    err = capsys.readouterr().err
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and fragment in err
    assert "Traceback" not in err
    assert not (d / "never.csv").exists()


def test_short_wavelength_range_is_reported(files, tmp_path, capsys) -> None:
    short = tmp_path / "short.csv"
    short.write_text("wavelength_nm,R,G,B\n420,1,1,1\n700,1,1,1\n")
    code = _simulate(
        str(short),
        str(files / "leds.csv"),
        str(files / "sg.csv"),
        "--grid",
        "380:730:5",
        "-o",
        str(tmp_path / "x.csv"),
    )
    err = capsys.readouterr().err
    assert code == 2 and "too short for the grid" in err and str(short) in err
    assert "420-700 nm" in err and len(err.strip().splitlines()) == 1


def test_more_bad_input_is_one_line_exit_2(files, tmp_path, capsys) -> None:
    d = files
    _simulate(
        *(d / f for f in SHIPPED_SPECTRA),
        "--no-noise",
        "--exposure-target",
        "0.8",
        "--illuminants-out",
        str(tmp_path / "L.csv"),
        "-o",
        str(tmp_path / "R.csv"),
    )
    capsys.readouterr()
    sg = read_spectra_csv(d / "sg.csv")
    write_spectra_csv(sg.select(["A1", "B2"]), tmp_path / "ref.csv")
    resp = ["--responses", str(tmp_path / "R.csv")]
    illum = ["--illuminants", str(tmp_path / "L.csv")]
    cases = [
        (
            [
                "calibrate",
                *resp,
                *illum,
                "--reflectances",
                str(d / "sg.csv"),
                "--hold-out-every",
                "1",
                "-o",
                str(tmp_path / "S.csv"),
            ],
            "--hold-out-every 1: N must be at least 2",
        ),
        (
            [
                "estimate",
                *resp,
                *illum,
                "--sensitivities",
                str(d / "cam.csv"),
                "--spd-shift-nm",
                "nan",
                "-o",
                str(tmp_path / "E.csv"),
            ],
            "wavelength shift nan nm is not finite",
        ),
        (
            [
                "evaluate",
                "--estimated",
                str(d / "sg.csv"),
                "--reference",
                str(tmp_path / "ref.csv"),
            ],
            f"{tmp_path / 'ref.csv'}: reference reflectances: 138 estimated patch(es) "
            "missing: A2, A3",
        ),
    ]
    for argv, fragment in cases:
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and fragment in err, err
    assert not (tmp_path / "S.csv").exists() and not (tmp_path / "E.csv").exists()
