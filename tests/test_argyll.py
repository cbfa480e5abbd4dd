"""ArgyllCMS reads our CGATS files and computes the same colorimetry; the export CLI.

Runs ArgyllCMS's ``spec2cie`` (spectral .ti3 -> XYZ/L*a*b*) and ``colverify``
(CIEDE2000 between two .ti3 files) on files written by ``tunespec.core`` and by
``tunespec export-cgats``. Those tests are skipped when the Argyll binaries are not on
PATH (``apt-get install argyll``); the CLI tests run everywhere.

What was measured (ArgyllCMS 2.3.1, ColorChecker SG reflectances, CIEDE2000 between
Argyll's L*a*b* and ours, max over 140 patches):

=============  ========  ===================================================
grid           max dE00  why
=============  ========  ===================================================
380:730:10      0.0009   both integrate the 10 nm data the same way (ASTM
                         E308 Table 6 weights ~ Argyll's interpolation)
380:730:1       0.0009   both sum 1 nm products
380:730:5       0.0009   Argyll interpolates 5 nm data linearly to 1 nm;
                         so does core.colorimetry (colour's own 5 nm ASTM
                         E308 sum of the 5 nm samples differs: 0.053).
380:720:20      0.014    (not asserted) Argyll's 20 nm rule is neither
                         the ASTM 20 nm table nor 1 nm interpolation (0.78).
=============  ========  ===================================================

``colverify`` on two of our files (XYZ given) reproduces our L*a*b* and CIEDE2000 to
its print precision (6 decimals).
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from tunespec.app.cli import export_cmds
from tunespec.core.calibration import correct_spd_shift
from tunespec.core.colorimetry import delta_e_2000, lab_d50, reflectance_stats, xyz_d50
from tunespec.core.datasets import (
    load_camera,
    load_colorchecker_sg,
    load_led_set,
    read_rawtoaces_json,
)
from tunespec.core.errors import InputError
from tunespec.core.forward_model import render_rgb
from tunespec.core.io.cgats import read_cgats, ti3_table, write_cgats
from tunespec.core.io.export import (
    export_measurement,
    reflectance_ti3,
    sensitivity_meta_path,
)
from tunespec.core.io.responses_csv import read_responses_csv, write_responses_csv
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.io.spectral_csv import write_spectra_csv
from tunespec.core.responses import Responses
from tunespec.core.spectra import Grid, Spectra

requires_argyll = pytest.mark.skipif(
    shutil.which("spec2cie") is None or shutil.which("colverify") is None,
    reason="ArgyllCMS not on PATH (spec2cie, colverify): apt-get install argyll",
)

#: Argyll's L*a*b* vs ours (both integrate the linear interpolation at 1 nm).
DE00_ARGYLL = 0.005
#: colverify prints six decimals.
ATOL_PRINTED = 2e-6

CREATED = "2026-01-02T03:04:05+00:00"


def _run(*args: str | Path) -> str:
    done = subprocess.run(
        [str(a) for a in args], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr + done.stdout
    return done.stdout


def _spec2cie(
    tmp_path: Path, spectra: Spectra, *, rgb: bool
) -> tuple[np.ndarray, np.ndarray]:
    """Our L*a*b* (written into the file) and Argyll's (recomputed from the spectra)."""
    ours = ti3_table(
        spectra.names,
        reflectance=spectra,
        rgb=np.full((len(spectra), 3), 0.5) if rgb else None,
        xyz=xyz_d50(spectra),
        lab=lab_d50(spectra),
        created=CREATED,
    )
    src = write_cgats(ours, tmp_path / "ours.ti3")
    out = tmp_path / "argyll.ti3"
    _run("spec2cie", "-n", "-i", "D50", "-o", "1931_2", src, out)
    argyll = read_cgats(out)  # Argyll's output, read by our reader
    assert argyll.sample_names == spectra.names
    return ours.lab, argyll.lab


