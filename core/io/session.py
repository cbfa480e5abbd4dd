"""A measurement session on disk: a folder with a versioned JSON manifest and raw files.

Layout of a session folder::

    SESSION/
      manifest.json          format "tunespec-session", version, devices, settings,
                             target layout, and one record per frame
      frames/<id>.<ext>      raw files as the camera wrote them (``.dng``, ``.cr2``)
      frames/<id>.spd.csv    the light source's measured SPD around that exposure
      tmp/                   files being written (never referenced by the manifest)
      session.lock           who is writing the session now (pid, host, start time)

Crash safety: a frame is written to ``tmp/``, flushed to disk, moved into ``frames/``
with :func:`os.replace` and only then entered into the manifest, which is itself
rewritten atomically (temporary file, ``fsync``, ``os.replace``, ``fsync`` of the
folder). A crash, a kill or a device error at any moment therefore leaves a manifest
that lists only complete, checksummed frames (the raw file and its SPD); what is not
listed, or fails its checksums, is taken again on resume (:meth:`Session.missing`).

One writer at a time: :class:`SessionLock` holds ``session.lock`` (an advisory
``flock``, released by the kernel when its process dies, so a lock left by a killed
capture is recognised as stale and taken over). Temp cleaning never follows links:
a ``tmp`` that is a symbolic link is removed (the link, not what it points to).

The frames a session needs follow from its :class:`CaptureSettings`
(:func:`plan_frames`): dark frame(s) for each distinct exposure, then per LED channel
a white-background frame and a target frame (one per exposure bracket).

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source (``shared/reference``),
section "Capturing and Processing": dark frame, white background ``A_B`` and target
``A`` under each of the 22 LEDs.
"""

from __future__ import annotations

import contextlib
import copy
import hashlib
import json
import math
import os
import socket
import threading
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from datetime import UTC, datetime
from os import PathLike
from pathlib import Path, PurePosixPath, PureWindowsPath
from typing import Any

from tunespec.core.atomic import (
    atomic_write_bytes,
    atomic_write_text,
    create_temp_file,
    fsync_dir,
)
from tunespec.core.errors import InputError
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.io.spectral_csv import write_spectra_csv
from tunespec.core.layout import TargetLayout
from tunespec.core.limits import (
    MAX_NAME_CHARS,
    dumps_json,
    read_json,
    shown,
    valid_number,
)
from tunespec.core.spectra import Spectra

__all__ = [
    "FRAME_KINDS",
    "LOCK_NAME",
    "MANIFEST_NAME",
    "SESSION_FORMAT",
    "SESSION_VERSION",
    "CaptureSettings",
    "FrameRecord",
    "FrameSpec",
    "Session",
    "SessionBusyError",
    "SessionLock",
    "atomic_write_bytes",
    "atomic_write_text",
    "create_temp_file",
    "dark_id",
    "find_darks",
    "frames_by_channel",
    "plan_frames",
    "sha256_file",
    "with_exposures",
]

SESSION_FORMAT = "tunespec-session"
SESSION_VERSION = 1
MANIFEST_NAME = "manifest.json"
FRAMES_DIR = "frames"
TMP_DIR = "tmp"
LOCK_NAME = "session.lock"

FRAME_KINDS: tuple[str, ...] = ("dark", "white", "target")
EXPOSURE_MODES = ("fixed", "auto")

#: Two exposures closer than this (relative) are the same setting (JSON keeps floats
#: exactly, so this only absorbs cameras that report a rounded value).
EXPOSURE_RTOL = 1e-6


# -- atomic file helpers (the one writer: tunespec.core.atomic) -------------------------
_fsync_dir = fsync_dir


