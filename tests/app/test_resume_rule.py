"""Issue 26, item 1: resume and retake are decided in one place
(``pipeline.capture.open_for_capture`` with ``Resume``), for ``tunespec capture``,
``run``/``demo`` and the wizard alike: a resumed session keeps its own settings, a
complete phase asked again is taken again, and what a mode forbids is refused
before anything is written."""

from __future__ import annotations

import pytest

from tunespec.app.pipeline.jobs import CaptureSettings, Resume, capture_session
from tunespec.core.datasets import resource_path
from tunespec.core.errors import InputError
from tunespec.core.io.session import Session
from tunespec.core.layout import TargetLayout
from tunespec.devices.registry import open_bench

LAYOUT = TargetLayout.load(resource_path("layouts", "colorchecker_24.json"))
ONE_LED = CaptureSettings(exposure=0.5, channels=("LED525",))


def test_each_mode_refuses_what_it_forbids_before_writing(tmp_path):
    root = tmp_path / "S"
    with pytest.raises(InputError, match="no session to resume here"):
        Resume("continue").session_exists(root)
    with pytest.raises(InputError, match="no session to resume here"):
        Resume("auto", retake=("dark_0.5s_iso100_0",)).session_exists(root)
    assert not root.exists()
    assert Resume("new").session_exists(root) is False
    with open_bench(resolution=(192, 128), layout=LAYOUT) as bench:
        capture_session(bench, root, LAYOUT, ONE_LED, Resume("new"))
    with pytest.raises(InputError, match="add --resume to continue it"):
        Resume("new").session_exists(root)
    assert Resume("continue").session_exists(root) is True


def test_a_resume_keeps_the_sessions_settings_and_a_complete_phase_is_retaken(
    tmp_path,
):
    root = tmp_path / "S"
    with open_bench(resolution=(192, 128), seed=2, layout=LAYOUT) as bench:
        session, first = capture_session(bench, root, LAYOUT, ONE_LED, Resume("new"))
    darks = sorted(f.id for f in session.frames if f.kind == "dark")
    assert len(first.captured) == len(session.frames) == 3  # dark, white, target
    # another ISO and exposure asked, on a bench of another seed: the session's
    # own are kept, and the complete dark phase is taken again, nothing else
    other = CaptureSettings(exposure=2.0, iso=400, channels=("LED450",))
    with open_bench(resolution=(384, 256), seed=0, layout=LAYOUT) as bench:
        session, again = capture_session(
            bench, root, LAYOUT, other, Resume("auto", retake_phase="dark")
        )
    assert sorted(again.captured) == darks
    session = Session.open(root)
    assert session.settings.iso == 100
    assert session.settings.channels == ("LED525",)
    assert session.devices["camera"]["serial"] == "SIM-2"
    assert not session.missing()
    # nothing missing and no retake asked: a resume takes nothing
    with open_bench(resolution=(192, 128), seed=2, layout=LAYOUT) as bench:
        _, none = capture_session(bench, root, LAYOUT, other, Resume("continue"))
    assert len(none.captured) == 0
    assert none.skipped == 3
