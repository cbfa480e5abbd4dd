"""Data of the generalisation benchmark: cameras, light sources and test reflectances
that the calibration was never tuned on, and the spectroradiometer's metering error.

Everything is rendered on a 1 nm grid (380-730 nm), close to the continuous Eq. 1.

Camera families (each camera carries the database cameras the estimator must not see):

``rawtoaces:<source>``
    The shipped rawtoaces-data cameras, grouped by who measured them (the
    ``document_creator`` of their headers: wetadigital, scitech, Jonathon Irons). A
    camera is scored with its *whole source* removed from the database
    (leave-one-source-out), so nothing measured by the same lab helps.
``colour-science``
    ``colour.MSDS_CAMERA_SENSITIVITIES``, measured at the National Physical Laboratory
    (NPL): the Foveon-type Sigma SD Merrill. Its Nikon 5100 is the shipped Nikon D5100
    (the same NPL measurement, equal to 5e-10), so it is left out here and scored as
    that one, its source removed; the Sigma is scored without the database's NPL
    cameras (leave-one-laboratory-out).
``synthetic:*``
    Cameras outside the database's span, seeded: ``shifted`` (a shipped camera with
    each channel moved by 10-20 nm either way), ``narrow`` (Gaussian sigma 20-28 nm,
    about 2/3 of a typical camera's band width; narrower bands leave spectral gaps
    that no estimate, not even the true sensitivities, bridges) and ``broad`` bands,
    ``overlap`` (strongly overlapping channels), ``ircut`` (a phone-like steep IR-cut
    filter at 620-650 nm and a UV cut), ``lobes`` (secondary lobes: red in the blue,
    blue in the red). Derived cameras exclude their parent from the database.

Light sources: ``cal1-model`` (the shipped 22-LED model, Ohno 2005 shapes) and
``heldout-leds``, 20 narrowband LEDs of another shape (skewed Gaussians, other peaks,
17-39 nm FWHM as commercial narrowband LEDs) and two whites with other phosphors,
not shipped and not used anywhere else in the project.

Test reflectances (not the calibration chart, not the Wiener prior): the 190
rawtoaces training reflectances, the 99 CIE 2017 colour-fidelity samples (TM-30), the
14 CIE 1995 test colour samples (CRI) and the 15 NIST CQS 9.0 samples.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from tunespec.core.datasets import (
    _raw_camera_database,
    load_colorchecker_sg,
    load_led_set,
    load_training_reflectances_190,
    resource_path,
)
from tunespec.core.responses import Responses
from tunespec.core.spectra import Grid, Spectra

FINE = Grid(380.0, 730.0, 1.0)
WL = FINE.wavelength_nm
FAMILIES = (
    "rawtoaces:wetadigital",
    "rawtoaces:scitech",
    "rawtoaces:Jonathon Irons",
    "colour-science",
    "synthetic:shifted",
    "synthetic:narrow",
    "synthetic:broad",
    "synthetic:overlap",
    "synthetic:ircut",
    "synthetic:lobes",
)


@dataclass(frozen=True)
class Camera:
    """One camera of the benchmark: its true sensitivities and what to hide."""

    name: str
    family: str
    truth: Spectra  # (3, n) on FINE, peak 1
    exclude: tuple[str, ...]  # database cameras the estimator must not use


def _norm(values: np.ndarray) -> np.ndarray:
    v = np.clip(values, 0.0, None)
    return v / v.max()


def _spectra(values: np.ndarray, source: str) -> Spectra:
    return Spectra(
        WL, _norm(np.asarray(values, dtype=float)), ("R", "G", "B"), {"source": source}
    )


@lru_cache(maxsize=1)
def _headers() -> dict[str, dict]:
    """Shipped camera name -> its rawtoaces-data header."""
    out = {}
    for f in sorted(resource_path("cameras").glob("*.json")):
        h = json.loads(f.read_text(encoding="utf-8"))["header"]
        out[f"{h.get('manufacturer', '')} {h.get('model', '')}".strip()] = h
    return out


def _sources() -> dict[str, str]:
    """Shipped camera name -> who measured it."""
    return {
        n: str(h.get("document_creator") or h.get("laboratory") or "unknown")
        for n, h in _headers().items()
    }


def _skewed(peak: float, left: float, right: float) -> np.ndarray:
    sig = np.where(peak > WL, left, right)
    return np.exp(-0.5 * ((WL - peak) / sig) ** 2)


def shipped_cameras() -> list[Camera]:
    """The rawtoaces-data cameras, each excluding its whole measuring source."""
    src = _sources()
    db = _raw_camera_database()
    out = []
    for name, s in db.items():
        source = src.get(name, "unknown")
        same = tuple(n for n in db if src.get(n, "unknown") == source)
        out.append(
            Camera(
                name,
                f"rawtoaces:{source}",
                _spectra(s.resample(FINE).values, name),
                same,
            )
        )
    return out


#: The laboratory that measured colour-science's camera sensitivities.
COLOUR_LABORATORY = "National Physical Laboratory"
#: Largest difference (of curves scaled to peak 1) at which two sets are one measurement.
SAME_MEASUREMENT = 1e-6


def colour_cameras() -> list[Camera]:
    """colour-science's measured camera sensitivities, zero outside their range: those
    the shipped database does not already hold, each scored without the database's
    cameras from the same laboratory."""
    with np.printoptions():
        import colour
    shipped = [s.truth.values for s in shipped_cameras()]
    same_lab = tuple(
        n for n, h in _headers().items() if h.get("laboratory") == COLOUR_LABORATORY
    )
    out = []
    for name, msds in colour.MSDS_CAMERA_SENSITIVITIES.items():
        wl = np.asarray(msds.wavelengths, dtype=float)
        vals = np.asarray(msds.values, dtype=float).T  # red, green, blue
        fine = _spectra(
            np.stack([np.interp(WL, wl, v, left=0.0, right=0.0) for v in vals]), name
        )
        if not any(np.abs(fine.values - v).max() < SAME_MEASUREMENT for v in shipped):
            out.append(Camera(name, "colour-science", fine, same_lab))
    return out


def synthetic_cameras(n_per_family: int = 6, seed: int = 2026) -> list[Camera]:
    """Seeded cameras outside the database's span (see the module docstring)."""
    rng = np.random.default_rng(seed)
    db = {n: s.resample(FINE).values for n, s in _raw_camera_database().items()}
    names = sorted(db)
    out: list[Camera] = []
    for j in range(n_per_family):
        tag = f"{j + 1:02d}"
        # shifted: each channel of a shipped camera moved by 10-20 nm either way
        parent = names[rng.integers(len(names))]
        d = rng.uniform(10, 20, 3) * rng.choice([-1, 1], 3)
        vals = np.stack(
            [np.interp(WL - d[k], WL, db[parent][k], left=0, right=0) for k in range(3)]
        )
        out.append(
            Camera(
                f"shifted-{tag}", "synthetic:shifted", _spectra(vals, parent), (parent,)
            )
        )
        # narrow and broad bands
        peaks = np.array([600.0, 535.0, 455.0]) + rng.uniform(-12, 12, 3)
        w = rng.uniform(20, 28, (3, 2))
        vals = np.stack(
            [_skewed(peaks[k], *w[k]) * rng.uniform(0.6, 1.0) for k in range(3)]
        )
        out.append(
            Camera(f"narrow-{tag}", "synthetic:narrow", _spectra(vals, "narrow"), ())
        )
        w = rng.uniform(45, 70, (3, 2))
        vals = np.stack(
            [_skewed(peaks[k], *w[k]) * rng.uniform(0.6, 1.0) for k in range(3)]
        )
        out.append(
            Camera(f"broad-{tag}", "synthetic:broad", _spectra(vals, "broad"), ())
        )
        # strong overlap: peaks close together, wide bands
        peaks = np.array([575.0, 530.0, 485.0]) + rng.uniform(-8, 8, 3)
        w = rng.uniform(30, 45, (3, 2))
        vals = np.stack([_skewed(peaks[k], *w[k]) for k in range(3)])
        out.append(
            Camera(f"overlap-{tag}", "synthetic:overlap", _spectra(vals, "overlap"), ())
        )
        # phone-like: a steep IR cut (and a UV cut) on a shipped camera
        parent = names[rng.integers(len(names))]
        cut_ir, cut_uv = rng.uniform(620, 650), rng.uniform(400, 420)
        filt = 1 / (1 + np.exp((WL - cut_ir) / rng.uniform(4, 8)))
        filt *= 1 / (1 + np.exp(-(WL - cut_uv) / 4))
        out.append(
            Camera(
                f"ircut-{tag}",
                "synthetic:ircut",
                _spectra(db[parent] * filt, parent),
                (parent,),
            )
        )
        # secondary lobes
        parent = names[rng.integers(len(names))]
        vals = db[parent] / db[parent].max(axis=1, keepdims=True)
        vals = vals + np.stack(
            [
                rng.uniform(0.1, 0.3) * _skewed(rng.uniform(425, 455), 15, 20),
                rng.uniform(0.05, 0.15) * _skewed(rng.uniform(420, 450), 15, 15),
                rng.uniform(0.05, 0.15) * _skewed(rng.uniform(610, 680), 20, 25),
            ]
        )
        out.append(
            Camera(f"lobes-{tag}", "synthetic:lobes", _spectra(vals, parent), (parent,))
        )
    return out


