"""The CLI and the GUI wizard are two front ends of one measurement folder.

A measurement run by ``tunespec demo``/``run`` opens in the wizard's model with its
calibration and estimate restored (the same writers and readers,
``tunespec.app.pipeline.folder``), and a measurement the wizard started is resumed
by ``tunespec run`` without capturing again what is already there.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from PySide6.QtCore import QSettings

from tests.app.test_wizard import SIM, capture_chart
from tunespec.app.gui.main_window import MainWindow
from tunespec.app.gui.settings import AppSettings
from tunespec.app.gui.wizard.measurement import Measurement
from tunespec.app.pipeline.run import run_config, run_demo
from tunespec.core.io.session import Session

pytestmark = pytest.mark.slow


def _settings(tmp_path, name: str) -> AppSettings:
    return AppSettings(
        QSettings(str(tmp_path / f"{name}.ini"), QSettings.Format.IniFormat)
    )


def test_a_cli_measurement_opens_in_the_wizard_with_its_results(
    qtbot, tmp_path, monkeypatch
):
    folder = tmp_path / "m"
    result = run_demo(folder, resolution=SIM["resolution"], report_files=False)
    model = Measurement(controller=None, settings=_settings(tmp_path, "a"))  # type: ignore[arg-type]
    model.open(folder)
    # both captures are complete: the wizard's capture steps are done
    assert model.phase_complete("chart", None)
    assert model.phase_complete("sample", None)
    cal = model.restore_calibration()
    assert cal is not None
    np.testing.assert_array_equal(cal.table1.mean, result.table1.mean)
    np.testing.assert_array_equal(cal.table1.max, result.table1.max)
    # spectra CSVs hold repr() of every float: the round trip is exact
    np.testing.assert_array_equal(
        cal.sensitivity.values, result.calibration.sensitivity.values
    )
    assert cal.sensitivity.meta.get("spd_shift_nm") is not None
    est = model.restore_estimate()
    assert est is not None
    np.testing.assert_array_equal(
        est.reflectance.values, result.estimation.reflectance.values
    )
    assert est.table2 is not None and result.table2 is not None
    np.testing.assert_allclose(
        est.table2.mean_delta_e00, result.table2.mean_delta_e00, rtol=1e-12
    )
    # the wizard exports the restored results without processing a raw frame or
    # estimating the sensitivities again
    from tunespec.app.pipeline import jobs
    from tunespec.app.pipeline.jobs import restore_calibration_steps

    restored = restore_calibration_steps(folder / "calibration", cal)
    assert restored is not None
    np.testing.assert_allclose(
        restored[1].table1.mean, result.table1.mean, rtol=1e-9, atol=1e-12
    )

    def no_processing(*_args, **_kwargs):
        raise AssertionError("raw frames processed again")

    monkeypatch.setattr(jobs, "_process_session", no_processing)
    exported = jobs.export_job(jobs.ExportInputs(folder / "export", folder, cal, est))
    assert exported.paths["reflectances_csv"].is_file()
    assert exported.paths["sensitivities_csv"].is_file()


def test_a_wizard_measurement_is_resumed_by_the_cli(qtbot, tmp_path):
    folder = tmp_path / "m"
    w = MainWindow(_settings(tmp_path, "w"), sim_options=SIM)
    qtbot.addWidget(w)
    w.show()
    wizard = w.wizard_panel
    assert wizard.new_measurement(folder)
    capture_chart(qtbot, wizard)
    w.close()
    chart_before = Session.open(folder / "chart").fingerprint()
    width, height = SIM["resolution"]
    result = run_config(
        {
            "out": str(folder),
            "bench": {"resolution": f"{width}x{height}", "seed": SIM["seed"]},
            "export": {"report": False},
        }
    )
    # the wizard's chart frames were used as they are, nothing retaken
    assert Session.open(folder / "chart").fingerprint() == chart_before
    assert result.table1.mean[3] < 0.01
    # and the result opens in the wizard again
    model = Measurement(controller=None, settings=_settings(tmp_path, "b"))  # type: ignore[arg-type]
    model.open(folder)
    assert model.restore_calibration() is not None
    assert model.restore_estimate() is not None


#: What makes each export a new document: the CGATS ``CREATED`` keyword and the
#: rawtoaces header's creation date and UUID. Everything else must be identical.
_STAMPS = re.compile(
    r'^CREATED "[^"]*"$|"(document_creation_date|unique_identifier)": "[^"]*"',
    re.MULTILINE,
)


def _unstamped(path) -> str:
    text = path.read_text()
    assert _STAMPS.search(text), f"{path.name} differs and has no stamp"
    return _STAMPS.sub("", text)


def test_the_cli_and_the_wizard_jobs_write_identical_results(tmp_path):
    """The same plan's steps through the CLI and through the wizard's jobs (headless,
    on the CLI's sessions) give the same files, byte for byte: results and exports,
    both under the one folder layout (``export/`` included)."""
    import filecmp
    import json

    from tunespec.app.pipeline import jobs
    from tunespec.app.pipeline.plan import chart_layout, sample_layout
    from tunespec.core.io.session import Session
    from tunespec.devices.registry import layout_reflectances

    cli = tmp_path / "cli"
    run_demo(cli, resolution=SIM["resolution"], report_files=False)
    wiz = tmp_path / "wizard"
    # the wizard pages' jobs, with the inputs the pages give them
    cal = jobs.calibrate_job(
        jobs.CalibrateInputs(cli / "chart", wiz / "calibration", chart_layout())
    )
    est = jobs.estimate_job(
        jobs.EstimateInputs(
            cli / "sample",
            wiz / "estimate",
            cal.sensitivity,
            sample_layout(),
            reference=layout_reflectances(sample_layout()),
            calibration=cal.calibration.estimate,
        )
    )
    # the export page's job, with the devices of the session as the page passes them
    devices = Session.open(cli / "sample").devices
    jobs.export_job(jobs.ExportInputs(wiz / "export", cli, cal, est, devices))
    report = {"report.html", "report.pdf"}  # the CLI run wrote none (report_files)
    for sub in ("calibration", "estimate", "export"):
        names = sorted(p.name for p in (cli / sub).iterdir())
        wiz_names = sorted(p.name for p in (wiz / sub).iterdir())
        assert names == [n for n in wiz_names if n not in report]
        assert "responses.csv" in names
        for name in names:
            if name == "exports.json":
                continue
            a, b = cli / sub / name, wiz / sub / name
            if not filecmp.cmp(a, b, shallow=False):  # only the documents' stamps
                assert _unstamped(a) == _unstamped(b), name
    assert len(names) >= 20  # every export, not only the results
    index = json.loads((wiz / "export" / "exports.json").read_text())
    assert {k: v for k, v in index.items() if v not in report} == json.loads(
        (cli / "export" / "exports.json").read_text()
    )
