"""The CLI and the GUI wizard are two front ends of one measurement folder.

A measurement run by ``tunespec demo``/``run`` opens in the wizard's model with its
calibration and estimate restored (the same writers and readers,
``tunespec.app.pipeline.folder``), and a measurement the wizard started is resumed
by ``tunespec run`` without capturing again what is already there.
"""

from __future__ import annotations

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
    from tunespec.app.gui.wizard import measurement
    from tunespec.app.pipeline.folder import restore_calibration_steps

    restored = restore_calibration_steps(folder / "calibration", cal)
    assert restored is not None
    np.testing.assert_allclose(
        restored[1].table1.mean, result.table1.mean, rtol=1e-9, atol=1e-12
    )

    def no_processing(*_args, **_kwargs):
        raise AssertionError("raw frames processed again")

    monkeypatch.setattr(measurement, "_process", no_processing)
    exported = measurement.export_job(folder / "export", folder, cal, est, {})
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


def test_the_cli_and_the_wizard_jobs_write_identical_results(tmp_path):
    """The same plan's steps through the CLI and through the wizard's jobs (headless,
    on the CLI's sessions) give the same files, byte for byte."""
    import filecmp

    from tunespec.app.gui.wizard import measurement
    from tunespec.app.pipeline.plan import chart_layout, sample_layout
    from tunespec.devices.registry import layout_reflectances

    cli = tmp_path / "cli"
    run_demo(cli, resolution=SIM["resolution"], report_files=False)
    wiz = tmp_path / "wizard"
    cal = measurement.calibrate_job(cli / "chart", wiz / "calibration", chart_layout())
    measurement.estimate_job(
        cli / "sample",
        wiz / "estimate",
        sample_layout(),
        cal.sensitivity,
        layout_reflectances(sample_layout()),
    )
    for sub in ("calibration", "estimate"):
        names = sorted(p.name for p in (cli / sub).iterdir())
        assert names == sorted(p.name for p in (wiz / sub).iterdir())
        assert "responses.csv" in names
        for name in names:
            assert filecmp.cmp(cli / sub / name, wiz / sub / name, shallow=False), name
