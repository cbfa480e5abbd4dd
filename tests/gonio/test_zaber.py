"""The Zaber ASCII goniometer driver: scripted exchanges and the emulator."""

from __future__ import annotations

import pytest

from tunespec.core.errors import InputError
from tunespec.devices.goniometer import Geometry, Goniometer
from tunespec.devices.goniometer_registry import open_goniometer
from tunespec.devices.protocols import (
    DeviceCommandError,
    DeviceError,
    DeviceProtocolError,
    DeviceTimeoutError,
)
from tunespec.devices.sim.gonio import SimGoniometer
from tunespec.devices.testing import expected_protocol
from tunespec.devices.zaber.driver import ZaberAxis, ZaberGoniometer, open_zaber
from tunespec.devices.zaber.emulator import ZaberEmulator
from tunespec.devices.zaber.protocol import Alert, Reply, checksum, decode_line

SCALE = 0.001  # deg per step, round numbers in the scripts
AXES = [ZaberAxis("theta_i", 1, 1, SCALE), ZaberAxis("theta_r", 2, 1, SCALE, 10.0)]
LIMITS = [
    (b"/1 1 get limit.min\n", b"@01 1 OK IDLE -- -90000\r\n"),
    (b"/1 1 get limit.max\n", b"@01 1 OK IDLE -- 90000\r\n"),
    (b"/2 1 get limit.min\n", b"@02 1 OK IDLE -- -90000\r\n"),
    (b"/2 1 get limit.max\n", b"@02 1 OK IDLE -- 70000\r\n"),
]


def _driver(transport, **kw):
    return ZaberGoniometer(transport, AXES, poll_s=0.0, **kw)


def test_checksum_and_decoding():
    assert checksum("01 0 OK IDLE -- 0") == "8D"  # Zaber's manual example
    assert decode_line(b"@01 0 OK IDLE -- 0:8D") == Reply(1, 0, True, False, "--", "0")
    assert decode_line(b"!02 1 IDLE FS") == Alert(2, 1, False, "FS")
    assert decode_line(b"@01 1 RJ IDLE WR BADCOMMAND").data == "BADCOMMAND"
    with pytest.raises(DeviceProtocolError, match="checksum mismatch"):
        decode_line(b"@01 0 OK IDLE -- 0:8E")
    with pytest.raises(DeviceProtocolError, match="not a Zaber"):
        decode_line(b"hello")


def test_move_polls_until_idle_and_reads_back():
    script = [
        *LIMITS,
        (b"/1 1 move abs 45000\n", b"@01 1 OK BUSY -- 0\r\n"),
        (b"/2 1 move abs 20000\n", b"@02 1 OK BUSY -- 0\r\n"),
        (b"/1 1\n", b"@01 1 OK BUSY -- 0\r\n"),
        (b"/1 1\n", b"!01 1 IDLE --\r\n@01 1 OK IDLE -- 0\r\n"),  # alert first
        (b"/2 1\n", b"@02 1 OK IDLE -- 0\r\n"),
        (b"/1 1 get pos\n", b"@01 1 OK IDLE -- 45000\r\n"),
        (b"/2 1 get pos\n", b"@02 1 OK IDLE -- 20001\r\n"),
    ]
    with expected_protocol(_driver, script) as gonio:
        got = gonio.move_to({"theta_i": 45.0, "theta_r": 30.0})
    assert got == pytest.approx({"theta_i": 45.0, "theta_r": 30.001})
    assert gonio.alerts == [Alert(1, 1, False, "--")]


def test_limits_are_checked_before_anything_moves():
    with expected_protocol(_driver, LIMITS) as gonio:
        with pytest.raises(
            InputError, match=r"theta_r: target 85 deg outside .*-80..80"
        ):
            gonio.move_to({"theta_r": 85.0})
        with pytest.raises(InputError, match="unknown goniometer axis"):
            gonio.move_to({"phi_x": 0.0})


def test_rejection_fault_and_checksum():
    def summed(cmd: bytes) -> bytes:
        body = cmd[1:-1].decode()
        return f"/{body}:{checksum(body)}\n".encode()

    script = [(summed(c), r) for c, r in LIMITS]
    script.append((b"/1 1 move abs 1000:70\n", b"@01 1 RJ IDLE WR BADCOMMAND:XX\r\n"))
    with (
        expected_protocol(_driver, script, use_checksum=True) as gonio,
        pytest.raises(DeviceProtocolError, match="bad checksum field"),
    ):
        gonio.move_to({"theta_i": 1.0})
    script[-1] = (b"/1 1 move abs 1000:70\n", b"@01 1 RJ IDLE WR BADCOMMAND\r\n")
    with (
        expected_protocol(_driver, script, use_checksum=True) as gonio,
        pytest.raises(
            DeviceCommandError, match=r"rejected \(BADCOMMAND; warning flag WR"
        ),
    ):
        gonio.move_to({"theta_i": 1.0})
    stall = [
        *LIMITS,
        (b"/1 1 move abs 1000\n", b"@01 1 OK BUSY -- 0\r\n"),
        (b"/1 1\n", b"@01 1 OK IDLE FS 0\r\n"),
        (b"/1 1 stop\n", b"@01 1 OK IDLE FS 0\r\n"),
        (b"/2 1 stop\n", b"@02 1 OK IDLE -- 0\r\n"),
    ]
    with (
        expected_protocol(_driver, stall) as gonio,
        pytest.raises(DeviceError, match="fault FS"),
    ):
        gonio.move_to({"theta_i": 1.0})