@requires_argyll
@pytest.mark.parametrize(("step_nm", "rgb"), [(5.0, True), (10.0, True), (1.0, False)])
def test_spec2cie_lab_equals_ours(tmp_path: Path, step_nm: float, rgb: bool) -> None:
    """Includes the 5 nm working grid, where colour's own 5 nm ASTM E308 sum differs
    from Argyll by up to 0.05 dE00 (which is why core.colorimetry integrates at 1 nm).
    """
    sg = load_colorchecker_sg(Grid(380.0, 730.0, step_nm))
    ours, argyll = _spec2cie(tmp_path, sg, rgb=rgb)
    de = delta_e_2000(ours, argyll)
    assert de.max() < DE00_ARGYLL, de.max()


@requires_argyll
def test_argyll_rejects_integer_spectral_columns(tmp_path: Path) -> None:
    # Why every number is written with a decimal point.
    sg = load_colorchecker_sg(Grid(400.0, 700.0, 10.0)).select(["A1", "B2"])
    text = write_cgats(
        ti3_table(sg.names, reflectance=sg, created=CREATED), tmp_path / "a.ti3"
    )
    lines = text.read_text().splitlines()
    data = lines.index("BEGIN_DATA") + 1
    for k in (data, data + 1):  # SPEC_400 = 50 in both rows, as an integer
        cells = lines[k].split()
        cells[2] = "50"
        lines[k] = " ".join(cells)
    bad = tmp_path / "integer.ti3"
    bad.write_text("\n".join(lines) + "\n")
    done = subprocess.run(
        ["spec2cie", str(bad), str(tmp_path / "x.ti3")], capture_output=True, text=True
    )
    assert done.returncode != 0
    assert "SPEC_400 is wrong type" in done.stderr + done.stdout
    _run("spec2cie", text, tmp_path / "y.ti3")  # ours is accepted


_COLVERIFY_ROW = re.compile(
    r"^(\S+):\s+(\S+) (\S+) (\S+) <=> (\S+) (\S+) (\S+)\s+de (\S+)\s*$", re.M
)


ARGYLL_REF = Path("/usr/share/color/argyll/ref")


@pytest.mark.skipif(
    not ARGYLL_REF.is_dir(), reason="ArgyllCMS reference files not installed"
)
def test_reads_argyll_reference_files() -> None:
    # Argyll's own chart files: .ti1/.ti2/.cie, tabs, comments, KEYWORD lines, and
    # two (ColorChecker.ti2, FograStrip3.ti1) whose NUMBER_OF_FIELDS is one more than
    # their format list, which Argyll accepts.
    files = sorted(
        p for p in ARGYLL_REF.iterdir() if p.suffix in (".ti1", ".ti2", ".cie")
    )
    assert files
    for path in files:
        t = read_cgats(path)
        assert len(t) > 0 and len(t.sample_names) == len(t)
    cc = read_cgats(ARGYLL_REF / "ColorChecker.ti2")
    assert len(cc) == 24 and cc.xyz is not None and cc.xyz.shape == (24, 3)


@requires_argyll
def test_colverify_reproduces_our_delta_e(tmp_path: Path) -> None:
    sg = load_colorchecker_sg()
    rng = np.random.default_rng(0)
    est = sg.with_values(
        np.clip(sg.values + rng.normal(0, 0.01, sg.values.shape), 0, 1)
    )
    ref_path = write_cgats(reflectance_ti3(sg, created=CREATED), tmp_path / "ref.ti3")
    est_path = write_cgats(reflectance_ti3(est, created=CREATED), tmp_path / "est.ti3")
    out = _run("colverify", "-v", "2", "-k", ref_path, est_path)
    rows = _COLVERIFY_ROW.findall(out)
    assert len(rows) == len(sg)
    idx = [sg.names.index(r[0]) for r in rows]
    lab_ref = np.array([[float(v) for v in r[1:4]] for r in rows])
    lab_est = np.array([[float(v) for v in r[4:7]] for r in rows])
    de_argyll = np.array([float(r[7]) for r in rows])
    ours_ref, ours_est = lab_d50(sg)[idx], lab_d50(est)[idx]
    np.testing.assert_allclose(lab_ref, ours_ref, rtol=0, atol=ATOL_PRINTED)
    np.testing.assert_allclose(lab_est, ours_est, rtol=0, atol=ATOL_PRINTED)
    de_ours = delta_e_2000(ours_ref, ours_est)
    np.testing.assert_allclose(de_argyll, de_ours, rtol=0, atol=ATOL_PRINTED)
    peak, avg = map(
        float,
        re.search(
            r"Total errors \(CIEDE2000\):\s+peak = (\S+), avg = (\S+)", out
        ).groups(),
    )
    assert peak == pytest.approx(de_ours.max(), abs=ATOL_PRINTED)
    assert avg == pytest.approx(de_ours.mean(), abs=ATOL_PRINTED)


