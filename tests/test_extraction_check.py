"""The extraction check: wrong ROIs are refused (or flagged with --force)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.core.test_processing import _layout, _make_session, _npy_loader
from tests.helpers import without_progress
from tunespec.core.errors import InputError
from tunespec.core.extraction import (
    MAX_EXCESS_SPREAD,
    check_extraction,
    outline_offset,
    patch_statistics,
)
from tunespec.core.layout import TargetLayout


def _two_patch_image(noise: float, rng: np.random.Generator) -> np.ndarray:
    """(3, 100, 200): a dark patch left of a bright one, with pixel noise."""
    img = np.empty((3, 100, 200))
    img[:, :, :100] = 0.1
    img[:, :, 100:] = 0.6
    return img + noise * rng.standard_normal(img.shape)


def test_roi_on_a_patch_passes_and_across_two_fails() -> None:
    rng = np.random.default_rng(1)
    img = _two_patch_image(0.02, rng)
    inside = [[20, 20], [80, 20], [80, 80], [20, 80]]
    across = [[70, 20], [130, 20], [130, 80], [70, 80]]
    stats = patch_statistics(img, [inside, across])
    # noisy but uniform: its spread is the pixel noise, none beyond it
    np.testing.assert_allclose(stats.noise[0], 0.02, rtol=0.15)
    check = check_extraction(["in", "across"], stats)
    assert check.metrics["worst_patch"] == "across"
    assert check.metrics["worst_excess_spread"] > 0.3
    assert not check.ok and "across" in check.summary() and "in," not in check.summary()
    alone = check_extraction(["in"], patch_statistics(img, [inside]))
    assert alone.ok and alone.metrics["worst_excess_spread"] < MAX_EXCESS_SPREAD / 2


def test_roi_outside_the_image_fails() -> None:
    img = np.full((3, 50, 50), 0.5)
    stats = patch_statistics(img, [[[40, 10], [60, 10], [60, 30], [40, 30]]])
    assert stats.n_pixels[0] < stats.n_expected[0]
    assert "outside the image" in check_extraction(["P"], stats).summary()


def test_reference_tests_catch_shuffled_patches() -> None:
    rng = np.random.default_rng(2)
    xyz = rng.uniform(5, 90, (24, 3))
    m = np.array([[0.9, 0.2, 0.0], [0.3, 1.0, 0.1], [0.0, 0.1, 0.8]])
    rgb = np.linalg.solve(m, xyz.T).T * 0.01
    names = [f"P{k}" for k in range(24)]

    def stats(values):
        return _stats(values, np.zeros_like(values), np.full(24, 100))

    good = check_extraction(names, stats(rgb), reference_xyz=xyz)
    assert good.ok, good.summary()
    assert good.metrics["colour_residual"] < 1e-9
    bad = check_extraction(names, stats(rgb[rng.permutation(24)]), reference_xyz=xyz)
    assert not bad.ok and "reference" in bad.summary()


def _stats(mean, std, n):
    from tunespec.core.extraction import PatchStatistics

    return PatchStatistics(mean, std, np.zeros_like(mean), n, n, np.zeros(len(n)))


def test_outline_offset_in_patch_sides() -> None:
    squares = np.array([[10.0 + 20 * k, 10.0, 15.0] for k in range(5)])
    quads = np.array(
        [
            [[x - 7.5, 2.5], [x + 7.5, 2.5], [x + 7.5, 17.5], [x - 7.5, 17.5]]
            for x in 13.0 + 20 * np.arange(5)
        ]
    )
    offset, n = outline_offset(squares, quads)
    assert n == 5 and offset == pytest.approx(3.0 / 15.0)
    assert math.isnan(outline_offset(squares[:3], quads)[0])


def _wrong_layout() -> TargetLayout:
    """The test chart's outline read as a 2 x 2 grid: every ROI across patches."""
    right = _layout()
    return TargetLayout(
        name="wrong 2x2",
        rows=2,
        cols=2,
        width_mm=right.width_mm,
        height_mm=right.height_mm,
        margin_mm=right.margin_mm,
        patch_fraction=0.9,
        roi_fraction=0.5,
        patch_names=("W1", "W2", "W3", "W4"),
    )


def test_process_refuses_a_wrong_layout_and_force_keeps_it(tmp_path) -> None:
    from tests.core.test_processing import CORNERS
    from tunespec.app.pipeline.steps import process

    session, _ = _make_session(tmp_path / "s")
    right = process(session, loader=_npy_loader)
    assert right.check is not None and right.check.ok, right.check.summary()
    wrong = _wrong_layout().with_corners(CORNERS)
    with pytest.raises(InputError, match=r"patch extraction refused.*not uniform"):
        process(session, layout=wrong, corners="layout", loader=_npy_loader)
    kept = process(
        session, layout=wrong, corners="layout", loader=_npy_loader, force=True
    )
    assert not kept.check.ok
    assert any("check failed" in w for w in kept.warnings)


@pytest.mark.slow
def test_sg_session_processed_as_cc24_is_refused_or_flagged(tmp_path, capsys) -> None:
    """A bench capture of the ColorChecker SG processed with the CC24 layout."""
    from tunespec.app.cli import main
    from tunespec.app.pipeline.steps import capture_target
    from tunespec.devices.registry import open_bench

    sg = TargetLayout.load("colorchecker_sg")
    with open_bench("sim", None, layout=sg, seed=3) as bench:
        session, _ = capture_target(bench, tmp_path / "sg", sg)
    out, png = tmp_path / "r.csv", tmp_path / "p.png"
    args = ["process", str(session.root), "-o", str(out), "--layout", "colorchecker_24"]
    assert main([*args, "--preview", str(png)]) == 2
    err = without_progress(capsys.readouterr().err)
    assert "refused" in err and "not uniform" in err and "\n" not in err
    assert png.is_file() and not out.exists()
    assert main([*args, "--force"]) == 0
    assert "FORCED" in out.read_text().splitlines()[1]
    # the right layout passes, with the reference tests too (the SG's own data)
    assert main(["process", str(session.root), "-o", str(out)]) == 0
    assert "quality" not in out.read_text().splitlines()[0]
