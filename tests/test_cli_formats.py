"""The commands take every format they write: JSON and CSV sensitivities give the same
estimates, reflectances in percent the same Table 2, grids come from the data."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.helpers import write_shipped_spectra
from tunespec.app.cli import main
from tunespec.core.datasets import (
    load_colorchecker_sg,
    resource_path,
)
from tunespec.core.io.spectral import read_spectral
from tunespec.core.io.spectral_csv import write_spectra_csv


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    """A calibration (with its .meta.json) and a target's responses, from the CLI."""
    d = write_shipped_spectra(tmp_path_factory.mktemp("formats"))
    sim = ["simulate-responses", "--sensitivities", d / "cam.csv", "--illuminants"]
    assert main(map(str, [*sim, d / "leds.csv", "--reflectances", d / "sg.csv",
                          "--exposure-target", "0.8", "--illuminants-out", d / "L.csv",
                          "-o", d / "R.csv", "-q"])) == 0  # fmt: skip
    assert main(map(str, ["calibrate", "--responses", d / "R.csv", "--illuminants",
                          d / "L.csv", "--reflectances", d / "sg.csv", "-o",
                          d / "S.csv", "--grid", "380:730:5", "-q"])) == 0  # fmt: skip
    return d


def _estimate(d, sensitivities, out, *extra) -> dict:
    args = ["estimate", "--responses", d / "R.csv", "--illuminants", d / "L.csv"]
    args += ["--sensitivities", sensitivities, "-o", d / out, "--json", *extra]
    assert main(list(map(str, args))) == 0
    return args


def test_json_and_csv_sensitivities_give_identical_estimates(calibrated, capsys):
    d = calibrated
    assert main(["export-rawtoaces", "--sensitivities", str(d / "S.csv"),
                 "-o", str(d / "S.json"), "-q"]) == 0  # fmt: skip
    assert (d / "S.json.meta.json").is_file()  # the LED corrections travel along
    assert json.loads((d / "S.json").read_text())["header"]["license"] == "CC-BY-4.0"
    assert main(["export-rawtoaces", "--sensitivities", str(d / "S.csv"), "-o",
                 str(d / "T.json"), "-q", "--license", "CC0-1.0"]) == 0  # fmt: skip
    assert json.loads((d / "T.json").read_text())["header"]["license"] == "CC0-1.0"
    capsys.readouterr()
    # one noise level: skips the uncertainty (seconds); the LED corrections of the
    # calibration's side file still apply to both
    _estimate(d, d / "S.csv", "from_csv.csv", "--noise-std", "0.001")
    from_csv = json.loads(capsys.readouterr().out)
    _estimate(d, d / "S.json", "from_json.csv", "--noise-std", "0.001")
    from_json = json.loads(capsys.readouterr().out)
    assert from_csv["grid"] == from_json["grid"] == "380:730:5"
    a = read_spectral(d / "from_csv.csv")
    b = read_spectral(d / "from_json.csv")
    # the JSON holds the curves normalised to peak 1: x / peak * peak rounds
    np.testing.assert_allclose(a.values, b.values, rtol=0, atol=1e-10)
    assert from_json["n_clipped_samples"] == from_csv["n_clipped_samples"]


def test_relative_sensitivities_are_refused(calibrated, capsys):
    d = calibrated
    db = resource_path("cameras", "Canon_EOS_5D_Mark_III_380_780_5.json")
    with pytest.raises(AssertionError):
        _estimate(d, db, "never.csv")
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "relative units" in err
    assert str(db) in err


def test_percent_reference_gives_the_same_table2(calibrated, capsys):
    d = calibrated
    _estimate(d, d / "S.csv", "est.csv", "--noise-std", "0.001")
    sg = load_colorchecker_sg()
    write_spectra_csv(sg.with_values(sg.values * 100), d / "sg_pct.csv")
    tables = []
    for ref in ("sg.csv", "sg_pct.csv"):
        capsys.readouterr()
        argv = ["evaluate", "--estimated", d / "est.csv", "--reference", d / ref]
        assert main([*map(str, argv), "--json"]) == 0
        captured = capsys.readouterr()
        tables.append(json.loads(captured.out))
    assert "percent" in captured.err and "sg_pct.csv" in captured.err
    for key in ("average", "max"):
        assert tables[0][key] == pytest.approx(tables[1][key], rel=1e-12)
    assert tables[0]["grid"] == tables[1]["grid"] and tables[0]["n"] == 140
    assert tables[0]["average"]["delta_e00"] < 1.0


def test_quiet_prints_nothing(calibrated, capsys):
    d = calibrated
    argv = ["evaluate", "--estimated", d / "sg.csv", "--reference", d / "sg.csv", "-q"]
    capsys.readouterr()
    assert main(list(map(str, argv))) == 0
    assert capsys.readouterr() == ("", "")


def test_grid_the_data_cannot_cover_is_one_line(calibrated, capsys):
    d = calibrated
    argv = ["evaluate", "--estimated", d / "sg.csv", "--reference", d / "sg.csv"]
    assert main([*map(str, argv), "--grid", "360:780:5"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "sg.csv" in err and "380-730 nm" in err


def test_progress_plain_lines_in_a_log_and_a_bar_on_a_terminal(capsys) -> None:
    from tunespec.app.cli.common import TerminalProgress, close_progress

    log = TerminalProgress("work")  # pytest's stdout/stderr are not terminals
    for k in range(101):
        log(k / 100)
    cap = capsys.readouterr()
    assert cap.out == ""  # stdout keeps to the results
    out = cap.err.splitlines()
    assert out[0].startswith("work: 0%") and out[-1].startswith("work: 100%")
    assert len(out) == 11  # one line per 10 %
    bar = TerminalProgress("work", force=True)  # as on a terminal: rich draws it
    bar(0.5)
    close_progress()  # an error mid-run stops the bar (main() does this)
    assert "work" in capsys.readouterr().err
