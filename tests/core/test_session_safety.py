"""Issue 12, items 1-3: temp cleaning stays inside the session, one writer at a time,
every file a frame depends on is checksummed and verified."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys

import numpy as np
import pytest

from tunespec.core.errors import InputError
from tunespec.core.io.session import (
    LOCK_NAME,
    CaptureSettings,
    FrameSpec,
    Session,
    SessionBusyError,
    SessionLock,
    plan_frames,
)
from tunespec.core.spectra import Spectra

SETTINGS = CaptureSettings(
    ("L1", "L2"), exposure_mode="fixed", exposures_s={"L1": (0.5,), "L2": (2.0,)}
)


def _spd(peak: float = 0.3) -> Spectra:
    return Spectra(np.array([400.0, 500.0, 600.0]), [[0.1, peak, 0.2]], ("measured",))


def _full_session(root) -> Session:
    s = Session.create(root, settings=SETTINGS)
    for spec in plan_frames(SETTINGS):
        path = s.temp_stem(spec.id).with_suffix(".dng")
        path.write_bytes(b"raw" + spec.id.encode())
        s.commit_frame(spec, path, spd=None if spec.kind == "dark" else _spd())
    return s


# -- 1. temp cleaning ------------------------------------------------------------------
def test_clean_temp_never_follows_a_tmp_symlink(tmp_path) -> None:
    s = _full_session(tmp_path / "s")
    other = tmp_path / "other"
    other.mkdir()
    (other / "precious.txt").write_text("keep me")
    (other / "sub").mkdir()
    tmp = s.root / "tmp"
    for p in tmp.iterdir():
        p.unlink()
    tmp.rmdir()
    tmp.symlink_to(other, target_is_directory=True)
    s.clean_temp()
    assert (other / "precious.txt").read_text() == "keep me"
    assert (other / "sub").is_dir()
    # and a new temp file lands inside the session, not in the linked folder
    stem = s.temp_stem("x")
    assert not (s.root / "tmp").is_symlink()
    assert stem.parent.resolve() == (s.root / "tmp").resolve()
    assert list(other.iterdir()) == [other / "precious.txt", other / "sub"] or sorted(
        p.name for p in other.iterdir()
    ) == ["precious.txt", "sub"]


def test_clean_temp_removes_links_inside_tmp_not_their_targets(tmp_path) -> None:
    s = _full_session(tmp_path / "s")
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me")
    (s.root / "tmp" / "link").symlink_to(victim)
    s.clean_temp()
    assert victim.read_text() == "keep me"
    assert not (s.root / "tmp" / "link").is_symlink()


def test_commit_refuses_a_frames_folder_that_links_elsewhere(tmp_path) -> None:
    s = Session.create(tmp_path / "s", settings=SETTINGS)
    other = tmp_path / "other"
    other.mkdir()
    (s.root / "frames").rmdir()
    (s.root / "frames").symlink_to(other, target_is_directory=True)
    spec = plan_frames(SETTINGS)[0]
    path = s.temp_stem(spec.id).with_suffix(".dng")
    path.write_bytes(b"raw")
    with pytest.raises(InputError, match="frames"):
        s.commit_frame(spec, path)
    assert list(other.iterdir()) == []


# -- 2. lock, SPD temp names -----------------------------------------------------------
def test_spd_temp_name_keeps_the_process_id(tmp_path, monkeypatch) -> None:
    s = Session.create(tmp_path / "s", settings=SETTINGS)
    seen = []
    import tunespec.core.io.session as mod

    real = mod.write_spectra_csv

    def spy(spd, path, **kw):
        seen.append(str(path))
        return real(spd, path, **kw)

    monkeypatch.setattr(mod, "write_spectra_csv", spy)
    spec = FrameSpec("white_L1", "white", "L1", 0.5, 100)
    path = s.temp_stem(spec.id).with_suffix(".dng")
    path.write_bytes(b"raw")
    s.commit_frame(spec, path, spd=_spd())
    assert seen and str(os.getpid()) in os.path.basename(seen[0])


def _lock_script(root, *lines: str) -> str:
    """Python code taking the session lock of ``root`` in another process, then
    running ``lines`` (``lock`` is the lock)."""
    head = "from tunespec.core.io.session import SessionLock\n"
    return (
        head
        + f"lock = SessionLock({str(root)!r}); lock.acquire()\n"
        + "".join(f"{line}\n" for line in lines)
    )


def test_a_second_writer_is_refused_naming_the_holder(tmp_path) -> None:
    root = tmp_path / "s"
    root.mkdir()
    code = _lock_script(
        root, "import sys", "print('locked', flush=True)", "sys.stdin.readline()",
        "lock.release()",
    )  # fmt: skip
    with subprocess.Popen(
        [sys.executable, "-c", code],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    ) as child:
        try:
            assert child.stdout.readline().strip() == "locked"
            with pytest.raises(SessionBusyError) as info:
                SessionLock(root).acquire()
            msg = str(info.value)
            assert f"pid {child.pid}" in msg
            assert socket.gethostname() in msg
            assert "since" in msg and "\n" not in msg
        finally:
            child.stdin.close()
            child.wait(timeout=30)
    # the holder is gone: the lock is free again (released cleanly, nothing stale)
    lock = SessionLock(root)
    lock.acquire()
    assert lock.stale_holder is None
    lock.release()


def test_a_stale_lock_of_a_killed_process_is_taken_over(tmp_path) -> None:
    root = tmp_path / "s"
    root.mkdir()
    code = _lock_script(
        root, "import os, signal", "os.kill(os.getpid(), signal.SIGKILL)"
    )
    child = subprocess.run([sys.executable, "-c", code], check=False)
    assert child.returncode == -9
    holder = json.loads((root / LOCK_NAME).read_text())
    lock = SessionLock(root)
    lock.acquire()
    try:
        assert lock.stale_holder is not None
        assert lock.stale_holder["pid"] == holder["pid"]
        assert json.loads((root / LOCK_NAME).read_text())["pid"] == os.getpid()
    finally:
        lock.release()


def test_the_lock_is_reentrant_within_one_process(tmp_path) -> None:
    root = tmp_path / "s"
    a, b = SessionLock(root), SessionLock(root)
    a.acquire()
    b.acquire()
    b.release()
    # still held by ``a``: another process would be refused
    out = subprocess.run(
        [
            sys.executable,
            "-c",
            "from tunespec.core.io.session import SessionLock\n"
            f"SessionLock({str(root)!r}).acquire()",
        ],
        capture_output=True,
        text=True,
        check=False,
    )
    assert "SessionBusyError" in out.stderr
    a.release()


# -- 3. checksums of every file a frame depends on -------------------------------------
def test_a_damaged_or_missing_spd_makes_the_frame_missing(tmp_path) -> None:
    s = _full_session(tmp_path / "s")
    assert s.missing() == []
    rec = s.frame("target_L1")
    assert rec.spd_sha256
    spd = s.root / rec.spd_file
    spd.write_bytes(spd.read_bytes()[:20])
    assert [f.id for f in Session.open(s.root).missing()] == ["target_L1"]
    spd.unlink()
    assert [f.id for f in Session.open(s.root).missing(verify=False)] == ["target_L1"]


def test_verify_names_what_is_wrong(tmp_path) -> None:
    s = _full_session(tmp_path / "s")
    rec = s.frame("white_L2")
    (s.root / rec.spd_file).write_text("wavelength_nm,measured\n400,1\n500,1\n")
    assert "SPD" in s.problem(rec)
    assert s.problem(s.frame("white_L1")) == ""
