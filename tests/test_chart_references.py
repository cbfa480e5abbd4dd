"""Every chart a lab owns, as data (issue 25): reference files from other tools,
name maps, shipped layouts by name, layouts that ship no reference data."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tunespec.core.errors import InputError
from tunespec.core.io.name_map import read_name_map, rename_spectra
from tunespec.core.io.spectral import read_spectral
from tunespec.core.layout import TargetLayout, shipped_layout_names
from tunespec.core.spectra import Spectra

DNG = Path(__file__).parent / "data" / "tinydng_colorchart.dng"
NAME_MAP = (
    Path(__file__).parents[1]
    / "resources"
    / "charts"
    / "colorchecker_24_colour_science_names.csv"
)


def write_txt2ti3_like(refl: Spectra, path: Path, *, ids_only: bool = False) -> Path:
    """A CGATS reference as Argyll's txt2ti3 writes it: SAMPLE_ID counts 1..n, the
    patch is in SAMPLE_LOC, spectra in percent (SPEC_nnn)."""
    wl = refl.wavelength_nm
    fields = ["SAMPLE_ID", *([] if ids_only else ["SAMPLE_LOC"])]
    fields += [f"SPEC_{round(float(w)):03d}" for w in wl]
    lines = [
        "CTI3",
        "",
        'DESCRIPTOR "reference"',
        f'SPECTRAL_BANDS "{len(wl)}"',
        f'SPECTRAL_START_NM "{wl[0]:.6f}"',
        f'SPECTRAL_END_NM "{wl[-1]:.6f}"',
        f"NUMBER_OF_FIELDS {len(fields)}",
        "BEGIN_DATA_FORMAT",
        " ".join(fields),
        "END_DATA_FORMAT",
        f"NUMBER_OF_SETS {len(refl.names)}",
        "BEGIN_DATA",
    ]
    for k, (name, v) in enumerate(zip(refl.names, refl.values, strict=True)):
        cells = [str(k + 1), *([] if ids_only else [f'"{name}"'])]
        lines.append(" ".join(cells + [f"{100 * x:.4f}" for x in v]))
    lines.append("END_DATA")
    path.write_text("\n".join(lines) + "\n")
    return path


def _cc24() -> Spectra:
    from tunespec.core.datasets import resource_path

    return read_spectral(resource_path("charts", "colorchecker_24.csv"))


def test_txt2ti3_reference_matches_by_sample_loc(tmp_path) -> None:
    refl = _cc24()
    got = read_spectral(
        write_txt2ti3_like(refl, tmp_path / "r.ti3"), kind="reflectance"
    )
    assert got.names == refl.names
    np.testing.assert_allclose(got.values, refl.values, atol=1e-6)
    # without SAMPLE_LOC the sets keep their numbers
    only = read_spectral(write_txt2ti3_like(refl, tmp_path / "i.ti3", ids_only=True))
    assert only.names[:2] == ("1", "2")


def _colour_science_csv(path: Path) -> Path:
    import colour

    cc = colour.SDS_COLOURCHECKERS["ColorChecker N Ohta"]
    wl = np.arange(380, 781, 5)
    rows = ["wavelength_nm," + ",".join(cc)]
    rows += [f"{w}," + ",".join(repr(float(cc[k][w])) for k in cc) for w in wl]
    path.write_text("\n".join(rows) + "\n")
    return path


def test_colour_science_names_through_the_shipped_map(tmp_path) -> None:
    cs = read_spectral(_colour_science_csv(tmp_path / "cs.csv"), kind="reflectance")
    assert cs.names[0] == "dark skin"
    mapped = rename_spectra(cs, read_name_map(NAME_MAP))
    assert mapped.names == TargetLayout.load("colorchecker_24").patch_names
    # the white (D1) is the brightest, the black (D6) the darkest
    mean = mapped.values.mean(axis=1)
    assert mapped.names[int(np.argmax(mean))] == "D1"
    assert mapped.names[int(np.argmin(mean))] == "D6"
    with pytest.raises(InputError, match="none of the names"):
        rename_spectra(_cc24(), read_name_map(NAME_MAP))


def test_extract_with_colour_science_reference_and_name_map(tmp_path, capsys) -> None:
    from tunespec.app.cli import main

    cs = _colour_science_csv(tmp_path / "cs.csv")
    args = ["extract", str(DNG), "--layout", "colorchecker_24"]
    args += ["-o", str(tmp_path / "p.csv"), "--reflectances", str(cs)]
    assert main([*args, "--names", str(NAME_MAP)]) == 0
    out = capsys.readouterr().out
    assert "check: ok" in out and "y_correlation 0.99" in out


@pytest.mark.parametrize(
    "body",
    ["wavelength_nm,R,G,B\n400,-2e-19,0.1,0.2\n410,0.5,1e-13,0.3\n"],
)
def test_round_off_below_1e_12_reads_as_zero(tmp_path, body) -> None:
    p = tmp_path / "cam.csv"
    p.write_text(body)
    s = read_spectral(p, kind="sensitivity")
    assert s.values.min() == 0.0
    p.write_text(body.replace("-2e-19", "-2e-6"))
    with pytest.raises(InputError, match="negative"):
        read_spectral(p, kind="sensitivity")


def test_shipped_layouts_by_name_and_unknown_names_listed() -> None:
    assert {"colorchecker_24", "colorchecker_passport", "it8_7_2"} <= set(
        shipped_layout_names()
    )
    assert TargetLayout.load("colorchecker_passport").n_patches == 50
    with pytest.raises(InputError, match="colorchecker_24, colorchecker_passport"):
        TargetLayout.load("colorchecker_25")


def test_layout_without_shipped_data_asks_for_reflectances() -> None:
    from tunespec.devices.registry import layout_reflectances

    with pytest.raises(InputError) as err:
        layout_reflectances(TargetLayout.load("it8_7_2"))
    text = str(err.value)
    assert "--reflectances" in text and "batch-specific" in text and "\n" not in text
    # the Passport names the ColorChecker data of its classic panel
    refl = layout_reflectances(TargetLayout.load("colorchecker_passport"))
    assert refl.names[0] == "A1" and len(refl.names) == 24


@pytest.mark.slow
@pytest.mark.parametrize("chart", ["colorchecker_passport", "it8_7_2"])
def test_chart_calibrates_end_to_end_with_a_cgats_reference(tmp_path, chart) -> None:
    """The bench renders the chart; its reference comes as a txt2ti3-like CGATS
    file (patch names in SAMPLE_LOC); process (with the extraction check) and
    calibrate recover the simulated camera."""
    from tunespec.app.pipeline.extract import reference_xyz
    from tunespec.app.pipeline.steps import calibrate, capture_target, process
    from tunespec.core.spectra import CALIBRATION_GRID, DEFAULT_GRID
    from tunespec.devices.registry import open_bench
    from tunespec.devices.sim.scene import it8_bench_reflectances

    layout = TargetLayout.load(chart)
    truth_refl = it8_bench_reflectances(layout.patch_names, DEFAULT_GRID, seed=5)
    cgats = write_txt2ti3_like(truth_refl, tmp_path / "ref.ti3")
    refl = read_spectral(cgats, kind="reflectance")
    assert refl.names == layout.patch_names
    with open_bench("sim", None, layout=layout, reflectances=refl, seed=3) as bench:
        session, _ = capture_target(bench, tmp_path / chart, layout)
        truth = bench.truth
    processed = process(session, reference_xyz=reference_xyz(layout, refl))
    assert processed.check is not None and processed.check.ok
    assert processed.check.metrics["colour_residual"] < 0.05
    cal = calibrate(processed, refl)
    true = truth["absolute_sensitivity"].resample(CALIBRATION_GRID).values
    est = cal.sensitivity.values
    scale = float(np.sum(est * true) / np.sum(true * true))
    assert np.sqrt(np.mean((est - scale * true) ** 2)) / (scale * true.max()) < 0.08
