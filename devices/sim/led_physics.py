"""Physics of a CAL1-like LED light source, shared by the simulator and the emulator.

:class:`LedPhysics` is one simulated *unit*: 22 LED channels (or any LED spectral CSV)
with seeded per-unit variation, thermal warm-up, slow drift, and an internal
spectroradiometer with its own wavelength grid, calibration offset and noise. Both
:class:`~tunespec.devices.sim.light.SimLightSource` and
:class:`~tunespec.devices.cal1.emulator.Cal1Emulator` drive one, so a simulated camera
can ask either for the truth (:meth:`LedPhysics.emitted_spd`).

Model (all parameters in :class:`LedPhysicsParams`)
--------------------------------------------------
Emitted spectral radiance at time ``t``::

    L(λ, t) = L_peak * Σ_k level_k * g_k(t) * s_k(λ - δ_k(t))

- ``s_k``: nominal relative SPD of channel ``k`` (strongest LED peak = 1).
- ``L_peak``: :data:`PEAK_RADIANCE_W_SR_M2_NM`, the radiance of a perfect white
  Lambertian diffuser in the sample plane at ~70 cm under the strongest LED at full
  level (see the constant for the plausibility argument).
- ``g_k(t) = a_k * (1 + c_k ΔT_k(t)) * (1 + A_k sin(2π t / P_k + φ_k))``: unit gain
  ``a_k`` (uniform within ±5 %), thermal droop ``c_k`` (per K, wavelength-dependent:
  about -0.1 %/K for blue InGaN, -0.8 %/K for amber AlInGaP) and a slow seeded drift
  (0.1-0.2 % over 30-120 min).
- ``δ_k(t) = d_k + e_k ΔT_k(t)``: unit peak shift ``d_k`` (normal, sd 0.75 nm,
  clipped at ±2 nm) and thermal red shift ``e_k`` (0.03-0.14 nm/K).
- ``ΔT_k = T_case + J_k - T_ref``: the junction temperature above the reference at
  which the nominal SPDs hold. ``T_case`` warms after power-on (electronics,
  exponential, τ = 600 s) and with the total LED load (τ = 300 s); the junction rise
  ``J_k`` follows ``level_k`` (τ = 20 s). Levels are piecewise constant in time,
  so each of these is an exact exponential between level changes, and the history
  of changes lets the SPD be evaluated (and integrated) at any past time.

The internal spectroradiometer reports at its nominal wavelength ``λ`` the emitted
radiance at ``λ + δ_m`` (unit calibration offset ``δ_m``, sd 0.5 nm) seen through a
Gaussian band-pass (2.5 nm FWHM), averaged over its integration time, plus noise of
standard deviation ``sqrt((0.7 % * M)^2 + (0.1 % * max M)^2 + dark^2)``, clipped at 0.

Time comes from a :class:`~tunespec.devices.clock.Clock` (a ``VirtualClock`` in tests,
so nothing waits). Seeded: the unit (``seed``) and the metering noise stream are
reproducible. Thread-safe (the emulator serves from its own thread).
"""

from __future__ import annotations

import bisect
import itertools
import math
import re
import threading
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tunespec.core.datasets import load_led_set
from tunespec.core.spectra import Grid, Spectra
from tunespec.devices.clock import Clock, VirtualClock
from tunespec.devices.protocols import Channel, LightStatus

__all__ = [
    "LED_GRID",
    "METER_GRID",
    "PEAK_RADIANCE_W_SR_M2_NM",
    "RADIANCE_UNIT",
    "LedPhysics",
    "LedPhysicsParams",
    "UnitVariation",
    "channels_from_spectra",
    "validate_levels",
]

RADIANCE_UNIT = "W sr^-1 m^-2 nm^-1"

#: Spectral radiance of the strongest nominal LED peak at full level, in
#: W sr^-1 m^-2 nm^-1, as seen on a perfect white Lambertian diffuser in the sample
#: plane ~70 cm from the CAL1 (irradiance E = π L ≈ 3e-3 W m^-2 nm^-1 at the peak,
#: ~0.1 W m^-2 over a 30 nm wide LED). Plausibility: a green LED at this level gives a
#: white patch ~10 cd/m²; a 5D Mark III at ISO 100, f/8 then needs seconds to reach
#: full scale, the order of the paper's 6 s exposures for the narrowband LEDs.
PEAK_RADIANCE_W_SR_M2_NM = 1.0e-3

