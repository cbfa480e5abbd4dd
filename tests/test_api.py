"""The Python API (``tunespec.app.api``) gives the command line's answers.

- ``docs/api-example.ipynb``, its code cells run in order on a fresh demo folder,
  gives the demo's Table 2 exactly, and the ``estimate`` + ``evaluate`` commands on
  the same files give the same numbers (slow: runs the demo once).
- colour-science objects cross the boundary both ways, checked as files are.
- Inputs are refused as the command line refuses them.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from tunespec.app import api
from tunespec.app.cli import main
from tunespec.core.datasets import load_camera, load_colorchecker_sg, load_led_set
from tunespec.core.errors import InputError
from tunespec.core.io.responses_csv import write_responses_csv
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.io.spectral_csv import write_spectra_csv
from tunespec.core.responses import Responses
from tunespec.core.spectra import Grid, Spectra

NOTEBOOK = Path(__file__).resolve().parents[1] / "docs" / "api-example.ipynb"
GRID = Grid(400.0, 700.0, 10.0)


def _run_notebook(cwd: Path, monkeypatch) -> dict:
    """The notebook's code cells executed in order in one namespace, in ``cwd``."""
    nb = json.loads(NOTEBOOK.read_text(encoding="utf-8"))
    assert nb["nbformat"] == 4
    monkeypatch.chdir(cwd)
    ns: dict = {"__name__": "__notebook__"}
    for cell in nb["cells"]:
        if cell["cell_type"] == "code":
            exec(compile("".join(cell["source"]), str(NOTEBOOK), "exec"), ns)
    return ns


def _leaves(doc: dict, prefix: str = "") -> dict[str, float]:
    """A nested document's numbers by path."""
    out: dict[str, float] = {}
    for k, v in doc.items():
        out |= _leaves(v, f"{prefix}{k}/") if isinstance(v, dict) else {prefix + k: v}
    return out


def _flat(doc: dict) -> dict[str, float]:
    return {f"{p}/{k}": v for p, d in doc.items() for k, v in d.items()}


@pytest.fixture(scope="module")
def demo_root(tmp_path_factory) -> Path:
    """A fresh ``tunespec demo --out demo`` (in the folder returned)."""
    root = tmp_path_factory.mktemp("api_demo")
    assert main(["demo", "--out", str(root / "demo"), "--no-report", "-q"]) == 0
    return root


@pytest.mark.slow
def test_the_notebook_gives_the_clis_table2_exactly(
    demo_root, tmp_path, monkeypatch
) -> None:
    demo = demo_root / "demo"
    ns = _run_notebook(demo_root, monkeypatch)
    got = ns["table2"].as_dict()
    # the demo's own Table 2 (summary.json and the report's table2 CSV): the same
    # numbers to 1e-12 (with numpy 2.4.6 the two paths' CIEDE2000 differ by up to
    # 1.4e-14, the code of 5f4c3f6 too: summation order, not another computation)
    summary = json.loads((demo / "summary.json").read_text())["table2"]
    mine = _leaves({k: got[k] for k in summary})
    assert mine == pytest.approx(_leaves(summary), abs=1e-12)
    with (demo / "export" / "table2_reflectance.csv").open(newline="") as fh:
        rows = {r["patch"]: r for r in csv.DictReader(fh)}
    for patch, stats in got["patches"].items():
        assert float(rows[patch]["delta_e00_d50"]) == pytest.approx(
            stats["delta_e00"], abs=1e-12
        ), patch
        assert float(rows[patch]["spectral_rms"]) == stats["spectral_rms"], patch
    # the command line's estimate + evaluate on the same files: the same numbers
    export = demo / "export"
    out, stats_json = tmp_path / "cli_reflectances.csv", tmp_path / "table2.json"
    assert main(["estimate", "--responses", str(export / "responses.csv"),
                 "--illuminants", str(export / "illuminants.csv"),
                 "--sensitivities", str(export / "sensitivities.csv"),
                 "--grid", "400:700:5", "-o", str(out), "-q"]) == 0  # fmt: skip
    assert main(["evaluate", "--estimated", str(out),
                 "--reference", str(export / "reference_reflectances.csv"),
                 "--stats", str(stats_json), "-q"]) == 0  # fmt: skip
    cli = json.loads(stats_json.read_text())
    # the reflectances bit for bit, and api.evaluate is `evaluate` bit for bit
    np.testing.assert_array_equal(
        read_spectra_csv(out).values, ns["result"].reflectance.values
    )
    # api.evaluate is `evaluate`: on the same files, the same Table 2 bit for bit
    from_files = api.evaluate(out, export / "reference_reflectances.csv").as_dict()
    assert {k: from_files[k] for k in ("patches", "average", "max")} == {
        k: cli[k] for k in ("patches", "average", "max")
    }
    # the CSV reader hands back a Fortran-ordered array, which changes the BLAS
    # summation order of the colorimetry: CIEDE2000 from the file may differ from
    # the in-memory estimate's in the last bits of a double (as tests/test_demo_chain)
    assert _flat(cli["patches"]) == pytest.approx(_flat(got["patches"]), rel=1e-12)
    assert ns["again"].as_dict()["average"] == got["average"]
    assert ns["result"].reflectance.names == tuple(got["patches"])
    # and the mean is the demo's 0.07, not the 0.2-0.4 of uncorrected spectra
    assert got["average"]["delta_e00"] < 0.1


