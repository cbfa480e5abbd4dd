"""A captured session read into patch responses and illuminants: the stage.

:func:`process_session` reads a session's folder (manifest, raw frames, measured
SPDs; checksums verified), and drives the numerics of
:mod:`tunespec.core.processing` on the frames it reads: darks averaged, brackets
merged, Eq. 2 and the ROI statistics. :func:`write_processed` writes what
``calibrate`` and ``estimate`` read. The steps and their equations are described in
:mod:`tunespec.core.processing`.

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source (``shared/reference``),
section "Capturing and Processing", Eq. 1, 2 and 6.
"""

from __future__ import annotations

import contextlib
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from os import PathLike

import numpy as np
from numpy.typing import ArrayLike

from tunespec.app.pipeline.heap import reused_heap
from tunespec.app.pipeline.read_ahead import ReadAhead
from tunespec.core.errors import InputError
from tunespec.core.io.raw import RawFrame, full_to_plane_px, load_raw
from tunespec.core.io.responses_csv import write_responses_csv
from tunespec.core.io.session import (
    FrameRecord,
    Session,
    find_darks,
    frames_by_channel,
)
from tunespec.core.io.spectral_csv import write_spectra_csv
from tunespec.core.layout import TargetLayout
from tunespec.core.processing import (
    _FLAT,
    FLAT_WINDOW_PX,
    Loader,
    ProcessedSession,
    RoiSet,
    _ChannelStats,
    _detect_in_session,
    _detection_channel,
    _merge_brackets,
    _Pixels,
    _RoiGeometry,
    flat_window,
    frame_settings_problem,
)
from tunespec.core.progress import Cancelled, ProgressFn, StopFn, check_stop, report
from tunespec.core.spectra import Spectra

__all__ = [
    "SPD_MIN_COVERAGE_NM",
    "check_spds",
    "process_session",
    "write_processed",
]


def process_session(
    session: Session,
    *,
    layout: TargetLayout | None = None,
    corners: str | ArrayLike | None = None,
    roi_fraction: float | None = None,
    window_px: int = FLAT_WINDOW_PX,
    channels: Sequence[str] | None = None,
    allow_incomplete: bool = False,
    verify: bool = True,
    loader: Loader | None = None,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
) -> ProcessedSession:
    """Patch responses and illuminants of a captured session (dark, Eq. 2, ROIs).

    Parameters
    ----------
    session
        A captured session (see :mod:`tunespec.core.io.session`).
    layout
        The target's layout; default the one stored in the session.
    corners
        ``"auto"`` (find the target in a white-LED frame), ``"layout"`` (use
        ``layout.corners_px``), or four (x, y) mosaic-pixel corners TL, TR, BR, BL.
        Default: the layout's corners if set, else ``"auto"``.
    roi_fraction
        ROI area as a fraction of the patch area; default the layout's (paper: 0.2).
    window_px
        Side of the flat-field normalisation window at the white frame's centre, in
        plane pixels (paper: 100).
    channels
        Channels to process (default: all captured, in capture order).
    allow_incomplete
        Skip channels with missing frames (with a warning) instead of failing.
    verify
        Check every raw and SPD file's SHA-256 first (``--no-verify`` skips it).
    loader
        Reads a raw file; default :func:`tunespec.core.io.raw.load_raw`.
    progress, should_stop
        Progress (fraction of frames read) and cancellation hooks.

    Returns
    -------
    ProcessedSession
        Responses, illuminants, the layout with the corners used, and flags.

    Raises
    ------
    InputError
        Missing frames (unless ``allow_incomplete``), a file failing its checksum,
        no layout, corners not found, ROIs outside the image.
    Cancelled
        When ``should_stop()`` turns true.

    References
    ----------
    Trichromatic Reflectance Capture Using a Tunable Light Source, Eq. 2 and 6.
    """
    layout = layout or session.layout
    if layout is None:
        raise InputError(
            "the session has no target layout; pass one (--layout)",
            path=session.manifest_path,
        )
    if roi_fraction is not None:
        layout = replace(layout, roi_fraction=float(roi_fraction))
    whites = frames_by_channel(session.frames, "white")
    targets = frames_by_channel(session.frames, "target")
    wanted = list(channels) if channels is not None else list(session.settings.channels)

    def usable(checksums: bool) -> tuple[list[str], list[str]]:
        return _usable_channels(
            session, whites, targets, wanted,
            allow_incomplete=allow_incomplete, verify=checksums,
        )  # fmt: skip

    def run(use: list[str], warnings: list[str]) -> ProcessedSession:
        return _process(
            session, layout, whites, targets, use, warnings, corners, window_px,
            loader or load_raw, progress, should_stop,
        )  # fmt: skip

    if not verify:
        return run(*usable(False))
    # The checksums (SHA-256 of 2 GB for a 22-LED 5760x3840 session: 1.4 s, a
    # third of the processing when computed first) are computed on a thread of
    # their own while the frames are decoded and measured. The result is returned
    # only once every file has passed; a failure raises the error that checking
    # first raises, and with --allow-incomplete a channel that fails is left out
    # by processing again without it.
    with ThreadPoolExecutor(1, thread_name_prefix="checksums") as pool:
        checked = pool.submit(usable, True)
        try:
            chosen = usable(False)
            result = run(*chosen)
        except Cancelled:
            raise
        except BaseException:
            checked.result()  # its error first, as when checked before the work
            raise
        verified = checked.result()
    if verified != chosen:
        return run(*verified)
    return result


