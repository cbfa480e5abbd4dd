"""Patch responses of a chart in one photograph (``tunespec extract``).

Reads a camera raw file (anything LibRaw reads: CR2, a CFA DNG, ...) or a linear
16-bit TIFF, finds the chart (:func:`tunespec.core.chart_finder.find_patch_grid`,
then the bench's outline finder :func:`tunespec.core.homography.locate_target`), or
takes its corners as given, takes the ROI statistics, checks them
(:func:`tunespec.core.extraction.check_extraction`) and writes the responses CSV
the other commands read, with a preview PNG of where it looked.

Pixel coordinates (``corners`` in and the layout's ``corners_px`` out) are those of
the file: mosaic pixels of a raw file (as in a session's layout), pixels of a TIFF.
The statistics of a raw file are on its half-resolution R, G (mean of two), B
planes, as in :mod:`tunespec.core.io.raw`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from os import PathLike
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tunespec.core.errors import InputError
from tunespec.core.extraction import (
    ExtractionCheck,
    PatchStatistics,
    check_extraction,
    outline_offset,
    patch_statistics,
)
from tunespec.core.layout import TargetLayout, apply_homography
from tunespec.core.limits import valid_name
from tunespec.core.responses import Responses
from tunespec.core.spectra import Spectra

__all__ = [
    "Extraction",
    "LinearImage",
    "extract_chart",
    "read_linear_image",
    "reference_xyz",
    "write_extraction",
]

RAW_TIFF_SUFFIXES = (".tif", ".tiff")
#: Fewest patches inside the image for a partial view to be written.
MIN_PATCHES_SEEN = 4


@dataclass(frozen=True, eq=False)
class LinearImage:
    """A linear RGB image of a chart.

    Parameters
    ----------
    planes : (3, H, W) float32
        R, G, B, linear (a raw file's planes in full-scale units, a 16-bit TIFF
        divided by 65535).
    saturated : (H, W) bool or None
    to_file_px, from_file_px
        Plane pixels <-> the file's pixel coordinates.
    kind
        ``"raw"`` or ``"tiff"``.
    """

    path: Path
    planes: NDArray[np.float32]
    saturated: NDArray[np.bool_] | None
    to_file_px: Callable[[ArrayLike], NDArray[np.float64]]
    from_file_px: Callable[[ArrayLike], NDArray[np.float64]]
    kind: str


def _same(xy: ArrayLike) -> NDArray[np.float64]:
    return np.asarray(xy, dtype=np.float64)


def read_linear_image(path: str | PathLike[str]) -> LinearImage:
    """A raw file (via LibRaw) or a linear TIFF as R, G, B planes.

    Raises
    ------
    InputError
        Naming the file: missing, not a raw file or TIFF, an 8-bit TIFF or one whose
        ICC profile declares a tone curve (not linear camera data), not RGB.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("image not found", path=path)
    if path.suffix.lower() in RAW_TIFF_SUFFIXES:
        return _read_tiff(path)
    from tunespec.core.io.raw import full_to_plane_px, load_raw, plane_to_full_px

    frame = load_raw(path)
    return LinearImage(
        path,
        frame.planes,
        frame.saturated,
        plane_to_full_px,
        full_to_plane_px,
        "raw",
    )


def _read_tiff(path: Path) -> LinearImage:
    import tifffile

    from tunespec.core.io.icc import profile_tone

    try:
        with tifffile.TiffFile(path) as tif:
            a = tif.asarray()
            profile = tif.pages.first.iccprofile
    except (OSError, ValueError, tifffile.TiffFileError) as exc:
        raise InputError(f"cannot read as a TIFF: {exc}", path=path) from None
    if profile and (gamma := profile_tone(profile)) is not None:
        raise InputError(
            f"its ICC profile declares a tone curve (gamma {gamma:.2f} at mid-grey): "
            "the TIFF is rendered, not linear camera data; export it linear (no "
            "tone curve, a linear profile or none) or give the raw file",
            path=path,
        )
    if a.ndim != 3 or a.shape[-1] not in (3, 4):
        raise InputError(
            f"expected an RGB TIFF (height x width x 3), got shape {a.shape}",
            path=path,
        )
    a = a[..., :3]
    if a.dtype == np.uint16:
        sat = np.any(a >= 65535, axis=-1)
        planes = np.moveaxis(a, -1, 0).astype(np.float32) / np.float32(65535.0)
    elif a.dtype in (np.float32, np.float64):
        sat = None
        planes = np.moveaxis(a, -1, 0).astype(np.float32)
    else:
        raise InputError(
            f"{a.dtype} TIFF: expected linear camera data as 16-bit integers or "
            "floats (an 8-bit TIFF is gamma-encoded)",
            path=path,
        )
    if not np.all(np.isfinite(planes)):
        raise InputError("the TIFF has non-finite values", path=path)
    return LinearImage(path, planes, sat, _same, _same, "tiff")


