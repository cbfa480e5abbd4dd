"""``tunespec demo | capture | process | run`` from the command line.

The crash test runs ``tunespec capture`` in a child process, kills it with SIGKILL in
the middle of the sequence, resumes the session and checks that nothing captured
before the kill changed and nothing is missing.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tunespec.app.cli import main
from tunespec.core.datasets import resource_path
from tunespec.core.io.responses_csv import read_responses_csv
from tunespec.core.io.session import MANIFEST_NAME, Session

LAYOUT = resource_path("layouts", "neugebauer_cmy.json")
#: Wall-clock budget of the killed capture (a safety net, not a timing assertion).
KILL_DEADLINE_S = 120.0
#: Frames the child must have committed before it is killed.
KILL_AFTER_FRAMES = 8


def _frames_in(manifest: Path) -> int:
    try:
        return len(json.loads(manifest.read_text())["frames"])
    except (FileNotFoundError, json.JSONDecodeError, KeyError):
        return 0


def test_sigkill_mid_capture_then_resume(tmp_path, capsys) -> None:
    out = tmp_path / "session"
    # realtime: the simulated camera really waits each exposure, so the child is
    # still capturing when it is killed
    args = [
        "capture", "--light", "sim", "--camera", "sim?realtime=1",
        "--resolution", "384x256", "--layout", str(LAYOUT), "--out", str(out),
        "--exposure", "0.05",
    ]  # fmt: skip
    child = subprocess.Popen(
        [sys.executable, "-m", "tunespec.app.cli", *args],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    try:
        deadline = time.monotonic() + KILL_DEADLINE_S
        while _frames_in(out / MANIFEST_NAME) < KILL_AFTER_FRAMES:
            assert child.poll() is None, child.stderr.read().decode()
            assert time.monotonic() < deadline, "the capture did not start in time"
            time.sleep(0.01)
        os.kill(child.pid, signal.SIGKILL)
        child.wait()
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
        child.stderr.close()
    assert child.returncode == -signal.SIGKILL

    killed = Session.open(out)
    done = {f.id: (f, killed.path_of(f).read_bytes()) for f in killed.frames}
    missing_before = killed.missing()
    assert done and missing_before, "the kill should land mid-sequence"
    # a resume refuses without --resume ...
    assert main(["capture", "--light", "sim", "--out", str(out)]) == 2
    # ... and with it takes only what is missing (no realtime needed now)
    resume_args = ["capture", "--light", "sim", "--camera", "sim",
                   "--resolution", "384x256", "--out", str(out), "--resume"]  # fmt: skip
    assert main(resume_args) == 0
    resumed = Session.open(out)
    assert resumed.missing() == []
    assert {f.id for f in missing_before} <= {f.id for f in resumed.frames}
    for fid, (rec, data) in done.items():
        now = resumed.frame(fid)
        assert now == rec  # same record: checksum, time, exposure
        assert resumed.path_of(now).read_bytes() == data
    assert not (out / "tmp").exists()
    capsys.readouterr()


def test_retake_one_frame_then_process(tmp_path, capsys) -> None:
    out = tmp_path / "s"
    base = ["capture", "--light", "sim", "--resolution", "384x256", "--out", str(out)]
    assert main([*base, "--layout", str(LAYOUT), "--exposure", "2",
                 "--channels", "LED450,WHITE_WARM"]) == 0  # fmt: skip
    before = {f.id: f.sha256 for f in Session.open(out).frames}
    assert main([*base, "--retake", "white_LED450"]) == 0
    after = {f.id: f.sha256 for f in Session.open(out).frames}
    assert after.pop("white_LED450") != before.pop("white_LED450")
    assert after == before
    assert "1 frame(s) captured" in capsys.readouterr().out

    assert main(["process", str(out), "-o", str(tmp_path / "r.csv")]) == 0
    r = read_responses_csv(tmp_path / "r.csv")
    assert r.rgb.shape == (8, 2, 3) and r.illuminants == ("LED450", "WHITE_WARM")
    assert (tmp_path / "r_illuminants.csv").is_file()
    said = capsys.readouterr().out
    assert "corners (auto)" in said and "(aperture not recorded)" in said
    assert main(["process", str(out), "-o", str(tmp_path / "r.csv"), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["f_number"] is None and summary["patches"] == 8


def test_capture_input_errors_exit_2(tmp_path, capsys) -> None:
    assert main(["capture", "--light", "sim", "--out", str(tmp_path / "x")]) == 2
    assert "--layout" in capsys.readouterr().err
    assert main(["capture", "--light", "nope", "--layout", str(LAYOUT),
                 "--out", str(tmp_path / "y")]) == 2  # fmt: skip
    assert main(["process", str(tmp_path / "none"), "-o", str(tmp_path / "r.csv")]) == 2


@pytest.mark.slow
def test_demo_command_prints_both_tables(tmp_path, capsys) -> None:
    out = tmp_path / "demo"
    record = ["--operator", "Kim", "--sample-id", "CMY-1", "--temperature-c", "23"]
    rc = main(
        ["demo", "--out", str(out), "--resolution", "512x340", "--no-report", *record]
    )
    text = capsys.readouterr().out
    assert rc == 0
    assert "Table 1" in text and "Table 2" in text and "average" in text
    assert (out / "summary.json").is_file()
    # the exports under export/, listed there, as the GUI wizard writes them
    index = json.loads((out / "export" / "exports.json").read_text())
    assert index["reflectances_csv"] == "reflectances.csv"
    assert all((out / "export" / name).is_file() for name in index.values())
    assert not (out / "reflectances.csv").exists()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["table1_rgb_rms_mean"] <= 0.0024
    # the good bench passes its self-check (issue 23): reduced chi-square 0.87-1.07
    # at this resolution, 1 in 5 left-out patches predicted as well as the fitted
    assert "Self-check:" in text and "all checks passed" in text
    checked = summary["self_check"]
    assert checked["passed"] is True and checked["warnings"] == []
    assert max(checked["residual_chi_square"]["reduced"].values()) < 1.5
    held = checked["held_out"]
    assert held["prediction"]["RGB"]["mean"] < 1.5 * held["training"]["RGB"]["mean"]
    assert not any("self-check" in w for w in summary["warnings"])
    # the measurement record (issue 27): kept in the folder, in summary.json with
    # the devices' serials and the software
    prov = summary["provenance"]
    assert (prov["operator"], prov["sample_id"], prov["temperature_c"]) == (
        "Kim",
        "CMY-1",
        "23",
    )
    assert prov["chart"] == "ColorChecker SG" and prov["chart_serial"] == ""
    assert [i["serial_source"] for i in prov["instruments"]] == ["device"] * 3
    assert prov["settings"]["sensitivity method"] == "bayes"
    light = prov["light_status"]  # the simulated light's own status
    assert float(light["light source case temperature at the run's start (°C)"]) > 15
    assert json.loads((out / "record.json").read_text())["operator"] == "Kim"
