"""Table 1 per patch (the report's map, histogram and worst patches): its mean is
Table 1's RGB mean, and a patch whose responses are off is the worst one."""

from __future__ import annotations

import numpy as np

from tunespec.app.pipeline.plan import chart_layout
from tunespec.app.pipeline.steps import calibrate
from tunespec.core.datasets import load_camera, load_colorchecker_sg, load_led_set
from tunespec.core.forward_model import render_rgb
from tunespec.core.processing import ProcessedSession
from tunespec.core.responses import Responses
from tunespec.core.spectra import DEFAULT_GRID

#: Table 1's RGB mean is a mean over stimuli; per patch, over the same LEDs: equal up
#: to rounding.
RTOL_SAME_MEAN = 1e-12


def _chart(offset_patch: str | None = None) -> ProcessedSession:
    sg = load_colorchecker_sg(DEFAULT_GRID)
    leds = load_led_set(DEFAULT_GRID)
    cam = load_camera(grid=DEFAULT_GRID)
    rgb = render_rgb(sg.values, leds.values, cam.values, DEFAULT_GRID.step_nm)
    rgb = 0.8 * rgb / rgb.max()
    rng = np.random.default_rng(0)
    rgb = rgb * (1 + rng.normal(0, 0.002, rgb.shape))
    if offset_patch is not None:
        rgb[sg.names.index(offset_patch)] *= 1.05  # 5 % too bright under every LED
    return ProcessedSession(
        responses=Responses(sg.names, leds.names, rgb),
        illuminants=leds,
        layout=chart_layout(),
        corners_source="layout",
    )


def test_per_patch_errors_average_to_table1_and_find_the_bad_patch() -> None:
    cal = calibrate(_chart("F5"), method="pca")
    errors = cal.patch_rgb_error
    assert errors is not None
    assert len(errors) == 140 - len(cal.estimate.excluded_patches)
    np.testing.assert_allclose(
        np.mean(list(errors.values())), cal.table1.mean[3], rtol=RTOL_SAME_MEAN
    )
    worst = max(errors, key=errors.__getitem__)
    assert worst == "F5"
    assert errors["F5"] > 5 * np.median(list(errors.values()))