def all_cameras(n_synthetic: int = 6, seed: int = 2026) -> list[Camera]:
    return [
        *shipped_cameras(),
        *colour_cameras(),
        *synthetic_cameras(n_synthetic, seed),
    ]


def cameras_per_family(per_family: int, families: str | None = None) -> list[Camera]:
    """:func:`all_cameras`, at most ``per_family`` of each family (in their order);
    ``families``: only these (comma-separated)."""
    wanted = None if not families else set(families.split(","))
    seen: dict[str, int] = {}
    picked = []
    for c in all_cameras():
        if wanted is not None and c.family not in wanted:
            continue
        if seen.get(c.family, 0) < per_family:
            picked.append(c)
            seen[c.family] = seen.get(c.family, 0) + 1
    return picked


def light_sources() -> dict[str, Spectra]:
    """``cal1-model`` (shipped) and ``heldout-leds`` (built here only), on FINE."""
    rng = np.random.default_rng(7)
    peaks = np.linspace(415.0, 695.0, 20) + rng.uniform(-4, 4, 20)
    rows, names = [], []
    for p in peaks:
        fwhm = 20.0 + 16.0 * (1.0 - abs(p - 560.0) / 140.0) ** 2 + rng.uniform(-3, 3)
        sig = fwhm / 2.355
        skew = rng.uniform(0.7, 1.4)
        rows.append(_skewed(p, sig * skew, sig / skew))
        names.append(f"H{round(p)}")
    for pump, phos, width, name in (
        (452.0, 555.0, 55.0, "HWHITE_C"),
        (448.0, 605.0, 60.0, "HWHITE_W"),
    ):
        rows.append(0.6 * _skewed(pump, 9, 11) + _skewed(phos, width, width * 1.3))
        names.append(name)
    held = Spectra(WL, np.array(rows), tuple(names), {"source": "heldout-leds"})
    return {"cal1-model": load_led_set(FINE), "heldout-leds": held}


