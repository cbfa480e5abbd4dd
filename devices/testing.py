"""Testing helpers for device drivers: a scripted fake transport (PyMeasure style).

A driver takes its transport as an argument (nothing opens in ``__init__``), so a test
hands it a :class:`FakeTransport` holding the exact exchanges the driver must make and
the replies it then gets; any deviation fails at once, naming what was expected, and
:func:`expected_protocol` asserts at the end that the whole script was used::

    with expected_protocol(make_driver, [(b"*IDN?\n", b"Image Engineering,CAL1\n")]) as dev:
        dev.identity

Shipped (not only in ``tests/``) so that drivers outside this package can use it too,
as PyMeasure's ``pymeasure.test.expected_protocol``. No Qt, no real I/O.

For the gphoto2 camera, whose transport is the python-gphoto2 library itself,
:func:`make_fake_gphoto2` gives a stand-in module driving a :class:`FakeCameraState`
(the camera, its card and the errors it will raise).
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any, TypeVar

from tunespec.devices.protocols import DeviceConnectionError, DeviceTimeoutError

__all__ = [
    "DROP",
    "REOPEN",
    "REOPEN_FAILS",
    "FakeCameraState",
    "FakeGPhoto2Error",
    "FakeTransport",
    "FakeWidget",
    "ScriptItem",
    "canon_5d3_config",
    "expected_protocol",
    "make_fake_gphoto2",
]

D = TypeVar("D")


class _Event:
    """A scripted event that is not plain bytes."""

    def __init__(self, name: str) -> None:
        self.name = name

    def __repr__(self) -> str:
        return self.name


#: Reply marker: the connection is lost after the command was sent.
DROP = _Event("DROP")
#: Script item: the driver reopens the link, which succeeds.
REOPEN = _Event("REOPEN")
#: Script item: the driver tries to reopen the link, which fails.
REOPEN_FAILS = _Event("REOPEN_FAILS")

ScriptItem = tuple[bytes, bytes | _Event] | _Event


class FakeTransport:
    """A scripted :class:`Transport`: expected commands and the replies to give.

    Parameters
    ----------
    script
        In order: ``(command, reply)`` pairs, where ``command`` is the exact line the
        driver must send (with terminator) and ``reply`` the bytes then received
        (zero or more lines; ``b""`` makes the next read time out) or :data:`DROP`
        (reading raises :class:`DeviceConnectionError` and the link is closed); and
        bare :data:`REOPEN` / :data:`REOPEN_FAILS` items where the driver must call
        :meth:`reopen`.
    url
        Shown in messages.

    Use as a context manager to assert at the end that the script was consumed::

        with FakeTransport([(b"OUTP:OFF\\n", b"OK\\n")]) as t:
            ...

    A deviation raises ``AssertionError`` at once, naming what was expected.
    """

    def __init__(
        self,
        script: Iterable[ScriptItem],
        *,
        url: str = "fake://cal1",
        terminator: bytes = b"\n",
    ) -> None:
        self._script = list(script)
        self._pos = 0
        self._url = url
        self._terminator = terminator
        self._tx = bytearray()
        self._rx = bytearray()
        self._open = True
        #: Every line written, in order (terminators included).
        self.sent: list[bytes] = []
        #: The timeouts passed to :meth:`read_line`, in order (for timeout tests).
        self.timeouts_s: list[float] = []

    @property
    def url(self) -> str:
        """The fake URL."""
        return self._url

    @property
    def is_open(self) -> bool:
        """Whether the fake link is open."""
        return self._open

    @property
    def remaining(self) -> list[ScriptItem]:
        """Script items not consumed yet."""
        return self._script[self._pos :]

    def write(self, data: bytes) -> None:
        """Check each complete line against the script and queue its reply."""
        if not self._open:
            raise DeviceConnectionError(f"connection to {self._url} is closed")
        self._tx += data
        while (end := self._tx.find(self._terminator)) >= 0:
            line = bytes(self._tx[: end + len(self._terminator)])
            del self._tx[: end + len(self._terminator)]
            self.sent.append(line)
            item = self._next(f"command {line!r}")
            if not isinstance(item, tuple):
                raise AssertionError(f"expected {item!r}, but the driver sent {line!r}")
            expected, reply = item
            if line != expected:
                raise AssertionError(f"expected command {expected!r}, got {line!r}")
            if reply is DROP:
                self._rx.clear()
                self._open = False
            elif isinstance(reply, bytes):
                self._rx += reply
            else:
                raise AssertionError(f"bad reply {reply!r} in the script")

    def read_line(self, timeout_s: float) -> bytes:
        """The next scripted reply line; see :meth:`Transport.read_line`."""
        self.timeouts_s.append(timeout_s)
        if not self._open:
            raise DeviceConnectionError(f"connection to {self._url} lost (scripted)")
        end = self._rx.find(self._terminator)
        if end < 0:
            raise DeviceTimeoutError(
                f"no complete reply from {self._url} within {timeout_s:g} s (scripted)"
            )
        line = bytes(self._rx[:end])
        del self._rx[: end + len(self._terminator)]
        return line.removesuffix(b"\r")

    def reset_input(self) -> None:
        """Discard received, unread bytes (as a real flush would)."""
        self._rx.clear()

    def reopen(self) -> None:
        """Consume a :data:`REOPEN` (open again) or :data:`REOPEN_FAILS` item."""
        item = self._next("reopen()")
        if item is REOPEN:
            self._rx.clear()
            self._tx.clear()
            self._open = True
        elif item is REOPEN_FAILS:
            self._open = False
            raise DeviceConnectionError(f"cannot reopen {self._url} (scripted)")
        else:
            raise AssertionError(f"expected {item!r}, but the driver called reopen()")

    def close(self) -> None:
        """Close the fake link (not scripted: allowed at any time)."""
        self._open = False

    def assert_consumed(self) -> None:
        """Fail unless every item was used and nothing is left unsent or unread."""
        if self._pos < len(self._script):
            raise AssertionError(f"script not consumed: {self.remaining!r}")
        if self._tx:
            raise AssertionError(f"unterminated bytes written: {bytes(self._tx)!r}")
        if self._rx:
            raise AssertionError(f"reply bytes never read: {bytes(self._rx)!r}")

    def _next(self, what: str) -> ScriptItem:
        if self._pos >= len(self._script):
            raise AssertionError(f"unexpected {what}: the script is finished")
        item = self._script[self._pos]
        self._pos += 1
        return item

    def __enter__(self) -> FakeTransport:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, *_: object) -> None:
        if exc_type is None:
            self.assert_consumed()


@contextmanager
def expected_protocol(
    make_driver: Callable[..., D],
    exchanges: Iterable[ScriptItem],
    **kwargs: Any,
) -> Iterator[D]:
    """A driver talking to a :class:`FakeTransport` that holds ``exchanges``.

    Parameters
    ----------
    make_driver
        Builds the driver from the transport: ``make_driver(transport, **kwargs)``.
    exchanges
        The script (see :class:`FakeTransport`).

    Yields
    ------
    The driver. When the block ends without an exception, every exchange must have
    been made and every reply read (``AssertionError`` otherwise).
    """
    with FakeTransport(exchanges) as transport:
        yield make_driver(transport, **kwargs)


# -- a fake python-gphoto2 module (the gphoto2 driver's injected library) ------------
GP_ERROR_MESSAGES = {
    -1: "Unspecified error",
    -2: "Bad parameters",
    -7: "I/O problem",
    -10: "Timeout reading from or writing to the port",
    -52: "Could not find the requested device on the USB port",
    -53: "Could not claim the USB device",
    -105: "Unknown model",
    -110: "I/O in progress",
    -113: "Camera error",
}

SHUTTER_CHOICES_5D3 = [
    "bulb", "30", "25", "20", "15", "13", "10", "8", "6", "5", "4", "3.2", "2.5", "2",
    "1.6", "1.3", "1", "0.8", "0.6", "0.5", "0.4", "0.3", "1/4", "1/5", "1/6", "1/8",
    "1/10", "1/13", "1/15", "1/20", "1/25", "1/30", "1/40", "1/50", "1/60", "1/80",
    "1/100", "1/125", "1/160", "1/200", "1/250", "1/320", "1/400", "1/500", "1/640",
    "1/800", "1/1000", "1/1250", "1/1600", "1/2000", "1/2500", "1/3200", "1/4000",
    "1/5000", "1/6400", "1/8000",
]  # fmt: skip
ISO_CHOICES_5D3 = [
    "Auto", "100", "125", "160", "200", "250", "320", "400", "500", "640", "800",
    "1000", "1250", "1600", "2000", "2500", "3200", "4000", "5000", "6400", "8000",
    "10000", "12800", "16000", "20000", "25600",
]  # fmt: skip
FORMAT_CHOICES_5D3 = [
    "Large Fine JPEG", "Large Normal JPEG", "Medium Fine JPEG", "Small Fine JPEG",
    "RAW + Large Fine JPEG", "RAW", "mRAW", "sRAW",
]  # fmt: skip


class FakeGPhoto2Error(Exception):
    """Like ``gphoto2.GPhoto2Error``: ``code`` and ``string``."""

    def __init__(self, code: int) -> None:
        self.code = code
        self.string = GP_ERROR_MESSAGES.get(code, "Unknown error")
        super().__init__(f"[{code}] {self.string}")


class FakeWidget:
    """A node of the settings tree (section, radio or text widget)."""

    def __init__(
        self,
        name: str,
        value: str = "",
        choices: list[str] | None = None,
        children: list[FakeWidget] | None = None,
        readonly: bool = False,
    ) -> None:
        self.name = name
        self.value = value
        self.choices = choices
        self.children = children or []
        self.readonly = readonly

    def get_name(self) -> str:
        return self.name

    def get_value(self) -> str:
        return self.value

    def set_value(self, value: str) -> None:
        if self.readonly or (self.choices is not None and value not in self.choices):
            raise FakeGPhoto2Error(-2)
        self.value = value

    def get_readonly(self) -> int:
        return int(self.readonly)

    def count_choices(self) -> int:
        return len(self.choices or [])

    def get_choice(self, i: int) -> str:
        return (self.choices or [])[i]

    def count_children(self) -> int:
        return len(self.children)

    def get_child(self, i: int) -> FakeWidget:
        return self.children[i]

    def walk(self) -> list[FakeWidget]:
        out = [self]
        for c in self.children:
            out.extend(c.walk())
        return out


def canon_5d3_config(
    *, mode: str = "Manual", image_format: str = "Large Fine JPEG"
) -> FakeWidget:
    """The parts of a 5D Mark III's settings tree the driver uses (as libgphoto2 shows it)."""
    return FakeWidget(
        "main",
        children=[
            FakeWidget(
                "settings",
                children=[
                    FakeWidget(
                        "capturetarget", "Internal RAM", ["Internal RAM", "Memory card"]
                    ),
                ],
            ),
            FakeWidget(
                "status",
                children=[
                    FakeWidget("serialnumber", "0123456789", readonly=True),
                    FakeWidget("deviceversion", "1.3.5", readonly=True),
                ],
            ),
            FakeWidget(
                "imgsettings",
                children=[
                    FakeWidget("imageformat", image_format, list(FORMAT_CHOICES_5D3)),
                    FakeWidget("iso", "Auto", list(ISO_CHOICES_5D3)),
                ],
            ),
            FakeWidget(
                "capturesettings",
                children=[
                    FakeWidget(
                        "autoexposuremode",
                        mode,
                        ["P", "TV", "AV", "Manual", "Bulb"],
                        readonly=True,
                    ),
                    FakeWidget("shutterspeed", "1/60", list(SHUTTER_CHOICES_5D3)),
                ],
            ),
        ],
    )