def _process(
    session: Session,
    layout: TargetLayout,
    whites: dict[str, list[FrameRecord]],
    targets: dict[str, list[FrameRecord]],
    use: list[str],
    warnings: list[str],
    corners: str | ArrayLike | None,
    window_px: int,
    loader: Loader,
    progress: ProgressFn | None,
    should_stop: StopFn | None,
) -> ProcessedSession:
    """:func:`process_session` of the channels ``use`` (checked)."""
    warnings = list(warnings)
    first = _detection_channel(use)
    order = _read_order(session, whites, targets, [first, *use])
    reader = _FrameReader(session, loader, len(order), progress, should_stop)
    # the frames decoded one ahead on a thread of their own while this one takes the
    # previous one's statistics; freed frame buffers reused, not faulted in again
    with reused_heap(), contextlib.closing(reader):
        reader.read_ahead(order)
        # the SPD files read and checked while the first frames decode (0.15 s of
        # CSV parsing for 22 LEDs, which came before any decoding)
        spds = check_spds(session, {c: targets[c][0] for c in use})
        # -- geometry: corners, then ROIs rasterised once -----------------------------
        layout, source, residual, preloaded = _place_corners(
            session, layout, corners, whites, targets, use, reader
        )
        rois, window = _session_rois(
            layout, whites[first][0], preloaded, reader, window_px
        )

        # -- per channel: darks, brackets, Eq. 2, statistics ------------------------
        acc = _ChannelStats.empty(layout, use, _RoiGeometry.of(rois, layout.n_patches))
        for c in [first, *[c for c in use if c != first]]:
            acc.add(session, c, reader.pixels(whites[c]), reader.pixels(targets[c]))
            ref = targets[c][0]
            acc.add_spd(c, spds[c], ref.exposure_s, ref.iso)
    warnings.extend(acc.warnings())
    n_px = rois.n_pixels
    n_patch = layout.n_patches
    return ProcessedSession(
        responses=acc.responses(n_px[:n_patch]),
        # the f-number every frame was checked against, which the report shows
        illuminants=acc.illuminants(session, reader.aperture),
        layout=layout,
        corners_source=source,
        flagged=tuple(acc.flagged),
        warnings=tuple(warnings),
        corner_residual_px=residual,
        stats={
            "frames_read": reader.done,
            "roi_pixels_per_patch_min": int(n_px[:n_patch].min()),
            "flat_window_px": window,
            "flat_fields_borrowed": acc.n_borrowed,
        },
    )


#: Wavelengths every measured SPD must cover at least (the estimation grid's).
SPD_MIN_COVERAGE_NM = (400.0, 700.0)


