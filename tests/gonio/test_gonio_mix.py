"""The session's single-shot mix: plain D50 match or camera-tuned (plan ``mix``)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tunespec.app.cli import main
from tunespec.app.pipeline.gonio import GonioPlan, default_plan
from tunespec.app.pipeline.gonio_bench import run_gonio_demo
from tunespec.core.errors import InputError
from tunespec.core.io.spectral import read_spectra_csv


def test_plan_carries_the_mix_and_rejects_an_unknown_one(tmp_path):
    plan = default_plan(6, mix="camera")
    plan.save(tmp_path / "p.json")
    assert GonioPlan.load(tmp_path / "p.json").mix == "camera"
    doc = plan.to_dict()
    del doc["mix"]  # plans written before the option: the plain match
    (tmp_path / "old.json").write_text(json.dumps(doc))
    assert GonioPlan.load(tmp_path / "old.json").mix == "d50"
    doc["mix"] = "D65"
    (tmp_path / "bad.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match=r"bad.json: mix: expected one of d50, camera"):
        GonioPlan.load(tmp_path / "bad.json")
    with pytest.raises(InputError, match="mix: expected"):
        default_plan(4, mix="eye")
    assert main(["gonio-plan", "-o", str(tmp_path / "c.json"), "--mix", "camera"]) == 0
    assert GonioPlan.load(tmp_path / "c.json").mix == "camera"


@pytest.mark.slow
def test_camera_tuned_mix_is_not_worse_than_the_d50_match(tmp_path):
    plan = default_plan(6)
    out = {}
    for kind in ("d50", "camera"):
        folder = tmp_path / kind
        out[kind] = run_gonio_demo(folder, n_geometries=6, mix=kind, seed=1)
        doc = json.loads((folder / "mix.json").read_text())
        assert doc["mix"] == kind and len(doc["levels"]) == 22
        # the reported spectrum is kept with the capture, and is a D50 simulator
        spd = read_spectra_csv(folder / doc["measured_spd"])
        assert spd.values.max() > 0 and doc["measured"]["delta_uv"] < 1e-3
        assert doc["measured"]["cri_ra"] > 90
    doc = json.loads((tmp_path / "camera" / "mix.json").read_text())
    cam = doc["camera_mix"]
    # the optimiser's own figure: the camera is closer to colorimetric (noise-free)
    assert cam["camera_rms_deab"] < 0.8 * cam["camera_rms_deab_d50_match"]
    assert cam["metamerism_de00"] <= 0.5 + 1e-6 and cam["delta_uv"] < 1e-5
    assert not np.allclose(doc["levels"], doc["d50_match"]["levels"])
    # measured on the bench at the single-shot-only geometries (seed 1, 6 geometries):
    # single-shot XYZ mean dE00 0.385 (D50 match) -> 0.313 (camera-tuned)
    d50, camera = out["d50"], out["camera"]
    assert camera["mix"] == "camera" and d50["mix"] == "d50"
    ss_d50, ss_cam = (
        d50["de00_single_shot_fused_mean"],
        camera["de00_single_shot_fused_mean"],
    )
    assert ss_cam <= ss_d50  # not worse ...
    assert ss_cam <= 0.9 * ss_d50  # ... and on this bench, better
    assert camera["de00_fused_mean"] <= 0.5
    assert len(plan.steps) == camera["n_geometries"]


def test_demo_refuses_another_mix_on_resume(tmp_path, capsys):
    folder = tmp_path / "s"
    folder.mkdir()
    default_plan(4).save(folder / "plan.json")
    args = ["gonio-demo", "--out", str(folder), "--resume", "--mix", "camera"]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "uses the d50 mix" in err[0]
