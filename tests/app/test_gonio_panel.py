"""The gonio run view: live progress per geometry from the disk, the fused result
per geometry (spectrum with its band, L*a*b* against theta_r with bars), a failure
marking the geometry it names."""

from __future__ import annotations

import time

import numpy as np
import pytest

from tunespec.app.gui.panels.gonio_panel import COLUMNS, GonioPanel
from tunespec.app.gui.workers import Worker
from tunespec.app.pipeline import gonio_view
from tunespec.app.pipeline.gonio import GeometryStep, GonioPlan, frame_names
from tunespec.core.errors import InputError
from tunespec.devices.goniometer import Geometry

LEDS = [f"LED{k}" for k in range(3)]
THETA_R = (30.0, 0.0, 10.0, 20.0)  # not in order: the L*a*b* plot sorts them
BENT = (
    "geometry 1 (theta_i 45, theta_r 30), g00_ti45_pi0_tr30_pr180: its exposure "
    "brackets bend as response^(1 + gamma) with gamma +0.100 +- 0.00016"
)


def _plan() -> GonioPlan:
    steps = tuple(
        GeometryStep(Geometry(45.0, 0.0, t, 180.0), spectral=t in (0.0, 20.0))
        for t in THETA_R
    )
    return GonioPlan(steps, leds=tuple(LEDS))


def _result(plan: GonioPlan) -> dict:
    rng = np.random.default_rng(3)
    n_p, n_g, wl = 2, len(plan.steps), np.arange(400.0, 701.0, 10.0)
    return {
        "patches": ["P1", "P2"],
        "wavelength_nm": wl,
        "spectral": np.array([s.spectral for s in plan.steps]),
        "theta_i": np.full(n_g, 45.0),
        "theta_r": np.array(THETA_R),
        "phi_r": np.full(n_g, 180.0),
        "reflectance": rng.uniform(0.1, 0.9, (n_p, n_g, wl.size)),
        "u_reflectance": rng.uniform(0.001, 0.01, (n_p, n_g, wl.size)),
        "lab": rng.uniform(-30, 80, (n_p, n_g, 3)),
        "u_lab": rng.uniform(0.1, 0.5, (n_p, n_g, 3)),
        "warnings": [BENT],
    }


def _fake_run(fail_at: int | None):
    """A run_gonio_plan that writes the plan and each geometry's frames (empty
    files), pausing after each geometry, then returns a result or fails."""
    plan = _plan()

    def run(out, *, plan=None, n_geometries=14, devices=None, seed=0,
            progress=None, should_stop=None):  # fmt: skip
        p = _plan()
        out.mkdir(parents=True, exist_ok=True)
        p.save(out / "plan.json")
        for i, step in enumerate(p.steps):
            if i == fail_at:
                raise InputError(
                    f"geometry {i + 1} (theta_i 45, theta_r {THETA_R[i]:g}), "
                    f"{p.folder(i)}: corner detection: could not follow one of the "
                    "target's sides"
                )
            gdir = out / p.folder(i)
            gdir.mkdir(exist_ok=True)
            for n, k in frame_names(step, LEDS):
                (gdir / f"{n}_e{k}.npy").write_bytes(b"")
            progress((i + 1) / len(p.steps))
            time.sleep(0.4)  # the panel polls the disk meanwhile
        return _result(p)

    return run, plan


def _panel(qtbot, monkeypatch, fail_at=None) -> GonioPanel:
    run, _ = _fake_run(fail_at)
    monkeypatch.setattr(gonio_view, "run_gonio_plan", run)
    panel = GonioPanel()
    panel.worker_class = Worker  # the fake is not importable in a fresh process
    panel.poll_timer.setInterval(50)
    qtbot.addWidget(panel)
    return panel


