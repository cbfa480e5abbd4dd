"""What a session holds, in its manifest: the capture settings, the frame plan and
the frame records, with their checks (the format; :mod:`tunespec.core.io.session`
reads and writes the folder).

The frames a session needs follow from its :class:`CaptureSettings`
(:func:`plan_frames`): dark frame(s) for each distinct exposure, then per LED channel
a white-background frame and a target frame (one per exposure bracket). Each frame
taken is a :class:`FrameRecord` (paths inside the session folder, checksums, status).

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source (``shared/reference``),
section "Capturing and Processing": dark frame, white background ``A_B`` and target
``A`` under each of the 22 LEDs.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from os import PathLike
from pathlib import PurePosixPath, PureWindowsPath
from typing import Any

from tunespec.core.errors import InputError
from tunespec.core.limits import MAX_NAME_CHARS, shown, valid_number

__all__ = [
    "EXPOSURE_MODES",
    "EXPOSURE_RTOL",
    "FRAMES_DIR",
    "FRAME_KINDS",
    "LOCK_NAME",
    "MANIFEST_NAME",
    "MAX_BRACKETS",
    "MAX_CHANNELS",
    "MAX_DARKS",
    "MAX_FRAMES",
    "MAX_ISO",
    "SESSION_FORMAT",
    "SESSION_VERSION",
    "TMP_DIR",
    "CaptureSettings",
    "FrameRecord",
    "FrameSpec",
    "dark_id",
    "find_darks",
    "frames_by_channel",
    "plan_frames",
    "same_spec",
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


def same_spec(a: FrameSpec, b: FrameSpec) -> bool:
    """Whether a taken frame's spec is the planned one (exposures within
    :data:`EXPOSURE_RTOL`)."""
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
