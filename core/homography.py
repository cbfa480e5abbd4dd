"""Finding a target's four outer corners in an image, for the homography of the paper.

The paper maps each patch's central 20 % into the image with a homography from the
target's four corners. :func:`find_quadrilateral` finds the target as the largest
region that differs from the white background (threshold, contours, convex hull,
``approxPolyDP`` with a ``minAreaRect`` fallback) and refines each side to sub-pixel
precision by locating the edge along many normals and fitting a line through them
(Huber loss, so a white patch touching the edge does not pull it). The corners are the
intersections of adjacent sides.

A region found this way may be the target's outer edge, or (a target with margins as
white as the background) the edge of its patch grid. :func:`locate_target` tries
each reading and keeps the one under which the patches look most uniform, so it
returns the outer corners in the layout's sense either way.

Coordinates are those of the image passed in, x to the right and y down, pixel
centres at integers (OpenCV's convention).

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source (``shared/reference``),
section "Capturing and Processing": a homography corrects the projective distortion
of the 0/45 geometry.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tunespec.core.errors import InputError
from tunespec.core.layout import TargetLayout, apply_homography, homography_from_corners

__all__ = [
    "CornerFit",
    "find_quadrilateral",
    "locate_target",
    "order_corners",
]

#: The coarse search runs on a copy whose longer side has at most this many pixels.
COARSE_MAX_SIDE_PX = 900
#: Smallest relative difference from the background that counts as "target".
MIN_CONTRAST = 0.04
#: The coarse threshold is at least this many background noise sigmas.
NOISE_SIGMAS = 8.0
#: The region must cover at least this fraction of the image.
MIN_AREA_FRACTION = 0.01


@dataclass(frozen=True)
class CornerFit:
    """A quadrilateral found in an image.

    Parameters
    ----------
    corners_px : (4, 2)
        TL, TR, BR, BL in image pixels (x, y).
    residual_px
        RMS distance of the edge points from their fitted sides.
    n_edge_points
        Edge points used in the fit (of the four sides together).
    contrast
        Threshold used, as a relative difference from the background level.
    """

    corners_px: NDArray[np.float64]
    residual_px: float
    n_edge_points: int
    contrast: float


def order_corners(points: ArrayLike) -> NDArray[np.float64]:
    """Order four points as TL, TR, BR, BL (x right, y down).

    Sorts by angle around the centroid, then starts at the point nearest the image's
    top-left (smallest ``x + y``), so moderate rotations keep their meaning.

    Examples
    --------
    >>> order_corners([[10, 10], [0, 0], [0, 10], [10, 0]]).tolist()
    [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]]
    """
    p = np.asarray(points, dtype=np.float64).reshape(4, 2)
    c = p.mean(axis=0)
    ang = np.arctan2(p[:, 1] - c[1], p[:, 0] - c[0])
    p = p[np.argsort(ang)]  # clockwise on screen (y down), starting near -pi (left)
    start = int(np.argmin(p.sum(axis=1)))
    return np.roll(p, -start, axis=0)


def _background_level(img: NDArray[np.float32]) -> tuple[float, float]:
    """Median and robust noise (MAD) of a 4 %-wide frame along the image border."""
    h, w = img.shape
    b = max(2, round(0.04 * min(h, w)))
    ring = np.concatenate(
        [img[:b].ravel(), img[-b:].ravel(), img[:, :b].ravel(), img[:, -b:].ravel()]
    )
    ring = ring[np.isfinite(ring)]
    if ring.size == 0:
        raise InputError("corner detection: the image border has no finite pixels")
    level = float(np.median(ring))
    return level, 1.4826 * float(np.median(np.abs(ring - level)))


def _coarse_quad(
    dev: NDArray[np.float32], threshold: float
) -> tuple[NDArray[np.float64], float]:
    """Largest region above ``threshold`` -> 4 corners (coarse), and a line scale."""
    import cv2

    h, w = dev.shape
    mask = (dev > threshold).astype(np.uint8)
    # bridge the gaps between patches (targets whose margins match the background)
    k = max(3, round(0.012 * max(h, w)) | 1)
    kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (k, k))
    mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, kernel)
    mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    areas = stats[1:, cv2.CC_STAT_AREA]
    if n < 2:
        raise InputError("corner detection: no target found against the background")
    # a target whose gaps match the background falls apart into its patches: keep
    # every region of a size comparable to the largest, drop specks
    keep = 1 + np.nonzero(areas >= 0.1 * areas.max())[0]
    region = np.isin(labels, keep).astype(np.uint8)
    contours, _ = cv2.findContours(region, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    contour = np.concatenate(contours)
    area = cv2.contourArea(cv2.convexHull(contour))
    if area < MIN_AREA_FRACTION * h * w:
        raise InputError(
            f"corner detection: the largest region covers only {area / (h * w):.1%} "
            "of the image; set the target's corners in the layout"
        )
    if area > 0.97 * h * w:
        raise InputError(
            "corner detection: the target fills the whole image (no background "
            "around it); set its corners in the layout"
        )
    hull = cv2.convexHull(contour)
    perimeter = cv2.arcLength(hull, True)
    poly = cv2.approxPolyDP(hull, 0.01 * perimeter, True).reshape(-1, 2)
    quad = None
    if len(poly) >= 4:
        # the four longest sides of the outline are the target's sides; short ones
        # cut corners (a corner patch as white as the board, a rounded corner)
        edges = [(poly[i], poly[(i + 1) % len(poly)]) for i in range(len(poly))]
        lengths = [float(np.hypot(*(b - a))) for a, b in edges]
        longest = sorted(np.argsort(lengths)[-4:])
        lines = []
        for i in longest:
            a, b = (e.astype(np.float64) for e in edges[i])
            d = (b - a) / lengths[i]
            lines.append(np.array([d[0], d[1], a[0], a[1]]))
        try:
            quad = np.array(
                [_line_intersection(lines[k - 1], lines[k]) for k in range(4)]
            )
        except InputError:
            quad = None
        if quad is not None:
            # corners must stay near the outline (no wild intersections)
            near = [
                cv2.pointPolygonTest(hull, (float(x), float(y)), True) for x, y in quad
            ]
            if min(near) < -0.1 * perimeter / 4:
                quad = None
    if quad is None:
        quad = cv2.boxPoints(cv2.minAreaRect(hull)).astype(np.float64)
    return order_corners(quad), perimeter


def _line_intersection(
    a: NDArray[np.float64], b: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Intersection of lines given as (vx, vy, x0, y0)."""
    d1, p1 = a[:2], a[2:]
    d2, p2 = b[:2], b[2:]
    m = np.array([d1, -d2]).T
    if abs(np.linalg.det(m)) < 1e-9:
        raise InputError("corner detection: two adjacent sides are parallel")
    t = np.linalg.solve(m, p2 - p1)
    return p1 + t[0] * d1


