"""Automatic target corners: outline, sub-pixel sides, reading against the layout."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from tunespec.core.errors import InputError
from tunespec.core.homography import find_quadrilateral, locate_target, order_corners
from tunespec.core.layout import TargetLayout, apply_homography, homography_from_corners

#: Corners of an anti-aliased rendering are found to a fraction of a pixel.
ATOL_SUBPIXEL_PX = 0.25
#: With noise and a 10 % light fall-off the corners still land within this.
ATOL_NOISY_PX = 0.5

LAYOUT = TargetLayout(
    name="5x4",
    rows=4,
    cols=5,
    width_mm=120.0,
    height_mm=100.0,
    margin_mm=(8.0, 8.0, 8.0, 8.0),
    patch_fraction=0.8,
)
TRUE = np.array([[112.3, 95.7], [521.4, 80.2], [548.9, 402.6], [96.1, 421.3]])
SHAPE = (500, 640)
SUPER = 4  # supersampling of the rendering


def _render(
    layout: TargetLayout,
    *,
    frame: float,
    background: float = 0.9,
    corners: np.ndarray = TRUE,
    falloff: float = 0.0,
    noise: float = 0.0,
) -> np.ndarray:
    """The target (patches in 0.1 ... 0.9) on a board, anti-aliased, (H, W) float32."""
    rng = np.random.default_rng(3)
    k = layout.n_patches
    vals = rng.uniform(0.1, 0.9, k)
    vals[0] = vals[k - 1] = background  # white corner patches: the hard case
    s = 8  # chart pixels per mm in the flat rendering
    chart = np.full((round(layout.height_mm * s), round(layout.width_mm * s)), frame)
    for v, q in zip(vals, layout.patch_quads_mm(1.0), strict=True):
        chart[
            round(q[0, 1] * s) : round(q[2, 1] * s),
            round(q[0, 0] * s) : round(q[1, 0] * s),
        ] = v
    h, w = SHAPE
    # chart pixel (i + 0.5)/s mm  ->  image pixel (supersampled, centres at integers)
    src = layout.outer_corners_mm() * s - 0.5
    dst = (corners + 0.5) * SUPER - 0.5
    H = homography_from_corners(src, dst)
    big = cv2.warpPerspective(
        chart.astype(np.float32),
        H,
        (w * SUPER, h * SUPER),
        flags=cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=background,
    )
    img = cv2.resize(big, (w, h), interpolation=cv2.INTER_AREA)
    yy, xx = np.mgrid[0:h, 0:w]
    light = (
        1
        - falloff * (((xx - w / 2) / (w / 2)) ** 2 + ((yy - h / 2) / (h / 2)) ** 2) / 2
    )
    img = img * light
    if noise:
        img = img + rng.normal(0, noise, img.shape)
    return img.astype(np.float32), light.astype(np.float32)


def test_order_corners_is_rotation_tolerant() -> None:
    pts = TRUE[[2, 0, 3, 1]]
    np.testing.assert_array_equal(order_corners(pts), TRUE)


def test_dark_frame_outline_to_subpixel() -> None:
    img, _ = _render(LAYOUT, frame=0.03)
    fit = find_quadrilateral(img)
    np.testing.assert_allclose(fit.corners_px, TRUE, atol=ATOL_SUBPIXEL_PX)
    assert fit.residual_px < 0.2 and fit.n_edge_points > 100


def test_flat_fielded_ratio_copes_with_falloff_and_noise() -> None:
    img, light = _render(LAYOUT, frame=0.03, falloff=0.15, noise=0.01)
    background = 0.9 * light
    corners, _ = locate_target(img, LAYOUT, background=background)
    np.testing.assert_allclose(corners, TRUE, atol=ATOL_NOISY_PX)


@pytest.mark.parametrize("frame", [0.03, 0.9])
def test_locate_target_reads_outline_against_layout(frame) -> None:
    """A white frame hides the outer edge: the patch area is found and extended."""
    img, _ = _render(LAYOUT, frame=frame)
    corners, _ = locate_target(img, LAYOUT)
    np.testing.assert_allclose(corners, TRUE, atol=ATOL_NOISY_PX)


def test_corners_round_trip_through_the_homography() -> None:
    img, _ = _render(LAYOUT, frame=0.03)
    corners, _ = locate_target(img, LAYOUT)
    H = homography_from_corners(LAYOUT.outer_corners_mm(), corners)
    back = apply_homography(np.linalg.inv(H), corners)
    np.testing.assert_allclose(back, LAYOUT.outer_corners_mm(), atol=1e-6)


@pytest.mark.parametrize(
    ("image", "fragment"),
    [
        (np.ones((200, 300), np.float32), "no target"),
        (np.zeros((200, 300), np.float32), "black"),
        (np.ones((8, 8), np.float32), "2-D image"),
    ],
)
def test_no_target_is_an_input_error(image, fragment) -> None:
    with pytest.raises(InputError, match=fragment):
        find_quadrilateral(image)


def test_target_filling_the_image_asks_for_corners() -> None:
    img = np.full((200, 300), 0.2, np.float32)
    img[:, :3] = img[:, -3:] = img[:3] = img[-3:] = 0.9
    with pytest.raises(InputError, match="corners"):
        find_quadrilateral(img)


def test_nan_pixels_do_not_break_detection() -> None:
    img, _ = _render(LAYOUT, frame=0.03)
    img[10:20, 10:20] = np.nan
    fit = find_quadrilateral(img)
    np.testing.assert_allclose(fit.corners_px, TRUE, atol=ATOL_SUBPIXEL_PX)