@pytest.mark.slow
def test_calibrate_gives_the_demos_table1_and_sensitivities(
    demo_root, tmp_path
) -> None:
    """The chart's exported files through api.calibrate: the demo's Table 1 exactly
    and, saved, its sensitivities CSV byte for byte (as ``tunespec calibrate``)."""
    demo = demo_root / "demo"
    export = demo / "export"
    res = api.calibrate(
        export / "chart_responses.csv",
        export / "chart_illuminants.csv",
        export / "chart_camera.ti3",
    )
    summary = json.loads((demo / "summary.json").read_text())
    assert res.table1.as_dict() == summary["table1"]
    saved = res.calibration.save(tmp_path / "sensitivities.csv")
    assert saved.read_bytes() == (export / "sensitivities.csv").read_bytes()
    back = api.load_calibration(saved)
    assert back.led_correction == res.calibration.led_correction


@pytest.mark.slow
def test_estimate_images_is_the_estimate_image_command(demo_root, tmp_path) -> None:
    tifffile = pytest.importorskip("tifffile")
    demo = demo_root / "demo"
    sens = demo / "export" / "sensitivities.csv"
    assert main(["estimate-image", str(demo / "sample"), "--sensitivities", str(sens),
                 "--out", str(tmp_path / "cli"), "--formats", "tiff",
                 "--scheduler", "sync", "-q"]) == 0  # fmt: skip
    from tunespec.app.pipeline.image import ImageSettings

    got = api.estimate_images(
        demo / "sample",
        api.load_calibration(sens),
        tmp_path / "api",
        settings=ImageSettings(formats=("tiff",)),
    )
    assert got.out_dir == tmp_path / "api"
    for name in ("xyz.tif", "lab.tif", "uncertainty.tif"):
        np.testing.assert_array_equal(
            tifffile.imread(tmp_path / "api" / name),
            tifffile.imread(tmp_path / "cli" / name),
        )
    assert (
        got.provenance["shape"]
        == json.loads((tmp_path / "cli" / "provenance.json").read_text())["shape"]
    )


@pytest.mark.slow
def test_extract_is_the_extract_command(tmp_path) -> None:
    """The shipped DNG of a ColorChecker: the same responses as ``tunespec extract``
    writes, the reference given as colour-science spectra or the layout's own."""
    from tunespec.core.datasets import resource_path
    from tunespec.core.io.responses_csv import read_responses_csv
    from tunespec.core.io.spectral import read_spectral

    dng = Path(__file__).parent / "data" / "tinydng_colorchart.dng"
    out = tmp_path / "responses.csv"
    assert main(["extract", str(dng), "--layout", "colorchecker_24", "-o", str(out),
                 "-q"]) == 0  # fmt: skip
    cli = read_responses_csv(out)
    ex = api.extract(dng, "colorchecker_24")
    assert ex.check.ok and ex.responses.patches == cli.patches
    np.testing.assert_allclose(ex.responses.rgb, cli.rgb, rtol=1e-9)
    reference = read_spectral(resource_path("charts", "colorchecker_24.csv"))
    with_colour = api.extract(
        dng, "colorchecker_24", reflectances=api.to_colour(reference)
    )
    np.testing.assert_array_equal(with_colour.responses.rgb, ex.responses.rgb)


