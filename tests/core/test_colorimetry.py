"""D50 colorimetry (ASTM E308, ICC white), CIEDE2000 and the Table 2 statistics."""

from __future__ import annotations

import subprocess
import sys
import warnings

import numpy as np
import pytest

from tests.tolerances import (
    ATOL_COLOUR,
    ATOL_EXACT,
    ATOL_PUBLISHED_2DP,
    ATOL_PUBLISHED_4DP,
)
from tunespec.core.colorimetry import (
    ARGYLL_TABLE_STEPS_NM,
    CMFS_NAME,
    ICC_D50_XY,
    ICC_D50_XYZ,
    ReflectanceStats,
    astm_e308_weights_d50,
    delta_e_2000,
    lab_d50,
    reflectance_stats,
    spectral_rms,
    xyz_d50,
    xyz_to_lab_d50,
)

# imported as the core imports it: colour-science changes numpy's print options
with np.printoptions():
    import colour
from tunespec.core.datasets import load_colorchecker_sg, load_training_reflectances_190
from tunespec.core.errors import InputError
from tunespec.core.spectra import Grid, Spectra

# Sharma, Wu, Dalal (2005), "The CIEDE2000 color-difference formula: implementation
# notes, supplementary test data, and mathematical observations", Color Res. Appl.
# 30(1):21-30, Table 1 (pairs 1, 2, 4, 7, 9, 11, 13, 15, 17-20, 25-34). Chosen to
# exercise the hue-angle wrap, the a' rescaling near the neutral axis and large
# differences.
SHARMA_2005 = [
    ((50.0000, 2.6772, -79.7751), (50.0000, 0.0000, -82.7485), 2.0425),
    ((50.0000, 3.1571, -77.2803), (50.0000, 0.0000, -82.7485), 2.8615),
    ((50.0000, -1.3802, -84.2814), (50.0000, 0.0000, -82.7485), 1.0000),
    ((50.0000, 0.0000, 0.0000), (50.0000, -1.0000, 2.0000), 2.3669),
    ((50.0000, 2.4900, -0.0010), (50.0000, -2.4900, 0.0009), 7.1792),
    ((50.0000, 2.4900, -0.0010), (50.0000, -2.4900, 0.0011), 7.2195),
    ((50.0000, -0.0010, 2.4900), (50.0000, 0.0009, -2.4900), 4.8045),
    ((50.0000, -0.0010, 2.4900), (50.0000, 0.0011, -2.4900), 4.7461),
    ((50.0000, 2.5000, 0.0000), (73.0000, 25.0000, -18.0000), 27.1492),
    ((50.0000, 2.5000, 0.0000), (61.0000, -5.0000, 29.0000), 22.8977),
    ((50.0000, 2.5000, 0.0000), (56.0000, -27.0000, -3.0000), 31.9030),
    ((50.0000, 2.5000, 0.0000), (58.0000, 24.0000, 15.0000), 19.4535),
    ((60.2574, -34.0099, 36.2677), (60.4626, -34.1751, 39.4387), 1.2644),
    ((63.0109, -31.0961, -5.8663), (62.8187, -29.7946, -4.0864), 1.2630),
    ((61.2901, 3.7196, -5.3901), (61.4292, 2.2480, -4.9620), 1.8731),
    ((35.0831, -44.1164, 3.7933), (35.0232, -40.0716, 1.5901), 1.8645),
    ((22.7233, 20.0904, -46.6940), (23.0331, 14.9730, -42.5619), 2.0373),
    ((36.4612, 47.8580, 18.3852), (36.2715, 50.5065, 21.2231), 1.4146),
    ((90.8027, -2.0831, 1.4410), (91.1528, -1.6435, 0.0447), 1.4441),
    ((90.9257, -0.5406, -0.9208), (88.6381, -0.8985, -0.7239), 1.5381),
    ((6.7747, -0.2908, -2.4247), (5.8714, -0.0985, -2.2286), 0.6377),
    ((2.0776, 0.0795, -1.1350), (0.9033, -0.0636, -0.5514), 0.9082),
]

#: CIE D50, 1931 2° white (ASTM E308 / CIE 15 tables, 3 decimals).
# CIE 15:2004 Table T.3, D50 with the 1931 2° observer at 1 nm (2 decimals).
D50_WHITE_PUBLISHED = np.array([96.42, 100.0, 82.51])


@pytest.fixture(scope="module")
def sg() -> Spectra:
    return load_colorchecker_sg()


