"""The live preview is painted from its 8-bit RGB as it is (no per-pixel rescale of
levels 0-255 on the GUI thread, 11-28 ms a paint of a 1536 x 1024 frame)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from tunespec.app.gui.plots.frame_plot import FramePlot, build_preview


def test_preview_pixels_reach_the_screen_unchanged(qtbot):
    rng = np.random.default_rng(1)
    planes = rng.uniform(0.0, 0.8, (3, 48, 64)).astype(np.float32)
    saturated = np.zeros((48, 64), bool)
    saturated[5:9, 10:20] = True
    preview = build_preview(SimpleNamespace(planes=planes, saturated=saturated))
    plot = FramePlot()
    qtbot.addWidget(plot)
    plot.show_preview(preview)
    for item, expected in (
        (plot.image_item, preview.rgb),
        (plot.overlay_item, preview.overlay),
    ):
        assert item.levels is None  # the pass-through path for uint8 data
        item.render()
        qimage = item.qimage
        assert (qimage.width(), qimage.height()) == (64, 48)
        channels = expected.shape[2]
        for y, x in ((0, 0), (7, 12), (47, 63), (20, 33)):
            c = qimage.pixelColor(x, y)
            rgba = (c.red(), c.green(), c.blue(), c.alpha())
            assert rgba[:channels] == tuple(int(v) for v in expected[y, x])