def _refine(
    dev: NDArray[np.float32],
    quad: NDArray[np.float64],
    threshold: float,
    search_px: float,
    *,
    n_per_side: int = 48,
) -> tuple[NDArray[np.float64], float, int]:
    """Sub-pixel sides: half-level crossings along normals, Huber line fits."""
    import cv2
    from scipy.ndimage import map_coordinates

    centre = quad.mean(axis=0)
    lines = []
    residuals: list[NDArray[np.float64]] = []
    n_used = 0
    steps = np.linspace(-search_px, search_px, max(16, round(8 * search_px)))
    for i in range(4):
        p0, p1 = quad[i], quad[(i + 1) % 4]
        d = p1 - p0
        length = float(np.hypot(*d))
        if length < 4:
            raise InputError("corner detection: degenerate quadrilateral")
        t_hat = d / length
        normal = np.array([t_hat[1], -t_hat[0]])
        if np.dot((p0 + p1) / 2 - centre, normal) < 0:
            normal = -normal  # point outwards
        # stay clear of the corners, where two edges mix
        ts = np.linspace(0.08, 0.92, n_per_side)
        base = p0[None, :] + ts[:, None] * d[None, :]
        pts = base[:, None, :] + steps[None, :, None] * normal[None, None, :]
        prof = map_coordinates(
            dev, [pts[..., 1].ravel(), pts[..., 0].ravel()], order=1, cval=np.nan
        ).reshape(pts.shape[:2])
        inner = steps < -0.5 * search_px
        outer = steps > 0.5 * search_px
        edge_pts = []
        for j in range(n_per_side):
            pr = prof[j]
            if not np.all(np.isfinite(pr)):
                continue
            # the edge is where the profile crosses halfway between the levels on
            # either side (unbiased for a blurred step, whatever the contrast)
            lo, hi = float(np.median(pr[outer])), float(np.median(pr[inner]))
            if hi - lo < threshold:
                continue  # e.g. a patch as white as the board touching the edge
            half = 0.5 * (lo + hi)
            above = pr > half
            # last inside sample followed by an outside one (walking outwards)
            idx = np.nonzero(above[:-1] & ~above[1:])[0]
            if idx.size == 0:
                continue
            k = int(idx[np.argmin(np.abs(steps[idx]))])
            a, b = pr[k], pr[k + 1]
            frac = (a - half) / (a - b) if a != b else 0.5
            s = steps[k] + frac * (steps[k + 1] - steps[k])
            edge_pts.append(base[j] + s * normal)
        if len(edge_pts) < 4:
            raise InputError(
                "corner detection: could not follow one of the target's sides; "
                "set its corners in the layout"
            )
        ep = np.asarray(edge_pts, dtype=np.float32)
        line = cv2.fitLine(ep, cv2.DIST_HUBER, 0, 0.01, 0.01).ravel().astype(np.float64)
        lines.append(line)
        rel = ep.astype(np.float64) - line[2:]
        residuals.append(np.abs(rel[:, 0] * line[1] - rel[:, 1] * line[0]))
        n_used += len(ep)
    corners = np.array(
        [_line_intersection(lines[(i - 1) % 4], lines[i]) for i in range(4)]
    )
    res = np.concatenate(residuals)
    # robust RMS: the Huber fit ignores outliers, so should the figure of merit
    core_res = res[res <= np.percentile(res, 90)]
    return order_corners(corners), float(np.sqrt(np.mean(core_res**2))), n_used