def _colour_xyz(values: np.ndarray, wl: np.ndarray) -> np.ndarray:
    """colour-science's own ASTM E308 D50 XYZ, one spectrum at a time."""
    cmfs = colour.MSDS_CMFS[CMFS_NAME]
    d50 = colour.SDS_ILLUMINANTS["D50"]
    with warnings.catch_warnings():
        # colour warns when it aligns shapes, which is what it is asked to do here.
        warnings.simplefilter("ignore", colour.utilities.ColourRuntimeWarning)
        return np.array(
            [
                colour.sd_to_XYZ(
                    colour.SpectralDistribution(v, wl), cmfs, d50, method="ASTM E308"
                )
                for v in values
            ]
        )


@pytest.mark.parametrize(
    "grid",
    ["380:730:5", "400:700:10", "380:720:20", "380:780:1", "360:780:5", "385:725:10"],
)
def test_xyz_equals_colour_sd_to_xyz_astm_e308(sg: Spectra, grid: str) -> None:
    """Same settings as ArgyllCMS: ASTM E308 tables at 10/20 nm, else 1 nm."""
    g = Grid.parse(grid)
    wl = g.wavelength_nm
    # The SG data stop at 730 nm; hold the end value beyond it (as E308 does).
    values = np.stack([np.interp(wl, sg.wavelength_nm, v) for v in sg.values])
    step = 7 if g.step_nm == 1 else 5  # colour is slow at 1 nm; a subset of patches
    values = values[::step]
    if g.step_nm in ARGYLL_TABLE_STEPS_NM:  # colour's ASTM E308 path as it is
        expected = _colour_xyz(values, wl)
    else:  # 5 nm: linear interpolation to 1 nm first
        wl_1nm = np.arange(wl[0], wl[-1] + 1.0)
        on_1nm = np.stack([np.interp(wl_1nm, wl, v) for v in values])
        expected = _colour_xyz(on_1nm, wl_1nm)
    np.testing.assert_allclose(xyz_d50(values, wl), expected, rtol=0, atol=ATOL_COLOUR)


def test_other_grids_are_integrated_at_1nm_after_linear_interpolation(
    sg: Spectra,
) -> None:
    wl = np.arange(380.0, 731.0, 2.5)  # colour refuses 2.5 nm for ASTM E308
    values = np.stack([np.interp(wl, sg.wavelength_nm, v) for v in sg.values[:10]])
    wl_1nm = np.arange(380.0, 731.0)
    on_1nm = np.stack([np.interp(wl_1nm, wl, v) for v in values])
    np.testing.assert_allclose(
        xyz_d50(values, wl), _colour_xyz(on_1nm, wl_1nm), rtol=0, atol=ATOL_COLOUR
    )
    # ... and stays close to the 10 nm result of the same smooth spectra.
    diff = xyz_d50(values, wl) - xyz_d50(sg.values[:10], sg.wavelength_nm)
    assert np.abs(diff).max() < 0.05


def test_weights_are_cached_read_only_and_vectorised(sg: Spectra) -> None:
    W1 = astm_e308_weights_d50(sg.wavelength_nm)
    assert astm_e308_weights_d50(sg.wavelength_nm.copy()) is W1
    assert not W1.flags.writeable
    stacked = np.stack([sg.values[:5], sg.values[5:10]])  # (2, 5, n_wl)
    np.testing.assert_allclose(
        xyz_d50(stacked, sg.wavelength_nm),
        np.stack([xyz_d50(sg.values[:5], sg.wavelength_nm), xyz_d50(sg)[5:10]]),
        rtol=0,
        atol=ATOL_EXACT,
    )


def test_lab_equals_colour_xyz_to_lab_with_icc_white(sg: Spectra) -> None:
    xyz = xyz_d50(sg)
    icc_xy = colour.XYZ_to_xy(ICC_D50_XYZ / 100)
    np.testing.assert_allclose(
        lab_d50(sg), colour.XYZ_to_Lab(xyz / 100, icc_xy), rtol=0, atol=ATOL_COLOUR
    )
    # colour ships the same white as "ICC D50".
    np.testing.assert_allclose(
        ICC_D50_XY,
        colour.CCS_ILLUMINANTS[CMFS_NAME]["ICC D50"],
        rtol=0,
        atol=ATOL_COLOUR,
    )


def test_lab_matches_the_cie_formula_written_out(sg: Spectra) -> None:
    # CIE 15:2004 eq. 8.1-8.3, independent of colour-science.
    t = xyz_d50(sg) / ICC_D50_XYZ
    eps, kappa = 216 / 24389, 24389 / 27
    f = np.where(t > eps, np.cbrt(t), (kappa * t + 16) / 116)
    lab = np.stack(
        [116 * f[:, 1] - 16, 500 * (f[:, 0] - f[:, 1]), 200 * (f[:, 1] - f[:, 2])],
        axis=1,
    )
    np.testing.assert_allclose(lab_d50(sg), lab, rtol=0, atol=ATOL_COLOUR)


