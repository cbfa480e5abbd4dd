"""Canon EOS 5D Mark III (or any PTP camera) over USB through libgphoto2.

Needs python-gphoto2, the optional extra ``pip install 'tunespec[gphoto2]'`` (and
libgphoto2, so Linux or macOS). The module is imported only when a camera is opened,
and tests inject a fake module instead (``gp_module=``).

Operator checklist (what the error messages point back to):

- Mode dial on **M** (manual): shutter speed and ISO can be set only then.
- Lens focus switch on **MF**: with AF the camera tries to focus before every
  capture, and on a dim narrowband-LED scene it fails and the capture aborts
  (libgphoto2 reports an unspecified error or "out of focus").
- Only one program may hold the camera. On Linux desktops
  ``gvfs-gphoto2-volume-monitor``/``gvfsd-gphoto2`` claim it as soon as it is plugged
  in: unmount it in the file manager (or ``gio mount -s gphoto2``) first.
- A memory card must be in the camera: frames are captured to the card (``capturetarget``
  = card) and downloaded from it, which is more robust for 6 s raw exposures than the
  camera's internal RAM.
- Auto power off off (or long), or the camera vanishes from USB during a session.

Exposures come from the camera's own ``shutterspeed`` list ("30" ... "1/8000"); a
requested time is mapped to the nearest value (in stops), and :attr:`exposure_s`
reports the one set. Longer than 30 s needs bulb, which this driver does not do.
"""

from __future__ import annotations

import contextlib
import math
import os
from pathlib import Path
from types import ModuleType
from typing import Any, TypeVar

from tunespec.core.io.session import create_temp_file
from tunespec.devices.protocols import (
    DeviceBusyError,
    DeviceCommandError,
    DeviceConnectionError,
    DeviceError,
    DeviceIdentity,
    DeviceTimeoutError,
)

__all__ = [
    "Gphoto2Camera",
    "import_gphoto2",
    "map_gphoto2_error",
    "parse_shutter_speed",
]

# libgphoto2 result codes (gphoto2-port-result.h, gphoto2-result.h); python-gphoto2
# exposes the same numbers as gp.GP_ERROR_*, kept here so mapping needs no module.
GP_ERROR = -1
GP_ERROR_BAD_PARAMETERS = -2
GP_ERROR_NOT_SUPPORTED = -6
GP_ERROR_IO = -7
GP_ERROR_TIMEOUT = -10
GP_ERROR_IO_INIT = -31
GP_ERROR_IO_READ = -34
GP_ERROR_IO_WRITE = -35
GP_ERROR_IO_USB_CLEAR_HALT = -51
GP_ERROR_IO_USB_FIND = -52
GP_ERROR_IO_USB_CLAIM = -53
GP_ERROR_IO_LOCK = -60
GP_ERROR_MODEL_NOT_FOUND = -105
GP_ERROR_DIRECTORY_NOT_FOUND = -107
GP_ERROR_FILE_NOT_FOUND = -108
GP_ERROR_CAMERA_BUSY = -110
GP_ERROR_CAMERA_ERROR = -113
GP_ERROR_NO_SPACE = -115

#: Config names on Canon EOS bodies (libgphoto2's ptp2 driver).
SHUTTER_SPEED = "shutterspeed"
ISO = "iso"
IMAGE_FORMAT = "imageformat"
CAPTURE_TARGET = "capturetarget"
EXPOSURE_MODE = "autoexposuremode"
#: Farthest a requested exposure or ISO may be from an available value, in stops.
MAX_MISMATCH_STOPS = 1.0 / 3.0 + 0.02

_SUFFIXES_RAW = {".cr2", ".cr3", ".crw", ".nef", ".arw", ".dng", ".raf", ".orf"}


def import_gphoto2() -> ModuleType:
    """Import python-gphoto2, or say how to install it.

    Raises
    ------
    DeviceConnectionError
        When the module is missing.
    """
    try:
        import gphoto2
    except ImportError as exc:
        raise DeviceConnectionError(
            "python-gphoto2 is not installed, so a USB camera cannot be used: "
            "install the extra with pip install 'tunespec[gphoto2]' (needs libgphoto2, "
            f"Linux or macOS) ({exc})"
        ) from None
    return gphoto2


