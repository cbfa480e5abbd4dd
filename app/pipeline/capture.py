"""The capture step of every front end, and the one place resume and retake are decided.

:func:`capture_session` captures one session on an open bench; what it does with a
session already in the folder is :class:`Resume`'s, decided by
:func:`open_for_capture` for ``tunespec capture --resume/--retake``, ``run``/``demo``
and the wizard's capture and retake buttons alike (as bluesky's RunEngine resumes a
plan): the session keeps its own settings and, on the simulated bench, its camera's
resolution and seed (:func:`recorded_bench_options` for a bench opened by spec,
:func:`bench_as_recorded` for one already open); only the missing frames are taken.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from os import PathLike
from pathlib import Path
from typing import Any

from tunespec.app.pipeline.folder import add_capture_warnings, clear_capture_warnings
from tunespec.app.pipeline.plan import chart_layout, sample_layout
from tunespec.core.errors import InputError
from tunespec.core.io.session import MANIFEST_NAME, Session
from tunespec.core.layout import TargetLayout
from tunespec.core.progress import ProgressFn, StopFn
from tunespec.core.spectra import Spectra
from tunespec.devices.capture import (
    MAX_EXPOSURE_S,
    CaptureResult,
    FrameCallback,
    capture,
    new_session,
    recorded_sim_camera,
)
from tunespec.devices.registry import Bench, sim_scene

__all__ = [
    "RESUME_MODES",
    "RETAKE_PHASES",
    "CaptureSettings",
    "Resume",
    "bench_as_recorded",
    "bench_for_target",
    "capture_chart",
    "capture_sample",
    "capture_session",
    "capture_target",
    "open_for_capture",
    "recorded_bench_options",
]

log = logging.getLogger(__name__)


def bench_for_target(
    bench: Bench,
    layout: TargetLayout,
    reflectances: Spectra | None = None,
    *,
    seed: int = 1,
) -> Bench:
    """The bench with ``layout`` in front of the camera.

    On hardware the operator changes the target (the stage asks them), so the bench is
    returned as it is. A simulated bench gets the same simulated camera (same
    constants, light and clock; :meth:`SimCamera.looking_at`) looking at a scene with
    ``layout`` on the same board under the same light field
    (:meth:`SimScene.bench_options`).
    """
    if not bench.simulated:
        return bench
    # the same bench: camera pose, field of view, the light's fall-off, the white
    # board and the camera's sensor constants stay; only the target changes (a
    # scene or camera rebuilt from defaults would change the flat field and the
    # sensitivities between the calibration and the sample)
    same: dict[str, Any] = bench.sim_stage.bench_options()
    scene = sim_scene(layout, reflectances, **same)
    camera = bench.sim_camera.looking_at(scene, seed=seed)
    return Bench(bench.light, camera, scene, camera.truth())


# -- capture: the one rule of resume and retake ----------------------------------------
@dataclass(frozen=True)
class CaptureSettings:
    """How a new session is captured; a resumed one keeps its own (the manifest's).

    Parameters
    ----------
    exposure
        ``"auto"`` (metered per LED on the white background), seconds for every LED,
        or seconds per LED.
    iso, brackets, n_darks, repeats, channels
        As :func:`tunespec.devices.capture.new_session` takes them (``channels``
        ``None``: every LED).
    max_exposure_s, strict
        As :func:`tunespec.devices.capture.capture` takes them.
    """

    exposure: str | float | Mapping[str, float] = "auto"
    iso: int = 100
    brackets: tuple[float, ...] = (1.0,)
    n_darks: int = 1
    repeats: int = 1
    channels: tuple[str, ...] | None = None
    max_exposure_s: float = MAX_EXPOSURE_S
    strict: bool = False


#: :attr:`Resume.mode`: continue a session that is there, else start one (``run``,
#: ``demo``, the wizard); one must be there (``capture --resume``); none may be.
RESUME_MODES = ("auto", "continue", "new")
#: :attr:`Resume.retake_phase`: the frames of one kind, or ``"all"`` of them.
RETAKE_PHASES = ("dark", "white", "target", "all")


@dataclass(frozen=True)
class Resume:
    """What a capture does with the session already in its folder.

    Like a bluesky RunEngine resuming a plan, one place decides it
    (:func:`open_for_capture`), whichever front end asks: the session keeps its
    own settings (exposures, ISO, brackets, channels) and, on the simulated bench,
    its camera's resolution and seed; only the missing frames are taken.

    Parameters
    ----------
    mode
        One of :data:`RESUME_MODES`.
    retake
        Frame ids to take again (``capture --retake``; implies ``"continue"``).
    retake_phase
        One of :data:`RETAKE_PHASES`: when the session already holds every frame
        of that phase, they are all taken again (the wizard's retake buttons).
    """

    mode: str = "auto"
    retake: tuple[str, ...] = ()
    retake_phase: str | None = None

    def __post_init__(self) -> None:
        if self.mode not in RESUME_MODES:
            raise ValueError(f"resume mode {self.mode!r} not in {RESUME_MODES}")
        if self.retake_phase not in (None, *RETAKE_PHASES):
            raise ValueError(f"retake phase {self.retake_phase!r}")

    def session_exists(self, session_dir: str | PathLike[str]) -> bool:
        """Whether a session is in ``session_dir``, refusing what the mode forbids.

        Raises
        ------
        InputError
            A session there for ``"new"``, none for ``"continue"`` or a retake.
        """
        root = Path(session_dir)
        exists = (root / MANIFEST_NAME).is_file()
        if exists and self.mode == "new":
            raise InputError(
                "a session exists here; add --resume to continue it", path=root
            )
        if not exists and (self.mode == "continue" or self.retake):
            raise InputError("no session to resume here", path=root)
        return exists


def recorded_bench_options(
    session_dir: str | PathLike[str],
    *,
    resolution: tuple[int, int] | None,
    seed: int | None,
) -> tuple[tuple[int, int] | None, int | None]:
    """The simulated camera's ``(resolution, seed)`` to open a bench with for the
    session in ``session_dir``: its own when it is resumed, else those given.

    Raises
    ------
    InputError
        A resolution or seed given (``--resolution``, ``--seed``) that differs
        from the session's.
    """
    root = Path(session_dir)
    if not (root / MANIFEST_NAME).is_file():
        return resolution, seed
    recorded = recorded_sim_camera(Session.open(root))
    given = {"resolution": resolution, "seed": seed}
    for key, flag in (("resolution", "--resolution"), ("seed", "--seed")):
        if key in recorded and given[key] is not None and given[key] != recorded[key]:
            shown, was = given[key], recorded[key]
            if key == "resolution":
                shown, was = "x".join(map(str, shown)), "x".join(map(str, was))
            raise InputError(
                f"{flag} {shown} differs from the session's {was}: leave "
                f"{flag} out to resume with the session's",
                path=root,
            )
    return recorded.get("resolution", resolution), recorded.get("seed", seed)


def bench_as_recorded(bench: Bench, session: Session) -> Bench:
    """``bench`` with the simulated camera ``session`` was captured with (its
    resolution and seed: ``devices.capture.recorded_sim_camera``); hardware, or a
    camera already so, as it is. A bench opened before the session was known
    (the wizard's, ``run``'s) gets it here; ``capture`` opens its bench with
    :func:`recorded_bench_options`."""
    recorded = recorded_sim_camera(session)
    if not bench.simulated or not recorded:
        return bench
    camera = bench.sim_camera
    seed = recorded.get("seed")
    resolution = recorded.get("resolution")
    same_seed = seed is None or camera.identity.serial == f"SIM-{seed}"
    if same_seed and resolution in (None, camera.resolution):
        return bench
    camera = camera.looking_at(bench.sim_stage, seed=seed, resolution=resolution)
    return Bench(bench.light, camera, bench.stage, camera.truth())


def open_for_capture(
    bench: Bench,
    session_dir: str | PathLike[str],
    layout: TargetLayout,
    settings: CaptureSettings,
    resume: Resume,
) -> tuple[Session, Bench, tuple[str, ...]]:
    """The session to capture into and the bench to capture with: the one place
    resume and retake are decided (:class:`Resume`).

    A session that is there is resumed with its own settings (``settings`` are
    for a new one), its layout (``layout`` if it has none) and, on the simulated
    bench, its camera (:func:`bench_as_recorded`); a retake phase that is complete
    has its frames marked bad. A new session forgets the capture warnings of an
    earlier one in the folder.

    Returns
    -------
    (session, bench, retake)
        ``retake``: the frame ids for ``devices.capture.capture(retake=)``.
    """
    root = Path(session_dir)
    if not resume.session_exists(root):
        clear_capture_warnings(root)  # of an earlier session in this folder
        session = new_session(
            root,
            bench.light,
            bench.camera,
            layout=layout,
            exposure=settings.exposure,
            iso=settings.iso,
            channels=None if settings.channels is None else list(settings.channels),
            n_darks=settings.n_darks,
            brackets=settings.brackets,
            repeats=settings.repeats,
        )
        return session, bench, ()
    session = Session.open(root)
    if session.layout is None:
        session.set_layout(layout)
    phase = resume.retake_phase
    if phase is not None and session.settings.resolved:
        kind = None if phase == "all" else phase
        if not any(kind in (None, s.kind) for s in session.missing(verify=False)):
            again = [f.id for f in session.frames if kind in (None, f.kind)]
            session.mark_bad(again, "retaken by the operator")
            log.info("retaking %d %s frame(s)", len(again), kind or "")
    # the missing frames are taken as the others were: a simulated camera gets the
    # session's resolution and seed back (a camera that differs otherwise is
    # refused by capture() before its first frame)
    return session, bench_as_recorded(bench, session), resume.retake


def capture_session(
    bench: Bench,
    session_dir: str | PathLike[str],
    layout: TargetLayout,
    settings: CaptureSettings = CaptureSettings(),
    resume: Resume = Resume(),
    *,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
    on_frame: FrameCallback | None = None,
    on_warning: Callable[[str], None] | None = None,
    on_stage: Callable[[str], None] | None = None,
) -> tuple[Session, CaptureResult]:
    """Capture (or resume, or retake) one session of ``layout`` on ``bench``: the
    capture step of every front end (:func:`open_for_capture`, then
    ``devices.capture.capture``).

    Every warning is kept beside the session the moment it arises
    (:func:`~tunespec.app.pipeline.folder.add_capture_warnings`), so the calibrate
    and estimate steps report it even when the capture was resumed, by another
    front end, or interrupted.

    Parameters
    ----------
    layout
        Stored with a new session as it is (:func:`capture_target` takes its
        corners off: they are found in every session).
    on_warning, on_stage
        ``devices.capture.capture``'s hooks: each warning as it arises, and the
        stage that starts (``"metering LED495, 7 of 22"``).
    """
    root = Path(session_dir)

    def warned(text: str) -> None:
        add_capture_warnings(root, [text])
        if on_warning is not None:
            on_warning(text)

    session, bench, retake = open_for_capture(bench, root, layout, settings, resume)
    result = capture(
        session,
        bench.light,
        bench.camera,
        bench.stage,
        resume=True,
        retake=retake,
        max_exposure_s=settings.max_exposure_s,
        progress=progress,
        should_stop=should_stop,
        on_frame=on_frame,
        on_warning=warned,
        on_stage=on_stage,
        strict=settings.strict,
    )
    return session, result


def capture_target(
    bench: Bench,
    session_dir: str | PathLike[str],
    layout: TargetLayout,
    *,
    exposure: str | float | Mapping[str, float] = "auto",
    iso: int = 100,
    brackets: Sequence[float] = (1.0,),
    n_darks: int = 1,
    repeats: int = 1,
    resume: bool = True,
    retake_phase: str | None = None,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
    on_frame: FrameCallback | None = None,
    on_warning: Callable[[str], None] | None = None,
    on_stage: Callable[[str], None] | None = None,
) -> tuple[Session, tuple[str, ...]]:
    """:func:`capture_session` of ``layout`` without its corners (they are found in
    each session), continuing a session that is there (``resume=False``: refusing
    it).

    Returns
    -------
    (session, warnings)
        ``warnings``: those of this run.
    """
    session, result = capture_session(
        bench,
        session_dir,
        layout.with_corners(None),
        CaptureSettings(exposure, iso, tuple(brackets), n_darks, repeats),
        Resume("auto" if resume else "new", retake_phase=retake_phase),
        progress=progress,
        should_stop=should_stop,
        on_frame=on_frame,
        on_warning=on_warning,
        on_stage=on_stage,
    )
    return session, result.warnings


def capture_chart(
    bench: Bench, session_dir: str | PathLike[str], **kwargs: Any
) -> tuple[Session, tuple[str, ...]]:
    """:func:`capture_target` of the ColorChecker SG (:func:`chart_layout`)."""
    return capture_target(bench, session_dir, chart_layout(), **kwargs)


def capture_sample(
    bench: Bench,
    session_dir: str | PathLike[str],
    layout: TargetLayout | None = None,
    **kwargs: Any,
) -> tuple[Session, tuple[str, ...]]:
    """:func:`capture_target` of the sample target (default :func:`sample_layout`)."""
    return capture_target(bench, session_dir, layout or sample_layout(), **kwargs)