def test_delta_e_2000_equals_colour(sg: Spectra) -> None:
    rng = np.random.default_rng(0)
    lab1 = lab_d50(sg)
    lab2 = lab1 + rng.normal(0.0, 2.0, lab1.shape)
    np.testing.assert_allclose(
        delta_e_2000(lab1, lab2),
        colour.delta_E(lab1, lab2, method="CIE 2000"),
        rtol=0,
        atol=ATOL_COLOUR,
    )


def test_delta_e_2000_sharma_2005_test_data() -> None:
    lab1 = np.array([r[0] for r in SHARMA_2005])
    lab2 = np.array([r[1] for r in SHARMA_2005])
    expected = np.array([r[2] for r in SHARMA_2005])
    np.testing.assert_allclose(
        delta_e_2000(lab1, lab2), expected, rtol=0, atol=ATOL_PUBLISHED_4DP
    )
    # Symmetric, zero on the diagonal, broadcasts against one reference colour.
    np.testing.assert_allclose(
        delta_e_2000(lab2, lab1), expected, rtol=0, atol=ATOL_PUBLISHED_4DP
    )
    assert np.all(delta_e_2000(lab1, lab1) == 0.0)
    assert delta_e_2000(lab1, lab2[0]).shape == (len(SHARMA_2005),)


def test_icc_white_gives_lab_100_0_0_exactly() -> None:
    np.testing.assert_allclose(
        xyz_to_lab_d50(ICC_D50_XYZ), [100.0, 0.0, 0.0], rtol=0, atol=ATOL_EXACT
    )


def test_perfect_reflector_white_point_and_lab() -> None:
    wl = np.arange(380.0, 731.0, 5.0)
    xyz = xyz_d50(np.ones(wl.size), wl)
    # The spectral D50 white at 1 nm, as published to 2 decimals.
    np.testing.assert_allclose(
        xyz, D50_WHITE_PUBLISHED, rtol=0, atol=ATOL_PUBLISHED_2DP
    )
    assert xyz[1] == pytest.approx(100.0, abs=ATOL_EXACT)
    lab = lab_d50(np.ones(wl.size), wl)
    # L* is 100 exactly; a*, b* are the offset of the spectral D50 white from the
    # ICC PCS white, not zero: CIELAB written out for X_n/Z_n = 96.42/82.49.
    expected = [
        100.0,
        500 * (np.cbrt(xyz[0] / 96.42) - 1.0),
        200 * (1.0 - np.cbrt(xyz[2] / 82.49)),
    ]
    np.testing.assert_allclose(lab, expected, rtol=0, atol=ATOL_EXACT)
    # Frozen (colour-science 0.4.7, 380-730 nm, 1 nm): a* = 0.0066, b* = -0.0185.
    np.testing.assert_allclose(
        lab[1:], [0.0066, -0.0185], rtol=0, atol=ATOL_PUBLISHED_4DP
    )
    assert delta_e_2000(lab, [100.0, 0.0, 0.0]) < 0.03


def test_icc_white_differs_from_colour_default_d50_white_boundedly(sg: Spectra) -> None:
    # colour's default D50 is the rounded chromaticity (0.3457, 0.3585).
    default_xy = colour.CCS_ILLUMINANTS[CMFS_NAME]["D50"]
    for refl in (sg, load_training_reflectances_190()):
        lab_default = colour.XYZ_to_Lab(xyz_d50(refl) / 100, default_xy)
        d = delta_e_2000(lab_d50(refl), lab_default)
        # Measured: SG 0.0020..0.0268, 190 set 0.0020..0.0273.
        assert d.min() > 1e-3, "the ICC white must make a difference"
        assert d.max() < 0.03


def test_spectral_rms() -> None:
    a = np.array([[0.5, 0.5, 0.5, 0.5], [0.1, 0.3, 0.1, 0.3]])
    b = np.array([[0.5, 0.5, 0.5, 0.5], [0.2, 0.2, 0.2, 0.2]])
    np.testing.assert_allclose(spectral_rms(a, b), [0.0, 0.1], rtol=0, atol=ATOL_EXACT)
    with pytest.raises(InputError, match="shapes"):
        spectral_rms(a, b[:, :3])


