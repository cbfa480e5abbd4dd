"""The capture sequence on the simulated bench: order, metering, errors, resume."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from tunespec.app.pipeline.plan import sample_layout
from tunespec.core.errors import InputError
from tunespec.core.io.raw import load_raw
from tunespec.core.io.session import Session
from tunespec.core.progress import Cancelled
from tunespec.devices.capture import capture, meter_exposure, new_session
from tunespec.devices.protocols import DeviceTimeoutError
from tunespec.devices.registry import (
    OperatorStage,
    open_bench,
    open_camera,
    open_light_source,
    parse_resolution,
)

#: Small frames: these tests check bookkeeping, not accuracy.
RESOLUTION = (384, 256)
CHANNELS = ("LED450", "LED540", "WHITE_WARM")
#: Auto exposure lands the white board's brightest part in this band of full scale
#: (aim 0.75; the percentile metering sees shot noise and the light's small drift).
METERED_LEVEL_BAND = (0.65, 0.85)


@pytest.fixture
def bench():
    with open_bench("sim", resolution=RESOLUTION, layout=sample_layout()) as b:
        yield b


class _Recorder:
    """Wraps a stage to log what was presented, and the light's state then."""

    def __init__(self, stage, light) -> None:
        self.stage, self.light, self.log = stage, light, []

    def present(self, what) -> None:
        self.log.append(what)
        self.stage.present(what)


class _FlakyCamera:
    """A camera proxy whose ``fail_at``-th capture times out."""

    def __init__(self, camera, fail_at: int) -> None:
        self._camera, self._fail_at, self.n = camera, fail_at, 0

    def capture(self, stem):
        self.n += 1
        if self.n == self._fail_at:
            raise DeviceTimeoutError("camera did not answer (test)")
        return self._camera.capture(stem)

    def __getattr__(self, name):
        return getattr(self._camera, name)


def _session(tmp_path: Path, bench, **kw) -> Session:
    kw.setdefault("exposure", 6.0)
    kw.setdefault("channels", CHANNELS)
    return new_session(
        tmp_path / "s", bench.light, bench.camera, layout=sample_layout(), **kw
    )


def test_fixed_capture_order_spd_and_lights_off(tmp_path, bench) -> None:
    session = _session(tmp_path, bench)
    stage = _Recorder(bench.stage, bench.light)
    seen: list[str] = []
    fractions: list[float] = []
    result = capture(
        session,
        bench.light,
        bench.camera,
        stage,
        on_frame=lambda rec, path: seen.append(rec.id) or path.is_file(),
        progress=fractions.append,
    )
    ids = [f.id for f in session.frames]
    assert ids == [
        "dark_6s_iso100_0",
        *(f"white_{c}" for c in CHANNELS),
        *(f"target_{c}" for c in CHANNELS),
    ]
    assert list(result.captured) == ids == seen and result.skipped == 0
    assert stage.log == ["white", "target"]
    assert not np.any(bench.light.levels())
    assert fractions == sorted(fractions) and fractions[-1] == 1.0
    for f in session.frames:
        assert session.verify(f)
        if f.kind == "dark":
            assert f.spd_file is None
        else:
            spd = session.read_spd(f)
            assert spd.wavelength_nm[0] <= 380 and float(spd.values.max()) > 0
    # the raw files carry the exposure and ISO the manifest says
    frame = load_raw(session.path_of(session.frames[0]))
    assert frame.exposure_s == pytest.approx(6.0) and frame.iso == 100


def test_a_finished_capture_leaves_no_tmp_folder_and_one_file_mode(
    tmp_path, bench
) -> None:
    session = _session(tmp_path, bench, exposure="auto")
    capture(session, bench.light, bench.camera, bench.stage)
    root = tmp_path / "s"
    # session.lock stays: removing a flock()ed file would let two writers race
    assert sorted(p.name for p in root.iterdir()) == [
        "frames",
        "manifest.json",
        "session.lock",
    ]
    umask = os.umask(0)
    os.umask(umask)
    modes = {p.name: p.stat().st_mode & 0o777 for p in root.rglob("*") if p.is_file()}
    assert set(modes.values()) == {0o666 & ~umask}, modes


