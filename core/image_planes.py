"""Numerics on the half-resolution planes of per-pixel images (no file I/O).

- :func:`smooth_dark`: a mean dark plane without its temporal noise;
- :func:`flat_block_px`: the block the white board is smoothed over (Eq. 2's ``A_B``);
- :class:`Rectification` and :func:`rectification_for`: output pixels in the target's
  plane, through the homography of its corners;
- :class:`SystematicTable`: what a pixel's own noise does not cover, by CIELAB cell.

The stages that read frames and write the images are
:mod:`tunespec.app.pipeline.image_session`.

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source (``shared/reference``),
section "Capturing and Processing", Eq. 2 and 5.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tunespec.core.errors import InputError

__all__ = [
    "DARK_MODES",
    "DARK_OUTLIER_SIGMA",
    "DARK_SMOOTH_PX",
    "FLAT_BLOCK_PX",
    "Rectification",
    "SystematicTable",
    "flat_block_px",
    "rectification_for",
    "smooth_dark",
]

#: Largest side of the blocks (plane pixels) the white board is smoothed over
#: (Eq. 2's ``A_B``), see :func:`flat_block_px`.
FLAT_BLOCK_PX = 16


@dataclass(frozen=True)
class Rectification:
    """Output pixels in the target's plane: a homography from output to plane pixels.

    Parameters
    ----------
    H_out_to_plane : (3, 3)
        Maps output pixel ``(x, y, 1)`` to plane pixel coordinates of the frames.
    shape
        ``(rows, cols)`` of the rectified images.
    """

    H_out_to_plane: tuple[tuple[float, ...], ...]
    shape: tuple[int, int]

    def source_rows(self, row0: int, row1: int, plane_rows: int) -> tuple[int, int]:
        """The plane rows the output rows ``row0:row1`` read from (with margin)."""
        H = np.asarray(self.H_out_to_plane)
        cols = self.shape[1]
        x = np.array([0, cols - 1, 0, cols - 1, (cols - 1) / 2], dtype=np.float64)
        y = np.array([row0, row0, row1 - 1, row1 - 1, (row0 + row1) / 2])
        p = H @ np.stack([x, y, np.ones_like(x)])
        v = p[1] / p[2]
        lo = max(math.floor(v.min()) - 2, 0)
        hi = min(math.ceil(v.max()) + 3, plane_rows)
        return lo, max(hi, lo + 1)

    def maps(self, row0: int, row1: int) -> tuple[NDArray[np.float32], ...]:
        """Plane coordinates (x, y) of every output pixel of rows ``row0:row1``."""
        H = np.asarray(self.H_out_to_plane)
        yy, xx = np.mgrid[row0:row1, 0 : self.shape[1]].astype(np.float64)
        w = H[2, 0] * xx + H[2, 1] * yy + H[2, 2]
        u = (H[0, 0] * xx + H[0, 1] * yy + H[0, 2]) / w
        v = (H[1, 0] * xx + H[1, 1] * yy + H[1, 2]) / w
        return u.astype(np.float32), v.astype(np.float32)


#: Side of the box the dark planes are smoothed over with ``dark="smooth"``.
DARK_SMOOTH_PX = 15
#: With ``dark="smooth"``, a pixel further than this many robust standard
#: deviations from the smoothed dark keeps its own dark value (hot pixels, strong
#: fixed pattern).
DARK_OUTLIER_SIGMA = 5.0
DARK_MODES = ("pixel", "smooth")


def smooth_dark(plane: NDArray[np.float32]) -> NDArray[np.float32]:
    """A dark plane without its temporal noise: the :data:`DARK_SMOOTH_PX` box mean,
    except where the pixel departs from it by more than :data:`DARK_OUTLIER_SIGMA`
    robust standard deviations (1.4826 x the median absolute departure), which
    keep their own value.

    Subtracting a dark frame pixel by pixel adds its read noise to every pixel (with
    one dark frame, the read-noise variance doubles); its smooth level and its hot
    pixels are what the subtraction is for. The box mean keeps linear gradients
    (amplifier glow, a warm corner) and removes ``1 - 1/15^2`` of the noise
    variance; a fixed pattern below the read noise is not corrected (it cannot be
    told from noise in one frame).

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> d = (0.01 + 1e-3 * rng.standard_normal((64, 64))).astype(np.float32)
    >>> d[10, 20] = 0.5  # a hot pixel
    >>> s = smooth_dark(d)
    >>> float(s[10, 20]), bool(np.std(s[30:, 30:]) < 2e-4)
    (0.5, True)
    """
    import cv2

    k = DARK_SMOOTH_PX
    plane = np.ascontiguousarray(plane, dtype=np.float32)
    box = cv2.blur(plane, (k, k), borderType=cv2.BORDER_REFLECT)
    dev = plane - box
    sigma = 1.4826 * float(np.median(np.abs(dev)))
    far = np.abs(dev) > DARK_OUTLIER_SIGMA * max(sigma, 1e-12)
    if far.any():
        # the smooth level around hot pixels without them: the box mean again,
        # over the other pixels only
        keep = (~far).astype(np.float32)
        num = cv2.blur(plane * keep, (k, k), borderType=cv2.BORDER_REFLECT)
        den = cv2.blur(keep, (k, k), borderType=cv2.BORDER_REFLECT)
        box = np.where(den > 0, num / np.maximum(den, 1e-6), box)
        box[far] = plane[far]
    return box.astype(np.float32, copy=False)


def flat_block_px(width_px: int) -> int:
    """Smoothing block for planes ``width_px`` wide: at most :data:`FLAT_BLOCK_PX`,
    and at most 1/96 of the width (at least 4).

    Block means interpolated bilinearly miss the light field's curvature by about
    ``f'' B^2 / 6`` (relative); the curvature per plane pixel grows as the image
    shrinks (0.4 % at 192 px wide with 16 px blocks on the simulated bench), so small
    images take small blocks. At full resolution (2880 px) it is 16.

    Examples
    --------
    >>> flat_block_px(2880), flat_block_px(192)
    (16, 4)
    """
    return int(max(4, min(FLAT_BLOCK_PX, width_px // 96)))


def rectification_for(
    corners_px: Any, width_mm: float, height_mm: float
) -> Rectification:
    """The rectification of a target whose outer corners are at ``corners_px``.

    Parameters
    ----------
    corners_px : (4, 2)
        TL, TR, BR, BL of the target in mosaic pixels (a layout's ``corners_px``).
    width_mm, height_mm
        The target's size.

    Returns
    -------
    Rectification
        Output pixels square on the target, at the scale the planes have along
        the target's top and bottom edges.

    Examples
    --------
    >>> r = rectification_for([[0.5, 0.5], [200.5, 0.5], [200.5, 100.5], [0.5, 100.5]],
    ...                       100.0, 50.0)
    >>> r.shape
    (50, 100)
    """
    from tunespec.core.io.raw import full_to_plane_px
    from tunespec.core.layout import homography_from_corners

    plane = full_to_plane_px(np.asarray(corners_px, dtype=np.float64).reshape(4, 2))
    if not (width_mm > 0 and height_mm > 0):
        raise InputError(f"target size {width_mm} x {height_mm} mm must be positive")
    top = np.linalg.norm(plane[1] - plane[0])
    bottom = np.linalg.norm(plane[2] - plane[3])
    s = 0.5 * (top + bottom) / width_mm  # output px per mm
    shape = (max(1, round(height_mm * s)), max(1, round(width_mm * s)))
    mm = np.array(
        [[0.0, 0.0], [width_mm, 0.0], [width_mm, height_mm], [0.0, height_mm]]
    )
    H_mm = homography_from_corners(mm, plane)
    # output pixel centres at (x + 0.5) / s mm
    to_mm = np.array([[1 / s, 0, 0.5 / s], [0, 1 / s, 0.5 / s], [0, 0, 1.0]])
    H = H_mm @ to_mm
    return Rectification(tuple(tuple(float(v) for v in row) for row in H), shape)


#: CIELAB cells of the systematic-uncertainty table: L* 0-100, a*, b* -100-100.
_LAB_CELLS = (10, 10, 10)


@dataclass(frozen=True)
class SystematicTable:
    """What a pixel's own noise does not cover, by CIELAB cell (see
    :func:`systematic_table`).

    Parameters
    ----------
    var_l, var_rms : (n_L, n_a, n_b)
        Added variance of L* and of the RMS spectral uncertainty.
    n_samples : int
        Regions the table was computed from.
    """

    var_l: NDArray[np.float64]
    var_rms: NDArray[np.float64]
    n_samples: int = 0

    def lookup(self, lab: NDArray[np.floating]) -> tuple[NDArray[np.float64], ...]:
        """The added variances at CIELAB values (3, n)."""
        idx = _lab_cell(np.asarray(lab, dtype=np.float64))
        return self.var_l[idx], self.var_rms[idx]

    @staticmethod
    def cells(lab: NDArray[np.floating]) -> NDArray[np.uint16]:
        """The flat cell index of CIELAB values (3, n): what :meth:`add_to` needs
        of a pixel, kept while the table is still being computed."""
        idx = _lab_cell(np.asarray(lab, dtype=np.float64))
        return np.ravel_multi_index(idx, _LAB_CELLS).astype(np.uint16)

    def add_to(
        self, uncertainty: NDArray[np.float32], cells: NDArray[np.uint16]
    ) -> NDArray[np.float32]:
        """``uncertainty`` (n, 2: u(L*), RMS u) with the cells' added variances."""
        # one gather of (n, 2) rows and in-place sums: the same float64 arithmetic
        # as stacking the two lookups, at a third of the passes (the whole image's
        # uncertainty goes through here in the last, serial task)
        table = np.stack([self.var_l.reshape(-1), self.var_rms.reshape(-1)], axis=1)
        total = np.take(table, cells, axis=0)
        own = uncertainty.astype(np.float64)
        own *= own
        total += own
        return np.sqrt(total, out=total).astype(np.float32)


def _lab_cell(lab: NDArray[np.float64]) -> tuple[NDArray[np.int64], ...]:
    nl, na, nb = _LAB_CELLS
    il = np.clip((lab[0] / (100.0 / nl)).astype(np.int64), 0, nl - 1)
    ia = np.clip(((lab[1] + 100.0) / (200.0 / na)).astype(np.int64), 0, na - 1)
    ib = np.clip(((lab[2] + 100.0) / (200.0 / nb)).astype(np.int64), 0, nb - 1)
    return il, ia, ib
