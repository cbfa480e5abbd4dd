"""Repeated frames at one exposure are averaged before brackets are merged."""

from __future__ import annotations

import numpy as np
import pytest

from tunespec.core.errors import InputError
from tunespec.core.image import NoiseModel, SensorFigures
from tunespec.core.processing import _merge_brackets, _Pixels, exposure_groups


def test_exposure_groups_are_runs_of_equal_exposure() -> None:
    assert exposure_groups([2.0]) == [range(0, 1)]
    assert exposure_groups([2.0, 2.0, 2.0]) == [range(0, 3)]
    assert exposure_groups([2.0, 2.0, 0.5, 0.5]) == [range(0, 2), range(2, 4)]
    assert exposure_groups([2.0, 0.5]) == [range(0, 1), range(1, 2)]


def _px(values: np.ndarray, saturated: np.ndarray | None = None) -> _Pixels:
    v = np.asarray(values, dtype=np.float32)
    sat = np.zeros(v.shape[1], bool) if saturated is None else saturated
    return _Pixels(v.copy(), sat)


def test_repeats_are_averaged_and_their_noise_shrinks() -> None:
    rng = np.random.default_rng(1)
    n_px, sd = 20000, 0.01
    signal = np.full((3, n_px), 0.4)
    dark = _px(np.full((3, n_px), 0.02))
    frames = [
        _px(signal + 0.02 + sd * rng.standard_normal((3, n_px))) for _ in range(4)
    ]
    merged = _merge_brackets(frames, [dark] * 4, [1.5] * 4)
    np.testing.assert_allclose(
        merged.values, np.mean([f.values for f in frames], axis=0) - 0.02, atol=1e-6
    )
    assert abs(merged.values.std() / sd - 0.5) < 0.02  # sd / sqrt(4)
    # without shorter brackets, the 0.95 level does not flag: only the white level
    assert not merged.saturated.any()


def test_repeats_then_brackets() -> None:
    """A cell clipped in one long repeat takes the mean of the short repeats."""
    long_v = np.array([[0.5, 0.96], [0.5, 0.5], [0.5, 0.5]])
    long_clip = np.array([False, False])
    short_v = np.array([[0.125, 0.3], [0.125, 0.125], [0.125, 0.125]])
    frames = [
        _px(long_v, long_clip),
        _px(long_v * np.array([[1.0, 0.9]] * 3), long_clip),
        _px(short_v),
        _px(short_v * 1.1),
    ]
    zero = _px(np.zeros((3, 2)))
    merged = _merge_brackets(frames, [zero] * 4, [1.0, 1.0, 0.25, 0.25])
    np.testing.assert_allclose(merged.values[:, 0], 0.5 * (1 + 1.0) / 2)
    # cell 1: above 0.95 in the first long frame -> the short repeats' mean x 4
    np.testing.assert_allclose(
        merged.values[:, 1], 4 * (short_v[:, 1] * 2.1 / 2), rtol=1e-6
    )
    assert not merged.saturated.any()


def test_camera_noise_model_of_averaged_frames() -> None:
    one = NoiseModel.from_camera(full_well_e=67000, read_noise_e=30, n_darks=4)
    four = SensorFigures(67000, 30).model(n_darks=4, n_frames=4)
    np.testing.assert_allclose(four.shot_gain, one.shot_gain / 4)
    # read variance: (1/n_frames + 1/n_darks) of a frame's
    np.testing.assert_allclose(four.read_var, one.read_var * (0.25 + 0.25) / 1.25)
    with pytest.raises(InputError, match="n_frames"):
        NoiseModel.from_camera(full_well_e=67000, read_noise_e=30, n_frames=0)