#: Grid the shipped LED model is read on (its native 1 nm sampling).
LED_GRID = Grid(360.0, 780.0, 1.0)
#: Wavelengths of the internal spectroradiometer.
METER_GRID = Grid(380.0, 780.0, 1.0)

_SEGMENTS_KEPT = 4096
# Gauss-Legendre nodes on [0, 1] for integrating the SPD between level changes
# (smooth exponentials and sines: 4 nodes are exact to far below the noise).
_GL_X, _GL_W = np.polynomial.legendre.leggauss(4)
_GL_X = 0.5 * (_GL_X + 1.0)
_GL_W = 0.5 * _GL_W


@dataclass(frozen=True)
class LedPhysicsParams:
    """Parameters of :class:`LedPhysics` (defaults: a plausible CAL1-like unit).

    Temperatures in °C or K, times in s, radiance in W sr^-1 m^-2 nm^-1. Fractions
    (``gain_spread``, ``drift_amplitude``, ``meter_noise_*``) are relative.
    ``thermal_scale`` multiplies all thermal coefficients (0: no warm-up drift).
    """

    peak_radiance_w_sr_m2_nm: float = PEAK_RADIANCE_W_SR_M2_NM
    # per-unit variation
    peak_shift_sd_nm: float = 0.75
    peak_shift_max_nm: float = 2.0
    gain_spread: float = 0.05
    # thermal model
    thermal_scale: float = 1.0
    ambient_c: float = 23.0
    reference_c: float = 25.0
    electronics_rise_k: float = 5.0
    electronics_tau_s: float = 600.0
    load_rise_k: float = 4.0
    load_tau_s: float = 300.0
    junction_rise_k: float = 10.0
    junction_tau_s: float = 20.0
    warmup_s: float = 600.0
    # slow drift
    drift_amplitude: float = 0.002
    drift_period_min_s: float = 1800.0
    drift_period_max_s: float = 7200.0
    # internal spectroradiometer
    meter_grid: Grid = field(default=METER_GRID)
    meter_offset_sd_nm: float = 0.5
    meter_offset_max_nm: float = 1.0
    meter_bandwidth_nm: float = 2.5
    meter_noise_rel: float = 0.007
    meter_noise_floor_rel: float = 0.001
    meter_dark_noise_w_sr_m2_nm: float = 1.0e-8
    meter_integration_s: float = 0.5

    @classmethod
    def ideal(cls) -> LedPhysicsParams:
        """No unit variation, warm-up, drift, metering error or noise."""
        return cls(
            peak_shift_sd_nm=0.0,
            gain_spread=0.0,
            thermal_scale=0.0,
            warmup_s=0.0,
            drift_amplitude=0.0,
            meter_offset_sd_nm=0.0,
            meter_bandwidth_nm=0.0,
            meter_noise_rel=0.0,
            meter_noise_floor_rel=0.0,
            meter_dark_noise_w_sr_m2_nm=0.0,
        )


@dataclass(frozen=True)
class UnitVariation:
    """What makes one unit differ from the nominal model (drawn once per seed).

    Arrays have shape (n_channels,).
    """

    peak_shift_nm: NDArray[np.float64]
    gain: NDArray[np.float64]
    drift_amplitude: NDArray[np.float64]
    drift_period_s: NDArray[np.float64]
    drift_phase_rad: NDArray[np.float64]
    meter_offset_nm: float

    @classmethod
    def draw(
        cls, n_channels: int, params: LedPhysicsParams, rng: np.random.Generator
    ) -> UnitVariation:
        """Draw a unit's variation from ``rng``."""
        p = params
        shift = np.clip(
            rng.normal(0.0, 1.0, n_channels) * p.peak_shift_sd_nm,
            -p.peak_shift_max_nm,
            p.peak_shift_max_nm,
        )
        gain = 1.0 + p.gain_spread * rng.uniform(-1.0, 1.0, n_channels)
        amp = p.drift_amplitude * rng.uniform(0.5, 1.0, n_channels)
        period = rng.uniform(p.drift_period_min_s, p.drift_period_max_s, n_channels)
        phase = rng.uniform(0.0, 2.0 * np.pi, n_channels)
        offset = float(
            np.clip(
                rng.normal() * p.meter_offset_sd_nm,
                -p.meter_offset_max_nm,
                p.meter_offset_max_nm,
            )
        )
        return cls(shift, gain, amp, period, phase, offset)