@requires_argyll
def test_colverify_of_the_exports_reproduces_table2(tmp_path: Path) -> None:
    # Estimate on a shorter grid than the reference, as in the demo (400-700 nm).
    ref = load_colorchecker_sg(Grid(380.0, 730.0, 10.0))
    est = load_colorchecker_sg(Grid(400.0, 700.0, 10.0))
    est = est.with_values(est.values * 0.97 + 0.01)
    table2 = reflectance_stats(est, ref)
    paths = export_measurement(
        tmp_path, reflectance=est, reference=ref, created=CREATED
    )
    assert read_cgats(paths["reference_ti3"]).keywords["TUNESPEC_RESAMPLED"] == (
        "linear, onto the estimate's 400:700:10 nm"
    )
    out = _run(
        "colverify", "-v", "2", "-k", paths["reference_ti3"], paths["reflectances_ti3"]
    )
    rows = {r[0]: float(r[7]) for r in _COLVERIFY_ROW.findall(out)}
    de_argyll = np.array([rows[n] for n in table2.names])
    np.testing.assert_allclose(de_argyll, table2.delta_e00, rtol=0, atol=ATOL_PRINTED)


# ------------------------------------------------------------------ the export CLI


def _cli_ok(*argv: str | Path) -> None:
    """:func:`_cli` that must succeed."""
    assert _cli(*argv) == 0, argv