def check_spds(session: Session, refs: dict[str, FrameRecord]) -> dict[str, Spectra]:
    """The SPDs measured around ``refs`` (channel -> frame), each checked: not zero
    everywhere, covering at least :data:`SPD_MIN_COVERAGE_NM` (an SPD in µm does
    not) and the range the session's other SPDs cover (a file cut short).

    Raises
    ------
    InputError
        One line naming the SPD file and what is wrong.
    """
    spds = {c: session.read_spd(rec) for c, rec in refs.items()}
    where = {c: session.root / str(rec.spd_file) for c, rec in refs.items()}
    for c, spd in spds.items():
        if not np.any(spd.values > 0):
            raise InputError(
                "the measured SPD is zero everywhere: the light was not measured "
                f"(take the frame again: tunespec capture ... --retake {refs[c].id})",
                path=where[c],
            )
        if float(spd.wavelength_nm[-1]) < 100:
            raise InputError(
                f"wavelengths {float(spd.wavelength_nm[0]):g}-"
                f"{float(spd.wavelength_nm[-1]):g}: expected nm, not µm",
                path=where[c],
            )
    if not spds:
        return spds
    lo = min(float(s.wavelength_nm[0]) for s in spds.values())
    hi = max(float(s.wavelength_nm[-1]) for s in spds.values())
    want_a, want_b = SPD_MIN_COVERAGE_NM
    for c, spd in spds.items():
        wl = spd.wavelength_nm
        a, b = float(wl[0]), float(wl[-1])
        step = float(np.max(np.diff(wl))) if wl.size > 1 else 0.0
        if a > lo + step or b < hi - step:
            raise InputError(
                f"the SPD covers {a:g}-{b:g} nm where the session's others cover "
                f"{lo:g}-{hi:g} nm: the file is cut short",
                path=where[c],
            )
        if a > want_a or b < want_b:
            raise InputError(
                f"the SPD covers {a:g}-{b:g} nm, expected at least {want_a:g}-"
                f"{want_b:g} nm",
                path=where[c],
            )
    return spds


def _session_rois(
    layout: TargetLayout,
    first_white: FrameRecord,
    preloaded: dict[str, RawFrame],
    reader: _FrameReader,
    window_px: int,
) -> tuple[RoiSet, int]:
    """The patch ROIs and the flat-field window, rasterised once for the session, and
    the window's side; ``reader`` gathers them from now on."""
    # the plane shape comes from a frame processing reads first anyway
    if first_white.id not in preloaded:
        preloaded[first_white.id] = reader.read(first_white)
    shape = preloaded[first_white.id].shape
    r0, r1, c0, c1 = flat_window(shape, window_px)
    rois = RoiSet.from_quads(
        layout.patch_names, full_to_plane_px(layout.roi_quads_px()), shape
    ).with_window(_FLAT, r0, r1, c0, c1)
    reader.use_rois(rois, preloaded)
    return rois, r1 - r0


def _usable_channels(
    session: Session,
    whites: dict[str, list[FrameRecord]],
    targets: dict[str, list[FrameRecord]],
    wanted: Sequence[str],
    *,
    allow_incomplete: bool,
    verify: bool,
) -> tuple[list[str], list[str]]:
    """The channels with every frame (and its darks) in, and warnings for the rest."""
    frames = session.frames
    warnings: list[str] = []
    missing_specs = session.missing(verify=verify)
    incomplete = {s.channel for s in missing_specs if s.channel is not None}
    dark_missing = [s for s in missing_specs if s.kind == "dark"]
    use: list[str] = []
    for c in wanted:
        ok = c in whites and c in targets and c not in incomplete
        if ok:
            needed = [*whites[c], *targets[c]]
            if any(not find_darks(frames, f.exposure_s, f.iso) for f in needed):
                ok = False
        if ok:
            use.append(c)
        elif allow_incomplete:
            warnings.append(f"channel {c}: frames missing, left out")
        else:
            why = next(
                (
                    p
                    for r in (*whites.get(c, ()), *targets.get(c, ()))
                    if (p := session.problem(r, checksums=verify))
                ),
                "",
            )
            if why:
                raise InputError(
                    f"channel {c}: {why}; take it again (tunespec capture ... "
                    "--resume)",
                    path=session.manifest_path,
                )
            raise InputError(
                f"channel {c}: frames missing or marked bad; resume the capture "
                "(tunespec capture ... --resume) or pass --allow-incomplete to leave it out",
                path=session.manifest_path,
            )
    if dark_missing and not allow_incomplete:
        raise InputError(
            f"{len(dark_missing)} dark frame(s) missing; resume the capture",
            path=session.manifest_path,
        )
    if not use:
        raise InputError("no complete channel to process", path=session.manifest_path)
    return use, warnings


