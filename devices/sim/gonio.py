"""The simulated gonio-imager: a goniometer, a glossy target's BRDF and its view.

:class:`SimGoniometer` implements :class:`~tunespec.devices.goniometer.Goniometer`
in process (no transport): axes ``theta_i``, ``phi_i``, ``theta_r``, ``phi_r`` with
travel limits, a reference that ``home`` sets (moves before it are refused, as a
stage without reference would), position read-back with an optional repeatability
error, ``stop``, and a failure injected after a given number of moves (for the
kill-and-resume tests of a gonio session).

:class:`GonioBench` renders what the camera sees at the goniometer's geometry: a BRDF
per material (:func:`brdf_reflectance_factor`: Lambertian body + GGX microfacet lobe
with Schlick's Fresnel term and a roughness per patch) and the projective view of the
target (:func:`view_homography`), so every step of a gonio session is tested against
truth.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tunespec.core.simulate import NoiseModel
from tunespec.core.spectra import Grid
from tunespec.devices.goniometer import ANGLE_AXES, AxisInfo, Geometry, check_target
from tunespec.devices.protocols import (
    DeviceCommandError,
    DeviceConnectionError,
    DeviceIdentity,
)

__all__ = [
    "GonioBench",
    "SimGoniometer",
    "brdf_reflectance_factor",
    "ggx_specular",
    "view_homography",
]

#: Travel of the simulated axes (degrees).
LIMITS_DEG = {"theta_i": (-90.0, 90.0), "phi_i": (-360.0, 360.0),
              "theta_r": (-90.0, 90.0), "phi_r": (-360.0, 360.0)}  # fmt: skip


class SimGoniometer:
    """An in-process goniometer (see the module docstring).

    Parameters
    ----------
    repeatability_deg
        Standard deviation of the position reached around the target.
    fail_after_moves
        Raise :class:`DeviceConnectionError` on this move (counting from 1), as a
        controller that loses power would; ``None`` never.
    seed
        Seed of the repeatability error.
    """

    def __init__(
        self,
        *,
        repeatability_deg: float = 0.0,
        fail_after_moves: int | None = None,
        seed: int = 0,
    ) -> None:
        self._pos = dict.fromkeys(ANGLE_AXES, 0.0)
        self._homed = False
        self._closed = False
        self._rng = np.random.default_rng(seed)
        self._sigma = float(repeatability_deg)
        self._fail_after = fail_after_moves
        #: Moves made (targets reached), in order.
        self.moves: list[dict[str, float]] = []

    @property
    def identity(self) -> DeviceIdentity:
        return DeviceIdentity(
            "TuneSpec", "simulated goniometer", "SIM-GONIO", "1.0", "sim"
        )

    def axes(self) -> list[AxisInfo]:
        return [AxisInfo(n, "deg", *LIMITS_DEG[n]) for n in ANGLE_AXES]

    def home(self) -> None:
        self._check_open()
        self._pos = dict.fromkeys(ANGLE_AXES, 0.0)
        self._homed = True

    def is_homed(self) -> bool:
        return self._homed

    def move_to(self, targets: Mapping[str, float]) -> dict[str, float]:
        self._check_open()
        check_target(self.axes(), targets)
        if not self._homed:
            raise DeviceCommandError(
                "simulated goniometer: no reference position; home it first"
            )
        if self._fail_after is not None and len(self.moves) + 1 >= self._fail_after:
            self._closed = True
            raise DeviceConnectionError(
                "simulated goniometer: controller lost (injected)"
            )
        for name, value in targets.items():
            self._pos[name] = float(value) + self._sigma * float(
                self._rng.standard_normal()
            )
        self.moves.append(dict(targets))
        return dict(self._pos)

    def position(self) -> dict[str, float]:
        self._check_open()
        return dict(self._pos)

    def stop(self) -> None:
        """Moves are instantaneous: nothing is ever moving."""

    def close(self) -> None:
        self._closed = True

    def _check_open(self) -> None:
        if self._closed:
            raise DeviceConnectionError("simulated goniometer: closed")


# --- the simulated gonio bench: BRDF and the projective view of the target ----------

#: Refractive index of the simulated print surface (a resin: Fresnel F0 = 0.04).
IOR = 1.5


def ggx_specular(
    geometry: Geometry, roughness: ArrayLike, ior: float = IOR
) -> NDArray[np.float64]:
    """Specular reflectance factor ``pi f_s`` of a GGX microfacet lobe, per roughness.

    ``f_s = D(h) G(i, r) F(i.h) / (4 cos i cos r)`` with the GGX (Trowbridge-Reitz)
    normal distribution, the separable Smith shadowing-masking and Schlick's Fresnel
    term with ``F0 = ((n - 1) / (n + 1))^2``; a dielectric's specular reflection is
    spectrally flat. Multiplied by pi it is a reflectance factor (the perfect diffuser
    has 1).

    References
    ----------
    B. Walter, S. R. Marschner, H. Li, K. E. Torrance, "Microfacet models for
    refraction through rough surfaces", EGSR 2007 (GGX, Smith G); C. Schlick, "An
    inexpensive BRDF model for physically-based rendering", Computer Graphics Forum
    13(3), 1994 (Fresnel approximation); R. L. Cook, K. E. Torrance, "A reflectance
    model for computer graphics", ACM TOG 1(1), 1982.
    """
    a = np.asarray(roughness, dtype=np.float64)
    wi, wr = (
        _direction(geometry.theta_i, geometry.phi_i),
        _direction(geometry.theta_r, geometry.phi_r),
    )
    h = wi + wr
    h = h / np.linalg.norm(h)
    ci, cr, ch, cd = wi[2], wr[2], h[2], float(wi @ h)
    d = a**2 / (np.pi * (ch**2 * (a**2 - 1.0) + 1.0) ** 2)

    def g1(c: float) -> NDArray[np.float64]:
        return 2.0 * c / (c + np.sqrt(a**2 + (1.0 - a**2) * c**2))

    f0 = ((ior - 1.0) / (ior + 1.0)) ** 2
    fresnel = f0 + (1.0 - f0) * (1.0 - cd) ** 5
    return np.pi * d * g1(ci) * g1(cr) * fresnel / (4.0 * ci * cr)


def _direction(theta_deg: float, phi_deg: float) -> NDArray[np.float64]:
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


def brdf_reflectance_factor(
    diffuse: ArrayLike, roughness: ArrayLike, geometry: Geometry, ior: float = IOR
) -> NDArray[np.float64]:
    """Reflectance factor at ``geometry``: Lambertian body + GGX surface lobe.

    ``R(lambda) = (1 - F(theta_i)) rho(lambda) + pi f_s`` per material: the light
    that the surface reflects (Fresnel) does not reach the body.

    Parameters
    ----------
    diffuse : (n, n_wl)
        Body reflectance factors (the patch reflectances at 0/45).
    roughness : (n,)
        GGX roughness per material.
    """
    rho = np.asarray(diffuse, dtype=np.float64)
    f0 = ((ior - 1.0) / (ior + 1.0)) ** 2
    ci = np.cos(np.radians(geometry.theta_i))
    f_in = f0 + (1.0 - f0) * (1.0 - ci) ** 5
    spec = ggx_specular(geometry, roughness, ior)
    return (1.0 - f_in) / (1.0 - f0) * rho + spec[:, None]


def view_homography(geometry: Geometry, size_px: tuple[int, int],
                    px_per_mm: float, distance_mm: float = 500.0) -> NDArray[np.float64]:  # fmt: skip
    """Homography from target-centred mm (x right, y down) to image pixels.

    A pinhole camera at ``distance_mm`` along the viewing direction ``(theta_r,
    phi_r)`` looks at the target's centre, image "up" along the target's -y: the
    target is foreshortened by about ``cos theta_r`` along the azimuth ``phi_r`` and
    its far side shrinks (perspective), as on a gonio-imager.
    """
    v = _direction(geometry.theta_r, geometry.phi_r)
    ey = np.array([0.0, 1.0, 0.0])
    uy = ey - (ey @ v) * v
    uy /= np.linalg.norm(uy)
    ux = np.cross(uy, v)
    f = px_per_mm * distance_mm
    w, h = size_px
    # u = f (ux.P) / (D - v.P) + cx with P = (x, y, 0)
    K = np.array([[f, 0.0, w / 2.0], [0.0, f, h / 2.0], [0.0, 0.0, 1.0]])
    M = np.array(
        [[ux[0], ux[1], 0.0], [uy[0], uy[1], 0.0], [-v[0], -v[1], distance_mm]]
    )
    return K @ M


class GonioBench:
    """The simulated gonio-imager: light, goniometer, camera and a glossy target.

    The target is the CMY Neugebauer print (``resources/layouts/neugebauer_cmy.json``,
    its model reflectances as the body colour) with a GGX surface lobe per patch
    (roughness from ``roughness``), on a dark substrate, lying on a white board. A
    frame is rendered at the goniometer's position: each region's reflectance factor
    at that geometry (:func:`brdf_reflectance_factor`), Eq. 1 with the light's
    *emitted* spectrum times ``cos theta_i``, the projective view of the target
    (:func:`view_homography`, 2 x 2 supersampled edges), photon and read noise,
    clipping at full scale. Frames are float32 ``(3, H, W)`` in full-scale units,
    dark level 0.

    Parameters
    ----------
    light, gonio
        The light source (a :class:`SimLightSource`) and goniometer.
    roughness
        GGX roughness per patch (8 values).
    seed
        Noise seed (each frame draws from ``(seed, frame counter)``).
    """

    def __init__(
        self,
        light: Any,
        gonio: Any,
        *,
        roughness: ArrayLike | None = None,
        size_px: tuple[int, int] = (320, 200),
        px_per_mm: float = 2.0,
        noise: NoiseModel | None = None,
        seed: int = 0,
    ) -> None:
        from tunespec.core.datasets import load_camera, resource_path
        from tunespec.core.io.spectral import read_spectra_csv
        from tunespec.core.layout import TargetLayout

        self.light, self.gonio = light, gonio
        self.grid = Grid(380.0, 730.0, 1.0)
        self.layout = TargetLayout.load(resource_path("layouts", "neugebauer_cmy.json"))
        self.diffuse = read_spectra_csv(
            resource_path("charts", "neugebauer_cmy_model.csv"), self.grid
        ).select(self.layout.patch_names)
        n = self.layout.n_patches
        self.roughness = (
            np.linspace(0.12, 0.35, n)
            if roughness is None
            else np.asarray(roughness, float)
        )
        self.sensitivity = load_camera(grid=self.grid)
        leds = read_spectra_csv(resource_path("leds", "cal1_model_22.csv"), self.grid)
        #: Camera constant: a perfect white under the strongest LED at level 1 and
        #: exposure 1 gives full scale.
        physics = getattr(light, "physics", None)
        peak = physics.params.peak_radiance_w_sr_m2_nm if physics is not None else 1.0
        unit = leds.values / leds.values.max() * peak
        self.gain = 1.0 / float((unit @ self.sensitivity.values.T).max())
        self.size_px, self.px_per_mm = size_px, px_per_mm
        self.noise = noise if noise is not None else NoiseModel()
        self._seed = seed
        self._n_frames = 0
        self._regions: dict[Geometry, NDArray[np.float64]] = {}

    def geometry(self) -> Geometry:
        """The geometry the goniometer is at now."""
        p = self.gonio.position()
        return Geometry(abs(p["theta_i"]), p["phi_i"], abs(p["theta_r"]), p["phi_r"])

    def reflectance_factors(self, geometry: Geometry) -> NDArray[np.float64]:
        """Truth: (n_patches + 2, n_wl), patches then substrate and white board."""
        patches = brdf_reflectance_factor(self.diffuse.values, self.roughness, geometry)
        wl = self.grid.wavelength_nm
        substrate = brdf_reflectance_factor(
            np.full((1, wl.size), 0.05), [0.3], geometry
        )
        board = np.full((1, wl.size), 0.9)  # matte (Lambertian) white board
        return np.vstack([patches, substrate, board])

    def corners_px(self, geometry: Geometry) -> NDArray[np.float64]:
        """Truth: the target's outer corners (TL, TR, BR, BL) in the image."""
        from tunespec.core.layout import apply_homography

        H = self._homography(geometry)
        return apply_homography(H, self.layout.outer_corners_mm())

    def capture(self, exposure: float, key: int | None = None) -> NDArray[np.float32]:
        """One frame at the current geometry, light and ``exposure`` (relative).

        ``key`` seeds the frame's noise (with the bench's seed), so that a frame
        taken again after a resume has the noise it would have had; default: a
        counter.
        """
        g = self.geometry()
        cover = self._coverage(g)  # (n_regions, H, W)
        spd = self.light.emitted_spd().resample(self.grid, average=True).values[0]
        irr = spd * np.cos(np.radians(g.theta_i)) * exposure * self.gain
        rgb = self.reflectance_factors(g) @ (irr[:, None] * self.sensitivity.values.T)
        clean = np.einsum("rc,rhw->chw", rgb, cover)
        rng = np.random.default_rng(
            (self._seed, self._n_frames if key is None else key)
        )
        self._n_frames += 1
        noisy = clean + self.noise.pixel_std(clean) * rng.standard_normal(clean.shape)
        return np.minimum(noisy, 1.0).astype(np.float32)

    def _homography(self, geometry: Geometry) -> NDArray[np.float64]:
        shift = np.eye(3)
        shift[:2, 2] = [-self.layout.width_mm / 2, -self.layout.height_mm / 2]
        return view_homography(geometry, self.size_px, self.px_per_mm) @ shift

    def _coverage(self, geometry: Geometry) -> NDArray[np.float64]:
        """Fraction of each pixel covered by each region (2 x 2 supersampling)."""
        if geometry in self._regions:
            return self._regions[geometry]
        from tunespec.core.layout import apply_homography

        w, h = self.size_px
        n = self.layout.n_patches
        Hinv = np.linalg.inv(self._homography(geometry))
        cover = np.zeros((n + 2, h, w))
        quads = self.layout.patch_quads_mm()
        for dy in (0.25, 0.75):
            for dx in (0.25, 0.75):
                yy, xx = np.mgrid[0:h, 0:w]
                pts = np.stack([xx.ravel() + dx - 0.5, yy.ravel() + dy - 0.5], 1)
                mm = apply_homography(Hinv, pts)
                region = np.full(len(mm), n + 1)  # the white board
                inside = (
                    (mm[:, 0] >= 0) & (mm[:, 0] <= self.layout.width_mm)
                    & (mm[:, 1] >= 0) & (mm[:, 1] <= self.layout.height_mm)
                )  # fmt: skip
                region[inside] = n  # the substrate
                for p, q in enumerate(quads):
                    lo, hi = q.min(axis=0), q.max(axis=0)
                    hit = (mm >= lo).all(axis=1) & (mm <= hi).all(axis=1)
                    region[hit] = p
                cover += np.eye(n + 2)[region].T.reshape(n + 2, h, w) * 0.25
        self._regions[geometry] = cover
        return cover