def parse_shutter_speed(text: str) -> float | None:
    """Seconds of a ``shutterspeed`` choice ("1/100", "6", "0.8", "30s"); None if not timed.

    Examples
    --------
    >>> parse_shutter_speed("1/100"), parse_shutter_speed("6"), parse_shutter_speed("bulb")
    (0.01, 6.0, None)
    """
    t = text.strip().lower().rstrip('s"').strip()
    try:
        if "/" in t:
            num, den = t.split("/", 1)
            value = float(num) / float(den)
        else:
            value = float(t)
    except (ValueError, ZeroDivisionError):
        return None
    return value if value > 0 and math.isfinite(value) else None


def map_gphoto2_error(exc: BaseException, action: str) -> DeviceError:
    """A :class:`DeviceError` for the operator from a ``gphoto2.GPhoto2Error``.

    Parameters
    ----------
    exc
        The exception (its ``code`` attribute is libgphoto2's result code).
    action
        What was being done, e.g. ``"capture"``.
    """
    code = getattr(exc, "code", None)
    detail = f"{action} failed ({exc})"
    if code == GP_ERROR_IO_USB_CLAIM:
        return DeviceBusyError(
            "another program (gvfs-gphoto2-volume-monitor?) holds the camera: "
            f"{detail}. Unmount the camera in the file manager (or run "
            "'gio mount -s gphoto2'), close other camera programs, and try again"
        )
    if code in (GP_ERROR_CAMERA_BUSY, GP_ERROR_IO_LOCK):
        return DeviceBusyError(
            f"the camera is busy: {detail}. Wait until it has stored the last frame, "
            "make sure nobody is using its buttons or menu, and that no other "
            "program talks to it"
        )
    if code == GP_ERROR_MODEL_NOT_FOUND:
        return DeviceConnectionError(
            f"libgphoto2 does not know this camera model: {detail}. Check the USB "
            "mode (PTP) and the libgphoto2 version"
        )
    if code in (GP_ERROR_IO_USB_FIND, GP_ERROR_IO_INIT):
        return DeviceConnectionError(
            f"camera not found on USB: {detail}. Check the cable, that the camera is "
            "on and awake (auto power off), and the port in the spec"
        )
    if code == GP_ERROR_TIMEOUT:
        return DeviceTimeoutError(
            f"the camera did not answer in time: {detail}. Check the cable; "
            "switch the camera off and on"
        )
    if code in (
        GP_ERROR_IO,
        GP_ERROR_IO_READ,
        GP_ERROR_IO_WRITE,
        GP_ERROR_IO_USB_CLEAR_HALT,
    ):
        return DeviceConnectionError(
            f"lost the USB connection to the camera: {detail}. Check the cable and "
            "power, then reconnect"
        )
    if code == GP_ERROR_NO_SPACE:
        return DeviceCommandError(f"the camera's memory card is full: {detail}")
    if code in (GP_ERROR, GP_ERROR_CAMERA_ERROR) and action.startswith("capture"):
        return DeviceCommandError(
            f"the camera refused to take the picture: {detail}. Is the lens on MF "
            "(autofocus fails on dim LED scenes and aborts the capture), the mode "
            "dial on M, and a memory card in?"
        )
    return DeviceCommandError(f"camera: {detail}")


