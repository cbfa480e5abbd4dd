"""Issue 12: a capture killed (SIGKILL) at random moments -- during the raw write, the
SPD write, the manifest write, between commit steps, or at a random time -- resumes
to a session whose every frame and SPD verifies against its checksums."""

from __future__ import annotations

import os
import signal
import threading

import numpy as np
import pytest

from tunespec.app.pipeline.plan import sample_layout
from tunespec.core.io.session import Session
from tunespec.devices.capture import capture, new_session
from tunespec.devices.registry import open_bench

pytestmark = pytest.mark.skipif(not hasattr(os, "fork"), reason="needs os.fork")

RESOLUTION = (256, 192)
CHANNELS = ("LED450", "LED540", "WHITE_WARM")
#: Where a kill can land; the number says after how many calls of that step (the
#: timer kills after a random delay: the whole capture takes about 0.4 s).
POINTS = ("raw_write", "spd_write", "manifest_write", "before_record", "timer")


def _die() -> None:
    os.kill(os.getpid(), signal.SIGKILL)


def _arm(point: str, nth: int, delay_s: float) -> None:
    """In the child: make the ``nth`` call of ``point`` (or a timer) kill the process
    half-way through what it writes."""
    import tunespec.core.io.session as session_mod
    import tunespec.devices.dng as dng

    calls = {"n": 0}

    def due() -> bool:
        calls["n"] += 1
        return calls["n"] == nth

    def half_written_then_die(real, suffix, to_bytes):
        """``real(path, data)``, but the due call leaves half of ``data`` in a
        temporary file beside ``path`` and dies."""

        def write(path, data):
            if due():
                blob = to_bytes(data)
                part = path.with_name(f".{path.name}.killed{suffix}")
                part.write_bytes(blob[: len(blob) // 2])
                _die()
            return real(path, data)

        return write

    if point == "raw_write":
        dng._write_atomic = half_written_then_die(
            dng._write_atomic, ".part", lambda c: b"".join(bytes(x) for x in c)
        )
    elif point == "spd_write":
        real_spd = session_mod.write_spectra_csv

        def spd(spectra, path, **kw):
            real_spd(spectra, path, **kw)
            if due():
                with open(path, "r+b") as fh:
                    fh.truncate(os.path.getsize(path) // 2)
                _die()

        session_mod.write_spectra_csv = spd
    elif point == "manifest_write":
        session_mod.atomic_write_text = half_written_then_die(
            session_mod.atomic_write_text, ".tmp", str.encode
        )
    elif point == "before_record":
        real_put = session_mod.Session._put

        def put(self, record):
            if due():
                _die()
            return real_put(self, record)

        session_mod.Session._put = put
    else:
        threading.Timer(delay_s, _die).start()


def _bench():
    return open_bench("sim", resolution=RESOLUTION, layout=sample_layout(), seed=3)


def _start_or_resume(root) -> None:
    with _bench() as bench:
        if (root / "manifest.json").is_file():
            session, resume = Session.open(root), True
        else:
            session = new_session(
                root,
                bench.light,
                bench.camera,
                layout=sample_layout(),
                exposure=6.0,
                channels=CHANNELS,
            )
            resume = False
        capture(session, bench.light, bench.camera, bench.stage, resume=resume)


def _kill_and_resume(tmp_path, point: str, nth: int, delay_s: float) -> None:
    root = tmp_path / f"{point}_{nth}"
    pid = os.fork()
    if pid == 0:  # the child: capture until killed, never back into pytest
        code = 1
        try:
            _arm(point, nth, delay_s)
            _start_or_resume(root)
            code = 0
        finally:
            os._exit(code)
    _, status = os.waitpid(pid, 0)
    killed = os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL
    # a timer may (on a fast machine) come after the end; every other point is reached
    assert killed or point == "timer", f"{point} #{nth}: the capture ended first"
    assert killed or (os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0)
    _start_or_resume(root)
    session = Session.open(root)
    assert session.missing() == [], f"{point} #{nth}: frames left to take"
    for rec in session.frames:
        assert session.problem(rec) == "", f"{point} #{nth}: {rec.id}"
        if rec.spd_file is not None:
            assert session.read_spd(rec).values.max() > 0
    assert not (root / "tmp").exists() or not any((root / "tmp").iterdir())


def _moments(n: int, seed: int) -> list[tuple[str, int, float]]:
    """``n`` kill moments: every point at least once, the rest drawn at random."""
    rng = np.random.default_rng(seed)
    points = list(POINTS) + list(rng.choice(POINTS, n - len(POINTS)))
    # 1 dark + 3 white + 3 target frames; about 10 manifest writes
    most = {"raw_write": 7, "spd_write": 6, "manifest_write": 10, "before_record": 7}
    return [
        (
            str(p),
            int(rng.integers(1, most.get(str(p), 1) + 1)),
            float(rng.uniform(0.02, 0.25)),
        )
        for p in points
    ]


def test_kill_during_spd_and_manifest_writes_then_resume(tmp_path) -> None:
    for point, nth, delay_s in [
        ("spd_write", 2, 0.0),
        ("manifest_write", 4, 0.0),
        ("raw_write", 3, 0.0),
    ]:
        _kill_and_resume(tmp_path, point, nth, delay_s)


@pytest.mark.slow
@pytest.mark.parametrize(("point", "nth", "delay_s"), _moments(20, seed=12))
def test_kill_at_20_random_moments_then_resume(tmp_path, point, nth, delay_s) -> None:
    _kill_and_resume(tmp_path, point, nth, delay_s)
