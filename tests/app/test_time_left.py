"""Issue 27, item 3: the simulated bench is fast unless asked (virtual time by
default, a visible "Real-time exposures" switch), and the time left is taken from
the exposures chosen and only goes down."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from tests.app.helpers import ini_settings
from tests.app.test_warnings_progress import _dark_page_ready
from tests.app.test_wizard import STEP_TIMEOUT_MS, run_step
from tests.app.test_wizard import window as window  # the fixture
from tunespec.app.gui.wizard import measurement
from tunespec.app.gui.wizard.measurement import CaptureOptions, _PhaseProgress
from tunespec.app.gui.wizard.step_page import StepState

#: Metered exposures of the four LEDs (s); a metering takes one shot of that
#: exposure plus METER_EXTRA_S, a frame its exposure plus FRAME_EXTRA_S.
EXPOSURES_S = {"LED1": 2.0, "LED2": 4.0, "LED3": 6.0, "LED4": 8.0}
METER_EXTRA_S = 1.0
FRAME_EXTRA_S = 0.5


class FakeClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def _session(metered: dict[str, float], darks_left: list[float]):
    """A session as the dark phase sees it: what is metered, which darks miss."""
    channels = tuple(EXPOSURES_S)
    settings = SimpleNamespace(
        channels=channels,
        exposures_s={c: (t,) for c, t in metered.items()},
        resolved=len(metered) == len(channels),
        bracket_factors=(1.0,),
        n_darks=1,
    )
    missing = [SimpleNamespace(kind="dark", exposure_s=t) for t in darks_left]
    return SimpleNamespace(settings=settings, missing=lambda verify=False: missing)


@pytest.mark.parametrize("waits", [True, False])
def test_time_left_comes_from_the_exposures_metered(monkeypatch, waits):
    clock = FakeClock()
    monkeypatch.setattr(measurement.time, "monotonic", clock)
    monkeypatch.setattr(measurement, "_LAST_OVERHEAD_S", [])
    fractions: list[float] = []
    left: list[float] = []
    state = {"session": _session({}, [])}
    meter = _PhaseProgress(
        "dark",
        state["session"],
        len(EXPOSURES_S),
        CaptureOptions("auto", 100, 1, 1),
        fractions.append,
        waits=waits,
        remaining=left.append,
        session_now=lambda: state["session"],
    )
    wait = 1.0 if waits else 0.0
    metered: dict[str, float] = {}
    for channel, t in EXPOSURES_S.items():
        meter.stage_started()
        clock.t += wait * t + METER_EXTRA_S
        metered[channel] = t
        darks = list(EXPOSURES_S.values()) if len(metered) == 4 else []
        state["session"] = _session(metered, darks)
        meter.step()
    # metering one LED took (its exposure +) METER_EXTRA_S
    np.testing.assert_allclose(
        meter.meter_s, [wait * t + METER_EXTRA_S for t in EXPOSURES_S.values()]
    )
    darks = list(EXPOSURES_S.values())
    while darks:
        t = darks.pop(0)
        meter.stage_started()
        clock.t += wait * t + FRAME_EXTRA_S
        state["session"] = _session(metered, darks)
        meter.frame_taken(state["session"], t)
        meter.step()
        # from the first frame on, what is left is exactly the darks left
        assert left[-1] == pytest.approx(sum(wait * d + FRAME_EXTRA_S for d in darks))
    # the frames are estimated from the chosen exposures as soon as they are known
    truth_after_metering = sum(wait * d + FRAME_EXTRA_S for d in EXPOSURES_S.values())
    assert left[3] == pytest.approx(
        truth_after_metering + len(EXPOSURES_S) * (METER_EXTRA_S - FRAME_EXTRA_S)
    )
    assert np.all(np.diff(fractions) >= 0) and fractions[-1] == pytest.approx(1.0)
    assert np.all(np.isfinite(left))


def test_the_simulated_bench_is_virtual_unless_switched(qtbot, tmp_path):
    from tests.app.helpers import main_window

    assert ini_settings(tmp_path, "fresh").get("sim/realtime") is False
    settings = ini_settings(tmp_path)
    from tunespec.app.gui.main_window import MainWindow

    w = MainWindow(settings, sim_options={"resolution": (384, 256)})
    qtbot.addWidget(w)
    panel = w.device_panel
    check = panel.realtime_check
    assert check.text() == "Real-time exposures"
    assert not check.isChecked() and check.isEnabled()
    assert panel.sim_options["realtime"] is False
    check.setChecked(True)
    assert settings.get("sim/realtime") is True
    assert panel.sim_options["realtime"] is True
    assert w.measurement.sim_options["realtime"] is True
    check.setChecked(False)
    # hardware specs: nothing to switch
    panel.camera_spec_combo.setEditText("gphoto2")
    assert not check.isEnabled()
    panel.camera_spec_combo.setEditText("sim")
    assert check.isEnabled()
    w.close()
    # remembered: the next window starts with what was chosen
    settings.set("sim/realtime", True)
    with main_window(qtbot, tmp_path, {}) as w2:
        assert w2.device_panel.realtime_check.isChecked()


def test_time_left_only_goes_down(window, qtbot, tmp_path):
    _, page = _dark_page_ready(qtbot, window, tmp_path / "m")
    assert window.controller.is_open
    shown: list[float] = []
    page.progress_bar.valueChanged.connect(lambda _v: shown.append(page.remaining_s()))
    page.start_button.click()
    qtbot.waitUntil(lambda: not page.running, timeout=STEP_TIMEOUT_MS)
    assert page.state == StepState.DONE
    known = [s for s in shown if np.isfinite(s)]
    assert known, shown
    assert np.all(np.diff(known) <= 0), known
    # the connected panel cannot switch timing any more
    assert not window.device_panel.realtime_check.isEnabled()
    run_step(qtbot, window.wizard_panel, window.wizard_panel.white_page)