@lru_cache(maxsize=1)
def test_reflectances() -> Spectra:
    """318 reflectances from four collections, none of them the chart or the prior."""
    with np.printoptions():
        import colour
        from colour.quality.cfi2017 import load_TCS_CIE2017
        from colour.quality.datasets import SDS_TCS, SDS_VS

    shape = colour.SpectralShape(380, 730, 1)
    parts = [load_training_reflectances_190(FINE)]
    ces = load_TCS_CIE2017(colour.SpectralShape(380, 780, 5))
    vals = np.stack(
        [np.interp(WL, ces.wavelengths, v) for v in np.asarray(ces.values).T]
    )
    parts.append(Spectra(WL, vals, tuple(f"CES{j + 1:02d}" for j in range(len(vals)))))
    for label, sds in (("TCS", SDS_TCS["CIE 1995"]), ("VS", SDS_VS["NIST CQS 9.0"])):
        vals = np.stack([sd.copy().align(shape).values for sd in sds.values()])
        parts.append(Spectra(WL, vals, tuple(f"{label}-{k}" for k in sds)))
    names = tuple(n for p in parts for n in p.names)
    return Spectra(WL, np.clip(np.vstack([p.values for p in parts]), 0.0, 1.0), names)


def chart() -> Spectra:
    return load_colorchecker_sg(FINE)


