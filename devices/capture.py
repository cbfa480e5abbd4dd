"""The capture sequence of the paper on any light source, camera and target stage.

Order (each step only for what is still missing in the session):

1. ``stage.present("white")``; if the exposures are not resolved yet, meter them:
   per LED a shot of the white background, scaled so its brightest part lands at
   ``target_level`` of full scale (or, for fixed exposures, set each one and read
   back what the camera really uses).
2. Dark frame(s) for every distinct exposure, with every LED off.
3. Per LED (and exposure bracket) a frame of the white background (``A_B``).
4. ``stage.present("target")``; per LED (and bracket) a frame of the target (``A``).

Around every LED exposure the light source's spectroradiometer is read just before
and just after; their mean is stored with the frame (Eq. 1's illuminant is that SPD
times the exposure time). Every frame goes into the session at once
(:meth:`tunespec.core.io.session.Session.commit_frame`), so a crash, a kill or a device
error loses nothing already captured; :func:`capture` with ``resume=True`` takes only
what is missing, bad or damaged, and ``retake=[ids]`` takes chosen frames again. All
LEDs are switched off when the sequence ends, fails or is cancelled.
"""

from __future__ import annotations

import contextlib
import errno
import math
import shutil
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, replace
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from tunespec.core.errors import DiskFullError, InputError
from tunespec.core.io.session import (
    MAX_BRACKETS,
    CaptureSettings,
    FrameRecord,
    FrameSpec,
    Session,
    SessionLock,
    with_exposures,
)
from tunespec.core.layout import TargetLayout
from tunespec.core.progress import ProgressFn, StopFn, check_stop, report
from tunespec.core.spectra import Spectra
from tunespec.devices.protocols import (
    Camera,
    DeviceCommandError,
    DeviceError,
    LightSource,
    TargetStage,
)

__all__ = [
    "BadFrameError",
    "CaptureResult",
    "FrameCallback",
    "bytes_needed",
    "capture",
    "check_frame",
    "check_same_camera",
    "device_identities",
    "free_space_warning",
    "meter_exposure",
    "new_session",
    "recorded_sim_camera",
]

#: Called after each committed frame with its record and raw file (GUI live view).
FrameCallback = Callable[[FrameRecord, Path], None]

#: Default longest exposure the metering may choose, seconds (a camera's timed range).
MAX_EXPOSURE_S = 30.0
#: Shortest exposure the metering may choose, seconds.
MIN_EXPOSURE_S = 1.0 / 8000.0
#: Metering: the level is the high percentile of the brightest channel (robust to
#: hot pixels), and more than this fraction of clipped pixels means "too bright".
METER_PERCENTILE = 99.5
METER_CLIPPED_FRACTION = 1e-3
#: Metering looks at every this-many-th CFA cell in each direction.
METER_STEP = 4
#: Below this fraction of full scale at the longest exposure, an LED is reported as
#: too weak (its responses carry little more than noise).
LOW_SIGNAL_LEVEL = 0.05
#: Metering shots per channel before giving up.
METER_MAX_SHOTS = 6
#: A lit frame with more than this fraction of its (sampled) pixels clipped is
#: flagged the moment it is taken (what metering calls too bright).
FLAG_CLIPPED_FRACTION = METER_CLIPPED_FRACTION


@dataclass(frozen=True)
class CaptureResult:
    """What :func:`capture` did.

    Parameters
    ----------
    session
        The session (all frames it holds now).
    captured
        Ids of the frames taken in this call, in order.
    skipped
        Planned frames that were already complete.
    metered
        Channels whose exposure was metered (or resolved) in this call.
    warnings
        Operator-readable notes (e.g. an LED too weak for the longest exposure).
    """

    session: Session
    captured: tuple[str, ...]
    skipped: int
    metered: tuple[str, ...] = ()
    warnings: tuple[str, ...] = ()


class BadFrameError(InputError):
    """A frame failed its check and the capture was asked to stop (``strict``);
    the frame is marked bad, so a resume takes it again."""


