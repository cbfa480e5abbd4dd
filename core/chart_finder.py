"""Finding a chart's patch grid in a real photograph (any background, any rotation).

:func:`tunespec.core.homography.locate_target` finds a target on the bench, where it
lies flat on a white board: the largest region that differs from the board. A lab's
photograph is not like that (a cluttered table, a ColorChecker Passport open beside
its creative panel), so :func:`find_patch_grid` looks for the *patches* instead:

1. **Squares.** The image's luminance, square-root encoded and normalised, is
   thresholded against its local mean (``cv2.adaptiveThreshold``) at a few window
   sizes; the contours that are convex, four-cornered and roughly square at the
   size of a patch are kept (duplicates from the several thresholds merged).
2. **Lattices.** Squares of similar size whose centres lie about one patch pitch
   apart are linked; each connected group gets integer lattice coordinates by
   walking the links (each step solved in the local pitch vectors, so moderate
   perspective does not break it) and a homography lattice -> image.
3. **Fit to the layout.** Each lattice is placed on the layout's main patch grid in
   every rotation (0, 90, 180, 270 degrees) and offset that keeps it inside the
   grid. A placement is scored by how uniform the patches it predicts look and,
   when the chart's reference colours are known, by how well a 3 x 3 matrix maps
   the patch colours to the reference XYZ (this tells the rotations apart on a
   chart whose grid is symmetric). The best placement gives the homography
   chart mm -> image from all its matched patch centres, and so the outer corners.

This is the approach of the segmentation method of colour-science's
``colour-checker-detection`` (adaptive threshold, square contours, clustering),
generalised from the ColorChecker Classic to any grid layout and with the grid
placed by the layout (a partial view of a panel keeps its place). That package
itself is not used: it requires the GUI build of OpenCV (``opencv-python<5``), which
shares its ``cv2`` module with the ``opencv-python-headless`` TuneSpec depends on.

Coordinates are those of the image passed in: x to the right, y down, pixel centres
at integers.

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source (``shared/reference``),
section "Capturing and Processing" (the homography from the target's corners).
T. Mansencal et al., colour-checker-detection (BSD-3), ``detection/segmentation.py``
(the square-finding recipe).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tunespec.core.errors import InputError
from tunespec.core.layout import TargetLayout, apply_homography

__all__ = ["GridFit", "find_patch_grid", "find_squares"]

#: Detection runs on a copy whose longer side has at most this many pixels.
WORKING_MAX_SIDE_PX = 1400
#: A square's area, as a fraction of the image, between these.
MIN_SQUARE_AREA = 1.5e-4
MAX_SQUARE_AREA = 0.08
#: Fewest patches a lattice needs before it is fitted to the layout.
MIN_LATTICE_PATCHES = 6


@dataclass(frozen=True)
class GridFit:
    """A layout's patch grid found in an image.

    Parameters
    ----------
    corners_px : (4, 2)
        The layout's outer corners TL, TR, BR, BL in image pixels.
    n_matched
        Detected patches matched to the layout's main grid.
    residual_px
        RMS distance of the matched patch centres from where the fitted homography
        puts them, image pixels.
    rotation_deg
        How the chart lies in the image: 0, 90, 180 or 270 (the chart's top edge
        towards the image's top, right, bottom, left).
    score
        The placement's score (lower is better): patch non-uniformity plus, with a
        reference, the relative residual of the 3 x 3 colour fit.
    colour_residual
        That relative residual (NaN without a reference).
    """

    corners_px: NDArray[np.float64]
    n_matched: int
    residual_px: float
    rotation_deg: int
    score: float
    colour_residual: float


def _detection_image(image: NDArray[np.float32]) -> tuple[NDArray[np.uint8], float]:
    """8-bit square-root-encoded luminance on the working scale, and that scale."""
    import cv2

    lum = image.mean(axis=2) if image.ndim == 3 else image
    lum = np.where(np.isfinite(lum), lum, 0.0).astype(np.float32)
    top = float(np.percentile(lum, 99.5))
    if not top > 0:
        raise InputError("chart finder: the image is black")
    scale = min(1.0, WORKING_MAX_SIDE_PX / max(lum.shape))
    if scale < 1:
        lum = cv2.resize(lum, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    enc = np.sqrt(np.clip(lum / top, 0.0, 1.0))
    return (enc * 255.0 + 0.5).astype(np.uint8), scale


def find_squares(image: ArrayLike) -> NDArray[np.float64]:
    """Patch-like squares in an image.

    Parameters
    ----------
    image : (H, W) or (H, W, 3)
        Linear image (any scale).

    Returns
    -------
    (n, 3)
        Centre x, y (image pixels) and side (sqrt of the area, pixels) of each square.
    """
    import cv2

    img = np.asarray(image, dtype=np.float32)
    if img.ndim not in (2, 3) or min(img.shape[:2]) < 32:
        raise InputError(f"chart finder needs an image, got shape {img.shape}")
    g8, scale = _detection_image(img)
    h, w = g8.shape
    g8 = cv2.bilateralFilter(g8, 5, 20, 5)
    found: list[tuple[float, float, float]] = []
    for window in (0.02, 0.04, 0.08):
        block = max(3, int(window * max(h, w)) | 1)
        for offset in (2, 4):
            th = cv2.adaptiveThreshold(
                g8, 255, cv2.ADAPTIVE_THRESH_MEAN_C, cv2.THRESH_BINARY, block, offset
            )
            # patches brighter than the gaps around them, and darker ones
            for mask in (th, 255 - th):
                mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
                found.extend(_square_contours(mask, h * w))
    if not found:
        return np.zeros((0, 3))
    sq = np.array(found)
    # merge the same square found by several thresholds: keep the median of each
    order = np.argsort(-sq[:, 2])
    groups: list[list[int]] = []
    for k in order:
        for g in groups:
            c = sq[g[0]]
            if math.hypot(sq[k, 0] - c[0], sq[k, 1] - c[1]) < 0.3 * c[2]:
                g.append(k)
                break
        else:
            groups.append([k])
    merged = np.array([np.median(sq[g], axis=0) for g in groups])
    # working pixel centres -> image pixel centres
    merged[:, :2] = (merged[:, :2] + 0.5) / scale - 0.5
    merged[:, 2] /= scale
    return merged


def _square_contours(mask: NDArray[np.uint8], image_area: int) -> list:
    import cv2

    out = []
    contours, _ = cv2.findContours(mask, cv2.RETR_LIST, cv2.CHAIN_APPROX_SIMPLE)
    for c in contours:
        area = cv2.contourArea(c)
        if not MIN_SQUARE_AREA * image_area <= area <= MAX_SQUARE_AREA * image_area:
            continue
        hull = cv2.convexHull(c)
        if area < 0.85 * cv2.contourArea(hull):
            continue
        poly = cv2.approxPolyDP(hull, 0.06 * cv2.arcLength(hull, True), True)
        if len(poly) != 4:
            continue
        _, (rw, rh), _ = cv2.minAreaRect(c)
        if min(rw, rh) < 0.55 * max(rw, rh):
            continue
        m = cv2.moments(c)
        if m["m00"] <= 0:
            continue
        out.append((m["m10"] / m["m00"], m["m01"] / m["m00"], math.sqrt(area)))
    return out


def _lattices(squares: NDArray[np.float64]) -> list[tuple[NDArray[np.int64], NDArray]]:
    """Groups of squares on one lattice: (indices, integer (i, j) per square)."""
    n = len(squares)
    if n < 2:
        return []
    xy, side = squares[:, :2], squares[:, 2]
    d = xy[:, None, :] - xy[None, :, :]
    dist = np.hypot(d[..., 0], d[..., 1])
    mean_side = 0.5 * (side[:, None] + side[None, :])
    ratio = side[:, None] / side[None, :]
    link = (
        (dist > 0.95 * mean_side)
        & (dist < 1.9 * mean_side)
        & (ratio > 0.7)
        & (ratio < 1.0 / 0.7)
    )
    out = []
    seen = np.zeros(n, dtype=bool)
    for seed in range(n):
        if seen[seed]:
            continue
        # each square's nearest linked neighbour defines its local pitch vectors
        comp = _component(link, seed)
        seen[comp] = True
        if len(comp) < MIN_LATTICE_PATCHES:
            continue
        coords = _lattice_coords(xy, link, comp)
        if coords is not None:
            idx, ij = coords
            if len(idx) >= MIN_LATTICE_PATCHES:
                out.append((idx, ij))
    return out


def _component(link: NDArray[np.bool_], seed: int) -> NDArray[np.int64]:
    todo, comp = [seed], {seed}
    while todo:
        k = todo.pop()
        for m in np.nonzero(link[k])[0]:
            if int(m) not in comp:
                comp.add(int(m))
                todo.append(int(m))
    return np.array(sorted(comp))


def _lattice_coords(
    xy: NDArray[np.float64], link: NDArray[np.bool_], comp: NDArray[np.int64]
) -> tuple[NDArray[np.int64], NDArray[np.int64]] | None:
    """Integer lattice coordinates of a linked group, by walking its links."""
    vecs = []
    for k in comp:
        for m in np.nonzero(link[k])[0]:
            v = xy[m] - xy[k]
            if v[0] > 0 or (v[0] == 0 and v[1] > 0):
                vecs.append(v)
    if len(vecs) < 4:
        return None
    vecs_a = np.array(vecs)
    # the pitch vectors are the shortest links: the diagonals (1.4 pitches, as
    # many of them) must not be taken for an axis of the grid
    length = np.hypot(vecs_a[:, 0], vecs_a[:, 1])
    vecs_a = vecs_a[length <= 1.2 * np.percentile(length, 10)]
    if len(vecs_a) < 4:
        return None
    ang = np.mod(np.arctan2(vecs_a[:, 1], vecs_a[:, 0]), np.pi)
    # the two pitch directions: the most common angle and the most common one
    # roughly perpendicular to it (angles folded to 0..pi)
    hist, edges = np.histogram(ang, bins=36, range=(0, np.pi))
    a0 = _mode_angle(ang, hist, edges)
    off = np.abs(np.angle(np.exp(2j * (ang - a0)))) / 2  # distance mod pi
    perp = np.abs(off - np.pi / 2) < np.pi / 6
    if perp.sum() < 2:
        return None
    a1 = a0 + np.pi / 2
    near0 = off < np.pi / 9
    if near0.sum() < 2:
        return None
    u = _mean_vector(vecs_a[near0], a0)
    v = _mean_vector(vecs_a[perp], a1)
    basis_inv = np.linalg.inv(np.column_stack([u, v]))
    pos = {int(comp[0]): (0, 0)}
    queue = deque([int(comp[0])])
    in_comp = set(comp.tolist())
    while queue:
        k = queue.popleft()
        for m in np.nonzero(link[k])[0]:
            m = int(m)
            if m in pos or m not in in_comp:
                continue
            step = basis_inv @ (xy[m] - xy[k])
            r = np.round(step)
            if np.abs(step - r).max() > 0.3 or not 0 < np.abs(r).sum() <= 2:
                continue
            pos[m] = (pos[k][0] + int(r[0]), pos[k][1] + int(r[1]))
            queue.append(m)
    idx = np.array(sorted(pos))
    ij = np.array([pos[k] for k in idx], dtype=np.int64)
    # one square per lattice site (two thresholds may disagree at a gap)
    _, first = np.unique(ij, axis=0, return_index=True)
    return idx[first], ij[first]


def _mode_angle(ang: NDArray, hist: NDArray, edges: NDArray) -> float:
    b = int(np.argmax(hist))
    lo, hi = edges[b] - np.pi / 36, edges[b + 1] + np.pi / 36
    sel = ang[(ang >= lo) & (ang <= hi)]
    return float(np.median(sel)) if sel.size else float(0.5 * (lo + hi))


def _mean_vector(vecs: NDArray[np.float64], angle: float) -> NDArray[np.float64]:
    """Median of vectors pointing along ``angle`` (sign-folded), their shortest set."""
    d = np.array([math.cos(angle), math.sin(angle)])
    s = vecs @ d
    folded = vecs * np.sign(np.where(s == 0, 1, s))[:, None]
    length = np.hypot(folded[:, 0], folded[:, 1])
    short = folded[length < 1.4 * np.min(length)]
    return np.median(short, axis=0)


def _rotations(ij: NDArray[np.int64]) -> list[NDArray[np.int64]]:
    """(col, row) of the lattice coordinates under the four rotations.

    Lattice (i, j) runs along the pitch vectors u and v = u turned by +90 degrees
    (on screen, y down), the same handedness as the chart's (col, row); the mirror
    image of a chart is not considered (a photograph never shows one).
    """
    i, j = ij[:, 0], ij[:, 1]
    return [
        np.stack([i, j], 1),
        np.stack([j, -i], 1),
        np.stack([-i, -j], 1),
        np.stack([-j, i], 1),
    ]


def _sample_means(
    image: NDArray[np.float32], centres_px: NDArray[np.float64], half_px: float
) -> NDArray[np.float64]:
    """Mean and relative spread of small square windows, (n, C) and (n,)."""
    from scipy.ndimage import map_coordinates

    img = image if image.ndim == 3 else image[..., None]
    s = np.linspace(-half_px, half_px, 5)
    dx, dy = np.meshgrid(s, s)
    px = centres_px[:, None, :] + np.stack([dx.ravel(), dy.ravel()], 1)[None]
    out = np.empty((len(centres_px), px.shape[1], img.shape[2]))
    for c in range(img.shape[2]):
        out[..., c] = map_coordinates(
            img[..., c], [px[..., 1].ravel(), px[..., 0].ravel()], order=1, cval=np.nan
        ).reshape(px.shape[:2])
    return out


def _placement_score(
    image: NDArray[np.float32],
    layout: TargetLayout,
    H_mm: NDArray[np.float64],
    reference_xyz: NDArray[np.float64] | None,
) -> tuple[float, float]:
    """(score, colour residual) of a placement: lower is better."""
    n_main = layout.rows * layout.cols
    centres = apply_homography(H_mm, layout.patch_centers_mm()[:n_main])
    size_px = _patch_size_px(H_mm, layout)
    samples = _sample_means(image, centres, 0.25 * size_px)  # (n, 25, C)
    inside = np.all(np.isfinite(samples), axis=(1, 2))
    if inside.sum() < max(4, n_main // 2):
        return math.inf, math.nan
    lum = samples.mean(axis=2)
    mean = lum.mean(axis=1)
    level = np.percentile(mean[inside], 90) + 1e-12
    spread = lum.std(axis=1) / (np.abs(mean) + 0.05 * level)
    uniform = float(np.mean(spread[inside]))
    # a placement that predicts patches outside the image is worse than one inside
    score = uniform + 0.5 * (1.0 - inside.mean())
    resid = math.nan
    if reference_xyz is not None and image.ndim == 3 and inside.sum() >= 6:
        rgb = samples.mean(axis=1)[inside]
        xyz = reference_xyz[:n_main][inside]
        resid = colour_fit_residual(rgb, xyz)
        score += resid
    return score, resid


def colour_fit_residual(rgb: ArrayLike, xyz: ArrayLike) -> float:
    """Relative RMS residual of the least-squares 3 x 3 map camera RGB -> XYZ.

    ``||rgb @ M - xyz|| / ||xyz||`` (Frobenius) for the best ``M``: about 0.02-0.05
    for a camera and a chart in agreement, 0.3 or more for patches that are not the
    reference's (another chart, a wrong orientation, ROIs off their patches).

    Parameters
    ----------
    rgb : (n, 3)
        Patch means, linear.
    xyz : (n, 3)
        The same patches' reference XYZ.
    """
    a = np.asarray(rgb, dtype=np.float64)
    b = np.asarray(xyz, dtype=np.float64)
    ok = np.all(np.isfinite(a), axis=1) & np.all(np.isfinite(b), axis=1)
    a, b = a[ok], b[ok]
    if len(a) < 4:
        return math.nan
    m, *_ = np.linalg.lstsq(a, b, rcond=None)
    return float(np.linalg.norm(a @ m - b) / (np.linalg.norm(b) + 1e-300))


def _patch_size_px(H_mm: NDArray[np.float64], layout: TargetLayout) -> float:
    """Median side of the main-grid patches in image pixels."""
    n_main = layout.rows * layout.cols
    q = apply_homography(H_mm, layout.patch_quads_mm(1.0)[:n_main])
    sides = np.hypot(*np.moveaxis(q - np.roll(q, 1, axis=1), -1, 0))
    return float(np.median(sides))


def find_patch_grid(
    image: ArrayLike,
    layout: TargetLayout,
    *,
    reference_xyz: ArrayLike | None = None,
    squares: ArrayLike | None = None,
) -> GridFit:
    """Find a layout's main patch grid in a photograph.

    Parameters
    ----------
    image : (H, W, 3) or (H, W)
        Linear camera RGB (or one plane); any scale.
    layout
        The chart's geometry (corners not needed). Its main grid is searched for;
        extra grids follow from the homography.
    reference_xyz : (n_patches, 3), optional
        The chart's reference XYZ in the order of ``layout.patch_names`` (NaN rows
        for patches without a reference). Tells the rotations of a symmetric grid
        apart; without it the unrotated reading is preferred where they tie.
    squares : (n, 3), optional
        :func:`find_squares` of ``image``, if already known.

    Returns
    -------
    GridFit

    Raises
    ------
    InputError
        No group of at least :data:`MIN_LATTICE_PATCHES` patch-like squares in a
        grid, or none that fits the layout's grid.
    """
    import cv2

    img = np.asarray(image, dtype=np.float32)
    ref = None if reference_xyz is None else np.asarray(reference_xyz, dtype=float)
    squares = (
        find_squares(img)
        if squares is None
        else np.asarray(squares, dtype=np.float64).reshape(-1, 3)
    )
    lattices = _lattices(squares)
    if not lattices:
        raise InputError(
            f"chart finder: no grid of patch-like squares found ({len(squares)} "
            "squares); give the chart's corners (--corners)"
        )
    centres_mm = layout.patch_centers_mm()[: layout.rows * layout.cols]
    best: GridFit | None = None
    best_pairs: tuple[NDArray[np.float64], NDArray[np.float64], NDArray] = (
        np.zeros((0, 2)),
        np.zeros((0, 2)),
        np.zeros(0),
    )
    for idx, ij in lattices:
        xy = squares[idx, :2]
        for cr in _rotations(ij):
            span_c = int(cr[:, 0].max() - cr[:, 0].min()) + 1
            span_r = int(cr[:, 1].max() - cr[:, 1].min()) + 1
            if span_c > layout.cols or span_r > layout.rows:
                continue
            for oc in range(layout.cols - span_c + 1):
                for orow in range(layout.rows - span_r + 1):
                    col = cr[:, 0] - cr[:, 0].min() + oc
                    row = cr[:, 1] - cr[:, 1].min() + orow
                    mm = centres_mm[row * layout.cols + col]
                    H, _ = cv2.findHomography(mm, xy, 0)
                    if H is None or not np.all(np.isfinite(H)):
                        continue
                    fit = _evaluate(img, layout, H, mm, xy, ref)
                    if fit is not None and (best is None or fit.score < best.score):
                        best = fit
                        best_pairs = (mm, xy, squares[idx, 2])
    if best is None:
        raise InputError(
            f"chart finder: no grid of squares fits the {layout.rows} x "
            f"{layout.cols} patches of layout {layout.name!r}; give the chart's "
            "corners (--corners)"
        )
    return _refined(best, layout, *best_pairs)


def _refined(
    fit: GridFit,
    layout: TargetLayout,
    mm: NDArray[np.float64],
    xy: NDArray[np.float64],
    side: NDArray[np.float64],
) -> GridFit:
    """The placement's homography fitted again without the biased squares.

    A dark patch on a dark frame (the ColorChecker's black, its purple) is found
    only in part: a smaller square whose centre is off by a tenth of a patch. The
    fit keeps the squares of full size and, of those, the ones within 2.5 median
    residuals (at least a fiftieth of a patch) of the homography, twice.
    """
    import cv2

    keep = side >= 0.93 * np.median(side)
    if keep.sum() < 8:
        keep = np.ones(len(side), dtype=bool)
    H = None
    for _ in range(3):
        H_new, _ = cv2.findHomography(mm[keep], xy[keep], 0)
        if H_new is None or not np.all(np.isfinite(H_new)):
            break
        H = H_new
        res = np.hypot(*(apply_homography(H, mm) - xy).T)
        limit = max(2.5 * float(np.median(res[keep])), 0.02 * float(np.median(side)))
        trimmed = keep & (res <= limit)
        if trimmed.sum() < 8 or trimmed.sum() == keep.sum():
            break
        keep = trimmed
    if H is None:
        return fit
    res = np.hypot(*(apply_homography(H, mm[keep]) - xy[keep]).T)
    corners = apply_homography(H, layout.outer_corners_mm())
    return replace(
        fit,
        corners_px=corners,
        n_matched=int(keep.sum()),
        residual_px=float(np.sqrt(np.mean(res**2))),
    )


def _evaluate(
    img: NDArray[np.float32],
    layout: TargetLayout,
    H: NDArray[np.float64],
    mm: NDArray[np.float64],
    xy: NDArray[np.float64],
    ref: NDArray[np.float64] | None,
) -> GridFit | None:
    pred = apply_homography(H, mm)
    c = np.array([[0.5 * layout.width_mm, 0.5 * layout.height_mm]])
    axis = apply_homography(H, np.vstack([c[0], c[0] + [1.0, 0.0]]))
    dx, dy = axis[1] - axis[0]
    deg = round(math.degrees(math.atan2(dy, dx)) / 90.0) % 4 * 90
    resid = float(np.sqrt(np.mean(np.sum((pred - xy) ** 2, axis=1))))
    size = _patch_size_px(H, layout)
    if not (size > 0 and resid < 0.15 * size):
        return None
    score, colour = _placement_score(img, layout, H, ref)
    if not math.isfinite(score):
        return None
    # equal scores (a symmetric grid without a reference): the unrotated reading
    score += 1e-6 * deg / 90
    corners = apply_homography(H, layout.outer_corners_mm())
    return GridFit(corners, len(xy), resid, deg, score, colour)