# -- colour-science at the boundary -----------------------------------------------------
def test_to_colour_and_back_keeps_every_value() -> None:
    sg = load_colorchecker_sg(GRID).select(["A1", "B2", "C3"])
    msds = api.to_colour(sg)
    assert list(msds.labels) == ["A1", "B2", "C3"]
    np.testing.assert_array_equal(msds.wavelengths, sg.wavelength_nm)
    np.testing.assert_array_equal(msds.values.T, sg.values)
    back = api.from_colour(msds, kind="reflectance")
    assert back.names == sg.names
    np.testing.assert_array_equal(back.values, sg.values)
    # one SpectralDistribution, and a list of them
    sds = msds.to_sds()
    one = api.from_colour(sds[1])
    assert one.names == ("B2",)
    np.testing.assert_array_equal(one.values[0], sg.values[1])
    np.testing.assert_array_equal(api.from_colour(sds).values, sg.values)


def test_from_colour_converts_percent_and_refuses_what_a_file_could_not_hold() -> None:
    from colour import SpectralDistribution

    wl = np.arange(400.0, 701.0, 10.0)
    percent = SpectralDistribution(np.full(wl.size, 45.0), wl, name="grey")
    assert api.from_colour(percent, kind="reflectance").values.max() == pytest.approx(
        0.45
    )
    bad = SpectralDistribution(np.where(wl == 500.0, -0.2, 0.5), wl, name="dip")
    with pytest.raises(InputError, match=r"prior: values must lie in \[0, "):
        api.from_colour(bad, what="prior")
    with pytest.raises(InputError, match="SpectralDistribution"):
        api.from_colour({"A1": [0.1, 0.2]})


# -- refused at the boundary ----------------------------------------------------------------
@pytest.fixture
def files(tmp_path) -> dict[str, Path]:
    """Sensitivities (no side file), LED spectra and responses of three patches."""
    cam = load_camera(grid=GRID)
    sens = Spectra(cam.wavelength_nm, cam.values * 0.01, cam.names, {})
    leds = load_led_set(GRID)
    rgb = np.full((3, len(leds.names), 3), 0.2)
    resp = Responses(("A1", "B2", "C3"), leds.names, rgb, np.full_like(rgb, 1e-3))
    paths = {
        "sens": tmp_path / "sens.csv",
        "leds": tmp_path / "leds.csv",
        "resp": tmp_path / "responses.csv",
    }
    write_spectra_csv(sens, paths["sens"])
    write_spectra_csv(leds, paths["leds"])
    write_responses_csv(resp, paths["resp"])
    return paths


def test_estimate_refuses_sensitivities_without_their_side_file(files) -> None:
    with pytest.raises(InputError, match=r"sens\.csv\.meta\.json"):
        api.estimate(files["resp"], files["leds"], files["sens"])


def test_responses_under_illuminants_not_given_are_refused(files) -> None:
    leds = load_led_set(GRID)
    few = leds.select(leds.names[:3])
    with pytest.raises(InputError, match="not in the illuminants"):
        api.read_stimuli(files["resp"], few)


def test_an_unknown_method_is_refused_before_anything_runs(files) -> None:
    with pytest.raises(InputError, match="unknown method 'magic'"):
        api.calibrate(files["resp"], files["leds"], method="magic")


def test_load_calibration_refuses_curves_off_their_covariance_grid(tmp_path) -> None:
    """As ``estimate`` refuses them: a 5 nm CSV with the side file of a 10 nm
    calibration; ``force=True`` accepts it with a warning."""
    from tunespec.core.calibration import Calibration
    from tunespec.core.io.export import sensitivity_meta_path, write_sensitivities_csv
    from tunespec.core.plausibility import Implausible

    cam = load_camera(grid=GRID)
    sens = Spectra(cam.wavelength_nm, cam.values * 0.01, cam.names, {})
    n = 3 * cam.wavelength_nm.size
    write_sensitivities_csv(tmp_path / "s.csv", sens, 1e-8 * np.eye(n))
    write_spectra_csv(sens.resample(Grid(400.0, 700.0, 5.0)), tmp_path / "f.csv")
    sensitivity_meta_path(tmp_path / "f.csv").write_text(
        sensitivity_meta_path(tmp_path / "s.csv").read_text()
    )
    with pytest.raises(Implausible, match=r"force=True to accept$"):
        api.load_calibration(tmp_path / "f.csv")
    with pytest.warns(UserWarning, match="accepted with force=True"):
        cal = api.load_calibration(tmp_path / "f.csv", force=True)
    assert isinstance(cal, Calibration) and cal.covariance is not None