def check_frame(
    path: Path,
    spec: FrameSpec,
    fixed_exposure: bool,
    max_exposure_s: float = MAX_EXPOSURE_S,
) -> str | None:
    """What is wrong with a lit frame just taken, in the operator's words, or None.

    Saturation: more than :data:`FLAG_CLIPPED_FRACTION` of the pixels clipped
    (processing would refuse the white frame, or drop the patches). Under-exposure
    (fixed exposures only: a metered one was aimed at ``target_level``, and a weak
    LED is reported when metered): the brightest level below
    :data:`LOW_SIGNAL_LEVEL` of full scale, with a longer exposure advised unless
    the frame already has ``max_exposure_s``. Dark frames are not checked.
    """
    if spec.kind == "dark":
        return None
    level, clipped = _bright_level(path)
    what = f"{spec.kind} frame {spec.channel} at {spec.exposure_s:g} s"
    if clipped > FLAG_CLIPPED_FRACTION:
        return (
            f"{what}: {clipped:.1%} of its pixels are clipped (saturated); retake "
            "with a shorter exposure (--exposure, or auto to meter it)"
        )
    if fixed_exposure and level < LOW_SIGNAL_LEVEL:
        if spec.exposure_s >= max_exposure_s * (1.0 - 1e-9):
            # no longer exposure to advise: the LED is too weak for this scene
            return (
                f"{what}: under-exposed, its brightest part at {level:.1%} of full "
                "scale at the longest exposure allowed (--max-exposure); its "
                "responses will be noisy"
            )
        return (
            f"{what}: under-exposed, its brightest part at {level:.1%} of full "
            "scale; retake with a longer exposure (--exposure, or auto to meter it)"
        )
    return None


def _camera_record(camera: Camera) -> dict[str, str]:
    """The camera's identity, and its raw size (``"WxH"``) where it tells."""
    out = {k: str(v) for k, v in asdict(camera.identity).items()}
    resolution = getattr(camera, "resolution", None)
    if isinstance(resolution, tuple) and len(resolution) == 2:
        out["resolution"] = f"{int(resolution[0])}x{int(resolution[1])}"
    return out


def device_identities(
    light: LightSource, camera: Camera, stage: object | None = None
) -> dict[str, dict[str, str]]:
    """Identities of the devices as the session manifest stores them (the
    camera's with its raw size)."""
    out = {
        "light": {k: str(v) for k, v in asdict(light.identity).items()},
        "camera": _camera_record(camera),
    }
    if stage is not None:
        out["stage"] = {"kind": type(stage).__name__}
    return out


def recorded_sim_camera(session: Session) -> dict[str, Any]:
    """The simulated camera a session was captured with: ``{"resolution": (w, h),
    "seed": n}`` (what of them the manifest records), ``{}`` for hardware.

    A resume or a retake opens the simulated camera with these, so the missing
    frames match the ones already taken.
    """
    cam = session.devices.get("camera", {})
    if not cam.get("model", "").startswith("SimCamera"):
        return {}
    out: dict[str, Any] = {}
    with contextlib.suppress(ValueError):
        w, h = (int(v) for v in cam.get("resolution", "").split("x"))
        out["resolution"] = (w, h)
    serial = cam.get("serial", "")
    if serial.startswith("SIM-"):
        with contextlib.suppress(ValueError):
            out["seed"] = int(serial[4:])
    return out


def check_same_camera(session: Session, camera: Camera) -> None:
    """Refuse to add frames to a session from another camera than its frames came
    from: another model, serial or raw size (before the first frame is taken).

    Raises
    ------
    InputError
        Naming what differs.
    """
    if not session.ok_frames():
        return
    was = session.devices.get("camera", {})
    now = _camera_record(camera)
    diffs = [
        f"{key} {was[key]} -> {now[key]}"
        for key in ("model", "serial", "resolution")
        if was.get(key) and now.get(key) and was[key] != now[key]
    ]
    if diffs:
        raise InputError(
            "this session's frames were taken with another camera or camera "
            f"settings ({'; '.join(diffs)}): resume it with the camera it was "
            "captured with (a simulated camera: leave out --resolution and --seed, "
            "the session's are used)",
            path=session.manifest_path,
        )