def metering_error(
    leds: Spectra,
    rng: np.random.Generator,
    *,
    shift_max_nm: float = 1.0,
    gain_sigma: float = 0.01,
) -> tuple[Spectra, np.ndarray, np.ndarray]:
    """What the spectroradiometer reports: each LED shifted by its own U(-max, max) nm
    and scaled by its own N(1, gain_sigma) gain. Returns (reported, shifts, gains)."""
    n = len(leds)
    shifts = rng.uniform(-shift_max_nm, shift_max_nm, n)
    gains = 1.0 + gain_sigma * rng.standard_normal(n)
    vals = np.stack(
        [
            np.interp(WL - d, WL, v) * g
            for v, d, g in zip(leds.values, shifts, gains, strict=True)
        ]
    )
    return leds.with_values(vals), shifts, gains


def metering_noise(
    reported: Spectra,
    rng: np.random.Generator,
    floor_rel: float | np.ndarray,
    reads: int = 2,
) -> Spectra:
    """Each reported spectrum read ``reads`` times with Gaussian noise of ``floor_rel``
    of its peak (one for all, or (n, 1): one a spectrum), every reading clipped at zero (as the simulated CAL1's
    spectroradiometer), and the readings averaged (as capture does around a frame)."""
    v = reported.values
    sd = floor_rel * v.max(axis=1, keepdims=True)
    reads_ = [
        np.maximum(v + sd * rng.standard_normal(v.shape), 0.0) for _ in range(reads)
    ]
    return reported.with_values(np.mean(reads_, axis=0))


def report_at(leds: Spectra, step_nm: float, *, slit: bool = False) -> Spectra:
    """What a spectroradiometer that reports every ``step_nm`` gives over the fine
    grid's range: the spectrum's values at those wavelengths, or with ``slit``
    through a triangular slit of full width at half maximum ``step_nm`` (the hat
    kernels of :meth:`Spectra.resample` with ``average=True``). ``step_nm`` 1
    returns the spectra as they are."""
    if step_nm <= FINE.step_nm:
        return leds
    return leds.resample(Grid(FINE.start_nm, FINE.end_nm, step_nm), average=slit)


def systematic_effects(
    responses: Responses,
    rng: np.random.Generator,
    *,
    stray: float = 0.002,
    crosstalk: float = 0.002,
    nonlinearity: float = 1.003,
) -> Responses:
    """Sensor effects that photon and read noise do not describe, on top of the
    flat-field residual that :class:`~tunespec.core.simulate.NoiseModel` draws:

    - stray light: each patch under each LED gains ``stray * z`` of the mean
      response under that LED (``z ~ N(0, 1)``, one draw per patch and LED);
    - cross-talk: each channel gains ``crosstalk * z`` of the patch's mean over the
      other two channels (one draw per patch, LED and channel);
    - a slight non-linearity: ``signal ** nonlinearity`` (full-scale units).

    ``rgb_std`` is left as the noise model gave it: the product is not told."""
    rgb = responses.rgb
    level = rgb.mean(axis=0, keepdims=True)
    out = rgb + stray * rng.standard_normal(rgb.shape[:2])[..., None] * level
    others = (rgb.sum(axis=2, keepdims=True) - rgb) / 2.0
    out = out + crosstalk * rng.standard_normal(rgb.shape) * others
    out = np.maximum(out, 0.0) ** nonlinearity
    return replace(responses, rgb=out)