def sha256_file(path: str | PathLike[str], *, chunk_bytes: int = 1 << 20) -> str:
    """Hex SHA-256 of a file, read in chunks (raw files are tens of MB)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(chunk_bytes):
            h.update(block)
    return h.hexdigest()


def _utc_now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


# -- one writer at a time --------------------------------------------------------------
class SessionBusyError(InputError):
    """Another process is writing the session (it holds ``session.lock``)."""


#: Per process: real path of a session folder -> [open lock file descriptor, count].
_HELD: dict[str, list[int]] = {}
_HELD_GUARD = threading.Lock()


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True
    return True


class SessionLock:
    """The lock of a session folder: one writing process at a time.

    ``session.lock`` holds the holder's pid, host and start time (for the message
    a second writer gets) and is locked with ``flock`` while held. The kernel drops a
    ``flock`` when its process dies, so a lock file with content but no ``flock`` is
    stale (its holder was killed): it is taken over and the old holder is kept in
    :attr:`stale_holder`. The file is never deleted (deleting it would let two
    processes lock two different files). Re-entrant within one process. Where
    ``flock`` is missing (Windows), a holder on this host whose pid is gone is stale.

    Parameters
    ----------
    root
        The session folder (created if missing).
    """

    def __init__(self, root: str | PathLike[str]) -> None:
        self.root = Path(root)
        self.path = self.root / LOCK_NAME
        self.stale_holder: dict[str, Any] | None = None
        self._key: str | None = None

    def acquire(self) -> SessionLock:
        """Take the lock; :class:`SessionBusyError` naming the holder if taken."""
        self.root.mkdir(parents=True, exist_ok=True)
        key = os.path.realpath(self.root)
        with _HELD_GUARD:
            if key in _HELD:
                _HELD[key][1] += 1
                self._key = key
                return self
            flags = os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0)
            try:
                fd = os.open(self.path, flags, 0o644)
            except OSError as exc:
                raise InputError(
                    f"cannot open the session lock: {exc.strerror}", path=self.path
                ) from None
            try:
                previous = _read_holder(fd)
                if not _try_lock(fd, previous):
                    raise SessionBusyError(
                        "the session is being written by another capture: "
                        + _describe(previous)
                        + "; wait for it to finish or stop it",
                        path=self.root,
                    )
                if previous is not None and previous.get("pid") != os.getpid():
                    self.stale_holder = previous
                me = {
                    "pid": os.getpid(),
                    "host": socket.gethostname(),
                    "started_utc": _utc_now(),
                }
                _write_holder(fd, json.dumps(me) + "\n")
            except BaseException:
                os.close(fd)
                raise
            _HELD[key] = [fd, 1]
            self._key = key
        return self

    def release(self) -> None:
        """Give the lock back (the last release of this process empties the file)."""
        key, self._key = self._key, None
        if key is None:
            return
        with _HELD_GUARD:
            entry = _HELD.get(key)
            if entry is None:
                return
            entry[1] -= 1
            if entry[1] > 0:
                return
            del _HELD[key]
            fd = entry[0]
            with contextlib.suppress(OSError):
                _write_holder(fd, "")
            os.close(fd)  # drops the flock

    def __enter__(self) -> SessionLock:
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()


def _try_lock(fd: int, previous: dict[str, Any] | None) -> bool:
    try:
        import fcntl
    except ImportError:  # Windows: judge by the recorded holder
        if previous is None:
            return True
        same_host = previous.get("host") == socket.gethostname()
        pid = previous.get("pid")
        return same_host and isinstance(pid, int) and not _pid_alive(pid)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    return True


def _read_holder(fd: int) -> dict[str, Any] | None:
    try:
        os.lseek(fd, 0, os.SEEK_SET)
        data = os.read(fd, 4096)
        holder = json.loads(data.decode("utf-8")) if data.strip() else None
    except (OSError, ValueError):
        return {"pid": "?", "host": "?", "started_utc": "?"}
    return holder if isinstance(holder, dict) else None


def _write_holder(fd: int, text: str) -> None:
    # in place: replacing the file would hand the next process another inode to lock
    os.ftruncate(fd, 0)
    os.lseek(fd, 0, os.SEEK_SET)
    os.write(fd, text.encode("utf-8"))
    os.fsync(fd)


def _describe(holder: dict[str, Any] | None) -> str:
    if holder is None:
        return "a process that has not written its name yet"
    return (
        f"pid {holder.get('pid', '?')} on host {holder.get('host', '?')} "
        f"since {holder.get('started_utc', '?')}"
    )


# -- what to capture -------------------------------------------------------------------
def _exposure_tag(exposure_s: float) -> str:
    """A file-name-safe, exact-enough tag for an exposure, e.g. ``"0.0125s"``."""
    return f"{exposure_s:.6g}s"


def dark_id(exposure_s: float, iso: int, index: int) -> str:
    """Frame id of the ``index``-th dark frame at ``exposure_s`` and ``iso``."""
    return f"dark_{_exposure_tag(exposure_s)}_iso{iso}_{index}"


def _led_id(kind: str, channel: str, bracket: int) -> str:
    return f"{kind}_{channel}" + (f"_b{bracket}" if bracket else "")


@dataclass(frozen=True)
class FrameSpec:
    """One frame a session needs.

    Parameters
    ----------
    id
        Unique frame id, also the raw file's stem (``"target_LED410"``).
    kind
        ``"dark"`` (light off), ``"white"`` (white background, ``A_B`` of Eq. 2) or
        ``"target"`` (the chart or sample, ``A``).
    channel
        LED channel name for white and target frames, ``None`` for darks.
    exposure_s
        Exposure time in seconds.
    iso
        ISO speed.
    bracket
        Index into the exposure bracket (0 = the reference, longest exposure).
    """

    id: str
    kind: str
    channel: str | None
    exposure_s: float
    iso: int
    bracket: int = 0


@dataclass(frozen=True)
class CaptureSettings:
    """How a session is captured.

    Parameters
    ----------
    channels
        LED channel names to capture, in capture order.
    iso
        ISO speed of every frame.
    exposure_mode
        ``"fixed"``: ``exposures_s`` were given; ``"auto"``: metered from a shot of the
        white background under each LED so its brightest part lands at
        ``target_level`` of full scale.
    exposures_s
        Per channel, the exposure of each bracket in seconds (longest first), as the
        camera reported it after setting it. Empty until resolved or metered.
    bracket_factors
        Exposure brackets as fractions of the reference exposure, e.g. ``(1.0, 0.125)``
        for an HDR pair; ``(1.0,)`` for single exposures.
    n_darks
        Dark frames per distinct exposure (averaged in processing).
    target_level
        Auto exposure aim, fraction of full scale.
    levels
        LED drive level per channel in [0, 1] (missing = 1.0).
    requested_s
        For fixed exposures: per channel the bracketed exposures asked for, before
        the camera confirmed them (``exposures_s`` holds what it uses).
    """

    channels: tuple[str, ...]
    iso: int = 100
    exposure_mode: str = "auto"
    exposures_s: Mapping[str, tuple[float, ...]] = field(default_factory=dict)
    bracket_factors: tuple[float, ...] = (1.0,)
    n_darks: int = 1
    target_level: float = 0.75
    levels: Mapping[str, float] = field(default_factory=dict)
    requested_s: Mapping[str, tuple[float, ...]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "channels", tuple(self.channels))
        object.__setattr__(
            self, "bracket_factors", tuple(float(f) for f in self.bracket_factors)
        )
        object.__setattr__(
            self,
            "exposures_s",
            {str(k): tuple(float(t) for t in v) for k, v in self.exposures_s.items()},
        )
        object.__setattr__(
            self, "levels", {str(k): float(v) for k, v in self.levels.items()}
        )
        object.__setattr__(
            self,
            "requested_s",
            {str(k): tuple(float(t) for t in v) for k, v in self.requested_s.items()},
        )
        if not self.channels or len(set(self.channels)) != len(self.channels):
            raise InputError("capture settings: channels must be unique and non-empty")
        if self.exposure_mode not in EXPOSURE_MODES:
            raise InputError(
                f"capture settings: exposure_mode {shown(self.exposure_mode)}, expected "
                f"one of {', '.join(EXPOSURE_MODES)}"
            )
        f = self.bracket_factors
        if not f or f[0] != 1.0 or any(not (0 < x <= 1) for x in f):
            raise InputError(
                "capture settings: bracket_factors must start with 1.0, each in (0, 1]"
            )
        if self.n_darks < 1 or self.iso <= 0:
            raise InputError("capture settings: n_darks >= 1 and iso > 0 required")
        if not (0.05 <= self.target_level <= 0.95):
            raise InputError("capture settings: target_level must be in [0.05, 0.95]")
        for name, ts in (*self.exposures_s.items(), *self.requested_s.items()):
            if len(ts) != len(f) or any(not (t > 0 and math.isfinite(t)) for t in ts):
                raise InputError(
                    f"capture settings: channel {name}: expected {len(f)} positive "
                    f"exposure(s), got {ts}"
                )

    @property
    def resolved(self) -> bool:
        """True once every channel has its (bracketed) exposures."""
        return all(c in self.exposures_s for c in self.channels)

    def level(self, channel: str) -> float:
        """Drive level of ``channel`` in [0, 1]."""
        return self.levels.get(channel, 1.0)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["channels"] = list(self.channels)
        d["bracket_factors"] = list(self.bracket_factors)
        d["exposures_s"] = {k: list(v) for k, v in self.exposures_s.items()}
        d["levels"] = dict(self.levels)
        d["requested_s"] = {k: list(v) for k, v in self.requested_s.items()}
        return d

    @classmethod
    def from_dict(
        cls, d: Mapping[str, Any], *, source: str | PathLike[str] | None = None
    ) -> CaptureSettings:
        """Settings from their manifest form; :class:`InputError` if malformed."""
        if not isinstance(d, Mapping):
            raise InputError("bad capture settings: expected an object", path=source)
        channels = d.get("channels")
        # a string would split into one channel per character
        if not isinstance(channels, list | tuple) or not all(
            isinstance(c, str) for c in channels
        ):
            raise InputError(
                "bad capture settings: channels must be a list of names", path=source
            )
        for key in ("exposures_s", "levels", "requested_s"):
            if not isinstance(d.get(key, {}), Mapping):
                raise InputError(
                    f"bad capture settings: {key} must be an object", path=source
                )
        if len(channels) > MAX_CHANNELS:
            raise InputError(
                f"bad capture settings: {len(channels)} channels, at most "
                f"{MAX_CHANNELS}",
                path=source,
            )
        for c in channels:
            if not _safe_name(c):
                raise InputError(
                    f"bad capture settings: channel {shown(c)} must be a short name "
                    "without path separators",
                    path=source,
                )
        _check_setting_numbers(d, source)
        keys = set(cls.__dataclass_fields__)
        try:
            return cls(**{k: v for k, v in d.items() if k in keys})
        except (TypeError, ValueError) as exc:
            raise InputError(f"bad capture settings: {exc}", path=source) from None
        except InputError as exc:
            raise InputError(exc.message, path=source) from None


#: Limits of a manifest's settings (far beyond any real session).
MAX_CHANNELS = 256
MAX_DARKS = 100
MAX_BRACKETS = 16
MAX_ISO = 10_000_000
MANIFEST_MAX_EXPOSURE_S = 1e5
MAX_FRAMES = 100_000


def _check_setting_numbers(d: Mapping[str, Any], source: Any) -> None:
    """Types and ranges of the numbers in a manifest's settings (one-line errors)."""

    def check(value: Any, key: str, **kw: Any) -> None:
        valid_number(value, f"settings.{key}", path=source, **kw)

    check(d.get("iso", 100), "iso", lo=1, hi=MAX_ISO, integer=True)
    check(d.get("n_darks", 1), "n_darks", lo=1, hi=MAX_DARKS, integer=True)
    check(d.get("target_level", 0.75), "target_level", lo=0.05, hi=0.95)
    factors = d.get("bracket_factors", [1.0])
    if not isinstance(factors, list | tuple) or not 1 <= len(factors) <= MAX_BRACKETS:
        raise InputError(
            f"settings.bracket_factors: expected 1 to {MAX_BRACKETS} numbers",
            path=source,
        )
    for f in factors:
        check(f, "bracket_factors", lo=0, hi=1, lo_open=True)
    for key in ("exposures_s", "requested_s"):
        for ch, ts in dict(d.get(key, {})).items():
            if not isinstance(ts, list | tuple) or len(ts) > MAX_BRACKETS:
                raise InputError(
                    f"settings.{key}.{ch}: expected a list of seconds", path=source
                )
            for t in ts:
                check(t, f"{key}.{ch}", lo=0, hi=MANIFEST_MAX_EXPOSURE_S, lo_open=True)
    for ch, v in dict(d.get("levels", {})).items():
        check(v, f"levels.{ch}", lo=0, hi=1)


