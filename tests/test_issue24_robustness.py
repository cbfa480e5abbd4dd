"""Issue 24, item 7: what the audit's fuzzer found, each refused in one line.

match-illuminant on an illuminants file with a line missing or a 0.0175 nm grid
(tracebacks in colour-science), and on 5,000 constant columns (a hang); non-finite
noise options; a noise level of 1e300 (an overflow); a 100000x100000 simulated
camera (a MemoryError); a NUL byte in a manifest's file name; rawtoaces JSONs and
``.meta.json`` covariances that parse but cannot be data; CSV rows with an extra
field.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest

from tests.helpers import write_shipped_spectra
from tunespec.app.cli import main
from tunespec.core.datasets import load_colorchecker_sg, load_led_set
from tunespec.core.errors import InputError
from tunespec.core.illuminant_match import (
    MAX_MATCH_LEDS,
    colour_rendering,
    illuminant_spd,
    match_illuminant,
)
from tunespec.core.io.export import (
    read_sensitivity_meta,
    write_sensitivities_csv,
    write_sensitivity_json,
)
from tunespec.core.io.spectral import read_spectra_csv, read_spectral
from tunespec.core.io.spectral_csv import write_spectra_csv
from tunespec.core.spectra import Grid, Spectra


def _one_line(capsys, rc: int, code: int = 2) -> str:
    err = capsys.readouterr().err.strip()
    assert rc == code, err
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    return err


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> Path:
    return write_shipped_spectra(tmp_path_factory.mktemp("robust"))


# -- match-illuminant -------------------------------------------------------------------
def _d50_mix() -> Spectra:
    leds = load_led_set(Grid(360, 780, 1))
    return Spectra(leds.wavelength_nm, leds.values.sum(axis=0)[None], ("mix",))


def test_colour_rendering_takes_an_irregular_fine_or_coarse_grid() -> None:
    mix = _d50_mix()
    ra, rf = colour_rendering(mix)
    keep = np.ones(mix.wavelength_nm.size, bool)
    keep[48] = False  # one line deleted from the file
    gap = Spectra(mix.wavelength_nm[keep], mix.values[:, keep], ("mix",))
    fine_wl = np.arange(360.0, 780.0, 0.0175)
    fine_v = np.interp(fine_wl, mix.wavelength_nm, mix.values[0])[None]
    fine = Spectra(fine_wl, fine_v, ("mix",))
    coarse_wl = np.arange(360.0, 781.0, 10.0)
    coarse_v = np.interp(coarse_wl, mix.wavelength_nm, mix.values[0])[None]
    coarse = Spectra(coarse_wl, coarse_v, ("mix",))  # TM-30 wants <= 5 nm
    for spd in (gap, fine, coarse):
        ra2, rf2 = colour_rendering(spd)
        assert ra2 == pytest.approx(ra, abs=0.5) and rf2 == pytest.approx(rf, abs=0.5)


def test_match_illuminant_refuses_thousands_of_led_columns() -> None:
    leds = load_led_set(Grid(360, 780, 1))
    many = np.vstack([leds.values, np.ones((5000, leds.values.shape[1]))])
    names = leds.names + tuple(f"C{i}" for i in range(5000))
    with pytest.raises(InputError, match=f"at most {MAX_MATCH_LEDS}"):
        match_illuminant(
            Spectra(leds.wavelength_nm, many, names),
            illuminant_spd("D50"),
            load_colorchecker_sg(),
        )


# -- options that are not numbers a run can use ----------------------------------------
@pytest.mark.parametrize(
    ("option", "value"),
    [
        ("--full-well-e", "inf"),
        ("--read-noise-e", "inf"),
        ("--read-noise-e", "nan"),
        ("--full-well-e", "0"),
        ("--flat-field-residual", "-1"),
    ],
)
def test_simulate_refuses_non_finite_noise_options(
    files, tmp_path, capsys, option, value
) -> None:
    out = tmp_path / "r.csv"
    rc = main(
        ["simulate-responses", "--sensitivities", str(files / "cam.csv"),
         "--illuminants", str(files / "leds.csv"), "--reflectances",
         str(files / "sg.csv"), option, value, "-o", str(out)]
    )  # fmt: skip
    err = _one_line(capsys, rc)
    assert f"{option}:" in err and not out.exists()


def test_estimate_refuses_an_absurd_noise_std(tmp_path, capsys) -> None:
    rc = main(
        ["estimate", "--responses", "r.csv", "--illuminants", "l.csv",
         "--sensitivities", "s.csv", "--noise-std", "1e300", "-o",
         str(tmp_path / "e.csv")]
    )  # fmt: skip
    err = _one_line(capsys, rc)
    assert "--noise-std" in err and "1e+300" in err


def test_wiener_bounds_the_noise_level() -> None:
    from tunespec.core.responses import Responses
    from tunespec.core.wiener import wiener_reflectance

    sg = load_colorchecker_sg()
    leds = load_led_set()
    sens = Spectra(
        sg.wavelength_nm, np.ones((3, sg.wavelength_nm.size)), ("R", "G", "B")
    )
    rgb = np.full((2, len(leds), 3), 0.5)
    r = Responses(("A1", "A2"), leds.names, rgb)
    with pytest.raises(InputError, match="noise_std"):
        wiener_reflectance(r, leds, sens, sg, noise_std=1e300)


@pytest.mark.parametrize("res", ["100000x100000", "12002x12000", "20000x64"])
def test_a_simulated_camera_larger_than_any_sensor_is_refused(tmp_path, res) -> None:
    from tunespec.devices.registry import parse_resolution

    with pytest.raises(InputError, match="at most 12000 pixels a side"):
        parse_resolution(res)
    assert parse_resolution("11648x8736") == (11648, 8736)


# -- files that parse but cannot be data ------------------------------------------------
def test_a_nul_byte_in_a_manifest_file_name_is_refused(tmp_path) -> None:
    from tunespec.core.io.session import CaptureSettings, Session, plan_frames

    settings = CaptureSettings(
        ("L1",), exposure_mode="fixed", exposures_s={"L1": (1.0,)}
    )
    s = Session.create(tmp_path / "s", settings=settings)
    spec = plan_frames(settings)[0]
    raw = s.temp_stem(spec.id).with_suffix(".dng")
    raw.write_bytes(b"raw")
    s.commit_frame(spec, raw, spd=None)
    doc = json.loads(s.manifest_path.read_text())
    doc["frames"][0]["file"] = "frames/a\x00b.dng"
    s.manifest_path.write_text(json.dumps(doc))
    with pytest.raises(InputError, match="inside the session folder"):
        Session.open(tmp_path / "s")


def _sensitivities(tmp_path: Path) -> Path:
    from tunespec.core.datasets import load_camera

    path = tmp_path / "cam.json"
    write_sensitivity_json(load_camera(), path)
    return path


@pytest.mark.parametrize(
    ("value", "fragment"),
    [(-0.5, "value -0.5 outside"), (True, "got True"), (1e15, "value 1e+15 outside")],
)
def test_rawtoaces_json_refuses_negative_boolean_and_absurd_values(
    tmp_path, value, fragment
) -> None:
    good = _sensitivities(tmp_path)
    doc = json.loads(good.read_text())
    main_ = doc["spectral_data"]["data"]["main"]
    key = list(main_)[40]
    main_[key][1] = value
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    assert read_spectral(good, kind="sensitivity").values.max() > 0
    with pytest.raises(InputError) as info:
        read_spectral(bad, kind="sensitivity")
    assert f"spectral_data.data.main['{key}']" in str(info.value)
    assert fragment in str(info.value) and str(bad) in str(info.value)


def _meta_file(tmp_path: Path) -> tuple[Path, dict]:
    cam = load_led_set().select(("LED450", "LED540", "LED630"))
    cam = Spectra(cam.wavelength_nm, cam.values, ("R", "G", "B"))
    csv = tmp_path / "s.csv"
    n = 3 * cam.wavelength_nm.size
    rng = np.random.default_rng(0)
    a = rng.standard_normal((n, n)) * 1e-3
    write_sensitivities_csv(csv, cam, covariance=a @ a.T)
    return csv, json.loads(Path(f"{csv}.meta.json").read_text())


def _flip(doc: dict) -> None:
    doc["covariance"]["values"] = [
        [-v for v in row] for row in doc["covariance"]["values"]
    ]


def _bool(doc: dict) -> None:
    doc["covariance"]["values"][0][0] = True


def _absurd(doc: dict) -> None:
    doc["covariance"]["values"][3][3] = 1e15


def _not_psd(doc: dict) -> None:
    v = doc["covariance"]["values"]
    v[0][1] = v[1][0] = 10 * max(v[0][0], v[1][1])


@pytest.mark.parametrize(
    ("edit", "fragment"),
    [
        (_bool, "true/false"),
        (_flip, "negative variance"),
        (_absurd, "beyond any calibration"),
        (_not_psd, "not positive semi-definite"),
    ],
    ids=["boolean", "sign-flipped", "1e15", "not-psd"],
)
def test_meta_json_covariance_must_be_a_covariance(tmp_path, edit, fragment) -> None:
    csv, doc = _meta_file(tmp_path)
    assert read_sensitivity_meta(csv)["covariance"].shape[0] > 0
    bad = copy.deepcopy(doc)
    edit(bad)
    Path(f"{csv}.meta.json").write_text(json.dumps(bad))
    with pytest.raises(InputError) as info:
        read_sensitivity_meta(csv)
    assert fragment in str(info.value) and ".meta.json" in str(info.value)


def test_a_spectral_csv_row_with_an_extra_field_is_refused(tmp_path) -> None:
    path = tmp_path / "s.csv"
    write_spectra_csv(load_colorchecker_sg(), path)
    lines = path.read_text().splitlines()
    lines[7] += ",0.5"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError) as info:
        read_spectra_csv(path)
    assert info.value.line == 8 and "142 fields, expected 141" in str(info.value)
    # a trailing separator on every line is still fine
    path.write_text("\n".join(ln + "," for ln in lines[:7] + lines[8:]) + "\n")
    assert read_spectra_csv(path).values.shape[0] == 140


@pytest.mark.parametrize("value", ["nan", "inf", "-inf"])
def test_cgats_with_a_non_finite_spectral_range_keyword(tmp_path, value) -> None:
    from tunespec.core.io.cgats import read_cgats, ti3_table, write_cgats

    sg = load_colorchecker_sg()
    path = tmp_path / "x.ti3"
    write_cgats(ti3_table(sg.names, reflectance=sg), path)
    text = path.read_text()
    assert 'SPECTRAL_START_NM "380' in text
    path.write_text(
        text.replace('SPECTRAL_START_NM "380', f'SPECTRAL_START_NM "{value}', 1)
    )
    spectra = read_cgats(path).spectra()  # the field names give the wavelengths
    assert spectra is not None and spectra.wavelength_nm[0] == 380.0


def test_a_deep_key_path_in_an_error_is_cut() -> None:
    from tunespec.core.limits import loads_json

    key = "k" * 500
    with pytest.raises(InputError) as info:
        loads_json('{"' + key + '": [[[1e999]]]}')
    assert len(str(info.value)) < 200 and "non-finite" in str(info.value)


def test_a_negative_session_version_is_refused(tmp_path) -> None:
    from tunespec.core.io.session import CaptureSettings, Session

    settings = CaptureSettings(
        ("L1",), exposure_mode="fixed", exposures_s={"L1": (1.0,)}
    )
    s = Session.create(tmp_path / "s", settings=settings)
    doc = json.loads(s.manifest_path.read_text())
    doc["version"] = -1
    s.manifest_path.write_text(json.dumps(doc))
    with pytest.raises(InputError, match="bad session version -1"):
        Session.open(tmp_path / "s")


def test_sensitivities_off_their_side_files_grid_are_refused(tmp_path) -> None:
    """A CSV resampled by hand, its side file (covariance on 5 nm) copied along:
    ``estimate-image``'s loader refuses it in one line; on their own grid they load."""
    from tunespec.app.pipeline.image import _load_calibration
    from tunespec.core.plausibility import Implausible

    grid = Grid.parse("400:700:5")
    wl = grid.wavelength_nm
    values = np.stack([np.exp(-0.5 * ((wl - p) / 30.0) ** 2) for p in (600, 540, 450)])
    sens = Spectra(wl, 3.0 * values, ("R", "G", "B"), {"source": "sim"})
    write_sensitivities_csv(tmp_path / "s.csv", sens, 1e-6 * np.eye(3 * wl.size))
    _load_calibration(tmp_path / "s.csv", grid)
    coarse = sens.resample(Grid.parse("400:700:10"))
    write_spectra_csv(coarse, tmp_path / "t.csv")
    (tmp_path / "t.csv.meta.json").write_text(
        (tmp_path / "s.csv.meta.json").read_text()
    )
    with pytest.raises(Implausible, match=r"sensitivities at 400:700:10 nm, their "
                       r"calibration's covariance and LED corrections at 400:700:5 nm"):  # fmt: skip
        _load_calibration(tmp_path / "t.csv", grid)