def test_auto_exposure_puts_the_white_board_near_three_quarters(
    tmp_path, bench
) -> None:
    session = _session(tmp_path, bench, exposure="auto")
    result = capture(session, bench.light, bench.camera, bench.stage)
    assert set(result.metered) == set(CHANNELS)
    exposures = session.settings.exposures_s
    assert exposures["WHITE_WARM"][0] < exposures["LED450"][0]
    for c in CHANNELS:
        frame = load_raw(session.path_of(session.frame(f"white_{c}")))
        level = float(np.percentile(frame.planes.max(axis=0), 99.5))
        assert METERED_LEVEL_BAND[0] < level < METERED_LEVEL_BAND[1], (c, level)
    # one dark per distinct exposure, metering shots cleaned away
    assert len(session.ok_frames("dark")) == len(
        {t for v in exposures.values() for t in v}
    )
    assert not (session.root / "tmp").exists()  # metering shots removed with it


def test_auto_exposure_is_metered_at_the_sessions_iso(tmp_path, bench) -> None:
    """The camera starts at ISO 100; a session at ISO 400 must meter at ISO 400."""
    assert bench.camera.iso == 100
    session = _session(tmp_path, bench, exposure="auto", iso=400, channels=CHANNELS[2:])
    capture(session, bench.light, bench.camera, bench.stage)
    frame = load_raw(session.path_of(session.frame(f"white_{CHANNELS[2]}")))
    assert frame.iso == 400
    level = float(np.percentile(frame.planes.max(axis=0), 99.5))
    assert METERED_LEVEL_BAND[0] < level < METERED_LEVEL_BAND[1], level


def test_unsettled_metering_is_reported(tmp_path, bench, monkeypatch) -> None:
    import tunespec.devices.capture as capture_module

    monkeypatch.setattr(
        capture_module, "meter_exposure", lambda *a, **k: (2.0, float("nan"))
    )
    session = _session(tmp_path, bench, exposure="auto", channels=CHANNELS[:1])
    result = capture(session, bench.light, bench.camera, bench.stage)
    assert any("did not settle" in w for w in result.warnings)
    assert session.settings.exposures_s[CHANNELS[0]] == (2.0,)


def test_metering_recovers_from_clipping_and_darkness(tmp_path) -> None:
    class Cam:
        exposure_s = 1.0

        def set_exposure(self, t):
            self.exposure_s = t

        def capture(self, stem):
            p = Path(f"{stem}.dng")
            p.write_bytes(b"")
            return p

    def measure(path):  # a linear sensor reaching full scale at 0.2 s
        level = Cam.last.exposure_s / 0.2
        return min(level, 1.0), 0.5 if level >= 1 else 0.0

    cam = Cam()
    Cam.last = cam
    t, level = meter_exposure(
        cam, tmp_path / "m", start_s=1.0, target_level=0.75, measure=measure
    )
    assert t == pytest.approx(0.15) and level == pytest.approx(0.75)
    t, _ = meter_exposure(
        cam, tmp_path / "m", start_s=1e-4, target_level=0.75, measure=measure
    )
    assert t == pytest.approx(0.15)


def test_device_error_keeps_frames_and_resume_fills_the_rest(tmp_path, bench) -> None:
    session = _session(tmp_path, bench)
    flaky = _FlakyCamera(bench.camera, fail_at=4)
    with pytest.raises(DeviceTimeoutError):
        capture(session, bench.light, flaky, bench.stage)
    assert not np.any(bench.light.levels())  # switched off on the way out
    kept = {f.id: (f.sha256, session.path_of(f).read_bytes()) for f in session.frames}
    assert len(kept) == 3
    reopened = Session.open(session.root)
    result = capture(reopened, bench.light, bench.camera, bench.stage, resume=True)
    assert result.skipped == 3 and len(result.captured) == 4
    assert reopened.missing() == []
    for fid, (sha, data) in kept.items():
        rec = reopened.frame(fid)
        assert rec.sha256 == sha and reopened.path_of(rec).read_bytes() == data