def _place_corners(
    session: Session,
    layout: TargetLayout,
    corners: str | ArrayLike | None,
    whites: dict[str, list[FrameRecord]],
    targets: dict[str, list[FrameRecord]],
    use: Sequence[str],
    reader: _FrameReader,
) -> tuple[TargetLayout, str, float, dict[str, RawFrame]]:
    """The layout with the corners to use, their source, the detection residual and
    the frames the detection read (processing reads them again otherwise)."""
    if isinstance(corners, str) and corners not in ("auto", "layout"):
        raise InputError(
            f"corners must be 'auto', 'layout' or 4 points, got {corners!r}"
        )
    mode = (
        corners if corners is not None else ("layout" if layout.corners_px else "auto")
    )
    if isinstance(mode, str) and mode == "auto":
        found, w_frame, t_frame = _detect_in_session(
            whites, targets, use, layout, reader.read
        )
        preloaded = {found.white_id: w_frame, found.target_id: t_frame}
        return (
            layout.with_corners(found.corners_px),
            "auto",
            found.residual_px,
            preloaded,
        )
    if isinstance(mode, str):
        if layout.corners_px is None:
            raise InputError(
                "corners='layout' but the layout has no corners_px",
                path=session.manifest_path,
            )
        return layout, "layout", float("nan"), {}
    return layout.with_corners(mode), "given", float("nan"), {}


def _read_order(
    session: Session,
    whites: dict[str, list[FrameRecord]],
    targets: dict[str, list[FrameRecord]],
    channels: Sequence[str],
) -> list[FrameRecord]:
    """Every frame once, in the order :func:`process_session` reads them: the
    detection channel's first white and target frames, then per channel its
    white frames, their darks, its target frames and theirs (a dark once)."""
    order: dict[str, FrameRecord] = {}
    if channels:
        order.update(
            {r.id: r for r in (whites[channels[0]][0], targets[channels[0]][0])}
        )
    seen: set[tuple[float, int]] = set()
    for c in channels:
        for records in (whites[c], targets[c]):
            order.update({r.id: r for r in records if r.id not in order})
            for r in records:
                if (r.exposure_s, r.iso) not in seen:
                    seen.add((r.exposure_s, r.iso))
                    for d in find_darks(session.frames, r.exposure_s, r.iso):
                        order.setdefault(d.id, d)
    return list(order.values())