def find_quadrilateral(
    image: ArrayLike,
    *,
    background: ArrayLike | None = None,
) -> CornerFit:
    """Find the target's outline in an image of it lying on a white background.

    Parameters
    ----------
    image : (H, W)
        One colour plane of the target under a broadband (white) LED, linear.
    background : (H, W), optional
        The same plane of the white background alone under the same light. The
        ratio ``image / background`` flattens the illumination, which makes the
        threshold more reliable; without it the image itself is used.

    Returns
    -------
    CornerFit
        Corners (TL, TR, BR, BL) in ``image`` pixels.

    Raises
    ------
    InputError
        No clear target region, or it fills the whole image (then the corners must be
        given in the layout).

    Examples
    --------
    >>> import numpy as np
    >>> img = np.ones((200, 300), np.float32)
    >>> img[50:151, 60:241] = 0.2
    >>> fit = find_quadrilateral(img)  # the edges lie between pixel centres
    >>> np.round(fit.corners_px, 3).tolist()
    [[59.5, 49.5], [240.5, 49.5], [240.5, 150.5], [59.5, 150.5]]
    """
    import cv2

    img = np.asarray(image, dtype=np.float32)
    if img.ndim != 2 or min(img.shape) < 16:
        raise InputError(f"corner detection needs a 2-D image, got shape {img.shape}")
    if background is not None:
        bg = np.asarray(background, dtype=np.float32)
        if bg.shape != img.shape:
            raise InputError("corner detection: image and background differ in shape")
        with np.errstate(divide="ignore", invalid="ignore"):
            img = img / np.where(bg > 0, bg, np.nan)
    level, noise = _background_level(img)
    if not level > 0:
        raise InputError("corner detection: the background is black")
    dev = np.abs(img / level - 1.0).astype(np.float32)
    dev[~np.isfinite(dev)] = 0.0
    scale = min(1.0, COARSE_MAX_SIDE_PX / max(dev.shape))
    small = (
        cv2.resize(dev, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
        if scale < 1
        else dev
    )
    # anything clearly off the background is target (a threshold between the patch
    # levels, as Otsu's would be, drops the patches close to the board's white)
    threshold = max(MIN_CONTRAST, NOISE_SIGMAS * noise / level)
    quad_small, _ = _coarse_quad(small, threshold)
    # small pixel centres -> full-resolution pixel centres
    quad = (quad_small + 0.5) / scale - 0.5
    # the coarse sides may be off by a few coarse pixels at one end (a cut corner):
    # search wide first, then again, narrowly, around the refined sides
    search_px = max(3.0, 3.0 / scale)
    corners, _, _ = _refine(dev, quad, threshold, 3.0 * search_px)
    corners, residual, n = _refine(dev, corners, threshold, search_px)
    return CornerFit(corners, residual, n, threshold)


def _patch_nonuniformity(
    image: NDArray[np.float32],
    layout: TargetLayout,
    corners_px: NDArray[np.float64],
    *,
    area_fraction: float = 0.8,
    n_side: int = 7,
) -> float:
    """Mean over patches of the spread of ``image`` over most of each patch.

    Samples an ``n_side`` x ``n_side`` grid reaching the edges of the central
    ``area_fraction`` of each patch: small when the corners put every sample inside
    its patch, large when samples fall into gaps or neighbours. Readings of an
    outline that differ by a fraction of the gap between patches differ here.
    """
    from scipy.ndimage import map_coordinates

    try:
        H = homography_from_corners(layout.outer_corners_mm(), corners_px)
    except InputError:
        return float("inf")
    q = layout.patch_quads_mm(area_fraction)  # (n, 4, 2): TL, TR, BR, BL
    u = np.linspace(0.0, 1.0, n_side)
    uu, vv = np.meshgrid(u, u)
    tl, tr, bl = q[:, 0], q[:, 1], q[:, 3]
    pts = (
        tl[:, None, :]
        + uu.ravel()[None, :, None] * (tr - tl)[:, None, :]
        + vv.ravel()[None, :, None] * (bl - tl)[:, None, :]
    )
    px = apply_homography(H, pts)
    vals = map_coordinates(
        image, [px[..., 1].ravel(), px[..., 0].ravel()], order=1, cval=np.nan
    ).reshape(px.shape[:2])
    if np.isnan(vals).any():
        return float("inf")
    spread = vals.std(axis=1) / (np.abs(vals.mean(axis=1)) + 1e-3)
    return float(np.mean(spread))


def locate_target(
    image: ArrayLike,
    layout: TargetLayout,
    *,
    background: ArrayLike | None = None,
) -> tuple[NDArray[np.float64], CornerFit]:
    """The target's outer corners in ``image``, in the sense of ``layout``.

    Finds the outline with :func:`find_quadrilateral`, then reads it as the target's
    outer edge, as the edge of its patch grid, or as the edge of its outermost patches,
    and keeps the reading under which the patches look most uniform.

    Parameters
    ----------
    image : (H, W)
        One colour plane of the target under a broadband LED.
    layout
        The target's geometry (corners not needed).
    background : (H, W), optional
        The white background under the same light (see :func:`find_quadrilateral`).

    Returns
    -------
    corners_px : (4, 2)
        Outer corners TL, TR, BR, BL of ``layout`` in ``image`` pixels.
    fit : CornerFit
        The outline as found.

    Raises
    ------
    InputError
        If no target is found.
    """
    fit = find_quadrilateral(image, background=background)
    img = np.asarray(image, dtype=np.float32)
    if background is not None:
        with np.errstate(divide="ignore", invalid="ignore"):
            img = img / np.asarray(background, dtype=np.float32)
        img[~np.isfinite(img)] = 0.0
    l, t, r, b = layout.margin_mm
    w, h = layout.width_mm, layout.height_mm
    cw, ch = layout.cell_size_mm()
    gx, gy = (
        0.5 * cw * (1 - layout.patch_fraction),
        0.5 * ch * (1 - layout.patch_fraction),
    )
    readings = {
        "outer": (0.0, 0.0, w, h),
        "grid": (l, t, w - r, h - b),
        "patches": (l + gx, t + gy, w - r - gx, h - b - gy),
    }
    best: tuple[float, NDArray[np.float64]] | None = None
    outer_mm = layout.outer_corners_mm()
    for x0, y0, x1, y1 in readings.values():
        rect = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
        try:
            H = homography_from_corners(rect, fit.corners_px)
        except InputError:
            continue
        corners = apply_homography(H, outer_mm)
        score = _patch_nonuniformity(img, layout, corners)
        if best is None or score < best[0] - 1e-9:
            best = (score, corners)
    if best is None or not np.isfinite(best[0]):
        raise InputError(
            "corner detection: the outline found does not fit the layout; set the "
            "target's corners in the layout"
        )
    return best[1], fit
