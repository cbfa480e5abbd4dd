from __future__ import annotations

import math

import numpy as np
import pytest

from tests.tolerances import ATOL_EXACT
from tunespec.core.datasets import (
    camera_names,
    load_camera,
    load_colorchecker_sg,
    load_led_set,
)
from tunespec.core.errors import InputError
from tunespec.core.forward_model import lighting_matrix, render_rgb
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.io.spectral_csv import write_spectra_csv
from tunespec.core.spectra import MAX_GRID_SAMPLES, Grid, Spectra


def test_grid_parse_and_errors() -> None:
    g = Grid.parse("400:700:10")
    assert g.n == 31 and g.wavelength_nm[-1] == 700
    for bad in ("400:700", "a:b:c", "700:400:10", "400:705:10"):
        with pytest.raises(InputError):
            Grid.parse(bad)


def test_csv_round_trip_is_exact(tmp_path) -> None:
    rng = np.random.default_rng(0)
    s = Spectra(np.arange(400.0, 701.0, 10.0), rng.random((3, 31)), ("a", "b", "c"))
    write_spectra_csv(s, tmp_path / "s.csv")
    back = read_spectra_csv(tmp_path / "s.csv")
    assert back.names == s.names
    np.testing.assert_array_equal(back.values, s.values)


@pytest.mark.parametrize(
    ("text", "fragment", "line"),
    [
        ("x,a\n400,1\n", "expected a first column naming the wavelengths", 1),
        ("wavelength,a\n400,1\n410,x\n", "not a number", 3),
        ("wavelength,a\n400,1\n410,nan\n", "not finite", 3),
        ("wavelength,a\n400,1\n410,-0.5\n", "negative", 3),
        ("wavelength,a\n400,1\n400,1\n", "not above", 3),
        ("wavelength,a,b\n400,1,2\n410,1\n", "expected 3", 3),
        ("wavelength,a,a\n400,1,2\n410,1,2\n", "duplicate", 1),
    ],
)
def test_csv_errors_name_file_and_line(tmp_path, text, fragment, line) -> None:
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(InputError, match=fragment) as err:
        read_spectra_csv(p)
    assert err.value.line == line and err.value.path == str(p)
    assert str(err.value).startswith(f"{p}:{line}: ")


def test_resample_refuses_short_range(tmp_path) -> None:
    p = tmp_path / "short.csv"
    p.write_text("wavelength_nm,a\n420,1\n700,1\n")
    with pytest.raises(InputError, match="too short for the grid"):
        read_spectra_csv(p, Grid(400, 700, 10))


def test_resample_linear_is_exact_for_linear_data() -> None:
    wl = np.arange(380.0, 781.0, 10.0)
    s = Spectra(wl, (0.001 * wl)[None], ("lin",))
    r = s.resample(Grid(400, 700, 5))
    np.testing.assert_allclose(r.values[0], 0.001 * r.wavelength_nm, atol=ATOL_EXACT)


def test_shipped_data() -> None:
    assert len(camera_names()) == 52
    cam = load_camera()
    assert cam.names == ("R", "G", "B") and cam.values.max() == 1.0
    sg = load_colorchecker_sg()
    assert len(sg) == 140 and sg.names[0] == "A1" and sg.names[-1] == "N10"
    leds = load_led_set()
    assert len(leds) == 22
    peaks = leds.wavelength_nm[leds.values[:20].argmax(axis=1)]
    assert peaks.min() >= 405 and peaks.max() <= 705  # no LED at 400 nm (paper)


def test_forward_model_matches_lighting_matrix() -> None:
    rng = np.random.default_rng(0)
    r, i, S = rng.random((5, 71)), rng.random((22, 71)), rng.random((3, 71))
    c = render_rgb(r, i, S, 5.0)
    F = lighting_matrix(i, S, 5.0)
    np.testing.assert_allclose(r @ F.T, c.reshape(5, -1), atol=ATOL_EXACT)
    # Eq. 1 by hand for one patch/illuminant/channel
    assert c[2, 7, 1] == pytest.approx(5.0 * np.sum(S[1] * i[7] * r[2]), rel=1e-12)


def test_grid_refuses_non_finite_and_oversized_grids() -> None:
    for args in (
        (400.0, math.inf, 5.0),
        (math.nan, 700.0, 5.0),
        (400.0, 700.0, math.nan),
    ):
        with pytest.raises(InputError, match="finite"):
            Grid(*args)
    # A mistyped step would otherwise allocate n_wl x n_wl matrices later.
    with pytest.raises(InputError, match="300000000001 samples, at most 10001"):
        Grid.parse("400:700:1e-9")
    assert Grid(400.0, 700.0, 0.03).n == MAX_GRID_SAMPLES


def test_grid_accepts_a_step_read_back_from_sampled_wavelengths() -> None:
    # np.diff of 400 + 0.03 k carries rounding (step 0.029999999999973): the
    # multiple-of-STEP check has a tolerance (1e-6 nm), so reconstructing the grid of
    # sampled spectra (as reflectance_stats and wiener_reflectance do) works.
    wl = 400.0 + 0.03 * np.arange(MAX_GRID_SAMPLES)
    step = float(np.diff(wl)[-1])
    g = Grid(float(wl[0]), float(wl[-1]), step)
    assert g.n == MAX_GRID_SAMPLES
    np.testing.assert_allclose(g.wavelength_nm, wl, rtol=0, atol=1e-9)
    with pytest.raises(InputError, match="multiple of STEP"):
        Grid(400.0, 700.0, 0.031)


def test_spectra_refuse_non_finite_wavelengths() -> None:
    with pytest.raises(InputError, match="finite"):
        Spectra(np.array([400.0, np.nan, 420.0]), np.ones((1, 3)), ("a",))