def reference_xyz(layout: TargetLayout, reflectances: Spectra | None) -> NDArray | None:
    """The patches' reference XYZ (D50) in layout order, NaN rows where none."""
    if reflectances is None:
        return None
    from tunespec.core.colorimetry import xyz_d50

    have = [n for n in layout.patch_names if n in reflectances.names]
    if not have:
        return None
    xyz = xyz_d50(reflectances.select(have))
    out = np.full((layout.n_patches, 3), np.nan)
    row = {n: k for k, n in enumerate(have)}
    for i, n in enumerate(layout.patch_names):
        if n in row:
            out[i] = xyz[row[n]]
    return out


@dataclass(frozen=True, eq=False)
class Extraction:
    """One photograph's patch responses and how they were found.

    Parameters
    ----------
    responses
        One illuminant (the image's name), the layout's patches in the image
        (those wholly outside a partial view are left out, and listed in
        ``check.notes``).
    layout
        The layout with ``corners_px`` in the file's pixel coordinates.
    method
        ``"given"`` (corners from the user), ``"grid"`` (the patch-grid finder)
        or ``"outline"`` (the bench's outline finder).
    check
        The extraction check; ``forced`` when it failed and ``force`` was given.
    """

    responses: Responses
    layout: TargetLayout
    method: str
    check: ExtractionCheck
    stats: PatchStatistics
    forced: bool
    corners_plane_px: NDArray[np.float64]
    image: LinearImage


def _finders(
    img: LinearImage, layout: TargetLayout, ref: NDArray | None, squares: NDArray
) -> list[tuple[str, Callable[[], NDArray[np.float64]]]]:
    """(name, find) of each finder, in the order tried: outer corners, plane px."""
    from tunespec.core.chart_finder import find_patch_grid
    from tunespec.core.homography import locate_target

    rgb = np.moveaxis(img.planes, 0, -1)
    return [
        (
            "grid",
            lambda: (
                find_patch_grid(
                    rgb, layout, reference_xyz=ref, squares=squares
                ).corners_px
            ),
        ),
        ("outline", lambda: locate_target(img.planes[1], layout)[0]),
    ]


def _measure(
    img: LinearImage,
    layout: TargetLayout,
    corners_plane: NDArray[np.float64],
    ref: NDArray | None,
    squares: NDArray[np.float64],
) -> tuple[PatchStatistics, ExtractionCheck]:
    placed = layout.with_corners(corners_plane)
    stats = patch_statistics(img.planes, placed.roi_quads_px(), img.saturated)
    patches = apply_homography(placed.homography(), layout.patch_quads_mm(1.0))
    offset, _ = outline_offset(squares, patches)
    check = check_extraction(
        layout.patch_names, stats, reference_xyz=ref, outline_offset_sides=offset
    )
    return stats, check