def test_cancel_keeps_frames_and_switches_off(tmp_path, bench) -> None:
    session = _session(tmp_path, bench)
    seen: list[str] = []
    with pytest.raises(Cancelled):
        capture(
            session,
            bench.light,
            bench.camera,
            bench.stage,
            on_frame=lambda rec, _: seen.append(rec.id),
            should_stop=lambda: len(seen) >= 3,
        )
    assert [f.id for f in session.frames] == seen and len(seen) == 3
    assert not np.any(bench.light.levels())


def test_retake_replaces_only_that_frame(tmp_path, bench) -> None:
    session = _session(tmp_path, bench)
    capture(session, bench.light, bench.camera, bench.stage)
    before = {f.id: f.sha256 for f in session.frames}
    result = capture(
        session, bench.light, bench.camera, bench.stage, retake=["target_LED540"]
    )
    assert result.captured == ("target_LED540",)
    after = {f.id: f.sha256 for f in session.frames}
    assert after["target_LED540"] != before["target_LED540"]
    assert {k: v for k, v in after.items() if k != "target_LED540"} == {
        k: v for k, v in before.items() if k != "target_LED540"
    }


def test_resume_retakes_a_damaged_file(tmp_path, bench) -> None:
    session = _session(tmp_path, bench)
    capture(session, bench.light, bench.camera, bench.stage)
    victim = session.frame("white_LED450")
    session.path_of(victim).write_bytes(b"truncated")
    result = capture(session, bench.light, bench.camera, bench.stage, resume=True)
    assert result.captured == ("white_LED450",)
    assert session.verify(session.frame("white_LED450"))


def test_capture_refuses_a_started_session_without_resume(tmp_path, bench) -> None:
    session = _session(tmp_path, bench)
    capture(session, bench.light, bench.camera, bench.stage)
    with pytest.raises(InputError, match="resume"):
        capture(session, bench.light, bench.camera, bench.stage)


def test_new_session_checks_channels_and_exposures(tmp_path, bench) -> None:
    with pytest.raises(InputError, match="LED999"):
        _session(tmp_path, bench, channels=["LED999"])
    with pytest.raises(InputError, match="LED540"):
        _session(tmp_path, bench, exposure={"LED450": 1.0})


def test_brackets_are_planned_and_shot(tmp_path, bench) -> None:
    session = _session(tmp_path, bench, channels=("WHITE_WARM",), brackets=(1.0, 0.25))
    capture(session, bench.light, bench.camera, bench.stage)
    ids = sorted(f.id for f in session.frames)
    assert ids == sorted(
        [
            "dark_6s_iso100_0",
            "dark_1.5s_iso100_0",
            "white_WHITE_WARM",
            "white_WHITE_WARM_b1",
            "target_WHITE_WARM",
            "target_WHITE_WARM_b1",
        ]
    )
    assert session.frame("target_WHITE_WARM_b1").exposure_s == pytest.approx(1.5)


# -- registry -------------------------------------------------------------------------
def test_registry_specs() -> None:
    assert parse_resolution("640x480") == (640, 480)
    with pytest.raises(InputError):
        parse_resolution("640x")
    with pytest.raises(InputError, match="unknown light"):
        open_light_source("laser://x")
    with pytest.raises(InputError, match="unknown camera"):
        open_camera("polaroid")
    with pytest.raises(InputError, match="simulated light"):
        open_camera("sim")


def test_sim_bench_truth_and_spec_options() -> None:
    with open_bench("sim?seed=3", "sim?resolution=256x192") as b:
        assert b.simulated and b.camera.resolution == (256, 192)
        assert b.truth["corners_px"].shape == (4, 2)
        assert b.light.identity.serial.endswith("3")


def test_cal1_over_tcp_through_the_registry(cal1_emulator) -> None:
    light = open_light_source(cal1_emulator.spec)
    try:
        assert len(light.channels()) == 22
        light.set_levels(np.eye(22)[0])
        assert light.measure_spd().values.max() > 0
    finally:
        light.close()


def test_operator_stage_asks_only_when_something_changes() -> None:
    asked: list[str] = []
    stage = OperatorStage(asked.append)
    stage.present("white")
    stage.present("white")
    stage.present("target")
    assert len(asked) == 2 and "white" in asked[0].lower() and "target" in asked[1]