def test_no_reply_names_the_device():
    with (
        expected_protocol(_driver, [(b"/1 1\n", b"")]) as gonio,
        pytest.raises(DeviceTimeoutError, match=r"device 1 axis 1 .*115200"),
    ):
        gonio.is_homed()


def test_identity_and_homing_status():
    script = [
        (b"/1 0 get device.id\n", b"@01 0 OK IDLE -- 30222\r\n"),
        (b"/1 0 get system.serial\n", b"@01 0 OK IDLE -- 12345\r\n"),
        (b"/1 0 get version\n", b"@01 0 OK IDLE -- 7.38\r\n"),
        (b"/1 1\n", b"@01 1 OK IDLE WR 0\r\n"),  # no reference: no need to ask axis 2
    ]
    with expected_protocol(_driver, script) as gonio:
        assert gonio.identity.serial == "12345" and gonio.identity.vendor == "Zaber"
        assert gonio.is_homed() is False


@pytest.fixture
def emulator():
    with ZaberEmulator(n_devices=4) as emu:
        yield emu
    assert not emu.errors


def test_emulator_run(emulator):
    gonio = open_zaber(emulator.spec(), poll_s=0.005, timeout_s=2.0)
    with gonio:
        assert isinstance(gonio, Goniometer)
        assert not gonio.is_homed()
        with pytest.raises(DeviceCommandError, match="BADCOMMAND"):
            gonio.move_to({"theta_i": 10.0})
        gonio.home()
        assert gonio.is_homed()
        g = Geometry(45.0, 0.0, 30.0, 180.0)
        got = gonio.move_to(g.as_dict())
        assert got == pytest.approx(g.as_dict(), abs=0.001)
        assert gonio.position() == pytest.approx(g.as_dict(), abs=0.001)
        assert gonio.identity.model == "device id 30222"
        emulator.inject_fault("stall")
        with pytest.raises(DeviceError, match="fault FS"):
            gonio.move_to({"theta_i": -45.0})
        # stopped half way, and a later move works again
        assert gonio.position()["theta_i"] == pytest.approx(0.0, abs=0.01)
        assert gonio.move_to({"theta_i": -45.0})["theta_i"] == pytest.approx(
            -45.0, abs=0.001
        )
    assert "/1 1 move abs 192000" in emulator.received


def test_emulator_with_checksums_and_a_lost_reply(emulator):
    gonio = open_zaber(emulator.spec("theta_i:3:1:0.01"), poll_s=0.005,
                       timeout_s=0.3, use_checksum=True)  # fmt: skip
    with gonio:
        gonio.home()
        assert gonio.move_to({"theta_i": 12.5}) == {"theta_i": pytest.approx(12.5)}
        emulator.inject_fault("no_reply")
        with pytest.raises(DeviceTimeoutError):
            gonio.position()
    assert all(":" in line for line in emulator.received)


def test_specs():
    assert isinstance(open_goniometer("sim"), SimGoniometer)
    with pytest.raises(InputError, match="unknown goniometer"):
        open_goniometer("nope")
    with pytest.raises(InputError, match="axes=NAME:DEVICE:AXIS"):
        open_zaber("zaber+socket://127.0.0.1:1?axes=theta_i:1")
    with pytest.raises(InputError, match=r"theta_i = 95 deg outside"):
        Geometry(95.0, 0, 0, 0)


def test_sim_goniometer():
    sim = SimGoniometer(fail_after_moves=3)
    with pytest.raises(DeviceCommandError, match="home it first"):
        sim.move_to({"theta_i": 1.0})
    sim.home()
    assert sim.move_to({"theta_i": 30.0})["theta_i"] == 30.0
    sim.move_to({"theta_r": 10.0})
    with pytest.raises(DeviceError, match="lost"):
        sim.move_to({"theta_r": 20.0})


def test_cli_emulator_serves_the_driver():
    import io
    import re
    import threading
    import time

    from tunespec.app.cli import build_parser
    from tunespec.app.cli.gonio_cmds import run_zaber_emulator

    args = build_parser().parse_args(["emulate", "zaber", "--devices", "2"])
    assert args.devices == 2
    stop, out = threading.Event(), io.StringIO()
    t = threading.Thread(
        target=run_zaber_emulator, kwargs={"n_devices": 2, "stop": stop, "out": out}
    )
    t.start()
    try:
        for _ in range(100):
            if "spec:" in out.getvalue():
                break
            time.sleep(0.02)
        spec = re.search(r"spec: (\S+)", out.getvalue()).group(1)
        with open_zaber(
            spec + "?axes=theta_i:1:1:0.01,theta_r:2:1:0.01", poll_s=0.005
        ) as g:
            g.home()
            assert g.move_to({"theta_r": 30.0}) == pytest.approx(
                {"theta_i": 0.0, "theta_r": 30.0}
            )
    finally:
        stop.set()
        t.join(5)
