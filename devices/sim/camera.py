"""The simulated camera: a Canon EOS 5D Mark III model shooting CFA DNG files.

Image formation, per photosite ``x`` of colour ``c`` (the paper's Eq. 1 with the
bench's non-uniformities)::

    electrons(x) = t * K * sum_l S_c(l) L(l) r_m(x)(l) dl * E(x) * V(x)
                 + t * dark_current_e_per_s  (+ shot and read noise)
    DN(x)        = black_level + gain(ISO) * electrons(x), rounded, clipped

with ``t`` the exposure time, ``K`` :attr:`SimCamera.electrons_per_unit`, ``S`` the
camera sensitivities (peak 1), ``L`` the light source's true SPD
(``light.emitted_spd()``, W sr^-1 m^-2 nm^-1), ``r_m`` the reflectance of the material
at ``x`` (from :class:`~tunespec.devices.sim.scene.SimScene`), ``E`` the scene's
irradiance fall-off and ``V`` the lens's cos^4 vignetting.

The sum over wavelength is done once per material with
:func:`tunespec.core.forward_model.render_rgb`, and the materials are painted into the
image through label maps; no per-pixel spectral work. Label and shading maps are
computed once per scene geometry and resolution and cached (about 1-4 s for
5760 x 3840), after which a full frame renders in about 0.5 s of CPU plus 0.2 s for
the 44 MB DNG write.

Noise: photon shot noise (on signal and dark current) and read noise, drawn together
as one Gaussian per photosite with variance ``electrons + read_noise_e**2`` (the
Gaussian limit of Poisson; exact enough above a few tens of electrons, and read
noise dominates below). Then quantisation to integers and clipping at the white
level; photosites also clip at the full well before read noise is added.

Default sensor figures (Canon EOS 5D Mark III at ISO 100, as tabulated from DxOMark
measurements by sensorgen.info, rounded): full well ``67 000 e-``, read noise ``30 e-``.
Black level 2048 DN and a white level of 15000 DN are those of its 14-bit raw files.
The dark current (``1 e-/s``) is an assumed order of magnitude for a DSLR sensor near
room temperature, not a measured 5D Mark III figure. Read noise is held constant in
electrons over ISO (a simplification: real read noise falls at high ISO).

Calibration constant ``K`` (:data:`DEFAULT_ELECTRONS_PER_UNIT` = 2.5e5 e- per
(W sr^-1 m^-2 nm^-1 x unit sensitivity x nm x s)): chosen so that with the nominal
22-LED set at level 1 as ``SimLightSource`` emits it (``load_led_set()`` scaled to a
strongest peak of :data:`NOMINAL_PEAK_RADIANCE_W_SR_M2_NM` = 1e-3, the value of
``devices.sim.led_physics.PEAK_RADIANCE_W_SR_M2_NM``), a 6 s exposure (the paper's)
of the brightest ColorChecker SG patch (N10 under WHITE_WARM, G channel,
``render_rgb`` = 0.0350) collects ``2.5e5 * 6 * 0.0350 = 52 600 e-``: 78 % of the
ISO 100 full well before fall-off and vignetting, about 68 % where N10 sits in the
default scene. The narrowband LEDs reach 0.5-45 % in the same 6 s, the paper's
low-intensity regime. Plausibility: a 6.25 um pixel with QE 0.5 behind an f/8 lens
collects about 6.6e5 e- per (W sr^-1 m^-2 nm^-1 x nm x s) at 550 nm, so 2.5e5 is an
aperture near f/13. For another light scale pass ``electrons_per_unit``
(:func:`camera_constant_for` computes one; ``devices.registry`` does so).

Rendering grid: the sensitivities' grid (5 nm for the shipped curves), on which the
light's SPD is sampled (linear interpolation). Pass ``render_grid`` (e.g. 1 nm) to
integrate narrowband LEDs more finely than the estimators do.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from os import PathLike
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tunespec.core.datasets import DEFAULT_CAMERA, load_camera
from tunespec.core.forward_model import render_rgb
from tunespec.core.io.raw import full_to_plane_px
from tunespec.core.io.spectral_csv import write_spectra_csv
from tunespec.core.limits import dumps_json
from tunespec.core.spectra import Grid, Spectra
from tunespec.devices.clock import Clock, RealClock, VirtualClock
from tunespec.devices.dng import write_dng
from tunespec.devices.protocols import (
    DeviceCommandError,
    DeviceConnectionError,
    DeviceIdentity,
)
from tunespec.devices.sim.scene import SimScene

__all__ = [
    "DEFAULT_ELECTRONS_PER_UNIT",
    "NOMINAL_PEAK_RADIANCE_W_SR_M2_NM",
    "EmitsSpd",
    "SimCamera",
    "camera_constant_for",
]

#: Electrons per (W sr^-1 m^-2 nm^-1 x unit sensitivity x nm x s); see module doc.
DEFAULT_ELECTRONS_PER_UNIT = 2.5e5
#: Radiance of the strongest nominal LED at level 1 that the default constant assumes
#: (``devices.sim.led_physics.PEAK_RADIANCE_W_SR_M2_NM``; a test keeps them equal).
NOMINAL_PEAK_RADIANCE_W_SR_M2_NM = 1.0e-3
#: Exposure limits of the simulator (the 5D Mark III's timed range is 1/8000-30 s;
#: longer exposures stand for bulb).
MIN_EXPOSURE_S = 1.0 / 8000.0
MAX_EXPOSURE_S = 3600.0
#: ISO range (5D Mark III, expanded range included).
MIN_ISO, MAX_ISO = 50, 102400
#: 2 x 2 CFA of the 5D Mark III: (row offset, column offset) -> channel index.
_RGGB_SITES: tuple[tuple[int, int, int], ...] = (
    (0, 0, 0),
    (0, 1, 1),
    (1, 0, 1),
    (1, 1, 2),
)


class EmitsSpd(Protocol):
    """What the camera needs of a light source: the SPD it emits right now."""

    def emitted_spd(self) -> Spectra:
        """The true emitted SPD, one spectrum, W sr^-1 m^-2 nm^-1."""
        ...


@dataclass
class _Maps:
    """Per-site label and shading maps for one geometry and resolution."""

    labels: list[NDArray[np.int16]] | None  # 4 x (H/2, W/2); None: all background
    shading: list[NDArray[np.float32]]  # 4 x (H/2, W/2), irradiance x vignetting


def camera_constant_for(
    spd: Spectra,
    sensitivity: Spectra,
    reflectance: float = 0.9,
    *,
    exposure_s: float = 6.0,
    fill: float = 0.75,
    full_well_e: float = 67000.0,
) -> float:
    """The ``electrons_per_unit`` that fills a white patch to ``fill`` of full well.

    Parameters
    ----------
    spd
        The brightest illuminant (one spectrum, the light's absolute units).
    sensitivity
        Camera sensitivities R, G, B (peak 1).
    reflectance
        Flat reflectance of the brightest patch.
    exposure_s, fill, full_well_e
        Exposure time, target fraction of the full well, full well in electrons.

    Returns
    -------
    float
        Electrons per (radiance unit x sensitivity unit x nm x s), at irradiance and
        vignetting 1 (the image centre).
    """
    grid = sensitivity.grid
    light = spd.resample(grid).values[:1]
    rgb = render_rgb(
        np.full((1, grid.n), reflectance), light, sensitivity.values, grid.step_nm
    )
    peak = float(rgb.max())
    if not peak > 0:
        raise ValueError("the SPD gives no signal in any channel")
    return fill * full_well_e / (exposure_s * peak)


class SimCamera:
    """A simulated Canon EOS 5D Mark III imaging a :class:`SimScene`.

    Implements :class:`~tunespec.devices.protocols.Camera`; ``capture`` writes a CFA
    DNG (RGGB, 16-bit storage, 14-bit levels) that :func:`tunespec.core.io.raw.load_raw`
    reads.

    Parameters
    ----------
    light
        Anything with ``emitted_spd() -> Spectra`` (the true SPD now), e.g.
        ``SimLightSource``; ``None`` is a dark room. If it also has
        ``emitted_spd_over(t0_s, t1_s)`` (mean over a clock interval), the exposure
        integrates that; otherwise the mean of the SPD at its start and end.
    scene
        What is in front of the camera (also the TargetStage).
    sensitivity
        Camera sensitivities R, G, B (peak 1); default the shipped Canon EOS 5D
        Mark III curves.
    render_grid
        Wavelength grid of the sum in Eq. 1; default the sensitivities' grid.
    resolution
        ``(width, height)`` of the mosaic in pixels, even, at least 64 x 64
        (the real sensor: 5760 x 3840).
    clock
        Shared with the light source; default the light's ``clock`` if it has one,
        else a :class:`VirtualClock` (``realtime=False``) or a :class:`RealClock`.
    seed
        Noise seed.
    realtime
        Really wait the exposure time (for the GUI); tests use ``False``.
    electrons_per_unit
        Calibration constant ``K`` (see the module docstring).
    dark_current_e_per_s, full_well_e, read_noise_e
        Sensor noise figures (see the module docstring for their sources).
    black_level, white_level
        Raw DN of black and of clipping.
    base_iso
        ISO at which the full well fills the raw range.
    focal_length_mm, sensor_width_mm
        Lens and sensor for the cos^4 vignetting.
    exposure_s, iso
        Initial settings.
    """

    def __init__(
        self,
        light: EmitsSpd | None,
        scene: SimScene,
        *,
        sensitivity: Spectra | None = None,
        render_grid: Grid | None = None,
        resolution: tuple[int, int] = (1536, 1024),
        clock: Clock | None = None,
        seed: int = 0,
        realtime: bool = False,
        electrons_per_unit: float = DEFAULT_ELECTRONS_PER_UNIT,
        dark_current_e_per_s: float = 1.0,
        full_well_e: float = 67000.0,
        read_noise_e: float = 30.0,
        black_level: int = 2048,
        white_level: int = 15000,
        base_iso: int = 100,
        focal_length_mm: float = 50.0,
        sensor_width_mm: float = 36.0,
        exposure_s: float = 1.0,
        iso: int = 100,
    ) -> None:
        width, height = (int(v) for v in resolution)
        if width < 64 or height < 64 or width % 2 or height % 2:
            raise ValueError(
                f"resolution must be even and at least 64 x 64, got {width} x {height}"
            )
        if not 0 <= black_level < white_level <= 65535:
            raise ValueError("need 0 <= black_level < white_level <= 65535")
        if min(electrons_per_unit, full_well_e, focal_length_mm, sensor_width_mm) <= 0:
            raise ValueError("electrons_per_unit, full_well_e and optics must be > 0")
        if min(dark_current_e_per_s, read_noise_e) < 0:
            raise ValueError("noise figures must be >= 0")
        self._light = light
        self._scene = scene
        if sensitivity is None:
            sensitivity = load_camera(DEFAULT_CAMERA)
        self._sensitivity = sensitivity
        self._grid = render_grid or sensitivity.grid
        # linear interpolation between the given samples is the "true" curve
        self._render_sens = sensitivity.resample(
            self._grid, source="sensitivity"
        ).values
        self._width, self._height = width, height
        self._realtime = bool(realtime)
        self._clock: Clock = (
            clock
            or getattr(light, "clock", None)
            or (RealClock() if realtime else VirtualClock())
        )
        self._rng = np.random.default_rng(seed)
        self._seed = seed
        self.electrons_per_unit = float(electrons_per_unit)
        self.dark_current_e_per_s = float(dark_current_e_per_s)
        self.full_well_e = float(full_well_e)
        self.read_noise_e = float(read_noise_e)
        self.black_level = int(black_level)
        self.white_level = int(white_level)
        self.base_iso = int(base_iso)
        self.focal_length_mm = float(focal_length_mm)
        self.sensor_width_mm = float(sensor_width_mm)
        self._exposure_s = 1.0
        self._iso = base_iso
        self._closed = False
        self._maps: dict[tuple[Any, ...], _Maps] = {}
        self._frames = 0
        self.set_exposure(exposure_s)
        self.set_iso(iso)

    # -- Camera protocol -----------------------------------------------------------
    @property
    def identity(self) -> DeviceIdentity:
        name = self._sensitivity.meta.get("model", "") or DEFAULT_CAMERA
        return DeviceIdentity(
            vendor="TuneSpec",
            model=f"SimCamera ({name})",
            serial=f"SIM-{self._seed}",
            firmware="sim",
            spec="sim",
        )

    @property
    def exposure_s(self) -> float:
        return self._exposure_s

    def set_exposure(self, exposure_s: float) -> None:
        """Set the exposure time (1/8000 s ... 3600 s)."""
        self._check_open()
        t = float(exposure_s)
        if not (math.isfinite(t) and MIN_EXPOSURE_S <= t <= MAX_EXPOSURE_S):
            raise DeviceCommandError(
                f"SimCamera: exposure {exposure_s!r} s is outside "
                f"{MIN_EXPOSURE_S:g}-{MAX_EXPOSURE_S:g} s"
            )
        self._exposure_s = t

    @property
    def iso(self) -> int:
        return self._iso

    def set_iso(self, iso: int) -> None:
        """Set the ISO speed (50 ... 102400); the gain is proportional to it."""
        self._check_open()
        if int(iso) != iso or not MIN_ISO <= iso <= MAX_ISO:
            raise DeviceCommandError(
                f"SimCamera: ISO {iso!r} is outside {MIN_ISO}-{MAX_ISO}"
            )
        self._iso = int(iso)

    def capture(self, stem: Path | str) -> Path:
        """Expose one frame and write ``stem.dng`` (atomically); return its path.

        The light's SPD is sampled at the start and at the end of the exposure and
        averaged, so drift during the exposure (on the shared clock) is integrated.
        """
        self._check_open()
        path = Path(f"{stem}.dng")
        t0_s = self._clock.now_s()
        spd_start = self._emitted()
        self._clock.sleep(self._exposure_s)
        if self._realtime and not isinstance(self._clock, RealClock):
            time.sleep(self._exposure_s)
        t1_s = self._clock.now_s()
        over = getattr(self._light, "emitted_spd_over", None)
        if over is not None:
            spd = self._on_grid(over(t0_s, t1_s))
        else:
            spd_end = self._emitted()
            spd = None
            if spd_start is not None and spd_end is not None:
                spd = 0.5 * (spd_start + spd_end)
        mosaic = self.render(spd)
        self._frames += 1
        write_dng(
            path,
            mosaic,
            cfa_pattern="RGGB",
            black_level=self.black_level,
            white_level=self.white_level,
            exposure_s=self._exposure_s,
            iso=self._iso,
            make="TuneSpec",
            model="SimCamera",
            unique_camera_model=f"TuneSpec SimCamera ({DEFAULT_CAMERA} model)",
            description=(
                f"TuneSpec simulated frame {self._frames}: scene={self._scene.presented}"
                f", t={self._clock.now_s():.3f} s"
            ),
        )
        return path

    def close(self) -> None:
        self._closed = True
        self._maps.clear()

    def looking_at(
        self,
        scene: SimScene,
        *,
        seed: int | None = None,
        resolution: tuple[int, int] | None = None,
    ) -> SimCamera:
        """The same camera (sensor, lens, light, clock, settings) facing ``scene``
        (with another noise ``seed`` or ``resolution`` if given: a session resumed
        with the settings it was captured with).

        Everything that belongs to the camera and the bench is kept; only the scene
        and, if given, the noise seed change. A bench that swaps targets must not
        fall back to default camera constants.
        """
        self._check_open()
        cam = SimCamera(
            self._light,
            scene,
            sensitivity=self._sensitivity,
            render_grid=self._grid,
            resolution=resolution or (self._width, self._height),
            clock=self._clock,
            seed=self._seed if seed is None else int(seed),
            realtime=self._realtime,
            electrons_per_unit=self.electrons_per_unit,
            dark_current_e_per_s=self.dark_current_e_per_s,
            full_well_e=self.full_well_e,
            read_noise_e=self.read_noise_e,
            black_level=self.black_level,
            white_level=self.white_level,
            base_iso=self.base_iso,
            focal_length_mm=self.focal_length_mm,
            sensor_width_mm=self.sensor_width_mm,
            exposure_s=self._exposure_s,
            iso=self._iso,
        )
        return cam

    # -- rendering -------------------------------------------------------------------
    @property
    def resolution(self) -> tuple[int, int]:
        """``(width, height)`` of the mosaic."""
        return self._width, self._height

    @property
    def scene(self) -> SimScene:
        return self._scene

    @property
    def render_grid(self) -> Grid:
        """The wavelength grid of the sum in Eq. 1."""
        return self._grid

    @property
    def sensitivity(self) -> Spectra:
        """The true sensitivities (peak 1) the camera renders with."""
        return self._sensitivity

    @property
    def gain_dn_per_e(self) -> float:
        """Raw DN per electron at the current ISO."""
        return (
            (self.white_level - self.black_level) / self.full_well_e
            * self._iso / self.base_iso
        )  # fmt: skip

    def material_rates_e_per_s(
        self, spd: NDArray[np.float64] | None
    ) -> NDArray[np.float64]:
        """Electrons per second per material and channel, at shading 1.

        Parameters
        ----------
        spd : (n_wl,) or None
            Radiance on the rendering grid; ``None`` is darkness.

        Returns
        -------
        (n_materials, 3)
            ``K * render_rgb(materials, spd, S)`` (Eq. 1).
        """
        materials = self._scene.materials.resample(self._grid)
        if spd is None:
            return np.zeros((len(materials), 3))
        rgb = render_rgb(
            materials.values, spd[None, :], self._render_sens, self._grid.step_nm
        )
        return self.electrons_per_unit * rgb[:, 0, :]

    def render(self, spd: NDArray[np.float64] | None) -> NDArray[np.uint16]:
        """One noisy raw mosaic for the current scene and settings (no file, no wait).

        Parameters
        ----------
        spd : (n_wl,) or None
            The light's mean radiance during the exposure on the rendering grid
            (:attr:`render_grid`); ``None`` renders a dark frame.

        Returns
        -------
        (height, width) uint16
            Raw DN, RGGB.
        """
        maps = self._geometry()
        t = self._exposure_s
        rates = (self.material_rates_e_per_s(spd) * t).astype(np.float32)
        dark_e = np.float32(self.dark_current_e_per_s * t)
        read_var = np.float32(self.read_noise_e**2)
        gain = np.float32(self.gain_dn_per_e)
        full_well = np.float32(self.full_well_e)
        out = np.empty((self._height, self._width), dtype=np.uint16)
        for k, (dy, dx, ch) in enumerate(_RGGB_SITES):
            shading = maps.shading[k]
            if maps.labels is None:
                e = shading * rates[0, ch]
            else:
                e = rates[:, ch][maps.labels[k]]
                e *= shading
            e += dark_e
            # shot + read noise as one Gaussian: var = electrons + read^2
            z = self._rng.standard_normal(e.shape, dtype=np.float32)
            sigma = e + read_var
            np.sqrt(sigma, out=sigma)
            z *= sigma
            np.minimum(e, full_well, out=e)
            e += z
            e *= gain
            e += np.float32(self.black_level)
            np.rint(e, out=e)
            np.clip(e, 0, self.white_level, out=e)
            out[dy::2, dx::2] = e
        return out

    def shading(self, xy_px: ArrayLike) -> NDArray[np.float64]:
        """Irradiance fall-off times vignetting at mosaic pixels, (..., 2) -> (...)."""
        xy = np.asarray(xy_px, dtype=np.float64)
        return self._shading(xy[..., 0], xy[..., 1])

    def vignetting(self, xy_px: ArrayLike) -> NDArray[np.float64]:
        """cos^4 of the field angle at mosaic pixels, (..., 2) -> (...)."""
        xy = np.asarray(xy_px, dtype=np.float64)
        return self._vignetting(xy[..., 0], xy[..., 1])

    def _shading(
        self, x: NDArray[np.floating], y: NDArray[np.floating]
    ) -> NDArray[np.floating]:
        """Shading at broadcastable ``x, y`` (float32 in, float32 out)."""
        irradiance = self._scene.irradiance(x, y, self._width, self._height)
        return irradiance * self._vignetting(x, y)

    def _vignetting(
        self, x: NDArray[np.floating], y: NDArray[np.floating]
    ) -> NDArray[np.floating]:
        mm_per_px = self.sensor_width_mm / self._width
        f2 = self.focal_length_mm**2
        r2 = ((x - 0.5 * (self._width - 1)) * mm_per_px) ** 2 + (
            (y - 0.5 * (self._height - 1)) * mm_per_px
        ) ** 2
        cos2 = f2 / (r2 + f2)
        return cos2 * cos2

    def _geometry(self) -> _Maps:
        scene = self._scene
        key = (scene.geometry_key, scene.presented, self._width, self._height)
        maps = self._maps.get(key)
        if maps is not None:
            return maps
        shading_key = (scene.geometry_key, "shading", self._width, self._height)
        shading = self._maps.get(shading_key)
        if shading is None:
            shading = _Maps(
                None, [self._shading_site(dy, dx) for dy, dx, _ in _RGGB_SITES]
            )
            self._maps[shading_key] = shading
        labels = None
        if scene.presented == "target":
            labels = [
                scene.labels(
                    np.arange(dx, self._width, 2),
                    np.arange(dy, self._height, 2),
                    self._width,
                    self._height,
                )
                for dy, dx, _ in _RGGB_SITES
            ]
        maps = _Maps(labels, shading.shading)
        self._maps[key] = maps
        return maps

    def _shading_site(self, dy: int, dx: int) -> NDArray[np.float32]:
        x = np.arange(dx, self._width, 2, dtype=np.float32)[None, :]
        y = np.arange(dy, self._height, 2, dtype=np.float32)[:, None]
        return np.ascontiguousarray(self._shading(x, y), dtype=np.float32)

    def _emitted(self) -> NDArray[np.float64] | None:
        if self._light is None:
            return None
        return self._on_grid(self._light.emitted_spd())

    def _on_grid(self, spd: Spectra) -> NDArray[np.float64]:
        if len(spd) != 1:
            raise DeviceCommandError(
                f"SimCamera: the light source gave {len(spd)} spectra, expected one"
            )
        return spd.resample(self._grid, source="light source SPD").values[0]

    def _check_open(self) -> None:
        if self._closed:
            raise DeviceConnectionError("SimCamera: the camera is closed")

    # -- truth -------------------------------------------------------------------------
    def absolute_sensitivity(self) -> Spectra:
        """Sensitivities in full-scale units per (W sr^-1 m^-2 nm^-1 x nm x s).

        What a calibration should recover (times the exposure time) when the
        responses are the full-scale planes of :func:`tunespec.core.io.raw.load_raw` at
        the image centre (irradiance and vignetting there are 1 up to the fall-off
        centre's offset) and at the current ISO; processing counts the gain in Eq. 1's
        illuminants (:func:`tunespec.core.processing.iso_gain`), so a calibration
        recovers these over the gain, their value at ISO 100.
        """
        scale = (
            self.electrons_per_unit
            * self.gain_dn_per_e
            / (self.white_level - self.black_level)
        )
        out = self._sensitivity.with_values(self._sensitivity.values * scale)
        return Spectra(
            out.wavelength_nm,
            out.values,
            out.names,
            {**out.meta, "unit": "full scale per (W sr^-1 m^-2 nm^-1 nm s)"},
        )

    def truth(self) -> dict[str, Any]:
        """Everything the simulation was built with, for closed-loop checks.

        Returns
        -------
        dict
            ``sensitivity`` (Spectra, peak 1), ``absolute_sensitivity`` (Spectra),
            ``reflectances`` (Spectra: background, frame, patches), ``layout``
            (TargetLayout with corners in mosaic pixels), ``corners_px`` (4, 2)
            mosaic pixels, ``corners_plane_px`` (4, 2) plane pixels, ``resolution``,
            ``scene`` (its parameters), ``camera`` (constants and noise figures).
        """
        corners = self._scene.corners_px(self._width, self._height)
        return {
            "sensitivity": self._sensitivity,
            "absolute_sensitivity": self.absolute_sensitivity(),
            "reflectances": self._scene.materials,
            "layout": self._scene.layout_px(self._width, self._height),
            "corners_px": corners,
            "corners_plane_px": full_to_plane_px(corners),
            "resolution": (self._width, self._height),
            "scene": self._scene.describe(),
            "camera": {
                "electrons_per_unit": self.electrons_per_unit,
                "gain_dn_per_e": self.gain_dn_per_e,
                "iso": self._iso,
                "base_iso": self.base_iso,
                "exposure_s": self._exposure_s,
                "black_level": self.black_level,
                "white_level": self.white_level,
                "full_well_e": self.full_well_e,
                "read_noise_e": self.read_noise_e,
                "dark_current_e_per_s": self.dark_current_e_per_s,
                "focal_length_mm": self.focal_length_mm,
                "sensor_width_mm": self.sensor_width_mm,
                "cfa_pattern": "RGGB",
                "seed": self._seed,
            },
        }

    def write_truth(self, folder: str | PathLike[str]) -> list[Path]:
        """Write the truth beside a session.

        Files: ``truth_sensitivity.csv`` (R, G, B, peak 1),
        ``truth_sensitivity_absolute.csv`` (see :meth:`absolute_sensitivity`),
        ``truth_reflectances.csv`` (background, frame and patches),
        ``truth_layout.json`` (the layout with its true corners, mosaic pixels) and
        ``truth.json`` (corners in mosaic and plane pixels, scene and camera
        parameters).

        Returns
        -------
        list of Path
            The files written.
        """
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        t = self.truth()
        paths = [
            folder / "truth_sensitivity.csv",
            folder / "truth_sensitivity_absolute.csv",
            folder / "truth_reflectances.csv",
            folder / "truth_layout.json",
            folder / "truth.json",
        ]
        write_spectra_csv(t["sensitivity"], paths[0])
        write_spectra_csv(t["absolute_sensitivity"], paths[1])
        write_spectra_csv(t["reflectances"], paths[2])
        t["layout"].save(paths[3])
        doc = {
            "format": "tunespec-sim-truth",
            "version": 1,
            "coordinates": (
                "corners_px: mosaic pixels, x right, y down, pixel centres at "
                "integers; corners_plane_px: the half-resolution R/G/B planes "
                "(plane = (mosaic - 0.5) / 2)"
            ),
            "corners_px": np.asarray(t["corners_px"]).tolist(),
            "corners_plane_px": np.asarray(t["corners_plane_px"]).tolist(),
            "resolution": list(t["resolution"]),
            "scene": t["scene"],
            "camera": t["camera"],
            "absolute_sensitivity_unit": t["absolute_sensitivity"].meta["unit"],
        }
        from tunespec.core.atomic import atomic_write_text

        atomic_write_text(paths[4], dumps_json(doc))
        return paths