def test_reflectance_stats_matches_by_name_and_resamples(sg: Spectra) -> None:
    names = ("A1", "E5", "N10")
    est = sg.select(names).with_values(sg.select(names).values + 0.01)
    # Reference: all 140 patches, another order, on a 1 nm grid.
    wl_1nm = np.arange(380.0, 731.0)
    order = np.random.default_rng(0).permutation(len(sg))
    ref = Spectra(
        wl_1nm,
        np.stack([np.interp(wl_1nm, sg.wavelength_nm, sg.values[i]) for i in order]),
        tuple(sg.names[i] for i in order),
        {"source": "ref.csv"},
    )
    stats = reflectance_stats(est, ref)
    assert isinstance(stats, ReflectanceStats) and stats.names == names
    np.testing.assert_allclose(stats.spectral_rms, 0.01, rtol=0, atol=ATOL_EXACT)
    expected = delta_e_2000(lab_d50(est), lab_d50(sg.select(names)))
    np.testing.assert_allclose(stats.delta_e00, expected, rtol=0, atol=ATOL_EXACT)
    assert stats.mean_delta_e00 == pytest.approx(expected.mean())
    assert stats.max_delta_e00 == pytest.approx(expected.max())
    d = stats.as_dict()
    assert set(d["patches"]) == set(names) and d["n"] == 3
    assert d["average"]["spectral_rms"] == pytest.approx(0.01)
    table = stats.format_table()
    assert table.splitlines()[0].split() == [
        "patch",
        "CIEDE2000",
        "[D50]",
        "Spectral",
        "RMS",
    ]
    assert table.splitlines()[-2].startswith("average")
    assert "0.0100" in table.splitlines()[-1]
    assert "... (2 more)" in stats.format_table(max_rows=1)


def test_reflectance_stats_errors(sg: Spectra) -> None:
    est = Spectra(sg.wavelength_nm, sg.values[:3], ("A1", "ZZ9", "QQ1"))
    ref = Spectra(sg.wavelength_nm, sg.values, sg.names, {"source": "ref.csv"})
    with pytest.raises(
        InputError, match=r"ref.csv: .*2 estimated patch\(es\) missing: ZZ9, QQ1"
    ):
        reflectance_stats(est, ref)
    with pytest.raises(InputError, match="no patches"):
        reflectance_stats(Spectra(sg.wavelength_nm, np.empty((0, 71)), ()), ref)
    bad = sg.select(["A1"]).with_values(np.full((1, 71), np.nan))
    with pytest.raises(InputError, match="non-finite"):
        reflectance_stats(bad, ref)
    short = Spectra(np.arange(400.0, 701.0, 10.0), np.ones((1, 31)), ("A1",))
    with pytest.raises(InputError, match="too short"):
        reflectance_stats(sg.select(["A1"]), short)


def test_colorimetry_input_errors() -> None:
    with pytest.raises(InputError, match="too short"):
        xyz_d50(np.ones(31), np.arange(420.0, 721.0, 10.0))
    with pytest.raises(InputError, match="needs its wavelength_nm"):
        xyz_d50(np.ones(31))
    with pytest.raises(InputError, match="does not end in"):
        xyz_d50(np.ones(30), np.arange(400.0, 701.0, 10.0))
    with pytest.raises(InputError, match="strictly increasing"):
        xyz_d50(np.ones(3), [400.0, 700.0, 550.0])
    # NaN propagates per spectrum (never raises, never hangs).
    wl = np.arange(400.0, 701.0, 10.0)
    out = xyz_d50(np.stack([np.full(31, np.nan), np.ones(31)]), wl)
    assert np.isnan(out[0]).all() and np.isfinite(out[1]).all()


def test_importing_colorimetry_keeps_numpy_print_options() -> None:
    # colour-science sets numpy's legacy="1.13" printing when imported; the core must
    # not change how arrays print elsewhere (reports, doctests). A fresh interpreter,
    # since colour is already imported here.
    code = (
        "import numpy as np\n"
        "from tunespec.core import colorimetry, datasets\n"
        "datasets.load_training_reflectances_190()\n"
        "print(np.get_printoptions()['legacy'], repr(np.array([1.0])))\n"
    )
    assert _fresh_interpreter(code) == ["False", "array([1.])"]


def test_colour_imported_without_its_plotting() -> None:
    # the D50 weights need colour but not colour.plotting (matplotlib's pyplot, half
    # of colour's import); colour.plotting is still importable afterwards
    code = (
        "import sys\n"
        "import numpy as np\n"
        "from tunespec.core.colorimetry import astm_e308_weights_d50\n"
        "w = astm_e308_weights_d50(np.arange(400.0, 701.0, 5.0))\n"
        "print(round(float(w[:, 1].sum()), 6), 'matplotlib' in sys.modules)\n"
        "import colour.plotting\n"
        "import colour\n"
        "print(callable(colour.plotting.plot_single_sd), 'matplotlib' in sys.modules)\n"
    )
    assert _fresh_interpreter(code) == ["100.0", "False", "True", "True"]


def _fresh_interpreter(code: str) -> list[str]:
    """What ``code`` prints in a fresh interpreter (colour is imported here), split."""
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout.split()
