"""Every spectral format in, found from the content; percent detected; grids from data."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tunespec.core.datasets import load_camera, read_sensitivities, resource_path
from tunespec.core.errors import InputError
from tunespec.core.io.cgats import ti3_table, write_cgats
from tunespec.core.io.export import write_sensitivity_json
from tunespec.core.io.spectral import detect_format, read_spectral
from tunespec.core.io.spectral_csv import write_spectra_csv
from tunespec.core.spectra import Grid, Spectra, grid_from_data

DATA = Path(__file__).parent.parent / "data"
WL = np.array([400.0, 410.0, 420.0])
VALUES = np.array([[0.125, 0.5, 0.75], [0.0625, 0.25, 0.375]])


def _expected() -> Spectra:
    return Spectra(WL, VALUES, ("A1", "B 2"))


@pytest.mark.parametrize(
    "text",
    [
        "wavelength_nm,A1,B 2\n400,0.125,0.0625\n410,0.5,0.25\n420,0.75,0.375\n",
        "nm;A1;B 2\n400;0,125;0,0625\n410;0,5;0,25\n420;0,75;0,375\n",
        "Lambda\tA1\tB 2\n400\t0.125\t0.0625\n410\t0.5\t0.25\n420\t0.75\t0.375\n",
        "# exported\n\ufeffWavelength (nm),A1,B 2,\n400,0.125,0.0625,\n"
        "410,0.5,0.25,\n# note\n420,0.75,0.375,\n",
        "SAMPLE_NAME,L*,380_unused,400,410,420\nA1,50,x,0.125,0.5,0.75\n"
        "B 2,40,x,0.0625,0.25,0.375\n".replace("380_unused", "note"),
        "name;nm400;nm410;nm420\nA1;0,125;0,5;0,75\nB 2;0,0625;0,25;0,375\n",
    ],
    ids=["ours", "semicolon-decimal-comma", "tab-lambda", "comments-bom", "rows", "nm"],
)
def test_csv_variants_read_the_same(tmp_path, text) -> None:
    p = tmp_path / "x.txt"
    p.write_text(text, encoding="utf-8")
    s = read_spectral(p)
    assert s.names == ("A1", "B 2")
    np.testing.assert_array_equal(s.wavelength_nm, WL)
    np.testing.assert_array_equal(s.values, VALUES)


def test_colour_science_csv(tmp_path) -> None:
    import colour
    import colour.io

    sg = read_spectral(resource_path("charts", "colorchecker_sg.csv")).select(
        ["A1", "E5"]
    )
    sds = {
        n: colour.SpectralDistribution(
            dict(zip(sg.wavelength_nm, sg[n], strict=True)), name=n
        )
        for n in sg.names
    }
    colour.io.write_sds_to_csv_file(sds, str(tmp_path / "c.csv"))
    s = read_spectral(tmp_path / "c.csv", kind="reflectance")
    assert s.names == sg.names
    np.testing.assert_allclose(s.values, sg.values, rtol=0, atol=1e-12)


def test_format_from_content_not_extension(tmp_path) -> None:
    table = ti3_table(["A1", "B 2"], reflectance=_expected(), created="x")
    write_cgats(table, tmp_path / "looks_like.csv")
    write_spectra_csv(_expected(), tmp_path / "looks_like.ti3")
    a = read_spectral(tmp_path / "looks_like.csv", kind="reflectance")
    b = read_spectral(tmp_path / "looks_like.ti3", kind="reflectance")
    np.testing.assert_array_equal(a.values, VALUES)  # percent text moved back exactly
    np.testing.assert_array_equal(b.values, VALUES)
    assert "CGATS" in a.meta["format"] and "CSV" in b.meta["format"]
    assert detect_format("CGATS.17\nBEGIN_DATA_FORMAT\n") == "cgats"


def test_percent_detected_and_reported(tmp_path) -> None:
    p = tmp_path / "pct.csv"
    write_spectra_csv(_expected().with_values(VALUES * 100), p)
    s = read_spectral(p, kind="reflectance")
    np.testing.assert_allclose(s.values, VALUES, rtol=1e-15)
    assert "percent" in s.meta["note"] and "75" in s.meta["note"]
    factor = read_spectral(p.with_name("f.csv") if False else p, kind="spectra")
    assert factor.values.max() == 75.0  # only reflectances are rescaled
    write_spectra_csv(_expected().with_values(VALUES * 1e4), p)
    with pytest.raises(InputError, match="out of range"):
        read_spectral(p, kind="reflectance")


def test_i1profiler_export() -> None:
    s = read_spectral(DATA / "i1profiler_sg_patches.txt", kind="reflectance")
    sg = read_spectral(resource_path("charts", "colorchecker_sg.csv"))
    assert s.names == ("E5", "E6", "F5", "F6") and "note" not in s.meta
    np.testing.assert_array_equal(s.wavelength_nm, sg.wavelength_nm)
    np.testing.assert_allclose(s.values, sg.select(s.names).values, atol=5e-5)


def test_spectral_nm_fields_in_percent(tmp_path) -> None:
    p = tmp_path / "m.cgats"
    p.write_text(
        'IT8.7/2\nORIGINATOR "x"\nNUMBER_OF_FIELDS 4\nBEGIN_DATA_FORMAT\n'
        "SAMPLE_ID SPECTRAL_NM400 SPECTRAL_NM410 SPECTRAL_NM420\nEND_DATA_FORMAT\n"
        "NUMBER_OF_SETS 2\nBEGIN_DATA\nA1 12.5 50 75\nB 6.25 25 37.5\nEND_DATA\n"
    )
    s = read_spectral(p, kind="reflectance")
    np.testing.assert_allclose(s.values, VALUES, rtol=1e-15)
    assert s.names == ("A1", "B") and "percent" in s.meta["note"]


def test_argyll_spec2cie_output() -> None:
    s = read_spectral(DATA / "spec2cie_reference_reflectances.ti3", kind="reflectance")
    ref = read_spectral(resource_path("charts", "neugebauer_cmy_model.csv"))
    ref = ref.resample(Grid(400, 700, 5))
    assert s.names == ref.names
    np.testing.assert_allclose(s.values, ref.values, atol=6e-6)


def test_rawtoaces_json_back_on_the_absolute_scale(tmp_path) -> None:
    absolute = load_camera().with_values(load_camera().values * 0.0123)
    path = tmp_path / "cam.json"
    write_sensitivity_json(absolute, path)  # normalised, 380-780 nm, 0 beyond 730
    s = read_sensitivities(path)
    np.testing.assert_array_equal(s.wavelength_nm, absolute.wavelength_nm)
    np.testing.assert_allclose(s.values, absolute.values, rtol=1e-15, atol=0)
    assert "relative" not in s.meta
    db = read_sensitivities(resource_path("cameras", "Nikon_D850_380_780_5.json"))
    assert db.meta["relative"] == "1" and db.wavelength_nm[-1] == 780.0


def test_sensitivity_channels_any_case(tmp_path) -> None:
    p = tmp_path / "s.csv"
    p.write_text("nm,red,green,blue,ir\n400,1,2,3,4\n410,1,2,3,4\n")
    s = read_sensitivities(p)
    assert s.names == ("R", "G", "B") and s.values[:, 0].tolist() == [1, 2, 3]
    p.write_text("nm,R,G\n400,1,2\n410,1,2\n")
    with pytest.raises(InputError, match="missing channel"):
        read_sensitivities(p)


@pytest.mark.parametrize(
    ("text", "fragment", "line"),
    [
        ("name,400,410\nA,1\n", "expected 3", 2),
        ("name;nm400;nm410\nA;1;x\n", "not a number", 2),
        ("name,400,410\nA,1,2\nA,1,2\n", "duplicate", 1),
        ("name,410,400\n", "no data rows", 1),
        ('{"spectral_data": 3}', "rawtoaces", None),
        (
            "CTI3\nBEGIN_DATA_FORMAT\nSAMPLE_ID\nEND_DATA_FORMAT\nBEGIN_DATA\nA\n"
            "END_DATA\n",
            "without spectral fields",
            None,
        ),
    ],
)
def test_errors_name_file_and_line(tmp_path, text, fragment, line) -> None:
    p = tmp_path / "bad.txt"
    p.write_text(text)
    with pytest.raises(InputError, match=fragment) as err:
        read_spectral(p)
    assert err.value.path == str(p) and err.value.line == line


def test_grid_from_data() -> None:
    led = Spectra(np.arange(380.0, 781.0), np.ones((1, 401)), ("L",))
    sg = Spectra(np.arange(380.0, 731.0, 10.0), np.ones((1, 36)), ("A1",))
    sens = Spectra(np.arange(385.0, 721.0, 5.0), np.ones((1, 68)), ("R",))
    assert str(grid_from_data([led, sg], sets_step=[False, True])) == "380:730:10"
    assert str(grid_from_data([led, sg, sens], sets_step=[False, True, True])) == (
        "385:720:5"
    )
    assert str(grid_from_data([led])) == "380:780:1"
    coarse = Spectra(np.arange(400.0, 701.0, 20.0), np.ones((1, 16)), ("X",))
    assert grid_from_data([coarse]).step_nm == 10.0  # at most 10 nm
    far = Spectra(np.array([800.0, 900.0]), np.ones((1, 2)), ("Y",), {"source": "f"})
    with pytest.raises(InputError, match=r"no wavelength range .*f: 800-900 nm"):
        grid_from_data([sg, far])
