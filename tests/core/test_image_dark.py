"""``smooth_dark``: a dark plane's smooth level and hot pixels without its noise."""

from __future__ import annotations

import numpy as np

from tunespec.core.image_planes import DARK_SMOOTH_PX, smooth_dark


def test_noise_goes_gradient_and_hot_pixels_stay() -> None:
    rng = np.random.default_rng(3)
    h, w = 120, 160
    yy, xx = np.mgrid[0:h, 0:w]
    level = (0.01 + 2e-5 * xx + 1e-5 * yy).astype(np.float32)  # amplifier glow
    noise_sd = 5e-4
    plane = level + noise_sd * rng.standard_normal((h, w)).astype(np.float32)
    hot = [(7, 9), (60, 80), (100, 150)]
    for y, x in hot:
        plane[y, x] += 0.2
    out = smooth_dark(plane)
    for y, x in hot:
        assert out[y, x] == plane[y, x]
    inner = (
        slice(DARK_SMOOTH_PX, h - DARK_SMOOTH_PX),
        slice(DARK_SMOOTH_PX, w - DARK_SMOOTH_PX),
    )
    err = (out - level)[inner]
    mask = np.ones_like(err, dtype=bool)
    for y, x in hot:
        mask[
            max(0, y - DARK_SMOOTH_PX) : y + DARK_SMOOTH_PX,
            max(0, x - DARK_SMOOTH_PX) : x + DARK_SMOOTH_PX,
        ] = False
    # the box mean of 225 pixels: noise / 15, the linear glow kept
    assert np.std(err[mask]) < 2 * noise_sd / DARK_SMOOTH_PX
    assert abs(np.mean(err[mask])) < noise_sd / DARK_SMOOTH_PX
    # next to a hot pixel the level is that of the others (the hot one left out)
    near = out[60, 82] - level[60, 82]
    assert abs(near) < 3 * noise_sd / DARK_SMOOTH_PX


def test_flat_noise_free_dark_is_kept() -> None:
    plane = np.full((40, 50), 0.0123, dtype=np.float32)
    np.testing.assert_allclose(smooth_dark(plane), plane, rtol=1e-6)