def plan_frames(settings: CaptureSettings) -> list[FrameSpec]:
    """Every frame a session with ``settings`` needs, in capture order.

    Darks first (one set per distinct exposure and ISO), then one white frame per
    channel and bracket, then one target frame per channel and bracket. Needs resolved
    exposures (:attr:`CaptureSettings.resolved`).

    Raises
    ------
    InputError
        If the exposures are not resolved yet.

    Examples
    --------
    >>> s = CaptureSettings(("L1", "L2"), exposures_s={"L1": (0.5,), "L2": (0.5,)})
    >>> [f.id for f in plan_frames(s)]
    ['dark_0.5s_iso100_0', 'white_L1', 'white_L2', 'target_L1', 'target_L2']
    """
    if not settings.resolved:
        missing = [c for c in settings.channels if c not in settings.exposures_s]
        raise InputError(
            f"exposures not resolved for {len(missing)} channel(s), e.g. {missing[0]}"
        )
    exposures: list[float] = []
    for c in settings.channels:
        for t in settings.exposures_s[c]:
            if not any(math.isclose(t, u, rel_tol=EXPOSURE_RTOL) for u in exposures):
                exposures.append(t)
    plan = [
        FrameSpec(dark_id(t, settings.iso, n), "dark", None, t, settings.iso)
        for t in sorted(exposures, reverse=True)
        for n in range(settings.n_darks)
    ]
    for kind in ("white", "target"):
        for c in settings.channels:
            for b, t in enumerate(settings.exposures_s[c]):
                plan.append(FrameSpec(_led_id(kind, c, b), kind, c, t, settings.iso, b))
    return plan


