"""The report's "Chart choice" section and the bench comparison behind it."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tunespec.app.pipeline.chart_choice import (
    ChartComparison,
    ChartScore,
    compare_charts,
    held_out_card,
    load_chart_comparison,
)
from tunespec.app.report.report import ReportData, render_html
from tunespec.core.datasets import load_colorchecker_sg, resource_path
from tunespec.core.errors import InputError
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.spectra import DEFAULT_GRID

SCORES = (
    ChartScore("ColorChecker 24", 24, 0.00036, 0.0145, 0.082, 0.227, 0.0080),
    ChartScore("ColorChecker SG", 140, 0.00039, 0.0265, 0.080, 0.228, 0.0083),
)


def test_report_section_reads_the_saved_comparison(tmp_path) -> None:
    ChartComparison(SCORES, seed=4).save(tmp_path / "chart_choice.json")
    choice = load_chart_comparison(tmp_path / "chart_choice.json")
    html = render_html(ReportData(title="t", chart_choice=choice), figures=[])
    assert "Chart choice: calibrating on each chart" in html
    for text in ("ColorChecker SG", "140", "0.0265", "0.082", "0.228", "seed 4"):
        assert text in html
    # no section without a comparison
    assert "Chart choice" not in render_html(ReportData(title="t"), figures=[])


def test_a_bad_comparison_file_is_one_line(tmp_path) -> None:
    d = ChartComparison(SCORES).to_dict()
    del d["scores"][1]["de00_max"]
    p = tmp_path / "c.json"
    p.write_text(json.dumps(d))
    with pytest.raises(InputError, match="scores: expected objects") as err:
        load_chart_comparison(p)
    assert str(p) in str(err.value)


def test_held_out_card_is_none_of_the_charts() -> None:
    layout, refl = held_out_card(DEFAULT_GRID)
    assert layout.n_patches == len(refl) == 28
    assert layout.patch_names[0] == "TCS01" and layout.patch_names[-1] == "VS14"
    cc = read_spectra_csv(resource_path("charts", "colorchecker_24.csv"), DEFAULT_GRID)
    for chart in (load_colorchecker_sg(DEFAULT_GRID), cc):
        dist = np.abs(refl.values[:, None, :] - chart.values[None]).max(axis=2)
        assert dist.min() > 0.01


@pytest.mark.slow
def test_cc24_and_sg_calibrate_and_estimate_the_held_out_card(tmp_path) -> None:
    result = compare_charts(tmp_path, ("colorchecker_24", "colorchecker_sg"))
    cc, sg = result.scores
    assert (cc.n_patches, sg.n_patches) == (24, 140)
    for s in (cc, sg):
        assert s.table1_rgb_mean < 0.002
        assert s.sensitivity_rms < 0.06
        assert s.de00_mean < 0.5 and s.de00_max < 1.5
    result.save(tmp_path / "c.json")
    back = load_chart_comparison(tmp_path / "c.json")
    assert back["scores"][1]["de00_mean"] == sg.de00_mean


@pytest.mark.slow
def test_demo_report_carries_the_chart_choice_and_a_rerun_reuses_it(tmp_path) -> None:
    """``tunespec demo`` (chart choice on): ``export/chart_choice.json`` with the
    CC24 and the SG, the report's section, no scratch captures left; a re-run on the
    folder reads the comparison back instead of capturing the charts again."""
    from tunespec.app.pipeline.run import run_demo

    out = tmp_path / "demo"
    result = run_demo(out, resolution=(512, 340), chart_choice=True)
    saved = out / "export" / "chart_choice.json"
    doc = json.loads(saved.read_text(encoding="utf-8"))
    assert [s["n_patches"] for s in doc["scores"]] == [24, 140]
    assert all(0.0 < s["de00_mean"] < 1.0 for s in doc["scores"])
    assert result.files["chart_choice_json"] == saved
    html = result.files["report_html"].read_text(encoding="utf-8")
    assert "Chart choice" in html and "ColorChecker 24" in html
    assert not list(out.glob("chart-choice-*"))
    stamp = saved.stat().st_mtime_ns
    again = run_demo(out, resolution=(512, 340), chart_choice=True)
    assert saved.stat().st_mtime_ns == stamp
    assert "Chart choice" in again.files["report_html"].read_text(encoding="utf-8")