def test_progress_per_geometry_and_the_fused_result(qtbot, monkeypatch, tmp_path):
    panel = _panel(qtbot, monkeypatch)
    seen: list[list[str]] = []
    panel.poll_timer.timeout.connect(
        lambda: seen.append([panel.geometry_state(i) for i in range(4)])
    )
    with qtbot.waitSignal(panel.finished, timeout=20_000) as done:
        panel.start(tmp_path / "s")
    assert done.args == [True]
    # live: the geometries were captured one after another, as the disk said
    assert ["captured", "waiting", "waiting", "waiting"] in seen
    assert ["captured", "captured", "captured", "waiting"] in seen
    frames = COLUMNS.index("frames")
    totals = [len(frame_names(s, LEDS)) for s in _plan().steps]
    assert [panel.table.item(i, frames).text() for i in range(4)] == [
        f"{t}/{t}" for t in totals
    ]
    assert [panel.geometry_state(i) for i in range(4)] == [
        "fused", "spectral", "fused", "spectral"
    ]  # fmt: skip
    r = panel.result
    # geometry 4 (theta_r 20), patch P2: its spectrum and 95 % band
    panel.patch_combo.setCurrentIndex(1)
    panel.table.selectRow(3)
    x, y = panel.spectrum_curve.getData()
    np.testing.assert_allclose(x, r["wavelength_nm"])
    np.testing.assert_allclose(y, r["reflectance"][1, 3])
    _, upper = panel.spectrum_upper.getData()
    np.testing.assert_allclose(upper - y, 1.96 * r["u_reflectance"][1, 3])
    # L*a*b* against theta_r, sorted (0, 10, 20, 30 = geometries 2, 3, 4, 1)
    order = [1, 2, 3, 0]
    tx, L = panel.lab_curves["L*"].getData()
    np.testing.assert_allclose(tx, [0.0, 10.0, 20.0, 30.0])
    np.testing.assert_allclose(L, r["lab"][1, order, 0])
    bars = panel.lab_bars["b*"].opts
    np.testing.assert_allclose(bars["height"], 2 * 1.96 * r["u_lab"][1, order, 2])
    L4, uL4 = r["lab"][1, 3, 0], r["u_lab"][1, 3, 0]
    assert f"geometry 4: L*a*b* {L4:.2f} ± {uL4:.2f}" in panel.result_label.text()
    # what the processing said against the frames stays in view with the result
    assert panel.status.text().endswith(f"\nwarning: {BENT}")


def test_a_failure_marks_the_geometry_it_names(qtbot, monkeypatch, tmp_path):
    panel = _panel(qtbot, monkeypatch, fail_at=2)
    with qtbot.waitSignal(panel.finished, timeout=20_000) as done:
        panel.start(tmp_path / "s")
    assert done.args == [False]
    assert [panel.geometry_state(i) for i in range(4)] == [
        "captured", "captured", "failed", "waiting"
    ]  # fmt: skip
    assert "geometry 3 (theta_i 45, theta_r 10)" in panel.status.text()
    assert panel.run_button.isEnabled() and panel.result is None


@pytest.mark.slow
def test_the_simulated_gonio_bench_runs_from_the_panel(qtbot, tmp_path):
    """The real pipeline in a process: 4 geometries of the default plan (about
    15 s on two cores), the numbers those of the session's gonio.nc."""
    panel = GonioPanel()
    qtbot.addWidget(panel)
    panel.n_spin.setValue(4)
    with qtbot.waitSignal(panel.finished, timeout=300_000) as done:
        panel.start(tmp_path / "g")
    assert done.args == [True], panel.status.text()
    assert [panel.geometry_state(i) for i in range(4)] == [
        "spectral", "fused", "spectral", "fused"
    ]  # fmt: skip
    disk = gonio_view.load_gonio_result(tmp_path / "g")
    panel.table.selectRow(1)
    _, y = panel.spectrum_curve.getData()
    np.testing.assert_allclose(y, disk["reflectance"][0, 1])
    assert np.all(np.isfinite(disk["u_lab"])) and np.all(disk["u_lab"] > 0)
    assert disk["warnings"] == [] and "warning" not in panel.status.text()


def test_devices_are_passed_by_spec_and_all_are_needed(qtbot, monkeypatch, tmp_path):
    got = {}

    def run(out, *, plan=None, n_geometries=14, devices=None, seed=0,
            progress=None, should_stop=None):  # fmt: skip
        got.update(out=out, plan=plan, devices=devices)
        raise InputError("stop here")

    monkeypatch.setattr(gonio_view, "run_gonio_plan", run)
    panel = GonioPanel()
    panel.worker_class = Worker
    qtbot.addWidget(panel)
    panel.bench_combo.setCurrentIndex(1)
    assert not panel.device_rows.isHidden() and not panel.n_spin.isEnabled()
    panel.folder_edit.setText(str(tmp_path / "s"))
    panel.plan_edit.setText("plan.json")
    assert panel.start() is None and "Devices need" in panel.status.text()
    panel.light_edit.setText("cal1+socket://localhost:7001")
    panel.gonio_edit.setText("zaber+socket://localhost:7002")
    panel.sens_edit.setText("cal.csv")
    panel.layout_edit.setText("sample.json")
    with qtbot.waitSignal(panel.finished, timeout=10_000):
        panel.start()
    assert got["plan"] == "plan.json" and got["out"] == tmp_path / "s"
    assert got["devices"] == gonio_view.DeviceSpecs(
        "cal1+socket://localhost:7001", "sim", "zaber+socket://localhost:7002",
        "cal.csv", "sample.json",
    )  # fmt: skip
    assert panel.status.text() == "gonio run failed: stop here"
