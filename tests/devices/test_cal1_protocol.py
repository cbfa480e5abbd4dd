"""CAL1 driver against scripted exchanges (PyMeasure ``expected_protocol`` style).

Every test states the exact bytes the driver must send and the replies it gets from
:class:`FakeTransport`, which fails on any deviation and, at the end of the ``with``
block, on anything left unconsumed. The bytes are those of the *assumed* protocol in
``devices/cal1/PROTOCOL.md``; when the bench shows the real one, these expectations
change together with ``devices/cal1/commands.py``.
"""

from __future__ import annotations

import socket

import numpy as np
import pytest

from tunespec.core.errors import InputError
from tunespec.devices.cal1 import commands as cmds
from tunespec.devices.cal1.driver import Cal1LightSource, open_cal1, parse_cal1_spec
from tunespec.devices.cal1.transport import SerialTransport, Transport
from tunespec.devices.protocols import (
    DeviceBusyError,
    DeviceCommandError,
    DeviceConnectionError,
    DeviceError,
    DeviceProtocolError,
    DeviceTimeoutError,
    LightSource,
)
from tunespec.devices.testing import (
    DROP,
    REOPEN,
    REOPEN_FAILS,
    FakeTransport,
    expected_protocol,
)

IDN = (b"*IDN?\n", b"Image Engineering,CAL1,SN042,1.2.3\n")
COUNT = (b"CHAN:COUNT?\n", b"3\n")
LIST = (b"CHAN:LIST?\n", b"LED450,450.0,N;LED630,630.0,N;WHITE_COOL,444.0,W\n")
OFF = (b"OUTP:OFF\n", b"OK\n")
OPENED = [IDN, COUNT, LIST]  # what open_cal1 exchanges
TIMEOUT_S = 0.5
MEASURE_TIMEOUT_S = 7.0


def make_driver(transport: FakeTransport) -> Cal1LightSource:
    return Cal1LightSource(
        transport,
        spec="cal1+fake://",
        timeout_s=TIMEOUT_S,
        measure_timeout_s=MEASURE_TIMEOUT_S,
    )


# --- commands: the table's encoders and decoders ---------------------------------------


@pytest.mark.parametrize(
    ("key", "args", "line"),
    [
        ("identify", (), b"*IDN?\n"),
        ("channel_count", (), b"CHAN:COUNT?\n"),
        ("channel_list", (), b"CHAN:LIST?\n"),
        ("set_level", (0, 0.5), b"CHAN:LEVEL 1 0.5000\n"),
        ("set_levels", ([0.25, 0.0, 1.0],), b"CHAN:LEVEL:ALL 0.2500,0.0000,1.0000\n"),
        ("get_levels", (), b"CHAN:LEVEL:ALL?\n"),
        ("all_off", (), b"OUTP:OFF\n"),
        ("measure_spd", (), b"MEAS:SPD?\n"),
        ("status", (), b"SYST:STAT?\n"),
    ],
)
def test_request_bytes_and_device_side_decoding(
    key: str, args: tuple[object, ...], line: bytes
) -> None:
    assert cmds.encode_request(key, *args) == line
    request = cmds.decode_request(line.rstrip(b"\n"))
    assert request.command.key == key
    for got, sent in zip(request.args, args, strict=True):
        np.testing.assert_allclose(got, sent)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("identify", cmds.Identity("Image Engineering", "CAL1", "SN1", "2.0")),
        ("channel_count", 22),
        ("channel_list", [cmds.ChannelInfo("LED410", 410.0, "narrowband")]),
        ("get_levels", np.array([0.0, 0.1234, 1.0])),
        (
            "measure_spd",
            cmds.MeasuredSpectrum(380.0, 1.0, np.array([0.0, 1.5e-4, 2.25e-7])),
        ),
        ("status", {"READY": "1", "TEMP_C": "30.50", "ON_S": "2.0", "MSG": "ok"}),
        ("all_off", None),
    ],
)
def test_replies_round_trip(key: str, value: object) -> None:
    decoded = cmds.decode_reply(key, cmds.encode_reply(key, value).rstrip(b"\n"))  # type: ignore[arg-type]
    if isinstance(value, cmds.MeasuredSpectrum):
        assert isinstance(decoded, cmds.MeasuredSpectrum)
        np.testing.assert_allclose(decoded.values, value.values, rtol=1e-6)
        assert (decoded.start_nm, decoded.step_nm) == (380.0, 1.0)
    elif isinstance(value, np.ndarray):
        np.testing.assert_allclose(decoded, value)  # type: ignore[arg-type]
    else:
        assert decoded == value


