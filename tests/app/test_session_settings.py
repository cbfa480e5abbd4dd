"""Issue 24, item 3 (issue 27, item 4): a session keeps its own settings. A resume or
a retake takes the missing frames with the camera settings the session was
captured with (the simulated camera's resolution and seed included), through the
one rule the CLI and the GUI share; another camera is refused before its first
frame."""

from __future__ import annotations

import pytest

from tunespec.app.cli import main
from tunespec.app.pipeline.steps import capture_target
from tunespec.core.datasets import resource_path
from tunespec.core.errors import InputError
from tunespec.core.io.raw import load_raw
from tunespec.core.io.session import Session
from tunespec.core.layout import TargetLayout
from tunespec.devices.capture import capture, recorded_sim_camera
from tunespec.devices.registry import open_bench

SG_LAYOUT = resource_path("layouts", "colorchecker_sg.json")


def _capture(out, *extra):
    return main(
        ["capture", "--channels", "LED450", "--out", str(out), "--quiet", *extra]
    )


def _mosaic_shape(session: Session, frame_id: str) -> tuple[int, int]:
    return load_raw(session.path_of(session.frame(frame_id))).mosaic.shape


def test_cli_resume_takes_the_missing_frames_as_the_session_was_captured(tmp_path):
    out = tmp_path / "S"
    assert (
        _capture(out, "--layout", str(SG_LAYOUT), "--resolution", "768x512",
                 "--seed", "3") == 0
    )  # fmt: skip
    session = Session.open(out)
    assert recorded_sim_camera(session) == {"resolution": (768, 512), "seed": 3}
    target = next(f.id for f in session.frames if f.kind == "target")
    # as if killed before its last frame: that frame is taken again on --resume,
    # with no --resolution (the default would be 1536x1024) and no --seed
    session.mark_bad([target], "test: interrupted")
    assert _capture(out, "--resume") == 0
    session = Session.open(out)
    assert not session.missing()
    assert _mosaic_shape(session, target) == (512, 768)
    assert session.devices["camera"]["serial"] == "SIM-3"


def test_cli_resume_refuses_other_settings_before_a_frame(tmp_path, capsys):
    out = tmp_path / "S"
    assert _capture(out, "--layout", str(SG_LAYOUT), "--resolution", "384x256") == 0
    n = len(Session.open(out).frames)
    capsys.readouterr()
    assert _capture(out, "--retake", "dark_0.0001s_iso100_0", "--resolution",
                    "768x512") == 2  # fmt: skip
    err = capsys.readouterr().err
    assert "--resolution 768x512 differs from the session's 384x256" in err
    assert err[-1] == "\n" and err.count("\n") == 1
    assert len(Session.open(out).frames) == n


def test_capture_refuses_another_camera_before_its_first_frame(tmp_path):
    layout = TargetLayout.load(SG_LAYOUT)
    with open_bench(resolution=(384, 256), layout=layout) as bench:
        session, _ = capture_target(bench, tmp_path / "S", layout, exposure=0.5)
    frames = Session.open(tmp_path / "S").frames
    with open_bench(resolution=(448, 320), layout=layout) as other:
        session = Session.open(tmp_path / "S")
        session.mark_bad([frames[-1].id], "test")
        with pytest.raises(InputError, match="resolution 384x256 -> 448x320"):
            capture(session, other.light, other.camera, other.stage, resume=True)
    assert len(Session.open(tmp_path / "S").frames) == len(frames)


def test_the_shared_resume_gives_a_simulated_camera_its_session_settings(tmp_path):
    """What the GUI's 'Retake sample frames' runs (capture_target): a bench opened
    at another size and seed takes the frames at the session's."""
    layout = TargetLayout.load(SG_LAYOUT)
    root = tmp_path / "sample"
    with open_bench(resolution=(384, 256), seed=4, layout=layout) as bench:
        capture_target(bench, root, layout, exposure=0.5)
    session = Session.open(root)
    retaken = [f.id for f in session.frames if f.kind != "dark"]
    session.mark_bad(retaken, "retake")
    with open_bench(resolution=(768, 512), seed=0, layout=layout) as bench:
        session, _ = capture_target(bench, root, layout)
    assert not session.missing()
    assert {_mosaic_shape(session, i) for i in retaken} == {(256, 384)}
    assert session.devices["camera"]["serial"] == "SIM-4"