# -- what was captured -----------------------------------------------------------------
@dataclass(frozen=True)
class FrameRecord:
    """A captured frame as the manifest lists it.

    Parameters
    ----------
    id, kind, channel, exposure_s, iso, bracket
        As in :class:`FrameSpec` (``exposure_s`` as the camera reported it).
    file
        Raw file, relative to the session folder.
    sha256
        Hex SHA-256 of the raw file.
    time_utc
        ISO 8601 UTC time the frame was committed.
    status
        ``"ok"`` or ``"bad"`` (to be taken again).
    spd_file
        The measured SPD (CSV, relative path), ``None`` for darks.
    note
        Free text: why a frame is bad, what was retaken.
    spd_sha256
        Hex SHA-256 of the SPD file (``None`` for darks and for sessions written
        before it was recorded: then the SPD is only checked to be readable).
    """

    id: str
    kind: str
    channel: str | None
    exposure_s: float
    iso: int
    bracket: int
    file: str
    sha256: str
    time_utc: str
    status: str = "ok"
    spd_file: str | None = None
    note: str = ""
    spd_sha256: str | None = None

    @property
    def spec(self) -> FrameSpec:
        """The :class:`FrameSpec` this record fulfils."""
        return FrameSpec(
            self.id, self.kind, self.channel, self.exposure_s, self.iso, self.bracket
        )

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(
        cls, d: Mapping[str, Any], *, source: str | None = None
    ) -> FrameRecord:
        if not isinstance(d, Mapping):
            raise InputError("bad frame record: expected an object", path=source)
        keys = set(cls.__dataclass_fields__)
        try:
            rec = cls(**{k: v for k, v in d.items() if k in keys})
        except TypeError as exc:
            raise InputError(f"bad frame record: {exc}", path=source) from None
        if rec.kind not in FRAME_KINDS or rec.status not in ("ok", "bad"):
            raise InputError(
                f"frame {shown(rec.id)}: bad kind {shown(rec.kind)} or status {shown(rec.status)}",
                path=source,
            )
        problem = _record_problem(rec)
        if problem:
            raise InputError(f"frame {shown(rec.id)}: {problem}", path=source)
        return rec


