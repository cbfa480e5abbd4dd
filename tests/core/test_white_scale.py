"""The sample's scale against its chart session's, by the white background both are
flat-fielded to (``core.plausibility.check_white_scale``).

A sample whose illuminants are 2x (an exposure in another unit) gives reflectances
0.5x with every other check passing: a darker sample looks the same. The white
background does not change between the sessions, so its reflectance by Eq. 1 must.
The corpus (``tests/test_mistakes_corpus.py``) runs the mistakes through the CLI,
``tests/test_demo_chain.py`` the demo's own sessions.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from tunespec.core.calibration import white_from_meta
from tunespec.core.errors import InputError
from tunespec.core.plausibility import (
    MIN_SEEN_FRACTION,
    WHITE_SCALE_TOLERANCE,
    Implausible,
    check_white_scale,
    white_reflectance,
    white_response,
)
from tunespec.core.spectra import Spectra

LIGHTS = [f"LED{n}" for n in range(410, 700, 20)]


def _chart(rng) -> dict[str, float]:
    return dict(zip(LIGHTS, rng.uniform(0.85, 0.92, len(LIGHTS)), strict=True))


def test_the_same_scale_passes_and_returns_the_median_ratio() -> None:
    rng = np.random.default_rng(0)
    chart = _chart(rng)
    # the demo's lights agree within 0.6 %: noise of a percent is far inside
    sample = {n: v * (1.02 + 0.01 * rng.standard_normal()) for n, v in chart.items()}
    median = check_white_scale(sample, chart)
    assert median == pytest.approx(
        np.median([sample[n] / chart[n] for n in LIGHTS]), rel=1e-12
    )


@pytest.mark.parametrize("factor", [0.5, 0.77, 1.4, 2.0])
def test_a_sample_on_another_scale_is_refused(factor) -> None:
    chart = _chart(np.random.default_rng(1))
    sample = {n: v * factor for n, v in chart.items()}
    with pytest.raises(Implausible) as err:
        check_white_scale(sample, chart)
    assert err.value.check == "white"
    msg = str(err.value)
    assert f"reflects {factor:.3g}x" in msg and f"would come out {factor:.3g}x" in msg


def test_just_inside_the_tolerance_passes() -> None:
    chart = _chart(np.random.default_rng(2))
    f = 1.0 + 0.95 * WHITE_SCALE_TOLERANCE
    assert check_white_scale({n: v * f for n, v in chart.items()}, chart) == (
        pytest.approx(f)
    )


def test_one_light_off_is_named() -> None:
    chart = _chart(np.random.default_rng(3))
    sample = dict(chart)
    sample["LED530"] = chart["LED530"] * 1.25  # its exposure typed 1.25x too long
    with pytest.raises(Implausible, match=r"light LED530: .* is 1.25x the other"):
        check_white_scale(sample, chart)


def test_only_shared_finite_lights_count() -> None:
    chart = _chart(np.random.default_rng(4))
    assert np.isnan(check_white_scale({"OTHER": 0.9}, chart))
    sample = {**chart, "LED410": float("nan"), "EXTRA": 5.0}
    assert check_white_scale(sample, chart) == pytest.approx(1.0)


def test_white_reflectance_is_the_level_over_a_perfect_white() -> None:
    """Eq. 1's white over a perfect one; a light the camera hardly sees (a deep red
    LED past an IR-cut filter: its reading noise decides the ratio) is left out."""
    wl = np.arange(400.0, 701.0, 5.0)
    band = lambda c, w: np.exp(-0.5 * ((wl - c) / w) ** 2)  # noqa: E731
    ir_cut = wl < 660
    sens = Spectra(wl, np.stack([band(600, 30), band(540, 30), band(450, 30)]) * ir_cut,
                   ("R", "G", "B"))  # fmt: skip
    leds = Spectra(wl, np.stack([band(520, 10), band(670, 8)]), ("G", "DEEP_RED"))
    perfect = white_response(leds, sens)
    rho = white_reflectance(0.88 * perfect, leds, sens)
    assert rho[0] == pytest.approx(0.88)
    light = leds.values.sum(axis=1) * 5.0
    seen = perfect.sum(axis=1) / (light * sens.values.sum(axis=0).max())
    assert seen[0] > 0.7 and 0.005 < seen[1] < MIN_SEEN_FRACTION  # 0.74, 0.0095
    assert np.isnan(rho[1])
    # a light too weak to light the board (a failing LED): its level is the dark's
    two = Spectra(wl, np.stack([band(520, 10), band(540, 10)]), ("G1", "G2"))
    for dark in ([0.004, 0.009, 0.001], [-0.002, 0.001, 0.0]):
        weak = white_reflectance(np.array([[0.5, 0.6, 0.1], dark]), two, sens)
        assert np.isfinite(weak[0]) and np.isnan(weak[1])


@pytest.mark.parametrize(
    "doc",
    [
        '{"LED410": -1}',
        '{"LED410": 0}',
        "[0.9, 0.9]",
        '{"LED410": "x"}',
        "{}",
        "not json",
    ],
)
def test_a_malformed_record_names_the_side_file(doc) -> None:
    meta = {"white_background": doc, "meta_path": "S.csv.meta.json"}
    with pytest.raises(InputError, match=r"S.csv.meta.json: white_background"):
        white_from_meta(meta)
    assert white_from_meta({}) is None
    assert white_from_meta({"white_background": json.dumps({"A": 0.9})}) == {"A": 0.9}