def new_session(
    root: str | PathLike[str],
    light: LightSource,
    camera: Camera,
    *,
    layout: TargetLayout | None,
    exposure: str | float | Mapping[str, float] = "auto",
    iso: int = 100,
    channels: Sequence[str] | None = None,
    n_darks: int = 1,
    brackets: Sequence[float] = (1.0,),
    repeats: int = 1,
    target_level: float = 0.75,
    levels: Mapping[str, float] | None = None,
    meta: Mapping[str, str] | None = None,
) -> Session:
    """Create a session for ``light`` and ``camera`` (nothing is captured yet).

    Parameters
    ----------
    root
        The session folder (created).
    layout
        The target's layout (its corners may be unknown).
    exposure
        ``"auto"`` (metered per LED), one exposure in seconds for every LED, or a
        mapping channel name -> seconds.
    iso
        ISO speed of every frame.
    channels
        LED channels to capture (default: all of the light source, device order).
    n_darks
        Dark frames per distinct exposure.
    brackets
        Exposure bracket factors, starting with 1.0 (e.g. ``(1.0, 0.125)`` for HDR).
    repeats
        Frames per LED and bracket, averaged in processing (``1 / repeats`` of one
        frame's photon and read-noise variance, for per-pixel images): stored as
        each bracket factor repeated.
    target_level
        Auto exposure aim, fraction of full scale.
    levels
        LED drive level per channel (default 1.0).
    meta
        Free notes stored in the manifest.

    Raises
    ------
    InputError
        Unknown channels, a mapping missing channels, bad settings.
    """
    available = [c.name for c in light.channels()]
    chosen = list(channels) if channels is not None else available
    unknown = [c for c in chosen if c not in available]
    if unknown:
        raise InputError(
            f"unknown LED channel(s) {', '.join(unknown)}; the light source has "
            f"{', '.join(available)}"
        )
    if not 1 <= int(repeats) <= MAX_BRACKETS // max(1, len(brackets)):
        raise InputError(
            f"repeats: expected 1 to {MAX_BRACKETS // max(1, len(brackets))} frames "
            f"per LED and bracket (at most {MAX_BRACKETS} frames), got {repeats}"
        )
    factors = tuple(float(f) for f in brackets for _ in range(int(repeats)))
    if exposure == "auto":
        mode, exposures = "auto", {}
    else:
        mode = "fixed"
        if isinstance(exposure, Mapping):
            missing = [c for c in chosen if c not in exposure]
            if missing:
                raise InputError(
                    f"no exposure given for channel(s) {', '.join(missing)}"
                )
            base = {c: float(exposure[c]) for c in chosen}
        else:
            try:
                t = float(exposure)
            except (TypeError, ValueError):
                raise InputError(
                    f"exposure must be 'auto' or seconds, got {exposure!r}"
                ) from None
            base = dict.fromkeys(chosen, t)
        exposures = {c: tuple(t * f for f in factors) for c, t in base.items()}
        if any(not (t > 0 and math.isfinite(t)) for v in exposures.values() for t in v):
            raise InputError("exposures must be positive seconds")
    settings = CaptureSettings(
        tuple(chosen),
        iso=int(iso),
        exposure_mode=mode,
        # fixed exposures are confirmed with the camera (its steps) at capture time
        requested_s=exposures,
        bracket_factors=factors,
        n_darks=int(n_darks),
        target_level=float(target_level),
        levels=dict(levels or {}),
    )
    return Session.create(
        root,
        settings=settings,
        devices=device_identities(light, camera),
        layout=layout,
        meta=meta,
    )


def _levels_for(
    light: LightSource, settings: CaptureSettings, channel: str
) -> np.ndarray:
    names = [c.name for c in light.channels()]
    levels = np.zeros(len(names))
    levels[names.index(channel)] = settings.level(channel)
    return levels


def _set_exposure(camera: Camera, exposure_s: float) -> float:
    """Set an exposure and return what the camera really uses."""
    camera.set_exposure(exposure_s)
    return float(camera.exposure_s)


def _bright_level(path: Path) -> tuple[float, float]:
    """Brightest level and clipped fraction of a metering shot.

    The level is the :data:`METER_PERCENTILE` percentile, over CFA cells, of the
    brightest photosite of the cell (full-scale units); every
    :data:`METER_STEP`-th cell in each direction is enough for that and keeps
    metering cheap on a full-size frame.
    """
    from tunespec.core.io.raw import load_raw

    frame = load_raw(path)
    step = 2 * METER_STEP
    brightest: np.ndarray | None = None
    clipped: np.ndarray | None = None
    for k in range(4):
        dy, dx = divmod(k, 2)
        site = frame.mosaic[dy::step, dx::step]
        black = float(frame.black_level_cfa[dy, dx])
        value = (site.astype(np.float32) - black) / (frame.white_level - black)
        over = site >= frame.white_level
        brightest = value if brightest is None else np.maximum(brightest, value)
        clipped = over if clipped is None else clipped | over
    assert brightest is not None and clipped is not None
    return float(np.percentile(brightest, METER_PERCENTILE)), float(clipped.mean())