class _FrameReader:
    """Reads a session's frames once each: progress, cancellation, one mosaic geometry,
    darks averaged per (exposure, ISO) and brackets merged (ROI pixels only)."""

    def __init__(
        self,
        session: Session,
        load: Loader,
        total: int,
        progress: ProgressFn | None,
        should_stop: StopFn | None,
    ) -> None:
        self._session = session
        self._load = load
        self._total = total
        self._progress = progress
        self._should_stop = should_stop
        self._retake = (
            f"retake it (tunespec capture --out {session.root} --retake {{}})"
        )
        self._first: tuple[str, tuple[int, ...], str] | None = None
        self._aperture: float | None = None
        self._rois: RoiSet | None = None
        self._preloaded: dict[str, RawFrame] = {}
        self._darks: dict[tuple[float, int], _Pixels] = {}
        self._ahead: ReadAhead | None = None
        self.done = 0

    @property
    def aperture(self) -> float | None:
        """The f-number of the first frame read whose raw file states one, which
        the others are checked against (``None``: none states one)."""
        return self._aperture

    def read_ahead(self, records: Sequence[FrameRecord]) -> None:
        """Decode ``records`` in this order on a thread of their own, one ahead."""
        paths = [self._session.path_of(r) for r in records]
        self._ahead = ReadAhead(self._load, paths)

    def close(self) -> None:
        if self._ahead is not None:
            self._ahead.close()

    def step(self) -> None:
        self.done += 1
        report(self._progress, self.done / self._total)
        check_stop(self._should_stop)

    def read(self, rec: FrameRecord) -> RawFrame:
        check_stop(self._should_stop)
        path = self._session.path_of(rec)
        try:
            frame = self._ahead.get(path) if self._ahead else self._load(path)
        except InputError as exc:
            raise InputError(
                f"frame {rec.id}: {exc}; {self._retake.format(rec.id)}"
            ) from None
        # ROIs are rasterised once for one mosaic geometry: a frame of another size
        # (resumed at another resolution or with another camera) would be read at
        # the wrong photosites, or out of bounds
        geometry = (frame.mosaic.shape, frame.cfa_pattern)
        if self._first is None:
            self._first = (rec.id, *geometry)
        elif geometry != self._first[1:]:
            ref_id, (h, w), cfa = self._first
            raise InputError(
                f"frame {rec.id} is a {geometry[0][1]}x{geometry[0][0]} "
                f"{geometry[1]} mosaic but frame {ref_id} is {w}x{h} {cfa}: all "
                f"frames of a session need the same camera and raw size; "
                f"{self._retake.format(rec.id)}",
                path=self._session.manifest_path,
            )
        if self._aperture is None:  # the first frame whose raw file states one
            self._aperture = frame.aperture
        if why := frame_settings_problem(
            frame, rec.exposure_s, rec.iso, self._aperture
        ):
            raise InputError(
                f"frame {rec.id}: {why}: the camera took another frame than the "
                f"session's; {self._retake.format(rec.id)}",
                path=self._session.manifest_path,
            )
        return frame

    def use_rois(self, rois: RoiSet, preloaded: dict[str, RawFrame]) -> None:
        """Gather these ROIs from now on; ``preloaded`` frames are not read again."""
        self._rois = rois
        self._preloaded = preloaded

    def _gather(self, rec: FrameRecord) -> _Pixels:
        assert self._rois is not None
        frame = self._preloaded.pop(rec.id, None)
        return _Pixels(
            *self._rois.gather(frame if frame is not None else self.read(rec))
        )

    def dark_for(self, rec: FrameRecord) -> _Pixels:
        """The mean dark (ROI pixels) at the frame's exposure and ISO."""
        key = (rec.exposure_s, rec.iso)
        if key not in self._darks:
            acc: _Pixels | None = None
            darks = find_darks(self._session.frames, rec.exposure_s, rec.iso)
            for d in darks:
                px = self._gather(d)
                self.step()
                if acc is None:
                    acc = px
                else:
                    acc.values += px.values
            assert acc is not None  # checked above: every frame has its darks
            if len(darks) > 1:
                acc.values *= np.float32(1.0 / len(darks))
            self._darks[key] = acc
        return self._darks[key]

    def pixels(self, records: Sequence[FrameRecord]) -> _Pixels:
        """Dark-subtracted ROI pixels of a bracket series, merged."""
        got = []
        for rec in records:
            got.append(self._gather(rec))
            self.step()
        return _merge_brackets(
            got, [self.dark_for(r) for r in records], [r.exposure_s for r in records]
        )


def write_processed(
    processed: ProcessedSession,
    responses_path: str | PathLike[str],
    illuminants_path: str | PathLike[str] | None = None,
) -> None:
    """Write ``responses.csv`` and (optionally) ``illuminants.csv`` for calibrate/estimate."""
    write_responses_csv(processed.responses, responses_path)
    if illuminants_path is not None:
        write_spectra_csv(processed.illuminants, illuminants_path)
