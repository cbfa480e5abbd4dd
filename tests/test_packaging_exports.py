"""packaging/check_exports.py, which the bundle's smoke test runs on the built app's
exports: files are told by content (issue 29: the rawtoaces JSON, not its side file)
and a broken export fails it."""

from __future__ import annotations

import importlib.util
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from tunespec.core.datasets import load_camera
from tunespec.core.io.cgats import write_cgats
from tunespec.core.io.export import reflectance_ti3, write_sensitivity_json
from tunespec.core.io.spectral_csv import write_spectra_csv
from tunespec.core.spectra import Grid, Spectra

ROOT = Path(__file__).resolve().parents[1]

pytest.importorskip("jsonschema")


def _checker():
    spec = importlib.util.spec_from_file_location(
        "check_exports", ROOT / "packaging" / "check_exports.py"
    )
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _sensitivities(folder: Path) -> None:
    cam = load_camera(grid=Grid(380.0, 780.0, 5.0))
    write_sensitivity_json(
        cam, folder / "sensitivities.json", created="2026-01-02T03:04:05Z"
    )
    # the side file comes first in a name pattern's order: the failure
    (folder / "sensitivities.json.meta.json").write_text(
        json.dumps({"spd_shift_nm": 0.25, "grid": "380:780:5"})
    )


def _reflectances(folder: Path, *, shift: float = 0.0) -> None:
    wl = np.arange(380.0, 781.0, 5.0)
    values = np.stack([0.2 + 0.5 * (wl - 380) / 400, 0.6 - 0.4 * (wl - 380) / 400])
    refl = Spectra(wl, values, ("P1", "P2"))
    write_spectra_csv(refl, folder / "reflectances.csv")
    write_cgats(
        reflectance_ti3(refl.with_values(refl.values + shift)),
        folder / "reflectances.ti3",
    )


def test_a_sound_folder_passes_and_the_json_is_told_by_content(
    tmp_path, capsys
) -> None:
    check = _checker()
    _sensitivities(tmp_path)
    _reflectances(tmp_path)
    (tmp_path / "exports.json").write_text(
        json.dumps({k: k for k in sorted(p.name for p in tmp_path.iterdir())})
    )
    assert check.check_folder(tmp_path) == []
    out = capsys.readouterr().out
    assert "ok   sensitivities.json: rawtoaces JSON (schema 1.0.0" in out
    assert "ok   sensitivities.json.meta.json: side file of sensitivities.json" in out
    assert "reflectances.csv = reflectances.ti3" in out


def test_a_broken_rawtoaces_json_fails_whatever_its_name(tmp_path) -> None:
    check = _checker()
    _sensitivities(tmp_path)
    doc = json.loads((tmp_path / "sensitivities.json").read_text())
    doc["spectral_data"]["units"] = "watts"
    (tmp_path / "camera.json").write_text(json.dumps(doc))
    (tmp_path / "sensitivities.json").unlink()
    (tmp_path / "sensitivities.json.meta.json").unlink()
    (failure,) = check.check_folder(tmp_path)
    assert "camera.json: rawtoaces schema 1.0.0" in failure


def test_each_kind_of_damage_is_named(tmp_path) -> None:
    check = _checker()
    _reflectances(tmp_path, shift=0.01)  # .ti3 and .csv disagree by 1 %
    (tmp_path / "exports.json").write_text(json.dumps({"a": "gone.csv"}))
    (tmp_path / "notes.xyz").write_text("what is this")
    (tmp_path / "empty.csv").write_text("")
    (tmp_path / "report.pdf").write_bytes(b"%PDF-1.4\n1 0 obj\n")  # cut short
    shutil.copy(ROOT / "resources" / "icons" / "tunespec-16.png", tmp_path / "p.png")
    with (tmp_path / "p.png").open("r+b") as fh:
        fh.truncate(60)
    failures = "\n".join(check.check_folder(tmp_path))
    assert "reflectances.csv and reflectances.ti3 differ by 0.01" in failures
    assert "not written ['gone.csv']" in failures
    assert "notes.xyz: no reader for notes.xyz" in failures
    assert "empty.csv: empty file" in failures
    assert "report.pdf: no PDF trailer" in failures
    assert "p.png:" in failures
    assert check.main([str(tmp_path)]) == 1