def meter_exposure(
    camera: Camera,
    stem: Path,
    *,
    start_s: float,
    target_level: float,
    min_s: float = MIN_EXPOSURE_S,
    max_s: float = MAX_EXPOSURE_S,
    measure: Callable[[Path], tuple[float, float]] = _bright_level,
) -> tuple[float, float]:
    """The exposure that puts the brightest part of the scene at ``target_level``.

    The sensor is linear, so one unclipped shot with enough signal predicts the
    exposure; clipped shots are shortened eightfold and very dark ones lengthened.
    The light and the scene must already be set up.

    Parameters
    ----------
    camera
        The camera; its exposure is left at the result.
    stem
        Where to write metering shots (deleted afterwards).
    start_s
        First exposure to try.
    target_level
        Aim, fraction of full scale.
    min_s, max_s
        Exposure range allowed.
    measure
        ``path -> (level, clipped fraction)`` of a shot.

    Returns
    -------
    (exposure_s, expected_level)
        The exposure the camera uses and the level it is expected to give (below
        ``target_level`` when ``max_s`` limits it).
    """
    t = min(max(start_s, min_s), max_s)
    for _ in range(METER_MAX_SHOTS):
        t_set = _set_exposure(camera, t)
        path = camera.capture(stem)
        try:
            level, clipped = measure(path)
        finally:
            with contextlib.suppress(OSError):
                path.unlink()
        if clipped > METER_CLIPPED_FRACTION or level >= 0.98:
            if t_set <= min_s * 1.0001:
                return t_set, level
            t = max(min_s, t_set / 8.0)
            continue
        if level < 0.02:
            if t_set >= max_s * 0.9999:
                return t_set, level
            t = min(
                max_s,
                t_set * (100.0 if level <= 0 else min(100.0, target_level / level)),
            )
            continue
        t = min(max_s, max(min_s, t_set * target_level / level))
        t_final = _set_exposure(camera, t)
        return t_final, level * t_final / t_set
    return _set_exposure(camera, t), float("nan")


def _resolve_exposures(
    session: Session,
    light: LightSource,
    camera: Camera,
    stage: TargetStage,
    *,
    max_exposure_s: float,
    warnings: list[str],
    step: Callable[[], None],
    on_stage: Callable[[str], None] | None = None,
) -> tuple[str, ...]:
    """Meter (auto) or confirm (fixed) every channel's bracketed exposures."""
    settings = session.settings
    todo = [c for c in settings.channels if c not in settings.exposures_s]
    if not todo:
        return ()
    requested = settings.requested_s
    if settings.exposure_mode == "auto":
        stage.present("white")
    start_s = 1.0
    for i, c in enumerate(todo, 1):
        if settings.exposure_mode == "auto":
            if on_stage is not None:
                on_stage(f"metering {c}, {i} of {len(todo)}")
            light.set_levels(_levels_for(light, settings, c))
            t0, level = meter_exposure(
                camera,
                session.temp_stem(f"meter_{c}"),
                start_s=start_s,
                target_level=settings.target_level,
                max_s=max_exposure_s,
            )
            start_s = t0
            if not math.isfinite(level):
                warnings.append(
                    f"{c}: metering did not settle in {METER_MAX_SHOTS} shots; using "
                    f"{t0:g} s, check its frames for clipping or low signal"
                )
            elif level < LOW_SIGNAL_LEVEL:
                warnings.append(
                    f"{c}: only {level:.1%} of full scale at the longest exposure "
                    f"allowed ({t0:g} s); its responses will be noisy"
                )
            wanted = [t0 * f for f in settings.bracket_factors]
        else:
            if c not in requested:
                raise InputError(
                    f"no exposure recorded for channel {c}", path=session.manifest_path
                )
            wanted = list(requested[c])
        actual = tuple(_set_exposure(camera, t) for t in wanted)
        settings = with_exposures(settings, {c: actual})
        session.set_settings(settings)  # metered values survive a crash
        step()
    return tuple(todo)


