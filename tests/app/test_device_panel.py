"""DevicePanel on the simulated bench: connect, levels, frame, disconnect."""

from __future__ import annotations

import numpy as np
import pytest

from tests.app.helpers import caught

SIM = {"realtime": False, "resolution": (256, 192), "seed": 1}


def test_connect_levels_frame_disconnect_on_the_simulated_bench(panel, qtbot):
    c = panel.controller
    with caught(qtbot, c.devices_opened, timeout=20_000):
        panel.connect_button.click()
    assert panel.connected
    assert "simulated" in panel.state_label.text()
    assert panel.channel_table.rowCount() == 22
    assert not panel.connect_button.isEnabled() and panel.disconnect_button.isEnabled()

    # a channel on through its level box; the panel shows what the device reports
    with caught(qtbot, c.spd_measured, timeout=10_000) as spd:
        panel._level_spin(3).setValue(50.0)
    qtbot.waitUntil(lambda: panel.levels.size == 22 and panel.levels[3] == 0.5)
    assert spd.args[0].values.max() > 0

    with caught(qtbot, c.frame_acquired, timeout=20_000) as frame:
        panel.snap_button.click()
    preview = frame.args[0]
    assert preview.rgb.shape[:2] == (96, 128)
    assert panel.frame_plot.preview is preview

    with caught(qtbot, c.levels_changed, timeout=10_000):
        panel.all_off_button.click()
    qtbot.waitUntil(lambda: not np.any(panel.levels))

    with caught(qtbot, c.devices_closed, timeout=10_000):
        panel.disconnect_button.click()
    assert not panel.connected
    assert panel.channel_table.rowCount() == 0
    assert panel.connect_button.isEnabled()


def test_a_bad_spec_is_shown_plainly(panel, qtbot):
    panel.light_spec_combo.setCurrentText("nonsense")
    panel.camera_spec_combo.setCurrentText("gphoto2")
    panel.connect_button.click()
    qtbot.waitUntil(lambda: panel.error_label.text() != "", timeout=10_000)
    assert "unknown light source 'nonsense'" in panel.error_label.text()
    assert not panel.connected
    assert panel.connect_button.isEnabled()


def test_camera_settings_reach_the_camera(panel, qtbot):
    c = panel.controller
    with caught(qtbot, c.devices_opened, timeout=20_000):
        panel.connect_devices()
    with caught(qtbot, c.camera_changed, timeout=10_000) as changed:
        panel.exposure_spin.setValue(0.25)
    assert changed.args[0] == pytest.approx(0.25)
    with caught(qtbot, c.camera_changed, timeout=10_000) as changed:
        panel.iso_combo.setCurrentIndex(panel.iso_combo.findData(400))
    assert changed.args[1] == 400
