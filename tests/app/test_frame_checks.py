"""Issue 27, item 4: a bad frame is flagged the moment it exists (the CLI warns or,
with --strict, stops with exit 2; the GUI step gets its warning badge), and step
states come from what is on disk."""

from __future__ import annotations

import pytest

from tests.app.test_wizard import STEP_TIMEOUT_MS, run_step
from tests.app.test_wizard import window as window  # the fixture
from tests.helpers import without_progress
from tunespec.app.cli import main
from tunespec.app.gui.wizard.step_page import StepState
from tunespec.app.pipeline.folder import read_capture_warnings
from tunespec.core.datasets import resource_path
from tunespec.core.io.session import Session

SG_LAYOUT = resource_path("layouts", "colorchecker_sg.json")


def _capture(out, *extra):
    return main(
        [
            "capture",
            "--resolution",
            "384x256",
            "--layout",
            str(SG_LAYOUT),
            "--channels",
            "LED450,LED555",
            "--out",
            str(out),
            *extra,
        ]
    )


def test_cli_flags_an_over_exposed_frame_when_it_is_taken(tmp_path, capsys):
    out = tmp_path / "s"
    assert _capture(out, "--exposure", "30") == 0
    err = capsys.readouterr().err
    clipped = [w for w in read_capture_warnings(out) if "clipped (saturated)" in w]
    # LED450's frames at 30 s are clipped, and each was said on stderr as taken
    assert [w.split(":")[0] for w in clipped] == [
        "white frame LED450 at 30 s",
        "target frame LED450 at 30 s",
    ]
    assert all(w in err for w in clipped)


def test_cli_strict_stops_at_the_first_bad_frame_and_resume_retakes_it(
    tmp_path, capsys
):
    out = tmp_path / "s"
    assert _capture(out, "--exposure", "30", "--strict") == 2
    err = without_progress(capsys.readouterr().err)
    assert err.count("\n") == 0 and "--strict" in err and "clipped" in err
    session = Session.open(out)
    bad = [f for f in session.frames if f.status != "ok"]
    assert [f.id for f in bad] == [session.frames[-1].id]
    assert len(session.frames) == 2  # the dark (one exposure) and the first white
    # without --strict the resume takes it (and the rest) again, with warnings
    assert _capture(out, "--resume") == 0
    assert not Session.open(out).missing()


def test_a_metered_capture_flags_nothing(tmp_path, capsys):
    assert _capture(tmp_path / "s") == 0
    assert read_capture_warnings(tmp_path / "s") == ()
    assert "warning" not in capsys.readouterr().err


def test_the_gui_step_shows_a_clipped_frame_at_once(window, qtbot, tmp_path):
    wizard, m = window.wizard_panel, window.measurement
    assert wizard.new_measurement(tmp_path / "m")
    run_step(qtbot, wizard, wizard.connect_page)
    wizard.go_to(wizard.pages.index(wizard.dark_page))
    wizard.dark_page.exposure_combo.setCurrentIndex(1)  # fixed
    wizard.dark_page.exposure_spin.setValue(30.0)
    run_step(qtbot, wizard, wizard.dark_page)
    page = wizard.white_page
    wizard.go_to(wizard.pages.index(page))
    page.start_button.click()
    # flagged while the step runs, not at Calibrate
    qtbot.waitUntil(lambda: bool(page.warnings), timeout=STEP_TIMEOUT_MS)
    assert page.running or page.state == StepState.DONE
    assert "clipped (saturated)" in page.warnings[0]
    assert "white frame" in page.warnings[0]
    qtbot.waitUntil(lambda: not page.running, timeout=STEP_TIMEOUT_MS)
    assert page.warning_label.isVisible()
    assert "retake with a shorter exposure" in page.warning_label.text()
    assert m.capture_options.exposure == 30.0
    # the action under the badge: the clipped session is kept aside, and the
    # chart is taken again from the dark frame at a quarter of the exposure
    assert page.shorter_button.isVisible()
    page.shorter_button.click()
    dark = wizard.dark_page
    assert wizard.current_page is dark and dark.running
    assert m.capture_options.exposure == 7.5
    qtbot.waitUntil(lambda: not dark.running, timeout=STEP_TIMEOUT_MS)
    assert dark.state == StepState.DONE
    assert {f.exposure_s for f in m.session("chart").frames} == {7.5}
    assert page.state == StepState.PENDING and not page.shorter_button.isVisible()
    aside = [p for p in (tmp_path / "m").iterdir() if ".clipped-" in p.name]
    assert len(aside) == 1 and (aside[0] / "manifest.json").is_file()


@pytest.mark.slow
def test_an_interrupted_sample_capture_is_not_shown_done(window, qtbot, tmp_path):
    from tests.app.helpers import new_main_window
    from tests.app.test_wizard import SIM

    wizard, m = window.wizard_panel, window.measurement
    folder = tmp_path / "m"
    assert wizard.new_measurement(folder)
    for page in wizard.pages[:5]:  # connect ... calibrate
        run_step(qtbot, wizard, page)
    page = wizard.sample_page
    wizard.go_to(wizard.pages.index(page))
    page.start_button.click()
    qtbot.waitUntil(
        lambda: m.session("sample") is not None and bool(m.session("sample").frames),
        timeout=STEP_TIMEOUT_MS,
    )
    page.abort_button.click()
    qtbot.waitUntil(lambda: not page.running, timeout=STEP_TIMEOUT_MS)
    window.close()

    w2 = new_main_window(qtbot, tmp_path, SIM)
    wizard2 = w2.wizard_panel
    assert wizard2.open_measurement(folder)
    assert wizard2.calibrate_page.state == StepState.DONE
    assert wizard2.sample_page.state == StepState.PENDING
    assert "complete" not in wizard2.sample_page.result_label.text()
    w2.close()


@pytest.mark.parametrize("strict", [False, True])
def test_a_target_not_in_view_is_flagged_once_its_frames_are_in(
    tmp_path, monkeypatch, strict
):
    from tunespec.core.layout import TargetLayout
    from tunespec.devices.capture import BadFrameError, capture, new_session
    from tunespec.devices.registry import open_bench

    layout = TargetLayout.load(SG_LAYOUT).with_corners(None)
    with open_bench(resolution=(384, 256), layout=layout) as bench:
        # the operator forgot the chart: the camera sees the white board
        real = bench.stage.present
        monkeypatch.setattr(bench.stage, "present", lambda what: real("white"))
        session = new_session(
            tmp_path / "s", bench.light, bench.camera, layout=layout,
            channels=["LED450", "LED555"],
        )  # fmt: skip
        if strict:
            with pytest.raises(BadFrameError, match="target was not found"):
                capture(session, bench.light, bench.camera, bench.stage, strict=True)
            return
        result = capture(session, bench.light, bench.camera, bench.stage)
    found = [w for w in result.warnings if "target was not found" in w]
    assert len(found) == 1 and "corners" in found[0]


def test_an_under_exposed_frame_is_told_how_to_fix_it_only_where_it_can_be(
    tmp_path, capsys
):
    # a short fixed exposure: retake longer; at the longest exposure allowed there is
    # no longer one to advise
    for out, extra, advice in (
        (tmp_path / "a", (), True),
        (tmp_path / "b", ("--max-exposure", "0.001"), False),
    ):
        assert _capture(out, "--exposure", "0.001", *extra) == 0
        low = [w for w in read_capture_warnings(out) if "under-exposed" in w]
        assert low, read_capture_warnings(out)
        assert all(("retake with a longer exposure" in w) == advice for w in low)
        assert all(("longest exposure allowed" in w) != advice for w in low)