def validate_levels(levels: ArrayLike, n_channels: int) -> NDArray[np.float64]:
    """Levels as a float array, checked: shape ``(n_channels,)``, finite, in [0, 1].

    Raises
    ------
    ValueError
        Saying what is wrong.
    """
    arr = np.array(levels, dtype=np.float64)
    if arr.shape != (n_channels,):
        raise ValueError(f"expected {n_channels} levels, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError("levels must be finite")
    bad = np.flatnonzero((arr < 0.0) | (arr > 1.0))
    if bad.size:
        raise ValueError(f"level {arr[bad[0]]!r} of channel {bad[0]} is outside 0..1")
    return arr


def channels_from_spectra(leds: Spectra) -> list[Channel]:
    """Channel descriptions for LED spectra.

    A channel is ``"white"`` if its name contains ``WHITE`` or its half-maximum width
    exceeds 80 nm. A narrowband channel's peak is the 3-digit number in its name
    (``LED450`` -> 450 nm, the nominal peak a device reports) if there is one, else
    the wavelength of its maximum; a white channel's peak is its maximum.
    """
    out = []
    wl = leds.wavelength_nm
    for i, (name, spd) in enumerate(zip(leds.names, leds.values, strict=True)):
        above = wl[spd >= 0.5 * spd.max()]
        width_nm = float(above[-1] - above[0]) if above.size else 0.0
        kind: Literal["narrowband", "white"] = (
            "white" if "WHITE" in name.upper() or width_nm > 80.0 else "narrowband"
        )
        peak_nm = float(wl[int(np.argmax(spd))])
        m = re.search(r"(?<!\d)(\d{3})(?!\d)", name)
        if kind == "narrowband" and m and 350 <= int(m.group(1)) <= 800:
            peak_nm = float(m.group(1))
        out.append(Channel(index=i, name=name, peak_nm=peak_nm, kind=kind))
    return out


def _thermal_coefficients(
    channels: list[Channel],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Relative output change per K and peak shift in nm per K, per channel.

    Typical datasheet values: InGaN (blue-green) loses ~0.1-0.3 %/K, AlInGaP
    (amber-red) ~0.4-0.8 %/K; peaks shift red by ~0.03-0.14 nm/K. Phosphor whites
    behave like their blue pump plus a little phosphor quenching.
    """
    peak = np.array([c.peak_nm for c in channels])
    white = np.array([c.kind == "white" for c in channels])
    droop = np.interp(
        peak,
        [400, 480, 530, 570, 590, 620, 700],
        [-0.0010, -0.0015, -0.0030, -0.0060, -0.0080, -0.0060, -0.0040],
    )
    shift = np.interp(peak, [400, 550, 580, 700], [0.03, 0.04, 0.10, 0.14])
    droop[white] = -0.002
    shift[white] = 0.03
    return droop, shift


@dataclass(frozen=True)
class _Segment:
    """Levels constant from ``t_s`` on, with the thermal state at ``t_s``."""

    t_s: float
    levels: NDArray[np.float64]
    junction_k: NDArray[np.float64]
    load_k: float
    lit_since_s: float | None


class LedPhysics:
    """One simulated CAL1-like unit: what it emits, and what its meter reports.

    Parameters
    ----------
    leds
        LED spectra (relative power, any grid; e.g. ``read_spectra_csv(FILE)``);
        default the shipped 22-LED model (:func:`~tunespec.core.datasets.load_led_set`
        on its native 1 nm grid). Normalised so the strongest peak is 1.
    clock
        Time source; default a new :class:`~tunespec.devices.clock.VirtualClock`.
    seed
        Selects the unit (variation) and its metering noise stream.
    params
        Model parameters; default :class:`LedPhysicsParams` ().
    power_on_s
        Clock time at which the unit was switched on (default: now). A time well in
        the past (e.g. ``clock.now_s() - 3600``) gives a warmed-up unit.
    """

    def __init__(
        self,
        leds: Spectra | None = None,
        *,
        clock: Clock | None = None,
        seed: int = 0,
        params: LedPhysicsParams | None = None,
        power_on_s: float | None = None,
    ) -> None:
        if leds is None:
            leds = load_led_set(LED_GRID)
        peak = float(leds.values.max())
        if not peak > 0:
            raise ValueError("LED spectra are all zero")
        self.clock: Clock = clock if clock is not None else VirtualClock()
        self.params = params if params is not None else LedPhysicsParams()
        self.seed = int(seed)
        self.channels: list[Channel] = channels_from_spectra(leds)
        self.source = leds.meta.get("source", "")
        self._wl = leds.wavelength_nm
        self._nominal = leds.values / peak
        n = len(self.channels)
        unit_seq, noise_seq = np.random.SeedSequence(self.seed).spawn(2)
        self.unit = UnitVariation.draw(n, self.params, np.random.default_rng(unit_seq))
        self._noise_rng = np.random.default_rng(noise_seq)
        droop, shift = _thermal_coefficients(self.channels)
        self._droop_per_k = droop * self.params.thermal_scale
        self._shift_nm_per_k = shift * self.params.thermal_scale
        now = self.clock.now_s()
        self.power_on_s = now if power_on_s is None else float(power_on_s)
        if self.power_on_s > now:
            raise ValueError("power_on_s lies in the future")
        self._lock = threading.RLock()
        zeros = np.zeros(n)
        self._segments = [_Segment(self.power_on_s, zeros, zeros, 0.0, None)]
        self._starts = [self.power_on_s]

    # --- state ------------------------------------------------------------------------

    @property
    def n_channels(self) -> int:
        """Number of LED channels."""
        return len(self.channels)

    @property
    def wavelength_nm(self) -> NDArray[np.float64]:
        """Wavelengths of :meth:`emitted`, shape (n_wl,)."""
        return self._wl

    @property
    def meter_wavelength_nm(self) -> NDArray[np.float64]:
        """Wavelengths the spectroradiometer reports, shape (n_meter,)."""
        return self.params.meter_grid.wavelength_nm

    def set_levels(self, levels: ArrayLike) -> None:
        """Set every channel's level (0..1) now."""
        new = validate_levels(levels, self.n_channels)
        with self._lock:
            last = self._segments[-1]
            t = max(self.clock.now_s(), last.t_s)
            junction, load = self._thermal(last, t)
            lit = bool(np.any(new > 0))
            was_lit = bool(np.any(last.levels > 0))
            since = (last.lit_since_s if was_lit else t) if lit else None
            seg = _Segment(t, new, junction, load, since)
            if t == last.t_s and len(self._segments) > 1:
                self._segments[-1] = seg  # same instant: the later setting wins
            else:
                self._segments.append(seg)
                self._starts.append(t)
            if len(self._segments) > _SEGMENTS_KEPT:
                del self._segments[:-_SEGMENTS_KEPT]
                del self._starts[:-_SEGMENTS_KEPT]

    def set_level(self, index: int, level: float) -> None:
        """Set one channel's level now, keeping the others."""
        levels = self.levels()
        levels[index] = level
        self.set_levels(levels)

    def levels(self) -> NDArray[np.float64]:
        """The levels now set, shape (n_channels,) (a copy)."""
        with self._lock:
            return self._segments[-1].levels.copy()

    def all_off(self) -> None:
        """Switch every channel off."""
        self.set_levels(np.zeros(self.n_channels))

    @property
    def lights_on(self) -> bool:
        """Whether any channel is on now."""
        return bool(np.any(self.levels() > 0))

    # --- emission ---------------------------------------------------------------------

    def emitted(self, t_s: float | None = None) -> NDArray[np.float64]:
        """The true emitted spectral radiance at ``t_s`` (default now), (n_wl,)."""
        t = self.clock.now_s() if t_s is None else float(t_s)
        with self._lock:
            seg = self._segment_at(t)
            junction, load = self._thermal(seg, t)
        on = np.flatnonzero(seg.levels > 0)
        out = np.zeros_like(self._wl)
        if on.size == 0:
            return out
        gain, shift = self._gain_shift(t, junction, load)
        for k in on:
            base = np.interp(
                self._wl - shift[k], self._wl, self._nominal[k], left=0.0, right=0.0
            )
            out += seg.levels[k] * gain[k] * base
        return out * self.params.peak_radiance_w_sr_m2_nm

    def emitted_over(self, t0_s: float, t1_s: float) -> NDArray[np.float64]:
        """Time-averaged emitted radiance over ``[t0_s, t1_s]``, (n_wl,).

        Exact to the quadrature across level changes (integrated piecewise).
        ``t1_s <= t0_s`` gives :meth:`emitted` at ``t0_s``.
        """
        if t1_s <= t0_s:
            return self.emitted(t0_s)
        with self._lock:
            inner = [t for t in self._starts if t0_s < t < t1_s]
        edges = [t0_s, *inner, t1_s]
        total = np.zeros_like(self._wl)
        for a, b in itertools.pairwise(edges):
            for x, w in zip(_GL_X, _GL_W, strict=True):
                total += (w * (b - a)) * self.emitted(a + x * (b - a))
        return total / (t1_s - t0_s)

    def emitted_spd(self, t_s: float | None = None) -> Spectra:
        """The truth at ``t_s`` (default now): one spectrum named ``"emitted"``.

        Spectral radiance in W sr^-1 m^-2 nm^-1 on :attr:`wavelength_nm`.
        """
        t = self.clock.now_s() if t_s is None else float(t_s)
        return Spectra(
            self._wl,
            self.emitted(t)[np.newaxis, :],
            ("emitted",),
            {"unit": RADIANCE_UNIT, "t_s": repr(t)},
        )

    def emitted_spd_over(self, t0_s: float, t1_s: float) -> Spectra:
        """The truth averaged over ``[t0_s, t1_s]``, named ``"emitted"``.

        Mean spectral radiance in W sr^-1 m^-2 nm^-1; multiply by ``t1_s - t0_s`` for
        the radiant exposure of an exposure over that interval.
        """
        return Spectra(
            self._wl,
            self.emitted_over(t0_s, t1_s)[np.newaxis, :],
            ("emitted",),
            {"unit": RADIANCE_UNIT, "t0_s": repr(t0_s), "t1_s": repr(t1_s)},
        )

    # --- internal spectroradiometer ---------------------------------------------------

    def meter_response(self, radiance: ArrayLike) -> NDArray[np.float64]:
        """Noise-free meter reading of ``radiance`` (on :attr:`wavelength_nm`).

        Returns
        -------
        (n_meter,)
            The band-pass-weighted radiance at the meter's wavelengths shifted by
            its calibration offset ``unit.meter_offset_nm``.
        """
        p = self.params
        sigma_nm = p.meter_bandwidth_nm / (2.0 * math.sqrt(2.0 * math.log(2.0)))
        if sigma_nm > 0:
            u = np.linspace(-3.0 * sigma_nm, 3.0 * sigma_nm, 25)
            g = np.exp(-0.5 * (u / sigma_nm) ** 2)
        else:
            u, g = np.zeros(1), np.ones(1)
        g /= g.sum()
        x = self.meter_wavelength_nm[:, None] + self.unit.meter_offset_nm + u
        rad = np.asarray(radiance, dtype=np.float64)
        return np.interp(x, self._wl, rad, left=0.0, right=0.0) @ g

    def meter_noise_sd(self, reading: ArrayLike) -> NDArray[np.float64]:
        """Standard deviation of the metering noise for a noise-free ``reading``."""
        p = self.params
        m = np.asarray(reading, dtype=np.float64)
        peak = float(m.max()) if m.size else 0.0
        return np.sqrt(
            (p.meter_noise_rel * m) ** 2
            + (p.meter_noise_floor_rel * peak) ** 2
            + p.meter_dark_noise_w_sr_m2_nm**2
        )

    def measure_spd(self) -> Spectra:
        """Measure the emitted SPD as the internal spectroradiometer does.

        Integrates from now over ``params.meter_integration_s`` (advancing the clock,
        i.e. really waiting with a ``RealClock``) and adds seeded metering noise.

        Returns
        -------
        Spectra
            One spectrum named ``"measured"`` on the meter grid, in
            W sr^-1 m^-2 nm^-1, non-negative; ``meta`` has ``unit``, ``t0_s``,
            ``t1_s``.
        """
        t0 = self.clock.now_s()
        self.clock.sleep(self.params.meter_integration_s)
        t1 = t0 + self.params.meter_integration_s
        clean = self.meter_response(self.emitted_over(t0, t1))
        with self._lock:
            noise = self._noise_rng.standard_normal(clean.size)
        values = np.maximum(clean + self.meter_noise_sd(clean) * noise, 0.0)
        return Spectra(
            self.meter_wavelength_nm,
            values[np.newaxis, :],
            ("measured",),
            {"unit": RADIANCE_UNIT, "t0_s": repr(t0), "t1_s": repr(t1)},
        )

    # --- status -----------------------------------------------------------------------

    def temperature_c(self, t_s: float | None = None) -> float:
        """Case (LED heat-sink) temperature at ``t_s`` (default now), °C."""
        t = self.clock.now_s() if t_s is None else float(t_s)
        with self._lock:
            seg = self._segment_at(t)
            _, load = self._thermal(seg, t)
        return self._case_c(t, load)

    def status(self) -> LightStatus:
        """Readiness (``warmup_s`` after power-on), case temperature, on-time.

        ``on_time_s`` counts from the moment the lights last went from all-off to
        on (0 while off); ``extra`` holds ``warmup_left_s`` and ``power_on_s``.
        """
        t = self.clock.now_s()
        with self._lock:
            seg = self._segment_at(t)
            _, load = self._thermal(seg, t)
        age_s = t - self.power_on_s
        left_s = max(0.0, self.params.warmup_s - age_s)
        ready = left_s <= 0.0
        on_s = 0.0 if seg.lit_since_s is None else max(0.0, t - seg.lit_since_s)
        return LightStatus(
            ready=ready,
            temperature_c=round(self._case_c(t, load), 2),
            on_time_s=round(on_s, 3),
            message="ready" if ready else f"warming up, {left_s:.0f} s left",
            extra={"warmup_left_s": f"{left_s:.1f}", "power_on_s": f"{age_s:.1f}"},
        )

    # --- internals --------------------------------------------------------------------

    def _segment_at(self, t: float) -> _Segment:
        i = bisect.bisect_right(self._starts, t) - 1
        return self._segments[max(i, 0)]

    def _thermal(self, seg: _Segment, t: float) -> tuple[NDArray[np.float64], float]:
        """Junction rises (n,) and load rise of the case at ``t`` within ``seg``."""
        p = self.params
        dt = max(0.0, t - seg.t_s)
        j_target = seg.levels * p.junction_rise_k
        load_target = float(seg.levels.mean()) * p.load_rise_k
        junction = j_target + (seg.junction_k - j_target) * _decay(dt, p.junction_tau_s)
        load = load_target + (seg.load_k - load_target) * _decay(dt, p.load_tau_s)
        return junction, load

    def _case_c(self, t: float, load_k: float) -> float:
        p = self.params
        age = max(0.0, t - self.power_on_s)
        electronics = p.electronics_rise_k * (1.0 - _decay(age, p.electronics_tau_s))
        return p.ambient_c + electronics + load_k

    def _gain_shift(
        self, t: float, junction_k: NDArray[np.float64], load_k: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        u = self.unit
        delta_k = self._case_c(t, load_k) + junction_k - self.params.reference_c
        drift = 1.0 + u.drift_amplitude * np.sin(
            2.0 * np.pi * t / u.drift_period_s + u.drift_phase_rad
        )
        gain = u.gain * (1.0 + self._droop_per_k * delta_k) * drift
        shift = u.peak_shift_nm + self._shift_nm_per_k * delta_k
        return gain, shift


def _decay(dt_s: float, tau_s: float) -> float:
    """``exp(-dt/tau)``; a zero time constant settles at once."""
    return math.exp(-dt_s / tau_s) if tau_s > 0 else 0.0