def _cli(*argv: str | Path) -> int:
    """Run an export subcommand through its own parser (as ``tunespec`` does)."""
    import argparse

    parser = argparse.ArgumentParser(prog="tunespec")
    export_cmds.register(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args([str(a) for a in argv])
    return int(args.func(args))


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("cli")
    grid = Grid(380.0, 730.0, 10.0)
    sg = load_colorchecker_sg(grid).select(["A1", "B2", "C3", "D4", "N10"])
    leds = load_led_set(grid).select(["LED450", "WHITE_COOL"])
    cam = load_camera(grid=grid)
    rgb = render_rgb(sg.values, leds.values, cam.values, grid.step_nm)
    responses = Responses(sg.names, leds.names, 0.9 * rgb / rgb.max())
    paths = {
        "refl": d / "refl.csv",
        "resp": d / "resp.csv",
        "cam": d / "cam.csv",
        "leds": d / "leds.csv",
    }
    write_spectra_csv(sg, paths["refl"])
    write_responses_csv(responses, paths["resp"])
    write_spectra_csv(cam, paths["cam"])
    write_spectra_csv(leds, paths["leds"])
    return {**paths, "dir": d}


def test_cli_export_cgats(
    files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    out = files["dir"] / "out.ti3"
    _cli_ok("export-cgats", "--reflectances", files["refl"], "--responses",
            files["resp"], "--illuminant", "WHITE_COOL", "-o", out)  # fmt: skip
    assert capsys.readouterr().out == (
        f"5 patches (names, RGB, XYZ, Lab, 36 bands) written to {out}\n"
    )
    t = read_cgats(out)
    resp = read_responses_csv(files["resp"])
    np.testing.assert_array_equal(t.column("RGB_B", percent=True), resp.rgb[:, 1, 2])
    np.testing.assert_array_equal(
        t.spectra().values, read_spectra_csv(files["refl"]).values
    )
    with pytest.raises(InputError, match="several illuminants"):
        _cli("export-cgats", "--reflectances", files["refl"], "--responses",
             files["resp"], "-o", out)  # fmt: skip
    _cli_ok("export-cgats", "--reflectances", files["refl"], "--no-spectra",
            "--grid", "400:700:10", "-o", out)  # fmt: skip
    assert read_cgats(out).spectra() is None and read_cgats(out).rgb is None


def test_cli_export_rawtoaces(
    files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    out = files["dir"] / "cam.json"
    _cli_ok("export-rawtoaces", "--sensitivities", files["cam"], "--manufacturer",
            "Canon", "--model", "EOS 5D Mark III", "--absolute", "-o", out)  # fmt: skip
    back = read_rawtoaces_json(out)
    cam = read_spectra_csv(files["cam"])
    assert back.wavelength_nm.tolist() == list(range(380, 781, 5))  # as rawtoaces needs
    np.testing.assert_array_equal(
        back.resample(Grid(380.0, 730.0, 10.0)).values, cam.values
    )
    assert "81 wavelengths, 380-780 nm" in capsys.readouterr().out
    keep = files["dir"] / "cam_native.json"
    args = ("export-rawtoaces", "--sensitivities", files["cam"], "--keep-grid")
    assert _cli(*args, "--absolute", "-o", keep) == 0
    np.testing.assert_array_equal(read_rawtoaces_json(keep).values, cam.values)
    assert back.meta["model"] == "EOS 5D Mark III"


def test_cli_report(files: dict[str, Path]) -> None:
    out = files["dir"] / "report"
    # the LEDs of a session whose raw files were at f/8 (process keeps it with them)
    leds = files["dir"] / "leds_f8.csv"
    leds.write_text(files["leds"].read_text() + "# f_number: 8\n")
    _cli_ok("report", "-o", out, "--reflectances", files["refl"], "--reference",
            files["refl"], "--sensitivities", files["cam"], "--illuminants",
            leds, "--responses", files["resp"], "--session-id", "S-9")  # fmt: skip
    text = (out / "report.html").read_text()
    assert "S-9" in text and "Table 2: reflectance accuracy" in text
    assert re.search(r"aperture \(--illuminants\)</t[dh]>\s*<td>f/8</td>", text)
    assert '<td class="num">0.00</td>' in text  # estimate == reference
    assert (out / "report.pdf").read_bytes().startswith(b"%PDF-")


@requires_argyll
def test_cli_export_is_read_by_argyll(files: dict[str, Path]) -> None:
    out = files["dir"] / "argyll_in.ti3"
    _cli_ok("export-cgats", "--reflectances", files["refl"], "--responses",
            files["resp"], "--illuminant", "LED450", "-o", out)  # fmt: skip
    _run(
        "spec2cie",
        "-n",
        "-i",
        "D50",
        "-o",
        "1931_2",
        out,
        files["dir"] / "argyll_out.ti3",
    )
    ours, argyll = read_cgats(out).lab, read_cgats(files["dir"] / "argyll_out.ti3").lab
    assert delta_e_2000(ours, argyll).max() < DE00_ARGYLL


def test_cli_report_table1_undoes_the_fitted_spd_shift(
    files: dict[str, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    # Responses made under LEDs whose reported spectra are 3 nm off, and
    # sensitivities whose .meta.json carries that shift (as 'calibrate' writes it):
    # 'report --chart' must predict with the corrected spectra, as 'calibrate' did.
    import json

    from tunespec.app.report import report as report_module

    d = files["dir"] / "shift"
    d.mkdir()
    cam, leds = read_spectra_csv(files["cam"]), read_spectra_csv(files["leds"])
    sg = read_spectra_csv(files["refl"])
    true_leds = correct_spd_shift(leds, 3.0)
    rgb = render_rgb(sg.values, true_leds.values, cam.values, 10.0)
    write_responses_csv(Responses(sg.names, leds.names, rgb), d / "resp.csv")
    write_spectra_csv(cam, d / "cam.csv")
    sensitivity_meta_path(d / "cam.csv").write_text(json.dumps({"spd_shift_nm": 3.0}))
    seen = {}

    def capture(out: Path, data: report_module.ReportData) -> tuple[Path, Path]:
        seen["table1"] = data.table1
        return out / "report.html", out / "report.pdf"

    monkeypatch.setattr(report_module, "write_report", capture)
    args = ("report", "-o", d, "--sensitivities", d / "cam.csv", "--chart")
    args += (files["refl"], "--illuminants", files["leds"], "--responses")
    assert _cli(*args, d / "resp.csv") == 0
    assert seen["table1"].as_dict()["RGB"]["max"] < 1e-12