def _record_problem(rec: FrameRecord) -> str:
    """What is wrong with a record's field types or paths ("" if nothing).

    Processing and resume compare exposures and join paths, so a damaged manifest
    must fail here with one line rather than deep inside them.
    """

    def real(v: object) -> bool:
        return isinstance(v, int | float) and not isinstance(v, bool)

    if not _safe_name(rec.id):
        return "id must be a short name without path separators"
    if rec.channel is not None and not _safe_name(rec.channel):
        return "channel must be a short name without path separators, or null"
    if not (real(rec.exposure_s) and math.isfinite(rec.exposure_s)):
        return f"exposure_s must be a number, got {shown(rec.exposure_s)}"
    if not (0 < rec.exposure_s <= MANIFEST_MAX_EXPOSURE_S):
        return (
            f"exposure_s must be in (0, {MANIFEST_MAX_EXPOSURE_S:g}], got "
            f"{shown(rec.exposure_s)}"
        )
    for name, hi in (("iso", MAX_ISO), ("bracket", MAX_BRACKETS)):
        v = getattr(rec, name)
        if not isinstance(v, int) or isinstance(v, bool) or not 0 <= v <= hi:
            return f"{name} must be an integer in [0, {hi}], got {shown(v)}"
    for name in ("file", "spd_file"):
        v = getattr(rec, name)
        if v is None and name == "spd_file":
            continue
        if not isinstance(v, str) or not _inside_session(v):
            return f"{name} must be a path inside the session folder, got {shown(v)}"
    for name in ("sha256", "spd_sha256"):
        v = getattr(rec, name)
        if not (isinstance(v, str) or (v is None and name == "spd_sha256")):
            return f"{name} must be a string"
    if rec.spd_sha256 is not None and rec.spd_file is None:
        return "spd_sha256 without spd_file"
    return ""


def _safe_name(name: object) -> bool:
    """A frame id or channel name: short, one line, usable inside a file name."""
    return (
        isinstance(name, str)
        and 0 < len(name) <= MAX_NAME_CHARS
        and not name.startswith(".")
        and not any(c in name for c in "/\\\x00\n\r:")
    )


def _inside_session(rel: str) -> bool:
    """True for a short relative path that stays inside the session folder."""
    p = PurePosixPath(rel.replace("\\", "/"))
    return (
        0 < len(rel) <= 1024
        and not any(c in rel for c in "\x00\n\r")
        and all(len(part.encode()) <= 255 for part in p.parts)
        and not p.is_absolute()
        and not PureWindowsPath(rel).anchor
        and ".." not in p.parts
    )


