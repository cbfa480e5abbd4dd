"""Camera transforms from sensitivities: CCMs, the ACES IDT, the LED mix, rawtoaces JSON."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tunespec.core.characterisation import (
    aces_idt,
    colour_correction_matrix,
    illuminant_mix,
    standard_illuminant,
)
from tunespec.core.colorimetry import _colour
from tunespec.core.datasets import (
    load_camera,
    load_colorchecker_sg,
    load_led_set,
    load_training_reflectances_190,
)
from tunespec.core.io.export import sensitivity_rawtoaces_document
from tunespec.core.spectra import Grid, Spectra

DATA = Path(__file__).parent.parent / "data"
GRID = Grid(380.0, 730.0, 5.0)
FULL = Grid(300.0, 830.0, 5.0)


def _luther_camera() -> tuple[Spectra, np.ndarray]:
    """A camera whose sensitivities are a linear mix of the CIE 1931 CMFs."""
    c = _colour().MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    wl = GRID.wavelength_nm
    cmfs = np.stack([np.interp(wl, c.wavelengths, c.values[:, k]) for k in range(3)])
    A = np.array(
        [[1.2, 0.3, 0.0], [0.1, 1.0, 0.05], [0.0, 0.05, 0.8]]
    )  # R, B peak above G
    return Spectra(wl, A @ cmfs, ("R", "G", "B")), A


def test_ccm_of_a_luther_camera_is_exact() -> None:
    sens, _ = _luther_camera()
    sg = load_colorchecker_sg(GRID)
    test = load_training_reflectances_190(GRID)
    ccm = colour_correction_matrix(sens, standard_illuminant("D65", FULL), sg, test)
    assert ccm.training["mean_de00"] < 1e-6 and ccm.test["max_de00"] < 1e-6
    assert ccm.training["n"] == 140 and ccm.test["n"] == 190


def test_ccm_preserves_the_white_and_has_real_errors() -> None:
    sens = load_camera()
    sg = load_colorchecker_sg(GRID)
    test = load_training_reflectances_190(GRID)
    d50 = standard_illuminant("D50", FULL)
    ccm = colour_correction_matrix(sens, d50, sg, test)
    colour = _colour()
    d50_xy = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D50"]
    white = colour.xy_to_XYZ(d50_xy)
    xyz_white = ccm.matrix @ np.ones(3)
    np.testing.assert_allclose(xyz_white, white, atol=2e-3)  # 5 nm vs colour's 1 nm
    assert 0.3 < ccm.training["mean_de00"] < 2.0  # a real camera is not colorimetric
    assert ccm.test["mean_de00"] > ccm.training["mean_de00"]  # unseen reflectances


def test_aces_idt_is_exact_for_a_luther_camera() -> None:
    sens, _ = _luther_camera()
    sg = load_colorchecker_sg(GRID)
    idt = aces_idt(sens, standard_illuminant("D55", FULL), sg)
    assert idt.training["mean_de00"] < 0.05 and idt.test["mean_de00"] < 0.05
    real = aces_idt(load_camera(), standard_illuminant("D55", FULL), sg)
    assert 0.3 < real.training["mean_de00"] < 3.0
    # the published RAW to ACES v1 matrix's neighbourhood for a Canon 5D: white
    # balance multipliers of order (2, 1, 1.5) and rows summing to 1
    np.testing.assert_allclose(real.matrix.sum(axis=1), 1.0, atol=1e-6)
    assert real.white_balance[1] == 1.0 and real.white_balance[0] > 1.0


def test_illuminant_mix_recovers_known_weights() -> None:
    leds = load_led_set(Grid(380.0, 730.0, 1.0))
    w_true = np.zeros(len(leds))
    w_true[[2, 7, 12, 18]] = [0.5, 1.0, 0.25, 2.0]
    target = Spectra(leds.wavelength_nm, (w_true @ leds.values)[None], ("T",))
    w, mismatch = illuminant_mix(leds, target)
    scale = w.sum() / w_true.sum()
    np.testing.assert_allclose(w / scale, w_true, atol=1e-8)
    assert mismatch < 1e-10


def test_rawtoaces_json_validates_against_the_schema() -> None:
    jsonschema = pytest.importorskip("jsonschema")
    schema = json.loads((DATA / "rawtoaces_schema_1.0.0.json").read_text())
    doc = sensitivity_rawtoaces_document(load_camera(), created="2026-01-02T03:04:05Z")
    validator = jsonschema.Draft4Validator(schema)
    assert not list(validator.iter_errors(doc))
    bad = {**doc, "spectral_data": {**doc["spectral_data"], "units": "watts"}}
    assert list(validator.iter_errors(bad))
