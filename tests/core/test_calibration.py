"""One calibration object: sensitivities, metering corrections, excess variance and
covariance read and written together (``core/calibration.py``)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tunespec.core.calibration import (
    CALIBRATION_FORMAT,
    Calibration,
    MissingCorrectionsWarning,
    correct_illuminants_from_meta,
)
from tunespec.core.datasets import load_camera, load_led_set
from tunespec.core.errors import InputError
from tunespec.core.excess import ExcessVariance
from tunespec.core.io.export import read_sensitivity_meta, sensitivity_meta_path
from tunespec.core.io.spectral_csv import write_spectra_csv
from tunespec.core.led_correction import LedCorrection
from tunespec.core.spectra import Grid, Spectra

GRID = Grid(400.0, 700.0, 10.0)


@pytest.fixture
def calibration() -> Calibration:
    """A ``"bayes"``-like calibration: absolute sensitivities, two LED corrections,
    an excess variance and a positive definite covariance of matching size."""
    cam = load_camera(grid=GRID)
    sens = Spectra(cam.wavelength_nm, cam.values * 0.0123, cam.names, {})
    leds = load_led_set(GRID).names[:2]
    corr = LedCorrection(
        leds, (1.02, 0.97), (0.4, -0.7), 0.25, (0.01, 0.02), (0.1, 0.2)
    )
    n = 3 * sens.wavelength_nm.size + 2 * len(leds)
    rng = np.random.default_rng(3)
    a = rng.normal(size=(n, n)) * 1e-4
    cov = a @ a.T + 1e-8 * np.eye(n)
    excess = ExcessVariance(0.004, 0.002, 24, 1056, 0.001)
    return Calibration(
        sens, "bayes", spd_shift_nm=0.0, led_correction=corr, covariance=cov,
        excess=excess, provenance={"forced": ["check_x"]},
    )  # fmt: skip


def _same(a: Calibration, b: Calibration, cov_rtol: float) -> None:
    np.testing.assert_array_equal(
        a.sensitivity.wavelength_nm, b.sensitivity.wavelength_nm
    )
    np.testing.assert_allclose(a.sensitivity.values, b.sensitivity.values, rtol=1e-12)
    assert a.led_correction == b.led_correction
    assert a.excess == b.excess
    assert a.spd_shift_nm == b.spd_shift_nm
    np.testing.assert_allclose(a.covariance, b.covariance, rtol=cov_rtol, atol=1e-16)


@pytest.mark.parametrize("name", ["sens.csv", "calibration.json"])
def test_save_then_load_gives_the_calibration_back(tmp_path, calibration, name) -> None:
    path = calibration.save(tmp_path / name)
    back = Calibration.load(path)
    # the side file keeps 7 significant digits of the covariance
    _same(back, calibration, cov_rtol=1e-6)
    assert back.method == "bayes"
    assert back.provenance["forced"] == ["check_x"]
    # written again, the files are identical: nothing is lost on the way back
    again = back.save(tmp_path / f"again_{name}")
    assert again.read_bytes() == path.read_bytes()
    if name.endswith(".csv"):
        side = sensitivity_meta_path(path)
        assert sensitivity_meta_path(again).read_text() == side.read_text()


def test_the_json_holds_everything_in_one_file(tmp_path, calibration) -> None:
    path = calibration.save(tmp_path / "cal.json")
    doc = json.loads(path.read_text())
    assert doc["format"] == CALIBRATION_FORMAT
    assert {"led_correction", "excess_variance", "covariance"} <= set(doc)
    assert not sensitivity_meta_path(path).exists()


def test_loaded_corrections_are_the_ones_the_cli_applies(tmp_path, calibration) -> None:
    """The object's correction equals the side-file rule ``estimate`` and ``run``
    apply (read_sensitivity_meta + correct_illuminants_from_meta), and differs from
    the reported spectra."""
    csv = calibration.save(tmp_path / "sens.csv")
    cal = Calibration.load(csv)
    leds = load_led_set(GRID)
    via_meta = correct_illuminants_from_meta(leds, read_sensitivity_meta(csv))
    via_object = cal.correct_illuminants(leds)
    np.testing.assert_array_equal(via_object.values, via_meta.values)
    # the sensitivities' own meta says the same (the pipeline's estimate reads it)
    via_spectra_meta = correct_illuminants_from_meta(leds, cal.sensitivity.meta)
    np.testing.assert_array_equal(via_spectra_meta.values, via_meta.values)
    assert np.max(np.abs(via_object.values - leds.values)) > 0.01 * leds.values.max()


def test_sensitivities_without_side_file_are_refused_naming_it(
    tmp_path, calibration
) -> None:
    csv = tmp_path / "sens.csv"
    write_spectra_csv(calibration.sensitivity, csv)
    with pytest.raises(InputError, match=r"sens\.csv\.meta\.json") as info:
        Calibration.load(csv)
    assert info.value.path is not None
    assert str(info.value.path).endswith("sens.csv.meta.json")


def test_without_side_file_is_an_explicit_choice_that_warns(
    tmp_path, calibration
) -> None:
    csv = tmp_path / "sens.csv"
    write_spectra_csv(calibration.sensitivity, csv)
    with pytest.warns(MissingCorrectionsWarning, match="no LED corrections"):
        cal = Calibration.load(csv, without_side_file=True)
    assert cal.led_correction is None and cal.covariance is None
    assert cal.spd_shift_nm == 0.0
    leds = load_led_set(GRID)
    # nothing to undo but the meter's noise floor
    assert cal.correct_illuminants(leds).values.shape == leds.values.shape


def test_a_covariance_of_the_wrong_size_is_refused(tmp_path, calibration) -> None:
    path = calibration.save(tmp_path / "cal.json")
    doc = json.loads(path.read_text())
    doc["covariance"]["values"] = [row[:-1] for row in doc["covariance"]["values"][:-1]]
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError, match="covariance is"):
        Calibration.load(path)


def test_a_calibration_json_with_curves_missing_is_refused(tmp_path) -> None:
    path = tmp_path / "cal.json"
    path.write_text(json.dumps({"format": CALIBRATION_FORMAT, "wavelength_nm": [400]}))
    with pytest.raises(InputError, match="'sensitivity'"):
        Calibration.load(path)


def test_sensitivities_off_their_covariance_grid_are_refused_unless_forced(
    tmp_path, calibration
) -> None:
    """The curves resampled by hand (10 -> 5 nm), their side file copied along: the
    Python API refuses them as the command line does (check_calibration_grid); an
    override loads them with the covariance resampled after them (T Sigma T')."""
    from tunespec.core.plausibility import Checks, Implausible

    calibration.save(tmp_path / "sens.csv")
    fine = calibration.sensitivity.resample(Grid(400.0, 700.0, 5.0))
    write_spectra_csv(fine, tmp_path / "fine.csv")
    side = sensitivity_meta_path(tmp_path / "fine.csv")
    side.write_text(sensitivity_meta_path(tmp_path / "sens.csv").read_text())
    with pytest.raises(Implausible, match=r"sensitivities at 400:700:5 nm, their "
                       r"calibration's covariance and LED corrections at 400:700:10"):  # fmt: skip
        Calibration.load(tmp_path / "fine.csv")
    checks = Checks(force=True)
    cal = Calibration.load(tmp_path / "fine.csv", checks=checks)
    assert len(checks.overridden) == 1 and "400:700:10" in checks.overridden[0]
    n = 3 * 61 + 2 * 2
    assert cal.covariance is not None and cal.covariance.shape == (n, n)