@pytest.mark.parametrize(
    ("line", "code"),
    [
        (b"FOO?", cmds.ErrorCode.UNKNOWN_COMMAND),
        (b"CHAN:LEVEL 1", cmds.ErrorCode.BAD_ARGUMENT),
        (b"CHAN:LEVEL one 0.5", cmds.ErrorCode.BAD_ARGUMENT),
        (b"CHAN:LEVEL 0 0.5", cmds.ErrorCode.BAD_CHANNEL),
        (b"CHAN:LEVEL 1 1.5", cmds.ErrorCode.BAD_LEVEL),
        (b"CHAN:LEVEL:ALL 0.1,nan", cmds.ErrorCode.BAD_LEVEL),
        (b"\xff\xfe", cmds.ErrorCode.BAD_ARGUMENT),
    ],
)
def test_device_side_refuses_bad_requests(line: bytes, code: int) -> None:
    with pytest.raises(cmds.ErrorReply) as info:
        cmds.decode_request(line)
    assert info.value.code == code


@pytest.mark.parametrize(
    ("key", "reply"),
    [
        ("identify", b"CAL1"),
        ("channel_count", b"-3"),
        ("channel_list", b"LED410,410.0,X"),
        ("get_levels", b"0.1,,0.3"),
        ("measure_spd", b"380,1,3,0.1,0.2"),
        ("measure_spd", b"380,0,2,0.1,0.2"),
        ("status", b"READY=1;TEMP_C=20"),
        ("status", b"READY=yes;TEMP_C=20;ON_S=0"),
        ("all_off", b"DONE"),
        ("all_off", b"\x00\xff"),
    ],
)
def test_driver_side_rejects_invalid_replies(key: str, reply: bytes) -> None:
    with pytest.raises(DeviceProtocolError, match=r"reply"):
        cmds.decode_reply(key, reply)


def test_error_replies_are_decoded_with_code_and_text() -> None:
    with pytest.raises(cmds.ErrorReply) as info:
        cmds.decode_reply("all_off", b"ERR 300 over temperature")
    assert (info.value.code, info.value.text) == (300, "over temperature")
    assert cmds.error_info(409).exc_class is DeviceBusyError
    assert cmds.error_info(12345).exc_class is DeviceCommandError
    assert cmds.encode_error(101, "bad\nline") == b"ERR 101 bad line\n"


# --- driver: the normal exchanges -------------------------------------------------------


def test_identity_is_read_once() -> None:
    with FakeTransport([IDN]) as fake:
        dev = make_driver(fake)
        ident = dev.identity
        assert (ident.vendor, ident.model, ident.serial, ident.firmware) == (
            "Image Engineering",
            "CAL1",
            "SN042",
            "1.2.3",
        )
        assert ident.spec == "cal1+fake://"
        assert dev.identity is ident
        assert isinstance(dev, LightSource) and isinstance(fake, Transport)


def test_a_device_that_is_not_a_cal1_is_refused_and_left_alone() -> None:
    with (
        FakeTransport([(b"*IDN?\n", b"ACME,PSU-3000,1,1\n")]) as fake,
        pytest.raises(DeviceProtocolError, match="not a CAL1"),
    ):
        _ = make_driver(fake).identity


def test_channels() -> None:
    with expected_protocol(make_driver, OPENED) as dev:
        channels = dev.channels()
    assert [(c.index, c.name, c.peak_nm, c.kind) for c in channels] == [
        (0, "LED450", 450.0, "narrowband"),
        (1, "LED630", 630.0, "narrowband"),
        (2, "WHITE_COOL", 444.0, "white"),
    ]


def test_set_levels_sends_all_channels_in_one_line() -> None:
    script = [*OPENED, (b"CHAN:LEVEL:ALL 0.2500,0.0000,1.0000\n", b"OK\n")]
    with expected_protocol(make_driver, script) as dev:
        dev.set_levels(np.array([0.25, 0.0, 1.0]))