def extract_chart(
    image: str | PathLike[str] | LinearImage,
    layout: TargetLayout,
    *,
    corners_px: ArrayLike | None = None,
    reflectances: Spectra | None = None,
    illuminant: str | None = None,
    force: bool = False,
    preview: str | PathLike[str] | None = None,
) -> Extraction:
    """Patch responses of a chart in one photograph, checked.

    Parameters
    ----------
    image
        A raw file, a linear TIFF, or a :class:`LinearImage`.
    layout
        The chart's geometry; its ``corners_px`` are ignored.
    corners_px : (4, 2), optional
        The layout's outer corners TL, TR, BR, BL in the file's pixels; default
        found automatically.
    reflectances
        The chart's reference reflectances (by patch name) for the consistency
        tests and for telling the rotations of a symmetric grid apart.
    illuminant
        The responses' illuminant name (default the file's stem).
    force
        Keep an extraction that fails the check (``Extraction.forced``).
    preview
        Where to write the preview PNG (written before a refusal too).

    Raises
    ------
    InputError
        No chart found, or (without ``force``) the check failed: one line with the
        problems and where the preview is.
    """
    img = image if isinstance(image, LinearImage) else read_linear_image(image)
    name = illuminant if illuminant is not None else img.path.stem
    valid_name(name, "illuminant (--illuminant)", path=img.path)
    ref = reference_xyz(layout, reflectances)
    from tunespec.core.chart_finder import find_squares

    squares = find_squares(np.moveaxis(img.planes, 0, -1))
    if corners_px is not None:
        c = np.asarray(corners_px, dtype=np.float64)
        if c.shape != (4, 2) or not np.all(np.isfinite(c)):
            raise InputError("--corners: expected 4 x, y pairs (TL, TR, BR, BL)")
        given = img.from_file_px(c)
        finders = [("given", lambda: given)]
    else:
        finders = _finders(img, layout, ref, squares)
    results = []
    errors = []
    for method, find in finders:
        try:
            corners = find()
            stats, check = _measure(img, layout, corners, ref, squares)
        except InputError as exc:
            errors.append(exc.message)
            continue
        results.append((method, corners, stats, check))
        if check.ok:
            break
    if not results:
        hint = (
            ""
            if corners_px is not None
            else ("; give its corners with --corners x,y,... (TL, TR, BR, BL)")
        )
        raise InputError(f"the chart was not found ({errors[0]}){hint}", path=img.path)
    method, corners, stats, check = next((r for r in results if r[3].ok), results[0])
    if preview is not None:
        write_preview(img, layout, corners, check, preview)
    if not check.ok and not force:
        where = f"; preview in {preview}" if preview is not None else ""
        raise InputError(
            f"extraction refused ({method} outline): {check.summary()}{where}; "
            "--corners to set the outline, --force to keep it",
            path=img.path,
        )
    # a partial view: the patches wholly outside the image are left out
    seen = np.nonzero(stats.n_pixels > 0)[0]
    if len(seen) < MIN_PATCHES_SEEN:
        raise InputError(
            f"only {len(seen)} of the chart's patches lie in the image", path=img.path
        )
    responses = Responses(
        tuple(layout.patch_names[i] for i in seen),
        (name,),
        stats.mean[seen, None, :],
        np.where(np.isfinite(stats.std), stats.std, 0.0)[seen, None, :],
        stats.n_pixels[seen].astype(np.float64)[:, None],
        stats.saturated[seen, None],
    )
    placed = layout.with_corners(img.to_file_px(corners))
    return Extraction(
        responses, placed, method, check, stats, not check.ok, corners, img
    )


def write_preview(
    img: LinearImage,
    layout: TargetLayout,
    corners_plane: NDArray[np.float64],
    check: ExtractionCheck,
    path: str | PathLike[str],
) -> Path:
    """PNG of the image (square-root encoded) with the outline and the ROIs.

    The outline is drawn in yellow, each ROI in green, or red when the check
    failed; patch names beside the ROIs.
    """
    import cv2

    rgb = np.moveaxis(img.planes, 0, -1)
    top = float(np.percentile(rgb, 99.5)) or 1.0
    enc = np.sqrt(np.clip(rgb / top, 0.0, 1.0))
    bgr = np.ascontiguousarray((enc[..., ::-1] * 255 + 0.5).astype(np.uint8))
    scale = max(1, math.ceil(1000 / max(bgr.shape[:2])))
    if scale > 1:
        bgr = cv2.resize(bgr, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)
    placed = layout.with_corners(corners_plane)

    def pts(q: NDArray[np.float64]) -> NDArray[np.int32]:
        return np.round((q + 0.5) * scale - 0.5).astype(np.int32).reshape(-1, 1, 2)

    cv2.polylines(bgr, [pts(np.asarray(corners_plane))], True, (0, 220, 255), 2)
    colour = (0, 200, 0) if check.ok else (0, 0, 255)
    font = 0.3 + 0.1 * scale
    for name, q in zip(layout.patch_names, placed.roi_quads_px(), strict=True):
        cv2.polylines(bgr, [pts(q)], True, colour, 1)
        x, y = pts(q).reshape(-1, 2).min(axis=0)
        cv2.putText(
            bgr, name, (int(x), int(y) - 2), cv2.FONT_HERSHEY_PLAIN, font, colour, 1
        )
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    ok, buf = cv2.imencode(".png", bgr)
    if not ok:
        raise InputError("could not encode the preview PNG", path=path)
    path.write_bytes(buf.tobytes())
    return path


