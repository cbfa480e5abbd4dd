"""Exports: rawtoaces JSON, Table 1/2 CSV, reflectance .ti3, the whole measurement."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from tests.tolerances import ATOL_ROUNDTRIP
from tunespec.core.colorimetry import lab_d50, reflectance_stats, xyz_d50
from tunespec.core.datasets import (
    load_camera,
    load_colorchecker_sg,
    load_led_set,
    read_rawtoaces_json,
    resource_path,
)
from tunespec.core.errors import InputError
from tunespec.core.forward_model import render_rgb
from tunespec.core.io.cgats import read_cgats
from tunespec.core.io.export import (
    EXPORT_NAMES,
    RAWTOACES_GRID,
    export_measurement,
    reflectance_ti3,
    sensitivity_rawtoaces_document,
    write_prediction_stats_csv,
    write_reflectance_stats_csv,
    write_sensitivity_json,
)
from tunespec.core.io.responses_csv import read_responses_csv
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.responses import Responses
from tunespec.core.spectra import Grid, Spectra

CREATED = "2026-01-02T03:04:05Z"
SHIPPED = "Canon_EOS_5D_Mark_III_380_780_5.json"

#: Table 1 as PredictionStats.as_dict() gives it (the paper's numbers).
TABLE1 = {
    "n_stimuli": 3080,
    "Red": {"mean": 0.0026, "max": 0.0326, "p95": 0.0108},
    "Green": {"mean": 0.0024, "max": 0.0332, "p95": 0.0112},
    "Blue": {"mean": 0.0021, "max": 0.0252, "p95": 0.0097},
    "RGB": {"mean": 0.0024, "max": 0.0305, "p95": 0.0106},
}


@pytest.fixture(scope="module")
def measurement() -> dict[str, object]:
    grid = Grid(380.0, 730.0, 10.0)
    sg = load_colorchecker_sg(grid).select(["A1", "B2", "C3", "D4", "E5", "N10"])
    leds = load_led_set(grid).select(["LED450", "LED540", "WHITE_COOL"])
    cam = load_camera(grid=grid)
    rgb = render_rgb(sg.values, leds.values, cam.values, grid.step_nm)
    rgb = rgb / rgb.max() * 0.8
    sat = np.zeros(rgb.shape[:2])
    sat[1, 2] = 0.03
    responses = Responses(
        sg.names, leds.names, rgb, 0.01 * rgb, np.full(rgb.shape[:2], 400.0), sat
    )
    rng = np.random.default_rng(0)
    est = sg.with_values(
        np.clip(sg.values + rng.normal(0, 0.01, sg.values.shape), 0, 1)
    )
    return {"sg": sg, "leds": leds, "cam": cam, "responses": responses, "est": est}


def test_rawtoaces_json_matches_the_shipped_schema(tmp_path: Path) -> None:
    shipped = resource_path("cameras", SHIPPED)
    cam = read_rawtoaces_json(shipped)
    path = write_sensitivity_json(
        cam,
        tmp_path / "cam.json",
        manufacturer="Canon",
        model="EOS 5D Mark III",
        normalize=False,
        unique_identifier="id-1",
        created=CREATED,
    )
    back = read_rawtoaces_json(path)
    np.testing.assert_array_equal(back.wavelength_nm, cam.wavelength_nm)
    np.testing.assert_allclose(back.values, cam.values, rtol=0, atol=ATOL_ROUNDTRIP)
    assert (
        back.meta["manufacturer"] == "Canon" and back.meta["model"] == "EOS 5D Mark III"
    )
    ours = json.loads(path.read_text())
    ref = json.loads(resource_path("cameras", "ARRI_D21_380_780_5.json").read_text())
    assert set(ours) == set(ref) == {"header", "spectral_data"}
    assert set(ours["header"]) == set(ref["header"])  # schema 1.0.0 header fields
    assert set(ours["spectral_data"]) == set(ref["spectral_data"])
    assert ours["header"]["schema_version"] == "1.0.0"
    assert ours["header"]["document_creation_date"] == CREATED
    assert ours["header"]["license"] == "CC-BY-4.0"  # required: never empty
    assert list(ours["spectral_data"]["data"]["main"])[:2] == ["380", "385"]


def test_rawtoaces_json_normalised_keeps_the_scale_in_the_comment() -> None:
    wl = np.array([400.0, 402.5, 405.0])
    s = Spectra(
        wl, [[1.0, 2.0, 4.0], [0.5, 0.5, 0.5], [8.0, 0.0, 1.0]], ("R", "G", "B")
    )
    doc = sensitivity_rawtoaces_document(
        s, unique_identifier="x", created=CREATED, grid=None
    )
    main = doc["spectral_data"]["data"]["main"]
    assert list(main) == ["400", "402.5", "405"]
    assert main["400"] == [0.125, 0.0625, 1.0]  # [1, 0.5, 8] / 8
    assert doc["header"]["comments"].endswith("multiply by 8.0 for the absolute scale")
    with pytest.raises(InputError, match="must be named R, G, B"):
        sensitivity_rawtoaces_document(s.with_values(s.values, ("X", "Y", "Z")))


def test_rawtoaces_json_is_on_the_grid_rawtoaces_reads() -> None:
    # rawtoaces' Spst::loadSpst exits unless there are 81 samples, 380-780 nm by 5.
    # An estimate on the working grid 380:730:10 is interpolated onto it and set to
    # 0 beyond 730 nm, which the comments say.
    s = read_rawtoaces_json(resource_path("cameras", SHIPPED)).resample(
        Grid.parse("380:730:10")
    )
    doc = sensitivity_rawtoaces_document(s, normalize=False, created=CREATED)
    main = doc["spectral_data"]["data"]["main"]
    assert list(main) == [str(w) for w in range(380, 781, 5)]
    assert main["390"] == s.values[:, 1].tolist()  # on both grids: as it was
    np.testing.assert_allclose(
        main["395"],
        0.5 * (s.values[:, 1] + s.values[:, 2]),
        rtol=0,
        atol=ATOL_ROUNDTRIP,
    )
    assert main["735"] == main["780"] == [0.0, 0.0, 0.0]
    assert "set to 0 at 735-780 nm (not estimated)" in doc["header"]["comments"]
    full = read_rawtoaces_json(resource_path("cameras", SHIPPED))
    doc = sensitivity_rawtoaces_document(full, normalize=False, created=CREATED)
    assert "set to 0" not in doc["header"]["comments"]
    assert list(doc["spectral_data"]["data"]["main"].values()) == full.values.T.tolist()


def test_colour_science_has_no_rawtoaces_json_reader() -> None:
    # Checked so the docs stay true: colour 0.4.x reads the 190 training patches
    # (CSV) but not the rawtoaces-data camera JSON; update write_sensitivity_json's
    # docstring and add a cross-check here if that changes. (Imported as the core
    # does: colour-science changes numpy's print options on import.)
    with np.printoptions():
        import colour

    names = [
        n for n in dir(colour.io) if "json" in n.lower() or "rawtoaces" in n.lower()
    ]
    assert names == []


def test_table1_csv(tmp_path: Path) -> None:
    path = write_prediction_stats_csv(TABLE1, tmp_path / "t1.csv")
    rows = list(csv.reader(path.read_text().splitlines()))
    assert rows[0] == ["patches", "channel", "mean", "max", "p95", "n_stimuli"]
    assert rows[4] == ["fitted", "RGB", "0.0024", "0.0305", "0.0106", "3080"]
    assert [r[1] for r in rows[1:]] == ["Red", "Green", "Blue", "RGB"]
    # A calibration report (as 'tunespec calibrate --stats' writes it): both sets.
    doc = {"training": TABLE1, "held_out": {**TABLE1, "n_stimuli": 616}}
    rows = list(
        csv.reader(
            write_prediction_stats_csv(doc, tmp_path / "c.csv").read_text().splitlines()
        )
    )
    assert [r[0] for r in rows[1:]] == ["fitted"] * 4 + ["held_out"] * 4
    assert rows[8] == ["held_out", "RGB", "0.0024", "0.0305", "0.0106", "616"]
    with pytest.raises(InputError, match="not Table 1"):
        write_prediction_stats_csv({"n_stimuli": 3}, tmp_path / "bad.csv")


def test_table1_csv_from_prediction_stats(tmp_path: Path) -> None:
    stats_mod = pytest.importorskip("tunespec.core.stats")
    s = stats_mod.prediction_stats([[0.5, 0.5, 0.5]], [[0.5, 0.5, 0.53]])
    rows = list(
        csv.reader(
            write_prediction_stats_csv(s, tmp_path / "t1.csv").read_text().splitlines()
        )
    )
    assert [float(x) for x in rows[3][2:5]] == pytest.approx(
        [0.03, 0.03, 0.03], abs=1e-15
    )
    assert rows[1][2:] == ["0.0", "0.0", "0.0", "1"]


def test_table2_csv_is_exact(tmp_path: Path, measurement: dict[str, object]) -> None:
    stats = reflectance_stats(measurement["est"], measurement["sg"])  # type: ignore[arg-type]
    path = write_reflectance_stats_csv(stats, tmp_path / "t2.csv")
    rows = list(csv.reader(path.read_text().splitlines()))
    assert rows[0] == ["patch", "delta_e00_d50", "spectral_rms"]
    assert [r[0] for r in rows[1:]] == [*stats.names, "average", "max"]
    np.testing.assert_array_equal([float(r[1]) for r in rows[1:7]], stats.delta_e00)
    np.testing.assert_array_equal([float(r[2]) for r in rows[1:7]], stats.spectral_rms)
    assert float(rows[7][1]) == stats.mean_delta_e00
    assert float(rows[8][2]) == stats.max_spectral_rms


def test_reflectance_ti3(measurement: dict[str, object]) -> None:
    est: Spectra = measurement["est"]  # type: ignore[assignment]
    responses: Responses = measurement["responses"]  # type: ignore[assignment]
    t = reflectance_ti3(est, responses=responses, illuminant="LED540", created=CREATED)
    np.testing.assert_array_equal(t.xyz, xyz_d50(est))
    np.testing.assert_array_equal(t.lab, lab_d50(est))
    np.testing.assert_array_equal(
        t.column("RGB_G", percent=True), responses.rgb[:, 1, 1]
    )
    assert t.keywords["TUNESPEC_RGB_ILLUMINANT"] == "LED540"
    assert t.keywords["ILLUMINATION_NAME"] == "D50"
    assert t.keywords["ORIGINATOR"].startswith("TuneSpec ")
    with pytest.raises(InputError, match="several illuminants"):
        reflectance_ti3(est, responses=responses)
    with pytest.raises(InputError, match="'LED999' not in the responses"):
        reflectance_ti3(est, responses=responses, illuminant="LED999")
    with pytest.raises(InputError, match="have no responses: N10"):
        reflectance_ti3(
            est, responses=responses.subset(list(est.names[:5])), illuminant="LED540"
        )
    assert not any(
        f.startswith("SPEC_") for f in reflectance_ti3(est, spectra=False).fields
    )


def test_export_measurement_writes_everything_readable(
    tmp_path: Path, measurement: dict[str, object]
) -> None:
    m = measurement
    est: Spectra = m["est"]  # type: ignore[assignment]
    table2 = reflectance_stats(est, m["sg"])  # type: ignore[arg-type]
    paths = export_measurement(
        tmp_path / "out",
        sensitivity=m["cam"],  # type: ignore[arg-type]
        reflectance=est,
        responses=m["responses"],  # type: ignore[arg-type]
        table1=TABLE1,
        table2=table2,
        reference=m["sg"],  # type: ignore[arg-type]
        illuminants=m["leds"],  # type: ignore[arg-type]
        ti3_illuminant="WHITE_COOL",
        manufacturer="Canon",
        model="EOS 5D Mark III",
        created=CREATED,
    )
    assert list(paths) == list(EXPORT_NAMES)
    assert all(p.is_file() and p.name == EXPORT_NAMES[k] for k, p in paths.items())
    cam: Spectra = m["cam"]  # type: ignore[assignment]
    np.testing.assert_array_equal(
        read_spectra_csv(paths["sensitivities_csv"]).values, cam.values
    )
    js = read_rawtoaces_json(paths["sensitivities_json"])
    assert js.wavelength_nm.tolist() == RAWTOACES_GRID.wavelength_nm.tolist()
    np.testing.assert_allclose(
        js.resample(Grid(380.0, 730.0, 10.0)).values,
        cam.values / cam.values.max(),
        rtol=1e-15,
        atol=0,
    )
    np.testing.assert_array_equal(
        read_spectra_csv(paths["reflectances_csv"]).values, est.values
    )
    ti3 = read_cgats(paths["reflectances_ti3"])
    np.testing.assert_array_equal(ti3.spectra().values, est.values)
    assert (
        ti3.rgb is not None and ti3.keywords["TUNESPEC_RGB_ILLUMINANT"] == "WHITE_COOL"
    )
    ref = read_cgats(paths["reference_ti3"])
    assert ref.rgb is None and ref.keywords["DESCRIPTOR"] == "Reference reflectances"
    resp = read_responses_csv(paths["responses_csv"])
    np.testing.assert_array_equal(resp.rgb, m["responses"].rgb)  # type: ignore[attr-defined]
    np.testing.assert_array_equal(resp.saturated, m["responses"].saturated)  # type: ignore[attr-defined]
    assert read_spectra_csv(paths["illuminants_csv"]).names == m["leds"].names  # type: ignore[attr-defined]
    assert (
        paths["table1_csv"].read_text().splitlines()[1]
        == "fitted,Red,0.0026,0.0326,0.0108,3080"
    )
    assert len(paths["table2_csv"].read_text().splitlines()) == 1 + 6 + 2


def test_export_measurement_only_what_is_given(
    tmp_path: Path, measurement: dict[str, object]
) -> None:
    paths = export_measurement(
        tmp_path, reflectance=measurement["est"], responses=measurement["responses"]
    )  # type: ignore[arg-type]
    assert set(paths) == {"reflectances_csv", "reflectances_ti3", "responses_csv"}
    # Several illuminants and none chosen: the .ti3 has no RGB rather than failing.
    assert read_cgats(paths["reflectances_ti3"]).rgb is None