class Gphoto2Camera:
    """A Canon EOS camera through libgphoto2, shooting RAW to ``stem.cr2``.

    Use :meth:`open`; the constructor takes an already initialised camera object
    (nothing is opened in ``__init__``).

    Parameters
    ----------
    camera
        An initialised ``gphoto2.Camera`` (or a fake with the same methods).
    gp
        The gphoto2 module (or a fake) that made it.
    spec
        The spec it was opened from (for the identity).
    model, port
        Camera name and port as autodetected.
    delete_from_card
        Delete each frame from the memory card after it has been downloaded.
    """

    def __init__(
        self,
        camera: Any,
        gp: Any,
        *,
        spec: str = "gphoto2",
        model: str = "",
        port: str = "",
        delete_from_card: bool = False,
    ) -> None:
        self._camera = camera
        self._gp = gp
        self._spec = spec
        self._model = model
        self._port = port
        self._delete = bool(delete_from_card)
        self._closed = False
        self._exposure_s = math.nan
        self._iso = 0
        self._serial = ""
        self._firmware = ""

    # -- opening ------------------------------------------------------------------
    @classmethod
    def open(
        cls,
        spec: str = "gphoto2",
        *,
        gp_module: Any = None,
        delete_from_card: bool = False,
    ) -> Gphoto2Camera:
        """Open a camera by spec and prepare it for raw capture.

        Parameters
        ----------
        spec
            ``"gphoto2"`` (the first camera found) or ``"gphoto2:PORT"``, e.g.
            ``"gphoto2:usb:001,004"`` (as ``gphoto2 --auto-detect`` lists ports).
        gp_module
            The gphoto2 module; default ``import gphoto2`` (tests pass a fake).
        delete_from_card
            Delete frames from the card once downloaded.

        Raises
        ------
        DeviceConnectionError, DeviceBusyError, DeviceCommandError
            With what to check (no camera, claimed by another program, mode dial
            not on M, ...).
        """
        gp = gp_module if gp_module is not None else import_gphoto2()
        kind, _, port = spec.partition(":")
        if kind != "gphoto2":
            raise DeviceConnectionError(
                f"not a gphoto2 camera spec: {spec!r} (use 'gphoto2' or "
                "'gphoto2:usb:BUS,DEV')"
            )
        try:
            found = [(str(n), str(a)) for n, a in gp.Camera.autodetect()]
        except gp.GPhoto2Error as exc:
            raise map_gphoto2_error(exc, "looking for cameras") from exc
        if not found:
            raise DeviceConnectionError(
                "no camera found by libgphoto2: check that it is connected by USB, "
                "switched on, and not held by another program"
            )
        if port:
            match = [f for f in found if f[1] == port]
            if not match:
                listed = ", ".join(f"{n} at {a}" for n, a in found)
                raise DeviceConnectionError(
                    f"no camera at port {port!r}; found: {listed}"
                )
            name, addr = match[0]
        else:
            name, addr = found[0]
        camera = gp.Camera()
        try:
            ports = gp.PortInfoList()
            ports.load()
            camera.set_port_info(ports[ports.lookup_path(addr)])
            abilities = gp.CameraAbilitiesList()
            abilities.load()
            camera.set_abilities(abilities[abilities.lookup_model(name)])
            camera.init()
        except gp.GPhoto2Error as exc:
            raise map_gphoto2_error(exc, f"opening {name} at {addr}") from exc
        self = cls(
            camera,
            gp,
            spec=spec,
            model=name,
            port=addr,
            delete_from_card=delete_from_card,
        )
        try:
            self._prepare()
        except BaseException:
            self.close()
            raise
        return self

    def _prepare(self) -> None:
        """RAW only, capture to the card, check the mode dial, read the settings."""
        config = self._get_config()
        mode = _find_widget(config, EXPOSURE_MODE)
        if mode is not None and str(mode.get_value()).strip().lower() not in (
            "manual",
            "m",
        ):
            raise DeviceCommandError(
                f"{self._model}: the mode dial is on {mode.get_value()!r}; set it to "
                "M (manual) so that exposure time and ISO can be set"
            )
        self._set_choice(config, IMAGE_FORMAT, _pick_raw_format)
        self._set_choice(config, CAPTURE_TARGET, _pick_card_target)
        self._apply_config(config, "setting RAW image format and capture target")
        config = self._get_config()
        self._serial = _widget_text(config, "serialnumber") or _widget_text(
            config, "eosserialnumber"
        )
        self._firmware = _widget_text(config, "deviceversion")
        speed = _widget_text(config, SHUTTER_SPEED)
        self._exposure_s = parse_shutter_speed(speed) or math.nan
        iso = _widget_text(config, ISO)
        self._iso = int(iso) if iso.isdigit() else 0

    # -- Camera protocol -------------------------------------------------------------
    @property
    def identity(self) -> DeviceIdentity:
        make, _, model = self._model.partition(" ")
        return DeviceIdentity(
            vendor=make or "unknown",
            model=model or self._model,
            serial=self._serial,
            firmware=self._firmware,
            spec=self._spec,
        )

    @property
    def exposure_s(self) -> float:
        """The exposure time now set on the camera, seconds (NaN if not timed)."""
        return self._exposure_s

    def set_exposure(self, exposure_s: float) -> None:
        """Set the nearest timed shutter speed the camera offers.

        Raises
        ------
        DeviceCommandError
            If no offered speed is within 1/3 stop (e.g. beyond 30 s: bulb).
        """
        self._check_open()
        t = float(exposure_s)
        if not (t > 0 and math.isfinite(t)):
            raise DeviceCommandError(f"exposure must be > 0 s, got {exposure_s!r}")
        config = self._get_config()
        widget = self._widget(config, SHUTTER_SPEED)
        timed = [(c, parse_shutter_speed(c)) for c in _choices(widget)]
        options = [(c, s) for c, s in timed if s is not None]
        if not options:
            raise DeviceCommandError(
                f"{self._model}: no timed shutter speeds offered (mode dial on M?)"
            )
        lo, hi = min(s for _, s in options), max(s for _, s in options)
        choice, seconds = _nearest(
            options,
            t,
            f"{self._model}: exposure {t:g} s is outside the camera's timed "
            f"range {lo:g}-{hi:g} s",
        )
        self._set_and_apply(config, widget, choice, SHUTTER_SPEED, "the shutter speed")
        self._exposure_s = seconds

    @property
    def iso(self) -> int:
        """The ISO speed now set (0 if the camera is on Auto)."""
        return self._iso

    def set_iso(self, iso: int) -> None:
        """Set the nearest ISO speed the camera offers (within 1/3 stop)."""
        self._check_open()
        if not iso > 0:
            raise DeviceCommandError(f"ISO must be > 0, got {iso!r}")
        config = self._get_config()
        widget = self._widget(config, ISO)
        options = [(c, int(c)) for c in _choices(widget) if c.strip().isdigit()]
        if not options:
            raise DeviceCommandError(f"{self._model}: no numeric ISO values offered")
        choice, value = _nearest(
            options,
            iso,
            f"{self._model}: ISO {iso} is not offered; "
            f"choices {', '.join(c for c, _ in options)}",
        )
        self._set_and_apply(config, widget, choice, ISO, "ISO")
        self._iso = value

    def capture(self, stem: Path | str) -> Path:
        """Take one frame, download it to ``stem`` + its suffix (``.cr2``), atomically.

        Blocks for the exposure plus the download (a 5D Mark III CR2 is ~25 MB).
        """
        self._check_open()
        gp = self._gp
        try:
            where = self._camera.capture(gp.GP_CAPTURE_IMAGE)
        except gp.GPhoto2Error as exc:
            raise map_gphoto2_error(exc, "capture") from exc
        folder, name = str(where.folder), str(where.name)
        suffix = Path(name).suffix.lower()
        if suffix not in _SUFFIXES_RAW:
            raise DeviceCommandError(
                f"{self._model}: the camera stored {name}, not a raw file; set the "
                "image quality to RAW only"
            )
        target = Path(f"{stem}{suffix}")
        target.parent.mkdir(parents=True, exist_ok=True)
        # the umask's permissions, as the session's other files (not mkstemp's 0600)
        tmp = create_temp_file(target.parent, f".{target.name}.", ".part")
        try:
            camera_file = self._camera.file_get(folder, name, gp.GP_FILE_TYPE_NORMAL)
            camera_file.save(str(tmp))
            os.replace(tmp, target)
        except gp.GPhoto2Error as exc:
            raise map_gphoto2_error(exc, f"downloading {folder}/{name}") from exc
        finally:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
        if self._delete:
            try:
                self._camera.file_delete(folder, name)
            except gp.GPhoto2Error as exc:
                raise map_gphoto2_error(exc, f"deleting {folder}/{name}") from exc
        self._drain_events()
        return target

    def close(self) -> None:
        """Release the camera (idempotent)."""
        if self._closed:
            return
        self._closed = True
        with contextlib.suppress(Exception):
            self._camera.exit()

    # -- helpers ---------------------------------------------------------------------
    def _drain_events(self, timeout_ms: int = 100, max_events: int = 20) -> None:
        """Consume queued camera events (file added, ...) so the next call is not busy."""
        gp = self._gp
        timeout_event = getattr(gp, "GP_EVENT_TIMEOUT", None)
        for _ in range(max_events):
            try:
                kind, _data = self._camera.wait_for_event(timeout_ms)
            except gp.GPhoto2Error:
                return
            if kind == timeout_event:
                return

    def _get_config(self) -> Any:
        try:
            return self._camera.get_config()
        except self._gp.GPhoto2Error as exc:
            raise map_gphoto2_error(exc, "reading the camera settings") from exc

    def _apply_config(self, config: Any, action: str) -> None:
        try:
            self._camera.set_config(config)
        except self._gp.GPhoto2Error as exc:
            raise map_gphoto2_error(exc, action) from exc

    def _set_and_apply(
        self, config: Any, widget: Any, choice: str, name: str, what: str
    ) -> None:
        """Set ``widget`` (``name``) to ``choice`` and send ``config`` to the camera."""
        self._set_value(widget, choice, name)
        self._apply_config(config, f"setting {what} to {choice}")

    def _widget(self, config: Any, name: str) -> Any:
        widget = _find_widget(config, name)
        if widget is None:
            raise DeviceCommandError(
                f"{self._model}: the camera has no {name!r} setting (not a Canon EOS, "
                "or the mode dial is not on M?)"
            )
        return widget

    def _set_value(self, widget: Any, value: str, name: str) -> None:
        try:
            widget.set_value(value)
        except self._gp.GPhoto2Error as exc:
            raise map_gphoto2_error(exc, f"setting {name} to {value!r}") from exc

    def _set_choice(self, config: Any, name: str, pick: Any) -> None:
        widget = self._widget(config, name)
        choices = _choices(widget)
        value = pick(choices)
        if value is None:
            raise DeviceCommandError(
                f"{self._model}: no suitable {name!r} among {', '.join(choices)}"
            )
        if str(widget.get_value()) != value:
            self._set_value(widget, value, name)

    def _check_open(self) -> None:
        if self._closed:
            raise DeviceConnectionError(f"{self._model or 'camera'}: closed")


