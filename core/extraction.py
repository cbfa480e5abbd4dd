"""Patch statistics of one image, and the check that they are a chart's patches.

:func:`patch_statistics` takes the mean, spread, pixel count and clipped fraction of
each ROI of a linear RGB image (a raw frame's planes, a linear TIFF), and the pixel
noise inside it (from differences of neighbouring pixels, which a smooth light
fall-off or a slight blur does not raise but a patch edge does not reach either).

:func:`check_extraction` says whether the ROIs sit on the patches they are named
after, so a wrong outline is refused instead of reported:

- **uniformity**: the ROI's spread beyond its pixel noise, relative to its level
  (an ROI over a patch edge, a gap or two patches spreads far beyond its noise);
- **consistency with the chart's reference**: the rank order of the neutral
  patches, the correlation of the G channel with the reference Y, and the residual
  of the least-squares 3 x 3 map camera RGB -> reference XYZ;
- **outline fit**: how far the patch squares seen in the image lie from where the
  outline puts them (:func:`outline_offset`).

Each test has its limit below; the limits are far from what a right extraction of a
real frame gives (the ColorChecker Passport frame in ``tests/data``: excess spread
under 3 %, correlation 0.99, residual 0.03) and from what a wrong one gives
(an ROI across two patches: spread of 30 % or more; a wrong chart: residual 0.3).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tunespec.core.errors import InputError
from tunespec.core.io.raw import quad_mask
from tunespec.core.responses import Responses

__all__ = [
    "ExtractionCheck",
    "PatchStatistics",
    "check_extraction",
    "check_responses",
    "outline_offset",
    "patch_statistics",
]

#: An ROI's spread beyond its pixel noise, relative to its level, at most this.
MAX_EXCESS_SPREAD = 0.12
#: Least correlation of the G channel with the reference Y over the patches.
MIN_Y_CORRELATION = 0.95
#: Largest relative residual of the 3 x 3 camera RGB -> reference XYZ fit.
MAX_COLOUR_RESIDUAL = 0.12
#: Neutral pairs whose reference Y differ by at least this ratio must keep their order.
NEUTRAL_ORDER_RATIO = 1.15
#: Largest RMS offset of the patch squares seen from the outline's, in patch sides.
MAX_OUTLINE_OFFSET = 0.12
#: Levels below this fraction of the brightest patch count as this fraction (dark
#: patches are judged against the noise of a dim one, not their own tiny mean).
LEVEL_FLOOR = 0.1


@dataclass(frozen=True)
class PatchStatistics:
    """Per-ROI statistics of a linear RGB image.

    Parameters
    ----------
    mean, std : (n, 3)
        Mean and sample standard deviation (ddof=1) of R, G, B over the ROI's pixels
        (NaN for an ROI with no pixel in the image).
    noise : (n, 3)
        Pixel noise in the ROI: the robust spread of horizontal neighbour
        differences over sqrt(2).
    n_pixels : (n,)
        Pixels whose centre is inside the ROI and inside the image.
    n_expected : (n,)
        Pixels the ROI would have if it lay wholly inside the image.
    saturated : (n,)
        Fraction of the ROI's pixels that are clipped.
    """

    mean: NDArray[np.float64]
    std: NDArray[np.float64]
    noise: NDArray[np.float64]
    n_pixels: NDArray[np.int64]
    n_expected: NDArray[np.int64]
    saturated: NDArray[np.float64]


def patch_statistics(
    planes: ArrayLike,
    quads_px: ArrayLike,
    saturated: ArrayLike | None = None,
) -> PatchStatistics:
    """Mean, spread, noise, pixel count and clipping of each ROI.

    Parameters
    ----------
    planes : (3, H, W)
        Linear R, G, B.
    quads_px : (n, 4, 2)
        ROI corners in the planes' pixel coordinates (x, y); a pixel belongs to the
        ROI when its centre is inside.
    saturated : (H, W) bool, optional
        Clipped pixels.
    """
    p = np.asarray(planes)
    q = np.asarray(quads_px, dtype=np.float64)
    if p.ndim != 3 or p.shape[0] != 3:
        raise InputError(f"patch statistics need (3, H, W) planes, got {p.shape}")
    if q.ndim != 3 or q.shape[1:] != (4, 2) or not np.all(np.isfinite(q)):
        raise InputError(f"ROI quads must be finite (n, 4, 2), got {q.shape}")
    sat = None if saturated is None else np.asarray(saturated, dtype=bool)
    _, h, w = p.shape
    n = len(q)
    mean = np.full((n, 3), np.nan)
    std = np.full((n, 3), np.nan)
    noise = np.full((n, 3), np.nan)
    n_px = np.zeros(n, dtype=np.int64)
    n_exp = np.zeros(n, dtype=np.int64)
    frac = np.zeros(n)
    for i, quad in enumerate(q):
        x0, y0 = int(np.floor(quad[:, 0].min())), int(np.floor(quad[:, 1].min()))
        x1, y1 = int(np.ceil(quad[:, 0].max())) + 1, int(np.ceil(quad[:, 1].max())) + 1
        n_exp[i] = int(quad_mask(quad, x0, y0, x1 - x0, y1 - y0).sum())
        cx0, cy0, cx1, cy1 = max(x0, 0), max(y0, 0), min(x1, w), min(y1, h)
        if cx1 <= cx0 or cy1 <= cy0:
            continue
        mask = quad_mask(quad, cx0, cy0, cx1 - cx0, cy1 - cy0)
        k = int(mask.sum())
        if k == 0:
            continue
        window = p[:, cy0:cy1, cx0:cx1].astype(np.float64)
        vals = window[:, mask]
        n_px[i] = k
        mean[i] = vals.mean(axis=1)
        if k > 1:
            std[i] = vals.std(axis=1, ddof=1)
        pair = mask[:, 1:] & mask[:, :-1]
        if pair.sum() >= 8:
            diff = (window[:, :, 1:] - window[:, :, :-1])[:, pair]
            mad = np.median(np.abs(diff - np.median(diff, axis=1)[:, None]), axis=1)
            noise[i] = 1.4826 * mad / math.sqrt(2.0)
        if sat is not None:
            frac[i] = float(sat[cy0:cy1, cx0:cx1][mask].mean())
    return PatchStatistics(mean, std, noise, n_px, n_exp, frac)


@dataclass(frozen=True)
class ExtractionCheck:
    """Whether an extraction's ROIs sit on the chart's patches.

    Parameters
    ----------
    problems
        One line per failed test (empty when the extraction passes).
    metrics
        The measured figures: ``worst_excess_spread`` (and ``worst_patch``),
        ``y_correlation``, ``colour_residual``, ``neutral_inversions``,
        ``outline_offset`` (NaN where not measured).
    notes
        Tests that could not run, and why (no reference, too few patches seen);
        patches wholly outside the image (a partial view of a chart).
    """

    problems: tuple[str, ...]
    metrics: dict[str, float | str] = field(default_factory=dict)
    notes: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        return not self.problems

    def summary(self) -> str:
        """One line: ``"ok"`` or the problems joined by ``"; "``."""
        return "ok" if self.ok else "; ".join(self.problems)


def check_extraction(
    names: Sequence[str],
    stats: PatchStatistics,
    *,
    reference_xyz: ArrayLike | None = None,
    outline_offset_sides: float = math.nan,
    max_excess_spread: float = MAX_EXCESS_SPREAD,
) -> ExtractionCheck:
    """Check an extraction (see the module docstring for the tests and limits).

    Parameters
    ----------
    names : n patch names
    stats
        :func:`patch_statistics` of the patches, in the order of ``names``.
    reference_xyz : (n, 3), optional
        The chart's reference XYZ per patch (NaN rows where none); without it the
        consistency tests are skipped (and say so in ``notes``).
    outline_offset_sides
        :func:`outline_offset`'s RMS offset in patch sides (NaN: not measured).
    max_excess_spread
        The uniformity limit (a glossy sample near the specular direction shows a
        gradient across each patch: the gonio processing allows more).
    """
    from tunespec.core.chart_finder import colour_fit_residual

    problems: list[str] = []
    notes: list[str] = []
    metrics: dict[str, float | str] = {}
    mean, std, noise = stats.mean, stats.std, stats.noise
    names = list(names)
    seen = np.all(np.isfinite(mean), axis=1) & (stats.n_pixels > 0)
    partial = seen & (stats.n_pixels < 0.9 * stats.n_expected)
    if partial.any():
        out = [names[i] for i in np.nonzero(partial)[0]]
        problems.append(
            f"{len(out)} ROI(s) reach outside the image ({', '.join(out[:6])})"
        )
    if (~seen).any():
        out = [names[i] for i in np.nonzero(~seen)[0]]
        notes.append(
            f"{len(out)} patch(es) outside the image, left out ({', '.join(out[:6])})"
        )
    if seen.sum() == 0:
        return ExtractionCheck(tuple(problems), metrics, tuple(notes))
    g = mean[:, 1]
    level = np.maximum(g, LEVEL_FLOOR * np.nanmax(g[seen]))
    noise_ok = np.where(np.isfinite(noise), noise, 0.0)
    excess = np.sqrt(np.maximum(std**2 - noise_ok**2, 0.0))
    excess = np.where(np.isfinite(excess), excess, 0.0).max(axis=1)
    rel = np.where(seen & (level > 0), excess / np.where(level > 0, level, 1.0), np.nan)
    if np.isfinite(rel).any():
        worst = int(np.nanargmax(rel))
        metrics["worst_excess_spread"] = float(rel[worst])
        metrics["worst_patch"] = names[worst]
        bad = [names[i] for i in np.nonzero(rel > max_excess_spread)[0]]
        if bad:
            problems.append(
                f"{len(bad)} ROI(s) not uniform (spread {rel[worst]:.0%} of the level "
                f"beyond the pixel noise at {names[worst]}, limit "
                f"{max_excess_spread:.0%}): {', '.join(bad[:6])}"
            )
    metrics["outline_offset"] = float(outline_offset_sides)
    if outline_offset_sides > MAX_OUTLINE_OFFSET:
        problems.append(
            f"the patches seen lie {outline_offset_sides:.2f} patch sides from the "
            f"outline's (limit {MAX_OUTLINE_OFFSET})"
        )
    elif not np.isfinite(outline_offset_sides):
        notes.append("outline fit not measured (fewer than 4 patch squares matched)")
    if reference_xyz is None:
        notes.append("no reference data: rank, correlation and colour fit not checked")
        return ExtractionCheck(tuple(problems), metrics, tuple(notes))
    ref = np.asarray(reference_xyz, dtype=np.float64)
    use = seen & np.all(np.isfinite(ref), axis=1)
    if use.sum() < 6:
        notes.append(f"only {int(use.sum())} patches with reference data: not checked")
        return ExtractionCheck(tuple(problems), metrics, tuple(notes))
    y = ref[use, 1]
    r = float(np.corrcoef(g[use], y)[0, 1])
    metrics["y_correlation"] = r
    if not r >= MIN_Y_CORRELATION:
        problems.append(
            f"G does not follow the reference Y (correlation {r:.3f}, at least "
            f"{MIN_Y_CORRELATION})"
        )
    resid = colour_fit_residual(mean[use], ref[use])
    metrics["colour_residual"] = resid
    if not resid <= MAX_COLOUR_RESIDUAL:
        problems.append(
            f"the patch colours do not fit the reference (3x3 camera-to-XYZ residual "
            f"{resid:.0%}, at most {MAX_COLOUR_RESIDUAL:.0%})"
        )
    inv = _neutral_inversions(
        g[use], ref[use], [n for n, u in zip(names, use, strict=True) if u]
    )
    metrics["neutral_inversions"] = float(len(inv))
    if inv:
        problems.append(f"neutral patches out of order: {', '.join(inv[:4])}")
    return ExtractionCheck(tuple(problems), metrics, tuple(notes))


def check_responses(
    responses: Responses,
    illuminant: str,
    *,
    reference_xyz: ArrayLike | None = None,
) -> ExtractionCheck:
    """:func:`check_extraction` of processed responses under one illuminant.

    For a session's dark-corrected, flat-fielded responses (no pixels at hand):
    the pixel noise is not known, so the whole ROI spread counts as non-uniformity
    (a broadband LED's frames have a noise far below the limit), and the outline
    fit is not measured (the corner finder has its own residual).

    Parameters
    ----------
    responses
        With ``rgb_std`` (else the uniformity test is skipped).
    illuminant
        The illuminant (channel) to check: a broadband one.
    """
    i = responses.illuminants.index(illuminant)
    n = len(responses.patches)
    std = responses.rgb_std[:, i] if responses.rgb_std is not None else np.zeros((n, 3))
    n_px = (
        responses.n_pixels[:, i].astype(np.int64)
        if responses.n_pixels is not None
        else np.ones(n, dtype=np.int64)
    )
    sat = responses.saturated[:, i] if responses.saturated is not None else np.zeros(n)
    stats = PatchStatistics(responses.rgb[:, i], std, np.zeros((n, 3)), n_px, n_px, sat)
    return check_extraction(responses.patches, stats, reference_xyz=reference_xyz)


def _neutral_inversions(
    g: NDArray[np.float64], xyz: NDArray[np.float64], names: list[str]
) -> list[str]:
    """Pairs of neutral patches whose G order contradicts their reference Y order."""
    s = xyz.sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        x, yy = xyz[:, 0] / s, xyz[:, 1] / s
    # neutral: chromaticity near the chart's own grey (the median of its greyest)
    grey = np.argsort(np.hypot(x - np.nanmedian(x), yy - np.nanmedian(yy)))
    x0, y0 = np.median(x[grey[:4]]), np.median(yy[grey[:4]])
    neutral = np.nonzero(np.hypot(x - x0, yy - y0) < 0.012)[0]
    out = []
    for a in neutral:
        for b in neutral:
            if xyz[a, 1] > NEUTRAL_ORDER_RATIO * xyz[b, 1] and not g[a] > g[b]:
                out.append(f"{names[a]} (Y {xyz[a, 1]:.3g}) not above {names[b]}")
    return out


def outline_offset(squares: ArrayLike, patch_quads_px: ArrayLike) -> tuple[float, int]:
    """How far the patch squares seen in an image lie from an outline's patches.

    Parameters
    ----------
    squares : (n, 3)
        :func:`tunespec.core.chart_finder.find_squares` of the image.
    patch_quads_px : (n, 4, 2)
        The whole patches (not the ROIs) the outline predicts, image pixels.

    Returns
    -------
    offset_sides : float
        RMS distance of each square's centre from the nearest predicted patch
        centre, in patch sides, over the squares within half a side of one (NaN
        when fewer than 4).
    n_matched : int
    """
    q = np.asarray(patch_quads_px, dtype=np.float64)
    centres = q.mean(axis=1)
    side = np.median(np.hypot(*np.moveaxis(q - np.roll(q, 1, axis=1), -1, 0)))
    squares = np.asarray(squares, dtype=np.float64).reshape(-1, 3)
    if len(squares) == 0 or not side > 0:
        return math.nan, 0
    d = np.hypot(*np.moveaxis(squares[:, None, :2] - centres[None], -1, 0))
    nearest = d.min(axis=1)
    similar = np.abs(np.log(squares[:, 2] / side)) < math.log(1.6)
    hit = similar & (nearest < 0.5 * side)
    if hit.sum() < 4:
        return math.nan, int(hit.sum())
    return float(np.sqrt(np.mean((nearest[hit] / side) ** 2))), int(hit.sum())