@dataclass
class FakeCameraState:
    """What the fake camera and its card hold, and the errors it will raise.

    ``errors`` maps a method name to result codes raised by its next calls, in order.
    ``make_raw(settings) -> bytes`` gives the content of a captured frame.
    """

    cameras: list[tuple[str, str]] = field(
        default_factory=lambda: [("Canon EOS 5D Mark III", "usb:001,004")]
    )
    config: FakeWidget = field(default_factory=canon_5d3_config)
    card: dict[str, bytes] = field(default_factory=dict)
    errors: dict[str, list[int]] = field(default_factory=dict)
    calls: list[str] = field(default_factory=list)
    opened_port: str = ""
    make_raw: Callable[[dict[str, str]], bytes] | None = None
    exited: bool = False
    n_captured: int = 0

    def settings(self) -> dict[str, str]:
        return {w.name: w.value for w in self.config.walk() if not w.children}

    def maybe_fail(self, method: str) -> None:
        self.calls.append(method)
        queue = self.errors.get(method)
        if queue:
            raise FakeGPhoto2Error(queue.pop(0))


def make_fake_gphoto2(state: FakeCameraState | None = None) -> Any:
    """A stand-in for the ``gphoto2`` module driving :class:`FakeCameraState`."""
    st = state or FakeCameraState()

    class PortInfoList(list):  # type: ignore[type-arg]
        def load(self) -> None:
            self[:] = [addr for _, addr in st.cameras]

        def lookup_path(self, path: str) -> int:
            if path not in self:
                raise FakeGPhoto2Error(-5)
            return self.index(path)

    class CameraAbilitiesList(list):  # type: ignore[type-arg]
        def load(self) -> None:
            self[:] = [name for name, _ in st.cameras]

        def lookup_model(self, model: str) -> int:
            if model not in self:
                raise FakeGPhoto2Error(-105)
            return self.index(model)

    class Camera:
        @staticmethod
        def autodetect() -> list[tuple[str, str]]:
            st.maybe_fail("autodetect")
            return list(st.cameras)

        def set_port_info(self, port: str) -> None:
            st.opened_port = port

        def set_abilities(self, model: str) -> None:
            pass

        def init(self) -> None:
            st.maybe_fail("init")

        def exit(self) -> None:
            st.exited = True

        def get_config(self) -> FakeWidget:
            st.maybe_fail("get_config")
            return copy.deepcopy(st.config)

        def set_config(self, config: FakeWidget) -> None:
            st.maybe_fail("set_config")
            st.config = copy.deepcopy(config)

        def capture(self, kind: int) -> SimpleNamespace:
            st.maybe_fail("capture")
            st.n_captured += 1
            suffix = ".CR2" if st.settings()["imageformat"] == "RAW" else ".JPG"
            name = f"IMG_{st.n_captured:04d}{suffix}"
            data = st.make_raw(st.settings()) if st.make_raw else b"raw"
            st.card[f"/store_00020001/DCIM/100CANON/{name}"] = data
            return SimpleNamespace(folder="/store_00020001/DCIM/100CANON", name=name)

        def file_get(self, folder: str, name: str, kind: int) -> SimpleNamespace:
            st.maybe_fail("file_get")
            data = st.card[f"{folder}/{name}"]
            return SimpleNamespace(save=lambda p: Path(p).write_bytes(data))

        def file_delete(self, folder: str, name: str) -> None:
            st.maybe_fail("file_delete")
            del st.card[f"{folder}/{name}"]

        def wait_for_event(self, timeout_ms: int) -> tuple[int, Any]:
            st.calls.append("wait_for_event")
            return (0, None)

    return SimpleNamespace(
        GPhoto2Error=FakeGPhoto2Error,
        Camera=Camera,
        PortInfoList=PortInfoList,
        CameraAbilitiesList=CameraAbilitiesList,
        GP_CAPTURE_IMAGE=0,
        GP_FILE_TYPE_NORMAL=1,
        GP_EVENT_TIMEOUT=0,
        state=st,
    )