def _find_widget(widget: Any, name: str) -> Any:
    """Depth-first search of the settings tree for the widget called ``name``."""
    if widget.get_name() == name:
        return widget
    for i in range(widget.count_children()):
        found = _find_widget(widget.get_child(i), name)
        if found is not None:
            return found
    return None


_N = TypeVar("_N", int, float)


def _nearest(
    options: list[tuple[str, _N]], target: float, error: str
) -> tuple[str, _N]:
    """The ``(choice, value)`` of ``options`` nearest to ``target`` in stops (log2);
    ``DeviceCommandError(error)`` when even that is more than
    ``MAX_MISMATCH_STOPS`` away."""
    choice, value = min(options, key=lambda cv: abs(math.log2(cv[1] / target)))
    if abs(math.log2(value / target)) > MAX_MISMATCH_STOPS:
        raise DeviceCommandError(error)
    return choice, value


def _choices(widget: Any) -> list[str]:
    return [str(widget.get_choice(i)) for i in range(widget.count_choices())]


def _widget_text(config: Any, name: str) -> str:
    widget = _find_widget(config, name)
    return "" if widget is None else str(widget.get_value()).strip()


def _pick_raw_format(choices: list[str]) -> str | None:
    """``"RAW"`` exactly (not mRAW/sRAW, not RAW + JPEG)."""
    for c in choices:
        if c.strip().upper() == "RAW":
            return c
    return None


def _pick_card_target(choices: list[str]) -> str | None:
    """The memory card capture target ("Memory card" on Canon EOS)."""
    for c in choices:
        if "card" in c.lower():
            return c
    return None