def _mean_spd(a: Spectra, b: Spectra) -> Spectra:
    """Mean of two one-spectrum measurements (on ``a``'s wavelengths)."""
    vb = np.interp(a.wavelength_nm, b.wavelength_nm, b.values[0])
    return Spectra(
        a.wavelength_nm,
        0.5 * (a.values[0] + vb)[None, :],
        ("measured",),
        {"how": "mean of readings just before and just after the exposure"},
    )


def capture(
    session: Session,
    light: LightSource,
    camera: Camera,
    stage: TargetStage,
    *,
    resume: bool = False,
    retake: Iterable[str] = (),
    max_exposure_s: float = MAX_EXPOSURE_S,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
    on_frame: FrameCallback | None = None,
    on_warning: Callable[[str], None] | None = None,
    on_stage: Callable[[str], None] | None = None,
    strict: bool = False,
) -> CaptureResult:
    """Run (or resume) the capture sequence of a session.

    Parameters
    ----------
    session
        A session from :func:`new_session` (or :meth:`Session.open` to resume).
    light, camera, stage
        The devices; ``stage.present("white"|"target")`` returns once that is in
        front of the camera.
    resume
        Continue a session that already holds frames: take only the frames that are
        missing, marked bad, or whose file fails its checksum.
    retake
        Frame ids to mark bad and take again (implies ``resume``).
    max_exposure_s
        Longest exposure the metering may choose.
    progress, should_stop
        Progress (fraction of the frames to take) and cancellation hooks; a
        cancelled capture keeps every frame taken so far.
    on_frame
        Called with each committed frame's record and raw file path.
    on_warning
        Called with each warning as it arises (all are also in the result): a
        lock taken over, too little free disk space for the frames to take, an LED
        too weak.
    on_stage
        Called with what starts now, for an operator watching a long sequence:
        ``"metering LED495, 7 of 22"``, ``"white frame LED410, 1 of 22"``.
    strict
        Stop at the first frame that fails :func:`check_frame` (it is marked bad)
        instead of warning and going on.

    Returns
    -------
    CaptureResult

    Raises
    ------
    InputError
        A session that already holds frames without ``resume``; channels the light
        source does not have.
    BadFrameError
        ``strict`` and a frame failed its check.
    SessionBusyError
        Another process is capturing into the session (its lock names it); a lock
        left by a killed capture is taken over, with a warning in the result.
    DiskFullError
        The disk filled up; frames committed before stay in the session, the
        manifest is consistent and a resume after freeing space goes on.
    DeviceError
        From the devices; frames committed before it stay in the session.
    Cancelled
        When ``should_stop()`` turns true.
    """
    warnings = _Warnings(on_warning)
    with SessionLock(session.root) as lock:
        session.reload()
        if lock.stale_holder is not None:
            holder = lock.stale_holder
            warnings.append(
                "took over the lock of an interrupted capture (pid "
                f"{holder.get('pid')} on {holder.get('host')}, started "
                f"{holder.get('started_utc')})"
            )
        try:
            return _capture_locked(
                session,
                light,
                camera,
                stage,
                resume=resume,
                retake=list(retake),
                max_exposure_s=max_exposure_s,
                progress=progress,
                should_stop=should_stop,
                on_frame=on_frame,
                warnings=warnings,
                on_stage=on_stage,
                strict=strict,
            )
        except OSError as exc:
            if exc.errno != errno.ENOSPC:
                raise
            # the manifest lists only what was committed before; resume goes on
            raise DiskFullError(
                session.root, needed_bytes=bytes_needed(session, camera), resume=True
            ) from None


class _Warnings(list[str]):
    """Warnings collected for the result and passed on at once to a callback."""

    def __init__(self, callback: Callable[[str], None] | None) -> None:
        super().__init__()
        self._callback = callback

    def append(self, warning: str) -> None:
        super().append(warning)
        if self._callback is not None:
            self._callback(warning)