@pytest.mark.parametrize(
    "bad", [[0.5, 0.5], [0.1, 0.2, 1.01], [-0.1, 0.0, 0.0], [np.inf, 0.0, 0.0]]
)
def test_bad_levels_are_refused_before_sending(bad: list[float]) -> None:
    with FakeTransport(OPENED) as fake, pytest.raises(ValueError, match="level"):
        make_driver(fake).set_levels(np.array(bad))


def test_set_one_level_numbers_channels_from_1() -> None:
    with FakeTransport([*OPENED, (b"CHAN:LEVEL 2 0.5000\n", b"OK\n")]) as fake:
        dev = make_driver(fake)
        dev.set_level(1, 0.5)
        with pytest.raises(ValueError, match="index"):
            dev.set_level(3, 0.5)


def test_levels_are_read_back() -> None:
    with FakeTransport(
        [*OPENED, (b"CHAN:LEVEL:ALL?\n", b"0.2500,0.0000,1.0000\n")]
    ) as fake:
        np.testing.assert_array_equal(make_driver(fake).levels(), [0.25, 0.0, 1.0])


def test_all_off() -> None:
    with expected_protocol(make_driver, [IDN, OFF]) as dev:
        dev.all_off()


def test_measure_spd_builds_a_spectrum_with_the_long_timeout() -> None:
    reply = b"380,50,9,1.000000e-03,2.500000e-03" + b",0.000000e+00" * 7 + b"\n"
    with FakeTransport([IDN, (b"MEAS:SPD?\n", reply)]) as fake:
        spd = make_driver(fake).measure_spd()
    np.testing.assert_array_equal(spd.wavelength_nm, np.arange(380.0, 781.0, 50.0))
    np.testing.assert_array_equal(spd.values, [[1e-3, 2.5e-3, *[0.0] * 7]])
    assert spd.names == ("measured",)
    assert spd.meta["unit"] == "W sr^-1 m^-2 nm^-1"
    assert spd.meta["device"] == "Image Engineering CAL1 SN042"
    assert fake.timeouts_s == [TIMEOUT_S, MEASURE_TIMEOUT_S]


def test_status() -> None:
    reply = b"READY=0;TEMP_C=27.25;ON_S=12.5;WARMUP_LEFT_S=300.0;MSG=warming up\n"
    with FakeTransport([IDN, (b"SYST:STAT?\n", reply)]) as fake:
        status = make_driver(fake).status()
    assert status.ready is False
    assert (status.temperature_c, status.on_time_s) == (27.25, 12.5)
    assert status.message == "warming up"
    assert status.extra == {"warmup_left_s": "300.0"}


def test_close_switches_off_once_and_then_refuses() -> None:
    with FakeTransport([IDN, OFF]) as fake:
        dev = make_driver(fake)
        dev.identity  # noqa: B018
        dev.close()
        dev.close()
        assert not fake.is_open
        with pytest.raises(DeviceConnectionError, match="closed"):
            dev.all_off()


def test_close_of_an_unidentified_driver_sends_nothing() -> None:
    with FakeTransport([]) as fake:
        make_driver(fake).close()


def test_a_late_reply_is_flushed_before_the_next_command() -> None:
    fake = FakeTransport([IDN, (b"OUTP:OFF\n", b"OK\n")])
    dev = make_driver(fake)
    dev.identity  # noqa: B018
    fake._rx += b"stale reply\n"  # arrived after a timeout, before the next command
    dev.all_off()
    fake.assert_consumed()


# --- driver: failures -------------------------------------------------------------------


@pytest.mark.parametrize(
    ("reply", "exc_class", "text"),
    [
        (b"ERR 103 level out of range\n", DeviceCommandError, "0..1"),
        (b"ERR 100 unknown command\n", DeviceCommandError, "firmware"),
        (b"ERR 300 over temperature\n", DeviceCommandError, "cool down"),
        (b"ERR 777 strange\n", DeviceCommandError, "Unknown error code"),
    ],
)
def test_error_replies_raise_and_switch_off(
    reply: bytes, exc_class: type[DeviceError], text: str
) -> None:
    script = [*OPENED, (b"CHAN:LEVEL:ALL 0.5000,0.5000,0.5000\n", reply), OFF]
    with FakeTransport(script) as fake, pytest.raises(exc_class) as info:
        make_driver(fake).set_levels(np.full(3, 0.5))
    message = str(info.value)
    assert "CAL1 light source SN042 on fake://cal1" in message
    assert reply.decode().strip() in message and text in message
    assert "The lights were switched off." in message