def write_extraction(extraction: Extraction, path: str | PathLike[str]) -> Path:
    """The responses CSV; a forced extraction gets a ``quality`` column saying why.

    The column is ignored by the readers of responses CSVs, so the file stays
    usable, but every row says that the check failed.
    """
    from tunespec.core.io.responses_csv import write_responses_csv

    path = Path(path)
    write_responses_csv(extraction.responses, path)
    if extraction.forced:
        flag_forced_csv(path, extraction.check)
    return path


def flag_forced_csv(path: str | PathLike[str], check: ExtractionCheck) -> None:
    """Add a ``quality`` column ("FORCED: <problems>") to a written responses CSV."""
    path = Path(path)
    flag = "FORCED: " + check.summary().replace('"', "'")
    lines = path.read_text(encoding="utf-8").splitlines()
    out = [lines[0] + ",quality"] + [f'{ln},"{flag}"' for ln in lines[1:]]
    path.write_text("\n".join(out) + "\n", encoding="utf-8")


def layout_reference_xyz(
    layout: TargetLayout,
    reflectances: str | PathLike[str] | None = None,
    layout_file: str | PathLike[str] | None = None,
    names: str | PathLike[str] | None = None,
) -> NDArray | None:
    """Reference XYZ for the extraction check: ``reflectances`` (a file, any
    spectral format) or the layout's own ``meta.reflectances``; None when neither
    gives data (the check then skips its reference tests)."""
    refl = layout_reference(layout, reflectances, layout_file, names)
    return reference_xyz(layout, refl)


def layout_reference(
    layout: TargetLayout,
    reflectances: str | PathLike[str] | None = None,
    layout_file: str | PathLike[str] | None = None,
    names: str | PathLike[str] | None = None,
) -> Spectra | None:
    """The chart's reference reflectances: the file given (its names mapped by the
    name map ``names``, :mod:`tunespec.core.io.name_map`), else the layout's own
    (None when the layout names none that exists)."""
    from tunespec.core.io.spectral import read_spectral

    if reflectances is not None:
        refl = read_spectral(reflectances, kind="reflectance")
        if names is not None:
            from tunespec.core.io.name_map import read_name_map, rename_spectra

            refl = rename_spectra(refl, read_name_map(names), source=str(reflectances))
        return refl
    from tunespec.devices.registry import layout_reflectances

    where = Path(layout_file) if layout_file is not None else None
    try:
        return layout_reflectances(
            layout, where if where is not None and where.is_file() else None
        )
    except InputError:
        return None


def session_preview(
    session: object, processed: object, path: str | PathLike[str]
) -> Path:
    """Preview PNG of a processed session: its broadband target frame, the outline
    and the ROIs (red when the extraction check failed)."""
    from tunespec.core.extraction import ExtractionCheck
    from tunespec.core.io.raw import full_to_plane_px
    from tunespec.core.io.session import frames_by_channel
    from tunespec.core.processing import _detection_channel

    targets = frames_by_channel(session.frames, "target")  # type: ignore[attr-defined]
    names = [c for c in processed.responses.illuminants if c in targets]  # type: ignore[attr-defined]
    channel = _detection_channel(names)
    rec = targets[channel][0]
    img = read_linear_image(session.path_of(rec))  # type: ignore[attr-defined]
    layout = processed.layout  # type: ignore[attr-defined]
    corners = full_to_plane_px(np.asarray(layout.corners_px))
    check = processed.check or ExtractionCheck(())  # type: ignore[attr-defined]
    return write_preview(img, layout.with_corners(None), corners, check, path)