class Session:
    """A session folder and its manifest (see the module docstring).

    Open with :meth:`create` or :meth:`open`. Every change is written to disk before
    the method returns. Not thread-safe: one owner (the capture thread) at a time.
    """

    def __init__(self, root: Path, manifest: dict[str, Any]) -> None:
        self.root = Path(root)
        self._m = manifest

    # -- opening -----------------------------------------------------------------------
    @classmethod
    def create(
        cls,
        root: str | PathLike[str],
        *,
        settings: CaptureSettings,
        devices: Mapping[str, Mapping[str, str]] | None = None,
        layout: TargetLayout | None = None,
        meta: Mapping[str, str] | None = None,
    ) -> Session:
        """Start a new session in ``root`` (created; must not hold a manifest yet).

        Parameters
        ----------
        settings
            Capture settings.
        devices
            Per role (``"light"``, ``"camera"``, ``"stage"``) the device identity as a
            dict (vendor, model, serial, firmware, spec).
        layout
            The target's layout (its ``corners_px`` may be unknown).
        meta
            Free key/value notes (operator, sample name, ...).

        Raises
        ------
        InputError
            If ``root`` already holds a session.
        """
        root = Path(root)
        if (root / MANIFEST_NAME).exists():
            raise InputError(
                "a session already exists here (resume it instead)", path=root
            )
        (root / FRAMES_DIR).mkdir(parents=True, exist_ok=True)
        manifest: dict[str, Any] = {
            "format": SESSION_FORMAT,
            "version": SESSION_VERSION,
            "created_utc": _utc_now(),
            "devices": {k: dict(v) for k, v in (devices or {}).items()},
            "settings": settings.to_dict(),
            "layout": None if layout is None else layout.to_dict(),
            "meta": dict(meta or {}),
            "frames": [],
        }
        session = cls(root, manifest)
        session._write_manifest()
        return session

    @classmethod
    def open(cls, root: str | PathLike[str]) -> Session:
        """Open an existing session folder.

        Raises
        ------
        InputError
            No manifest, not valid JSON, another format or a newer version.
        """
        root = Path(root)
        path = root / MANIFEST_NAME
        if not path.exists():
            raise InputError(f"not a TuneSpec session (no {MANIFEST_NAME})", path=root)
        m = read_json(path)
        if not isinstance(m, dict) or m.get("format") != SESSION_FORMAT:
            raise InputError(
                f"not a session manifest (format != {SESSION_FORMAT!r})", path=path
            )
        version = m.get("version", 0)
        if not isinstance(version, int) or isinstance(version, bool) or version < 0:
            raise InputError(f"bad session version {shown(version)}", path=path)
        if version > SESSION_VERSION:
            raise InputError(
                f"session version {version} is newer than this TuneSpec "
                f"understands ({SESSION_VERSION})",
                path=path,
            )
        # validate eagerly so a damaged manifest fails here, naming the file, and
        # not later with a traceback from whatever reads the bad field first
        if not isinstance(m.get("frames"), list):
            raise InputError("damaged manifest: 'frames' must be a list", path=path)
        if len(m["frames"]) > MAX_FRAMES:
            raise InputError(
                f"damaged manifest: more than {MAX_FRAMES} frames", path=path
            )
        for key in ("devices", "meta"):
            if not isinstance(m.get(key, {}), dict):
                raise InputError(
                    f"damaged manifest: {key!r} must be an object", path=path
                )
        if not all(isinstance(v, dict) for v in m.get("devices", {}).values()):
            raise InputError(
                "damaged manifest: each of 'devices' must be an object", path=path
            )
        if "settings" not in m:
            raise InputError("damaged manifest: no 'settings'", path=path)
        records = [FrameRecord.from_dict(d, source=str(path)) for d in m["frames"]]
        ids = [r.id for r in records]
        if len(set(ids)) != len(ids):
            raise InputError("damaged manifest: a frame id is listed twice", path=path)
        CaptureSettings.from_dict(m["settings"], source=path)
        layout = m.get("layout")
        if layout is not None:
            if not isinstance(layout, dict):
                raise InputError(
                    "damaged manifest: 'layout' must be an object or null", path=path
                )
            TargetLayout.from_dict(layout, source=str(path))
        return cls(root, m)

    def reload(self) -> None:
        """Read the manifest again (another writer may have changed it before this
        process took the lock)."""
        self._m = Session.open(self.root)._m

    # -- manifest ----------------------------------------------------------------------
    @property
    def manifest_path(self) -> Path:
        return self.root / MANIFEST_NAME

    def _write_manifest(self, manifest: dict[str, Any] | None = None) -> None:
        """Write ``manifest`` (default the current one) and only then adopt it.

        If the write fails, the file on disk and this object both keep the previous
        state, so they never disagree.
        """
        m = self._m if manifest is None else manifest
        atomic_write_text(self.manifest_path, dumps_json(m, indent=1))
        self._m = m

    def _edited(self) -> dict[str, Any]:
        """A deep copy of the manifest to change and pass to :meth:`_write_manifest`."""
        return copy.deepcopy(self._m)

    @property
    def manifest(self) -> dict[str, Any]:
        """A deep copy of the manifest (read-only view for reports)."""
        copied: dict[str, Any] = json.loads(json.dumps(self._m))
        return copied

    @property
    def devices(self) -> dict[str, dict[str, str]]:
        return {k: dict(v) for k, v in self._m.get("devices", {}).items()}

    def set_devices(self, devices: Mapping[str, Mapping[str, str]]) -> None:
        """Record the devices in use (a resumed session may use other serials)."""
        m = self._edited()
        old = m.get("devices", {})
        new = {k: dict(v) for k, v in devices.items()}
        if old and old != new:
            history = m.setdefault("device_history", [])
            history.append({"until_utc": _utc_now(), "devices": old})
        m["devices"] = new
        self._write_manifest(m)

    @property
    def settings(self) -> CaptureSettings:
        return CaptureSettings.from_dict(self._m["settings"])

    def set_settings(self, settings: CaptureSettings) -> None:
        """Replace the capture settings (e.g. once exposures are metered)."""
        m = self._edited()
        m["settings"] = settings.to_dict()
        self._write_manifest(m)

    @property
    def layout(self) -> TargetLayout | None:
        d = self._m.get("layout")
        return (
            None
            if d is None
            else TargetLayout.from_dict(d, source=str(self.manifest_path))
        )

    def set_layout(self, layout: TargetLayout | None) -> None:
        m = self._edited()
        m["layout"] = None if layout is None else layout.to_dict()
        self._write_manifest(m)

    @property
    def meta(self) -> dict[str, str]:
        return dict(self._m.get("meta", {}))

    # -- frames ------------------------------------------------------------------------
    @property
    def frames(self) -> tuple[FrameRecord, ...]:
        """Every recorded frame, in capture order."""
        return tuple(FrameRecord.from_dict(d) for d in self._m["frames"])

    def frame(self, frame_id: str) -> FrameRecord | None:
        """The record of ``frame_id``, or ``None``."""
        for d in self._m["frames"]:
            if d["id"] == frame_id:
                return FrameRecord.from_dict(d)
        return None

    def fingerprint(self) -> str:
        """SHA-256 over the ids and checksums of the frames with status ok.

        Results computed from a session store it; when a frame is retaken or marked
        bad the fingerprint changes, so stale results can be recognised.
        """
        h = hashlib.sha256()
        for f in sorted(self.ok_frames(), key=lambda f: f.id):
            h.update(f"{f.id}:{f.sha256}\n".encode())
        return h.hexdigest()

    def ok_frames(self, kind: str | None = None) -> list[FrameRecord]:
        """Frames with status ok (of one ``kind`` if given)."""
        return [f for f in self.frames if f.status == "ok" and kind in (None, f.kind)]

    def path_of(self, record: FrameRecord) -> Path:
        """Absolute path of a frame's raw file (inside the session, no link).

        Raises
        ------
        InputError
            The file, or ``frames/``, is a link (possibly out of the session).
        """
        return self.inside(record.file)

    def inside(self, rel: str) -> Path:
        """``root / rel`` when it is a path inside the session with no link on the
        way (``frames/`` or the file itself a link would let a session received
        from someone else read any file); the session folder itself may be a link.

        Raises
        ------
        InputError
            Naming the manifest and the file.
        """
        path = self.root / rel
        parts = PurePosixPath(rel).parts
        try:
            real = path.resolve()
            expected = self.root.resolve().joinpath(*parts)
        except (OSError, RuntimeError):
            real, expected = path, None
        if ".." in parts or PurePosixPath(rel).is_absolute() or real != expected:
            raise InputError(
                f"{rel} is a link (or leaves the session folder): frames are read "
                "only from files inside the session",
                path=self.manifest_path,
            )
        return path

    def plan(self) -> list[FrameSpec]:
        """The frames this session needs (:func:`plan_frames` of its settings)."""
        return plan_frames(self.settings)

    def verify(self, record: FrameRecord) -> bool:
        """True if every file of the frame exists and matches its checksum."""
        return self.problem(record) == ""

    def problem(self, record: FrameRecord, *, checksums: bool = True) -> str:
        """What is wrong with a frame's files ("" if nothing).

        The raw file and the SPD must exist and (``checksums``) match the checksums
        recorded when the frame was committed; an SPD recorded without a checksum
        (older sessions) must at least be readable.
        """
        try:
            return self._problem(record, checksums)
        except OSError as exc:  # a folder where a file was, a link loop, ...
            return f"files of frame {record.id} cannot be read ({exc.strerror})"
        except InputError as exc:  # a link out of the session
            return exc.message

    def _problem(self, record: FrameRecord, checksums: bool) -> str:
        path = self.path_of(record)
        if not path.is_file():
            return f"raw file {record.file} is missing"
        if checksums and sha256_file(path) != record.sha256:
            return f"raw file {record.file} fails its checksum"
        if record.spd_file is None:
            return ""
        spd = self.inside(record.spd_file)
        if not spd.is_file():
            return f"SPD file {record.spd_file} is missing"
        if not checksums:
            return ""
        if record.spd_sha256 is not None:
            if sha256_file(spd) != record.spd_sha256:
                return f"SPD file {record.spd_file} fails its checksum"
            return ""
        try:
            read_spectra_csv(spd)
        except InputError:
            return f"SPD file {record.spd_file} is not readable"
        return ""

    def missing(self, *, verify: bool = True) -> list[FrameSpec]:
        """Planned frames that have no ok record, in capture order.

        A frame counts as missing when it was never recorded, is marked bad, was
        recorded with other parameters than planned, its raw file or SPD is gone,
        or (``verify``) one of them fails its checksum.
        """
        records = {f.id: f for f in self.frames}
        out = []
        for spec in self.plan():
            rec = records.get(spec.id)
            if (
                rec is None
                or rec.status != "ok"
                or not _same_spec(rec.spec, spec)
                or self.problem(rec, checksums=verify)
            ):
                out.append(spec)
        return out

    def _tmp_dir(self) -> Path:
        """``tmp/`` as a real folder inside the session (a link there is removed)."""
        tmp = self.root / TMP_DIR
        if tmp.is_symlink() or (tmp.exists() and not tmp.is_dir()):
            tmp.unlink()  # the link itself, never what it points to
        tmp.mkdir(parents=True, exist_ok=True)
        return tmp

    def temp_stem(self, frame_id: str) -> Path:
        """Where a camera should write a frame before :meth:`commit_frame` (no suffix)."""
        return self._tmp_dir() / f"{frame_id}.{os.getpid()}"

    def clean_temp(self) -> None:
        """Remove leftovers of interrupted writes (never referenced by the manifest)
        and the then empty ``tmp/`` folder (:meth:`temp_stem` makes it again).

        Only entries directly in the session's own ``tmp/`` are removed; links are
        removed as links (never followed), folders are left alone.
        """
        tmp = self.root / TMP_DIR
        if not (tmp.is_symlink() or tmp.exists()):
            return
        tmp = self._tmp_dir()
        with os.scandir(tmp) as entries:
            for entry in entries:
                if entry.is_symlink() or entry.is_file(follow_symlinks=False):
                    with contextlib.suppress(OSError):
                        os.unlink(entry.path)
        with contextlib.suppress(OSError):  # not empty: something else is there
            tmp.rmdir()

    def commit_frame(
        self,
        spec: FrameSpec,
        raw_file: str | PathLike[str],
        *,
        spd: Spectra | None = None,
        note: str = "",
    ) -> FrameRecord:
        """Move a finished raw file into the session and record it (atomically).

        Parameters
        ----------
        spec
            The frame it fulfils (with the exposure the camera actually used).
        raw_file
            The file the camera wrote, ideally under :meth:`temp_stem` (same file
            system, so the move is a rename). It is flushed to disk, then renamed to
            ``frames/<id><suffix>``.
        spd
            The measured SPD (one spectrum) for LED frames.
        note
            Stored in the record.

        Returns
        -------
        FrameRecord
            The record now in the manifest (replacing an earlier one of that id).
        """
        src = Path(raw_file)
        if spec.kind not in FRAME_KINDS:
            raise InputError(f"frame {spec.id!r}: unknown kind {spec.kind!r}")
        with open(src, "rb+") as fh:
            os.fsync(fh.fileno())
        frames = self.root / FRAMES_DIR
        if frames.is_symlink():
            raise InputError(
                f"{FRAMES_DIR}/ is a link to another folder; frames are only written "
                "inside the session folder",
                path=self.root,
            )
        frames.mkdir(parents=True, exist_ok=True)
        rel = f"{FRAMES_DIR}/{spec.id}{''.join(src.suffixes[-1:]).lower()}"
        digest = sha256_file(src)
        spd_rel = spd_digest = None
        if spd is not None:
            spd_rel = f"{FRAMES_DIR}/{spec.id}.spd.csv"
            # the stem ends in the pid: two processes never share a temp name
            tmp_spd = Path(f"{self.temp_stem(spec.id)}.spd.csv")
            write_spectra_csv(spd, tmp_spd)
            with open(tmp_spd, "rb+") as fh:
                os.fsync(fh.fileno())
            spd_digest = sha256_file(tmp_spd)
            os.replace(tmp_spd, self.root / spd_rel)
        os.replace(src, self.root / rel)
        _fsync_dir(frames)
        record = FrameRecord(
            id=spec.id,
            kind=spec.kind,
            channel=spec.channel,
            exposure_s=float(spec.exposure_s),
            iso=int(spec.iso),
            bracket=int(spec.bracket),
            file=rel,
            sha256=digest,
            time_utc=_utc_now(),
            status="ok",
            spd_file=spd_rel,
            note=note,
            spd_sha256=spd_digest,
        )
        self._put(record)
        return record

    def mark_bad(self, frame_ids: str | Iterable[str], reason: str = "") -> None:
        """Mark frames bad so that a resume takes them again.

        Raises
        ------
        InputError
            If a frame id is not in the session's plan or records.
        """
        ids = [frame_ids] if isinstance(frame_ids, str) else list(frame_ids)
        try:
            planned = {f.id for f in self.plan()}
        except InputError:
            planned = set()
        known = planned | {d["id"] for d in self._m["frames"]}
        unknown = [i for i in ids if i not in known]
        if unknown:
            raise InputError(
                f"unknown frame id(s): {', '.join(unknown)}", path=self.manifest_path
            )
        m = self._edited()
        for d in m["frames"]:
            if d["id"] in ids:
                d["status"] = "bad"
                d["note"] = reason or "marked bad"
        self._write_manifest(m)

    def read_spd(self, record: FrameRecord) -> Spectra:
        """The SPD measured around a frame (one spectrum).

        Raises
        ------
        InputError
            If the frame has no SPD.
        """
        if record.spd_file is None:
            raise InputError(f"frame {record.id!r} has no measured SPD")
        return read_spectra_csv(self.inside(record.spd_file))

    def _put(self, record: FrameRecord) -> None:
        m = self._edited()
        frames = m["frames"]
        d = record.to_dict()
        for i, old in enumerate(frames):
            if old["id"] == record.id:
                frames[i] = d
                break
        else:
            frames.append(d)
        self._write_manifest(m)

    def __repr__(self) -> str:
        return f"Session({str(self.root)!r}, {len(self._m['frames'])} frames)"