def test_busy_reply_leaves_the_lights_alone() -> None:
    script = [IDN, (b"SYST:STAT?\n", b"ERR 409 busy: another client\n")]
    with (
        FakeTransport(script) as fake,
        pytest.raises(DeviceBusyError, match="another program"),
    ):
        make_driver(fake).status()


def test_timeout_raises_and_switches_off() -> None:
    with (
        FakeTransport([IDN, (b"MEAS:SPD?\n", b""), OFF]) as fake,
        pytest.raises(DeviceTimeoutError) as info,
    ):
        make_driver(fake).measure_spd()
    message = str(info.value)
    assert "no reply to MEAS:SPD? within 7 s" in message
    assert "switched on and its USB cable" in message
    assert "The lights were switched off." in message


def test_recovery_skips_the_late_reply_to_the_failed_command() -> None:
    late_then_ok = b"380,1,2,0.0,0.0\nOK\n"
    with (
        FakeTransport(
            [IDN, (b"MEAS:SPD?\n", b""), (b"OUTP:OFF\n", late_then_ok)]
        ) as fake,
        pytest.raises(DeviceTimeoutError, match="were switched off"),
    ):
        make_driver(fake).measure_spd()


def test_garbage_raises_a_protocol_error_and_switches_off() -> None:
    with (
        FakeTransport([IDN, (b"SYST:STAT?\n", b"\x00\xfe#garbage\xff\n"), OFF]) as fake,
        pytest.raises(DeviceProtocolError) as info,
    ):
        make_driver(fake).status()
    message = str(info.value)
    assert "unexpected reply to SYST:STAT?" in message
    assert "115200 baud" in message and "switched off" in message


def test_dropped_connection_reconnects_to_switch_off() -> None:
    script = [*OPENED, (b"CHAN:LEVEL:ALL?\n", DROP), REOPEN, OFF]
    with FakeTransport(script) as fake, pytest.raises(DeviceConnectionError) as info:
        make_driver(fake).levels()
    message = str(info.value)
    assert "connection lost during CHAN:LEVEL:ALL?" in message
    assert "Check the USB cable" in message and "switched off" in message


def test_when_the_lights_cannot_be_switched_off_the_operator_is_told() -> None:
    script = [IDN, (b"OUTP:OFF\n", DROP), REOPEN_FAILS, REOPEN_FAILS]
    with FakeTransport(script) as fake:
        dev = make_driver(fake)
        with pytest.raises(DeviceConnectionError) as info:
            dev.all_off()
        assert "could NOT be switched off" in str(info.value)
        assert "power switch" in str(info.value)
        # the link stays down: the next call fails the same way, without hanging
        with pytest.raises(DeviceConnectionError, match="could NOT"):
            dev.all_off()


def test_error_reply_to_the_recovery_is_reported() -> None:
    script = [IDN, (b"MEAS:SPD?\n", b"ERR 200 meter\n"), (OFF[0], b"ERR 500 x\n")]
    with (
        FakeTransport(script) as fake,
        pytest.raises(DeviceCommandError, match="could NOT be switched off"),
    ):
        make_driver(fake).measure_spd()


def test_nothing_but_idn_is_sent_to_an_unidentified_device() -> None:
    with (
        FakeTransport([(b"*IDN?\n", b"")]) as fake,
        pytest.raises(DeviceTimeoutError) as info,
    ):
        make_driver(fake).all_off()
    assert "switched off" not in str(info.value)


def test_an_echoing_port_is_recognised() -> None:
    with (
        FakeTransport([(b"*IDN?\n", b"*IDN?\n")]) as fake,
        pytest.raises(DeviceProtocolError, match="loopback"),
    ):
        _ = make_driver(fake).identity


def test_channel_count_and_list_must_agree() -> None:
    script = [IDN, (b"CHAN:COUNT?\n", b"4\n"), LIST, OFF]
    with (
        FakeTransport(script) as fake,
        pytest.raises(DeviceProtocolError, match="says 4"),
    ):
        make_driver(fake).channels()


