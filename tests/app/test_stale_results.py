"""A saved calibration or estimate is not restored once its frames were retaken."""

from __future__ import annotations

import json

from tests.core.test_session import LAYOUT, _commit, _settings
from tunespec.app.pipeline import folder as m
from tunespec.core.io.session import Session


def test_saved_results_are_dropped_when_their_session_changed(tmp_path, caplog) -> None:
    s = Session.create(tmp_path / m.CHART_DIR, settings=_settings(), layout=LAYOUT)
    for spec in s.plan():
        _commit(s, spec)
    doc = {"session_fingerprint": s.fingerprint()}
    assert m._is_current(doc, tmp_path / m.CHART_DIR, "calibration")
    assert m._is_current({}, tmp_path / m.CHART_DIR, "calibration")  # older files
    s.mark_bad("target_L1", "retake")
    assert not m._is_current(doc, tmp_path / m.CHART_DIR, "calibration")
    # the same through the reader: a stale calibration.json restores nothing
    folder = tmp_path / m.CALIBRATION_DIR
    folder.mkdir()
    (folder / "calibration.json").write_text(json.dumps(doc))
    caplog.clear()
    assert m.read_calibration(folder, tmp_path / m.CHART_DIR) is None
    assert "since been retaken" in caplog.text