#: Bytes assumed for a raw frame when neither the session nor the camera tells
#: (a 5D Mark III CR2 is 25-35 MB).
DEFAULT_FRAME_BYTES = 40_000_000
#: Room kept for the manifest, SPD files and temp files.
SPARE_BYTES = 5_000_000


def frame_bytes(session: Session, camera: Camera | None = None) -> int:
    """Expected size of one more frame (raw file and SPD), bytes.

    The mean of the frames already in the session; else from the camera's
    resolution (16-bit mosaic); else :data:`DEFAULT_FRAME_BYTES`.
    """
    sizes = []
    for rec in session.ok_frames():
        with contextlib.suppress(OSError):
            size = session.path_of(rec).stat().st_size
            if rec.spd_file is not None:
                size += (session.root / rec.spd_file).stat().st_size
            sizes.append(size)
    if sizes:
        return int(max(sizes))
    resolution = getattr(camera, "resolution", None)
    if isinstance(resolution, tuple) and len(resolution) == 2:
        w, h = resolution
        return int(w) * int(h) * 2 + 200_000
    return DEFAULT_FRAME_BYTES


def frames_to_take(session: Session) -> int:
    """Frames a capture of ``session`` still has to take (an upper bound before the
    exposures are metered: one dark per LED exposure)."""
    settings = session.settings
    if settings.resolved:
        return len(session.missing(verify=False))
    n_lit = 2 * len(settings.channels) * len(settings.bracket_factors)
    ok = len(session.ok_frames())
    return max(0, n_lit + (n_lit // 2) * settings.n_darks - ok)


def bytes_needed(session: Session, camera: Camera | None = None) -> int:
    """Disk space the rest of a capture needs, bytes (with some room to spare)."""
    return frames_to_take(session) * frame_bytes(session, camera) + SPARE_BYTES


def free_space_warning(session: Session, camera: Camera | None = None) -> str | None:
    """A warning if the frames still to take do not fit on the session's disk."""
    try:
        free = shutil.disk_usage(session.root).free
    except OSError:
        return None
    need = bytes_needed(session, camera)
    if need <= free:
        return None
    return (
        f"the {frames_to_take(session)} frame(s) still to take need about "
        f"{need / 1e6:.0f} MB but only {free / 1e6:.0f} MB are free in "
        f"{session.root}; the capture will stop when the disk is full (resume it "
        "after freeing space)"
    )


def _capture_locked(
    session: Session,
    light: LightSource,
    camera: Camera,
    stage: TargetStage,
    *,
    resume: bool,
    retake: list[str],
    max_exposure_s: float,
    progress: ProgressFn | None,
    should_stop: StopFn | None,
    on_frame: FrameCallback | None,
    warnings: list[str],
    on_stage: Callable[[str], None] | None = None,
    strict: bool = False,
) -> CaptureResult:
    if session.frames and not (resume or retake):
        raise InputError(
            "the session already holds frames; resume it (--resume) or start a new one",
            path=session.root,
        )
    settings = session.settings
    available = [c.name for c in light.channels()]
    unknown = [c for c in settings.channels if c not in available]
    if unknown:
        raise InputError(
            f"the light source has no channel(s) {', '.join(unknown)}",
            path=session.root,
        )
    session.clean_temp()
    check_same_camera(session, camera)
    session.set_devices(device_identities(light, camera, stage))
    if retake:
        session.mark_bad(retake, "retake requested")
    space = free_space_warning(session, camera)
    if space is not None:
        warnings.append(space)
    n_meter = sum(c not in settings.exposures_s for c in settings.channels)
    # until the exposures are known, count every possible dark (an overestimate, so
    # the fraction never goes back when the real count replaces it)
    n_lit = 2 * len(settings.channels) * len(settings.bracket_factors)
    total = [n_meter + n_lit + (n_lit // 2) * settings.n_darks if n_meter else 0]
    done = [0]

    def step() -> None:
        done[0] += 1
        report(progress, done[0] / max(1, total[0]))
        check_stop(should_stop)

    captured: list[str] = []
    try:
        check_stop(should_stop)
        # before metering: exposures metered at another ISO would be off by the ratio
        if camera.iso != settings.iso:
            camera.set_iso(settings.iso)
        metered = _resolve_exposures(
            session,
            light,
            camera,
            stage,
            max_exposure_s=max_exposure_s,
            warnings=warnings,
            step=step,
            on_stage=on_stage,
        )
        settings = session.settings
        todo = session.missing(verify=resume or bool(retake))
        total[0] = done[0] + len(todo)
        skipped = len(session.plan()) - len(todo)
        darks = [s for s in todo if s.kind == "dark"]
        if darks:
            light.all_off()
        for i, spec in enumerate(darks, 1):
            _stage(on_stage, spec, i, len(darks))
            captured.append(_take(session, camera, spec, None, on_frame).id)
            step()
        for kind in ("white", "target"):
            specs = [s for s in todo if s.kind == kind]
            if not specs:
                continue
            stage.present(kind)  # type: ignore[arg-type]
            current: str | None = None
            for i, spec in enumerate(specs, 1):
                assert spec.channel is not None
                _stage(on_stage, spec, i, len(specs))
                if spec.channel != current:
                    light.set_levels(_levels_for(light, settings, spec.channel))
                    current = spec.channel
                record = _take(session, camera, spec, light, on_frame)
                captured.append(record.id)
                _flag(session, record, warnings, strict, max_exposure_s)
                step()
        if any(s.kind == "target" for s in todo):
            _check_target_found(session, warnings, strict)
        light.all_off()
    except BaseException:
        # the original error matters more than a failure to switch off
        with contextlib.suppress(DeviceError, OSError):
            light.all_off()
        raise
    finally:
        # nothing is being written now: no empty tmp/ folder in the session
        session.clean_temp()
    report(progress, 1.0)
    return CaptureResult(session, tuple(captured), skipped, metered, tuple(warnings))


def _flag(
    session: Session,
    record: FrameRecord,
    warnings: list[str],
    strict: bool,
    max_exposure_s: float,
) -> None:
    """Check a frame just committed; warn (or, ``strict``, mark it bad and stop)."""
    problem = check_frame(
        session.path_of(record),
        record.spec,
        session.settings.exposure_mode == "fixed",
        max_exposure_s,
    )
    if problem is None:
        return
    if strict:
        session.mark_bad([record.id], problem)
        raise BadFrameError(f"{problem} (stopped: --strict)", path=session.root)
    warnings.append(problem)


def _check_target_found(session: Session, warnings: list[str], strict: bool) -> None:
    """Once the target frames are in: can processing find the target in them?
    (Not when the layout gives its corners: then nothing is searched.)"""
    from tunespec.core.processing import find_session_corners

    layout = session.layout
    if layout is None or layout.corners_px is not None:
        return
    try:
        find_session_corners(session, layout)
    except InputError as exc:
        problem = (
            f"the target was not found in its frames ({exc.message}); check that "
            "it lies flat, fully in view and lit, or give its corners in the "
            "layout (--layout with corners_px)"
        )
        if strict:
            raise BadFrameError(
                f"{problem} (stopped: --strict)", path=session.root
            ) from None
        warnings.append(problem)


def _stage(
    on_stage: Callable[[str], None] | None, spec: FrameSpec, i: int, n: int
) -> None:
    """``"dark frame 1 of 3"``, ``"white frame LED410, 1 of 22"``."""
    if on_stage is not None:
        what = f"{spec.kind} frame" + (f" {spec.channel}," if spec.channel else "")
        on_stage(f"{what} {i} of {n}")


def _take(
    session: Session,
    camera: Camera,
    spec: FrameSpec,
    light: LightSource | None,
    on_frame: FrameCallback | None,
) -> FrameRecord:
    """Expose one frame (with SPD readings around it) and commit it."""
    t = _set_exposure(camera, spec.exposure_s)
    if not math.isclose(t, spec.exposure_s, rel_tol=1e-6):
        raise DeviceCommandError(
            f"the camera set {t:g} s instead of the session's {spec.exposure_s:g} s "
            f"for frame {spec.id}; its exposure steps changed since metering"
        )
    spd = None
    if light is not None:
        before = light.measure_spd()
        path = camera.capture(session.temp_stem(spec.id))
        after = light.measure_spd()
        spd = _mean_spd(before, after)
    else:
        path = camera.capture(session.temp_stem(spec.id))
    record = session.commit_frame(replace(spec, exposure_s=t), path, spd=spd)
    if on_frame is not None:
        on_frame(record, session.path_of(record))
    return record