def test_timeouts_must_be_positive() -> None:
    with pytest.raises(ValueError, match="positive"):
        Cal1LightSource(FakeTransport([]), timeout_s=0.0)


# --- the scripted transport itself ------------------------------------------------------


def test_fake_transport_catches_deviations() -> None:
    fake = FakeTransport([OFF])
    with pytest.raises(AssertionError, match="expected command"):
        fake.write(b"OUTP:ON\n")
    with pytest.raises(AssertionError, match="not consumed"):
        FakeTransport([OFF]).assert_consumed()
    with pytest.raises(AssertionError, match="never read"):
        unread = FakeTransport([OFF])
        unread.write(b"OUTP:OFF\n")
        unread.assert_consumed()
    with pytest.raises(AssertionError, match="script is finished"):
        FakeTransport([]).write(b"*IDN?\n")


# --- spec strings and the pyserial transport --------------------------------------------


@pytest.mark.parametrize(
    ("spec", "url"),
    [
        ("cal1:///dev/ttyUSB0", "/dev/ttyUSB0"),
        ("cal1://COM3", "COM3"),
        ("cal1+socket://127.0.0.1:5025", "socket://127.0.0.1:5025"),
        ("cal1+loop://", "loop://"),
        (" cal1+rfc2217://host:2217 ", "rfc2217://host:2217"),
    ],
)
def test_parse_cal1_spec(spec: str, url: str) -> None:
    assert parse_cal1_spec(spec) == url


@pytest.mark.parametrize(
    "spec",
    [
        "cal1",
        "cal1://",
        "sim",
        "cal1+ftp://x",
        "/dev/ttyUSB0",
        # pyserial would answer these with unrelated messages
        "cal1+socket://127.0.0.1",
        "cal1+socket://127.0.0.1:abc",
        "cal1+socket://127.0.0.1:0",
        "cal1+socket://127.0.0.1:70000",
        "cal1+socket://:5025",
    ],
)
def test_parse_cal1_spec_rejects(spec: str) -> None:
    with pytest.raises(InputError, match="spec"):
        parse_cal1_spec(spec)


def test_serial_transport_over_loop() -> None:
    transport = SerialTransport.open("loop://")
    try:
        transport.write(b"first\r\nsecond")
        assert transport.read_line(1.0) == b"first"
        with pytest.raises(DeviceTimeoutError, match=r"within 0\.05 s"):
            transport.read_line(0.05)  # "second" has no terminator yet
        transport.write(b"\n")
        assert transport.read_line(1.0) == b"second"
        transport.write(b"stale\n")
        transport.reset_input()
        with pytest.raises(DeviceTimeoutError):
            transport.read_line(0.05)
        transport.reopen()
        assert transport.is_open
    finally:
        transport.close()
        transport.close()
    assert not transport.is_open
    with pytest.raises(DeviceConnectionError, match="closed"):
        transport.write(b"x\n")


def test_serial_transport_limits_line_length() -> None:
    transport = SerialTransport.open("loop://")
    transport._max_line_bytes = 16
    try:
        transport.write(b"x" * 40)
        with pytest.raises(DeviceProtocolError, match="without a line terminator"):
            transport.read_line(1.0)
    finally:
        transport.close()


def test_open_cal1_on_a_loopback_fails_identification() -> None:
    with pytest.raises(DeviceProtocolError, match="loopback"):
        open_cal1("cal1+loop://", timeout_s=0.2)


def test_open_cal1_where_nothing_listens() -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with pytest.raises(DeviceConnectionError, match="emulator"):
        open_cal1(f"cal1+socket://127.0.0.1:{port}", timeout_s=0.2)


def test_open_cal1_on_a_missing_serial_port() -> None:
    with pytest.raises(DeviceConnectionError, match="connected by USB"):
        open_cal1("cal1:///dev/does-not-exist-tunespec", timeout_s=0.2)


def test_expected_protocol_fails_on_an_unused_exchange() -> None:
    with (
        pytest.raises(AssertionError, match="script not consumed"),
        expected_protocol(make_driver, [IDN, OFF]) as dev,
    ):
        _ = dev.identity