def _same_spec(a: FrameSpec, b: FrameSpec) -> bool:
    return (
        a.kind == b.kind
        and a.channel == b.channel
        and a.iso == b.iso
        and a.bracket == b.bracket
        and math.isclose(a.exposure_s, b.exposure_s, rel_tol=EXPOSURE_RTOL)
    )


def frames_by_channel(
    frames: Sequence[FrameRecord], kind: str
) -> dict[str, list[FrameRecord]]:
    """Ok frames of ``kind`` grouped by channel, each list sorted by bracket."""
    out: dict[str, list[FrameRecord]] = {}
    for f in frames:
        if f.kind == kind and f.status == "ok" and f.channel is not None:
            out.setdefault(f.channel, []).append(f)
    for v in out.values():
        v.sort(key=lambda r: r.bracket)
    return out


def find_darks(
    frames: Sequence[FrameRecord], exposure_s: float, iso: int
) -> list[FrameRecord]:
    """Ok dark frames taken at ``exposure_s`` and ``iso``."""
    return [
        f
        for f in frames
        if f.kind == "dark"
        and f.status == "ok"
        and f.iso == iso
        and math.isclose(f.exposure_s, exposure_s, rel_tol=EXPOSURE_RTOL)
    ]


def with_exposures(
    settings: CaptureSettings, exposures_s: Mapping[str, Sequence[float]]
) -> CaptureSettings:
    """``settings`` with (some) channels' bracket exposures set."""
    merged = dict(settings.exposures_s)
    merged.update({k: tuple(v) for k, v in exposures_s.items()})
    return replace(settings, exposures_s=merged)
