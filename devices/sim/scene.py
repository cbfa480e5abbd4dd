"""The simulated scene: a chart on a white board, lit at 45 degrees, seen from 0 degrees.

:class:`SimScene` is what is in front of the simulated camera. It implements the
:class:`~tunespec.devices.protocols.TargetStage` protocol: ``present("white")`` shows
the bare white background board (the flat-field frame of the paper's Eq. 2),
``present("target")`` the chart lying on that board.

Geometry (resolution independent, so the same scene serves any camera resolution):

- The image spans ``field_width_mm`` of the target plane horizontally (504 mm: a
  50 mm lens on a 36 mm wide sensor at the paper's 70 cm).
- The camera is not exactly perpendicular to the target, so the chart's rectangle
  lands on a trapezoid (``keystone``: the top edge is that fraction shorter than the
  bottom one), turned by ``rotation_deg`` and centred at ``centre_frac`` of the image.
  Any four corners define a homography, and the true corners are kept
  (:meth:`SimScene.corners_px`).
- The 45-degree illumination is not uniform: irradiance falls off quadratically from
  a point ``falloff_centre_frac`` of the image, by ``falloff`` (10 %, the paper's
  "irradiance-difference of approx. 10 % between center and margin") at
  ``falloff_radius_mm`` (default :data:`FALLOFF_RADIUS_MM`, the half-diagonal of
  the measurement area, a ColorChecker SG card). The fall-off belongs to the light
  and the bench, not to the target: every target sees the same irradiance field, so
  a calibration on the SG carries over to a sample captured later.

Materials are numbered for the renderer: 0 the background board, 1 the chart's frame
(the black card around and between the patches), ``2 + k`` the k-th patch of the
layout (row-major, as ``layout.patch_names``), then the palettes of the scene's
:class:`MixedRegion` s in order.

Spatial structure with known per-pixel reflectance: a :class:`MixedRegion` covers a
rectangle of the board beside the chart with a reflectance that changes from
superpixel to superpixel: a printed CMY halftone below the camera's resolution
(:meth:`MixedRegion.halftone`: smooth, painting-like ink-coverage fields; each
superpixel's reflectance is the Murray-Davies area average of the eight Neugebauer
primaries with Demichel's coverage weights), or juxtaposed strokes of measured
reflectances (:meth:`MixedRegion.strokes`: the 24 ColorChecker spectra N. Ohta
measured, mixed by smooth weights and overlaid by strokes). A superpixel's 2 x 2
photosites see the same material, so its reflectance is exactly known
(:meth:`SimScene.plane_materials`); the weights are quantised to a palette so the
renderer's per-material sums (Eq. 1) stay few.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import product
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tunespec.core.datasets import load_colorchecker_sg, resource_path
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.layout import TargetLayout, homography_from_corners
from tunespec.core.spectra import DEFAULT_GRID, Grid, Spectra

__all__ = [
    "BACKGROUND",
    "FALLOFF_RADIUS_MM",
    "FRAME",
    "MixedRegion",
    "SimScene",
    "default_regions",
    "white_board_reflectance",
]

#: Material index of the background board.
BACKGROUND = 0
#: Material index of the chart's frame and the gaps between patches.
FRAME = 1

#: Rows of the image handled at once when labelling pixels (bounds temporary memory).
_CHUNK_ROWS = 256


def white_board_reflectance(wavelength_nm: ArrayLike) -> NDArray[np.float64]:
    """A matte white board: 0.90, dropping a little towards the UV (flat-ish).

    Parameters
    ----------
    wavelength_nm : (n_wl,)

    Returns
    -------
    (n_wl,)
        Reflectance factor, 0.86 at 380 nm rising to 0.90 above 500 nm.
    """
    wl = np.asarray(wavelength_nm, dtype=np.float64)
    return 0.90 - 0.04 * np.exp(-(wl - 380.0) / 40.0)


#: Default radius of the 10 % irradiance fall-off: the half-diagonal of the measured
#: area, a ColorChecker SG card (279.4 x 215.9 mm).
FALLOFF_RADIUS_MM = 0.5 * math.hypot(279.4, 215.9)


class SimScene:
    """A chart (or the bare white board) in front of the simulated camera.

    Parameters
    ----------
    layout
        The chart's geometry (``corners_px`` is ignored: the scene places it).
    reflectances
        One spectrum per patch, named as ``layout.patch_names`` (other names are
        ignored).
    background
        The board's reflectance: a number (flat), a one-spectrum :class:`Spectra`, or
        ``None`` for :func:`white_board_reflectance`.
    frame
        Reflectance of the chart's frame and of the gaps between patches (a number
        or a one-spectrum :class:`Spectra`); 0.03 is a black card.
    field_width_mm
        Width of the target plane the image spans.
    centre_frac
        Where the chart's centre lands, as fractions of image width and height.
    keystone
        Relative difference of the top and bottom edge lengths (perspective).
    rotation_deg
        Rotation of the chart in the image, counter-clockwise on screen.
    falloff
        Relative irradiance drop at ``falloff_radius_mm`` from the brightest point.
    falloff_radius_mm
        Where the drop reaches ``falloff``; default :data:`FALLOFF_RADIUS_MM`.
    falloff_centre_frac
        The brightest point, as fractions of image width and height.
    presented
        What is shown at first.
    regions
        Areas of the board beside the chart with per-pixel reflectance
        (:class:`MixedRegion`, e.g. :func:`default_regions`).
    """

    def __init__(
        self,
        layout: TargetLayout,
        reflectances: Spectra,
        *,
        background: float | Spectra | None = None,
        frame: float | Spectra = 0.03,
        field_width_mm: float = 504.0,
        centre_frac: tuple[float, float] = (0.505, 0.49),
        keystone: float = 0.04,
        rotation_deg: float = 1.2,
        falloff: float = 0.10,
        falloff_radius_mm: float | None = None,
        falloff_centre_frac: tuple[float, float] = (0.53, 0.47),
        presented: Literal["white", "target"] = "target",
        regions: tuple[MixedRegion, ...] = (),
    ) -> None:
        if not field_width_mm > 0:
            raise ValueError("field_width_mm must be > 0")
        if not 0 <= falloff < 1:
            raise ValueError("falloff must be in [0, 1)")
        if not -0.5 < keystone < 0.5:
            raise ValueError("keystone must be in (-0.5, 0.5)")
        self.layout = layout.with_corners(None)
        patches = reflectances.select(layout.patch_names, source="scene reflectances")
        wl = patches.wavelength_nm
        bg = (
            white_board_reflectance(wl)
            if background is None
            else _as_spectrum(background, wl, "background")
        )
        fr = _as_spectrum(frame, wl, "frame")
        self.regions = tuple(regions)
        self._region_first: list[int] = []
        values = [bg[None], fr[None], patches.values]
        names = ["background", "frame", *patches.names]
        first = 2 + len(patches)
        for k, region in enumerate(self.regions):
            pal = region.palette(wl)
            self._region_first.append(first)
            values.append(pal)
            names += [f"region{k}_{i}" for i in range(len(pal))]
            first += len(pal)
        if first > np.iinfo(np.int16).max:
            raise ValueError(f"{first} materials: more than the label maps can hold")
        self.materials = Spectra(
            wl,
            np.vstack(values),
            tuple(names),
            {"source": reflectances.meta.get("source", "")},
        )
        self.field_width_mm = float(field_width_mm)
        self.centre_frac = (float(centre_frac[0]), float(centre_frac[1]))
        self.keystone = float(keystone)
        self.rotation_deg = float(rotation_deg)
        self.falloff = float(falloff)
        self.falloff_radius_mm = float(
            FALLOFF_RADIUS_MM if falloff_radius_mm is None else falloff_radius_mm
        )
        self.falloff_centre_frac = (
            float(falloff_centre_frac[0]),
            float(falloff_centre_frac[1]),
        )
        self._presented: Literal["white", "target"] = "target"
        self.present(presented)

    def bench_options(self) -> dict[str, object]:
        """The arguments that describe the bench, not the target on it.

        Camera pose and field of view, the light's irradiance field and the white
        background board: a scene for another target on the same bench takes these
        (``SimScene(other_layout, refl, **scene.bench_options())``), so the flat
        field and the shading stay those the calibration saw.
        """
        return {
            "background": Spectra(
                self.materials.wavelength_nm,
                self.materials.values[BACKGROUND : BACKGROUND + 1],
                ("background",),
            ),
            "field_width_mm": self.field_width_mm,
            "centre_frac": self.centre_frac,
            "keystone": self.keystone,
            "rotation_deg": self.rotation_deg,
            "falloff": self.falloff,
            "falloff_radius_mm": self.falloff_radius_mm,
            "falloff_centre_frac": self.falloff_centre_frac,
        }

    # -- factories ---------------------------------------------------------------
    @classmethod
    def colorchecker_sg(cls, grid: Grid = DEFAULT_GRID, **kwargs: object) -> SimScene:
        """The ColorChecker SG (14 x 10) with its shipped reflectances."""
        layout = TargetLayout.load(resource_path("layouts", "colorchecker_sg.json"))
        return cls(layout, load_colorchecker_sg(grid), **kwargs)  # type: ignore[arg-type]

    @classmethod
    def neugebauer_cmy(cls, grid: Grid = DEFAULT_GRID, **kwargs: object) -> SimScene:
        """The sample target: 8 CMY Neugebauer primaries (model reflectances)."""
        layout = TargetLayout.load(resource_path("layouts", "neugebauer_cmy.json"))
        refl = read_spectra_csv(
            resource_path("charts", "neugebauer_cmy_model.csv"), grid
        )
        return cls(layout, refl, **kwargs)  # type: ignore[arg-type]

    @classmethod
    def it8_7_2(
        cls, grid: Grid = DEFAULT_GRID, *, seed: int = 0, **kwargs: object
    ) -> SimScene:
        """The IT8.7/2 (shipped layout) with :func:`it8_bench_reflectances`."""
        layout = TargetLayout.load(resource_path("layouts", "it8_7_2.json"))
        refl = it8_bench_reflectances(layout.patch_names, grid, seed=seed)
        return cls(layout, refl, **kwargs)  # type: ignore[arg-type]

    # -- TargetStage -------------------------------------------------------------
    def present(self, what: Literal["white", "target"]) -> None:
        """Show the white board (``"white"``) or the chart on it (``"target"``)."""
        if what not in ("white", "target"):
            raise ValueError(f"present() takes 'white' or 'target', not {what!r}")
        self._presented = what

    @property
    def presented(self) -> Literal["white", "target"]:
        """What is in front of the camera now."""
        return self._presented

    @property
    def geometry_key(self) -> tuple[float, ...]:
        """Everything the pixel maps depend on (for caching them)."""
        return (
            self.field_width_mm,
            *self.centre_frac,
            self.keystone,
            self.rotation_deg,
            self.falloff,
            self.falloff_radius_mm,
            *self.falloff_centre_frac,
        )

    # -- geometry ------------------------------------------------------------------
    def px_per_mm(self, width_px: int) -> float:
        """Image scale on the target plane, mosaic pixels per mm."""
        return width_px / self.field_width_mm

    def corners_px(self, width_px: int, height_px: int) -> NDArray[np.float64]:
        """The chart's outer corners TL, TR, BR, BL in mosaic pixels, (4, 2) x/y.

        Pixel centres are at integer coordinates, x to the right, y down.
        """
        s = self.px_per_mm(width_px)
        hw = 0.5 * self.layout.width_mm * s
        hh = 0.5 * self.layout.height_mm * s
        k = 0.5 * self.keystone
        local = np.array(
            [
                [-hw * (1 - k), -hh],
                [hw * (1 - k), -hh],
                [hw * (1 + k), hh],
                [-hw * (1 + k), hh],
            ]
        )
        a = math.radians(self.rotation_deg)
        # counter-clockwise on screen, where y points down
        rot = np.array([[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]])
        centre = np.array(
            [
                self.centre_frac[0] * width_px - 0.5,
                self.centre_frac[1] * height_px - 0.5,
            ]
        )
        return local @ rot.T + centre

    def layout_px(self, width_px: int, height_px: int) -> TargetLayout:
        """The layout with its true corners in mosaic pixels."""
        return self.layout.with_corners(self.corners_px(width_px, height_px))

    def homography_px_to_mm(self, width_px: int, height_px: int) -> NDArray[np.float64]:
        """3x3 homography from mosaic pixels to chart millimetres."""
        return homography_from_corners(
            self.corners_px(width_px, height_px), self.layout.outer_corners_mm()
        )

    def irradiance(
        self, x_px: ArrayLike, y_px: ArrayLike, width_px: int, height_px: int
    ) -> NDArray[np.float64]:
        """Relative irradiance (1 at the brightest point) at mosaic pixels.

        Parameters
        ----------
        x_px, y_px
            Broadcastable pixel coordinates.

        Returns
        -------
        Broadcast shape, float32 for float32 input, else float64
            ``1 - falloff * (d / falloff_radius_mm)**2`` with ``d`` the distance on the
            target plane, floored at 0.05.
        """
        x, y = _float_arrays(x_px, y_px)
        cx = self.falloff_centre_frac[0] * width_px - 0.5
        cy = self.falloff_centre_frac[1] * height_px - 0.5
        r_px = self.falloff_radius_mm * self.px_per_mm(width_px)
        d2 = (x - cx) ** 2 + (y - cy) ** 2
        d2 *= self.falloff / (r_px * r_px)
        return np.maximum(1.0 - d2, 0.05)

    def labels(
        self,
        x_px: NDArray[np.floating],
        y_px: NDArray[np.floating],
        width_px: int,
        height_px: int,
    ) -> NDArray[np.int16]:
        """Material index at each pixel centre of the grid ``y_px x x_px``.

        Parameters
        ----------
        x_px : (nx,)
            Column coordinates (mosaic pixels).
        y_px : (ny,)
            Row coordinates.

        Returns
        -------
        (ny, nx) int16
            :data:`BACKGROUND`, :data:`FRAME` or ``2 + patch index``; all
            :data:`BACKGROUND` when the white board is presented.
        """
        x = np.asarray(x_px, dtype=np.float64).ravel()
        y = np.asarray(y_px, dtype=np.float64).ravel()
        out = np.zeros((y.size, x.size), dtype=np.int16)
        if self._presented == "white":
            return out
        H = self.homography_px_to_mm(width_px, height_px).astype(np.float32)
        lay = self.layout
        ml, mt, _, _ = lay.margin_mm
        cw, ch = lay.cell_size_mm()
        hx, hy = 0.5 * lay.patch_fraction * cw, 0.5 * lay.patch_fraction * ch
        xr = x.astype(np.float32)[None, :]
        for r0 in range(0, y.size, _CHUNK_ROWS):
            yc = y[r0 : r0 + _CHUNK_ROWS].astype(np.float32)[:, None]
            w = H[2, 0] * xr + H[2, 1] * yc + H[2, 2]
            u = (H[0, 0] * xr + H[0, 1] * yc + H[0, 2]) / w
            v = (H[1, 0] * xr + H[1, 1] * yc + H[1, 2]) / w
            inside = (u >= 0) & (u < lay.width_mm) & (v >= 0) & (v < lay.height_mm)
            gx = (u - ml) / cw
            gy = (v - mt) / ch
            col = np.floor(gx)
            row = np.floor(gy)
            in_patch = (
                inside
                & (col >= 0)
                & (col < lay.cols)
                & (row >= 0)
                & (row < lay.rows)
                & (np.abs(gx - col - 0.5) * cw <= hx)
                & (np.abs(gy - row - 0.5) * ch <= hy)
            )
            block = out[r0 : r0 + _CHUNK_ROWS]
            block[inside] = FRAME
            idx = (row * lay.cols + col)[in_patch].astype(np.int16)
            block[in_patch] = idx + 2
            _paint_extra_grids(block, u, v, lay)
        for region, first in zip(self.regions, self._region_first, strict=True):
            region.paint(out, x, y, width_px, height_px, first)
        return out

    def plane_materials(self, width_px: int, height_px: int) -> NDArray[np.int16]:
        """Material of each 2 x 2 superpixel (plane pixel), -1 where its photosites
        see different materials (edges), shape (height / 2, width / 2).

        With :attr:`materials` this is the per-pixel truth of the reflectance.
        """
        sites = [
            self.labels(
                np.arange(dx, width_px, 2), np.arange(dy, height_px, 2),
                width_px, height_px,
            )
            for dy, dx in ((0, 0), (0, 1), (1, 0), (1, 1))
        ]  # fmt: skip
        out = sites[0].copy()
        for other in sites[1:]:
            out[other != sites[0]] = -1
        return out

    def describe(self) -> dict[str, object]:
        """The scene's parameters, for the truth file."""
        return {
            "chart": self.layout.name,
            "presented": self._presented,
            "field_width_mm": self.field_width_mm,
            "centre_frac": list(self.centre_frac),
            "keystone": self.keystone,
            "rotation_deg": self.rotation_deg,
            "falloff": self.falloff,
            "falloff_radius_mm": self.falloff_radius_mm,
            "falloff_centre_frac": list(self.falloff_centre_frac),
            "materials": [*self.materials.names[:2], "<patches>"],
            "regions": [r.describe() for r in self.regions],
        }


def _float_arrays(
    x: ArrayLike, y: ArrayLike
) -> tuple[NDArray[np.floating], NDArray[np.floating]]:
    """``x, y`` as float arrays, float32 kept (the pixel maps are float32)."""
    xa, ya = np.asarray(x), np.asarray(y)
    if xa.dtype == np.float32 and ya.dtype == np.float32:
        return xa, ya
    return xa.astype(np.float64), ya.astype(np.float64)


def _as_spectrum(
    value: float | Spectra, wavelength_nm: NDArray[np.float64], what: str
) -> NDArray[np.float64]:
    """A number or a one-spectrum Spectra as values on ``wavelength_nm``."""
    if isinstance(value, Spectra):
        if len(value) != 1:
            raise ValueError(f"{what}: expected one spectrum, got {len(value)}")
        return np.interp(wavelength_nm, value.wavelength_nm, value.values[0])
    v = float(value)
    if not 0 <= v <= 1.5:
        raise ValueError(f"{what}: reflectance {v} out of range")
    return np.full(wavelength_nm.shape, v)


@dataclass(frozen=True, eq=False)
class MixedRegion:
    """A rectangle of the board whose reflectance varies per superpixel.

    Every superpixel takes one palette entry: a mixture ``sum_i w_i r_i`` of the
    ``primaries`` with weights from smooth, seeded fields (see :meth:`halftone` and
    :meth:`strokes`), quantised to ``levels`` steps. Linear mixing is exact for
    areas finer than a pixel (a halftone's dots, juxtaposed strokes: the Murray-
    Davies average), which is what a superpixel integrates.

    Parameters
    ----------
    box_frac
        ``(x0, y0, x1, y1)`` of the rectangle, fractions of image width and height.
    primaries
        The reflectances mixed.
    kind
        ``"halftone"``: ``primaries`` are the 8 Neugebauer primaries of CMY (as
        ``charts/neugebauer_cmy_model.csv``, ``CcMmYy`` names) mixed by Demichel
        weights of three coverage fields; ``"strokes"``: any spectra mixed by
        normalised weight fields.
    levels
        Quantisation steps per coverage (halftone) or of the weights (strokes).
    seed
        Seeds the fields.
    """

    box_frac: tuple[float, float, float, float]
    primaries: Spectra
    kind: Literal["halftone", "strokes"] = "halftone"
    levels: int = 8
    seed: int = 0

    def __post_init__(self) -> None:
        x0, y0, x1, y1 = self.box_frac
        if not (0 <= x0 < x1 <= 1 and 0 <= y0 < y1 <= 1):
            raise ValueError(f"box_frac {self.box_frac}: expected 0 <= x0 < x1 <= 1")
        if self.kind not in ("halftone", "strokes") or not 2 <= self.levels <= 32:
            raise ValueError("kind 'halftone' or 'strokes', levels 2..32")
        if self.kind == "halftone" and len(self.primaries) != 8:
            raise ValueError("a halftone mixes the 8 Neugebauer primaries of CMY")

    # -- factories ---------------------------------------------------------------
    @classmethod
    def halftone(
        cls, box_frac: tuple[float, float, float, float], grid: Grid, seed: int = 0
    ) -> MixedRegion:
        """A CMY halftone print (the shipped Neugebauer primaries)."""
        refl = read_spectra_csv(
            resource_path("charts", "neugebauer_cmy_model.csv"), grid
        )
        order = ("C0M0Y0", "C1M0Y0", "C0M1Y0", "C1M1Y0",
                 "C0M0Y1", "C1M0Y1", "C0M1Y1", "C1M1Y1")  # fmt: skip
        return cls(box_frac, refl.select(order), "halftone", 8, seed)

    @classmethod
    def strokes(
        cls, box_frac: tuple[float, float, float, float], grid: Grid, seed: int = 1
    ) -> MixedRegion:
        """Strokes of six measured reflectances (ColorChecker, N. Ohta's data in
        colour-science): dark skin, blue, green, red, yellow, white."""
        import colour

        data = colour.SDS_COLOURCHECKERS["ColorChecker N Ohta"]
        names = ("dark skin", "blue", "green", "red", "yellow", "white 9.5 (.05 D)")
        wl = grid.wavelength_nm
        vals = np.stack(
            [np.interp(wl, data[n].wavelengths, data[n].values) for n in names]
        )
        spectra = Spectra(wl, vals, names, {"source": "colour-science, N. Ohta"})
        return cls(box_frac, spectra, "strokes", 5, seed)

    # -- palette -------------------------------------------------------------------
    def _weights(self) -> NDArray[np.float64]:
        """(n_palette, n_primaries) mixing weights of every palette entry."""
        q = self.levels
        if self.kind == "halftone":
            cov = np.array(list(product(range(q), repeat=3)), dtype=float) / (q - 1)
            c, m, y = cov.T
            cols = []
            for bits in product((0, 1), repeat=3):  # Demichel: (y, m, c) bits
                by, bm, bc = bits
                cols.append(
                    (c if bc else 1 - c) * (m if bm else 1 - m) * (y if by else 1 - y)
                )
            # columns c fastest, then m, then y: the primaries' order (CcMmYy)
            return np.stack(cols, axis=1)
        k = len(self.primaries)
        comps = [p for p in product(range(q + 1), repeat=k) if sum(p) == q]
        return np.array(comps, dtype=float) / q

    def palette(self, wavelength_nm: NDArray[np.float64]) -> NDArray[np.float64]:
        """Reflectance of every palette entry on ``wavelength_nm``, (n, n_wl)."""
        prim = np.stack(
            [np.interp(wavelength_nm, self.primaries.wavelength_nm, v)
             for v in self.primaries.values]
        )  # fmt: skip
        return self._weights() @ prim

    def _fields(self, u: NDArray[np.float64], v: NDArray[np.float64], n: int):
        """``n`` smooth fields in [0, 1] at region coordinates ``u, v`` in [0, 1]:
        two seeded waves each plus seeded elliptic strokes of constant value."""
        rng = np.random.default_rng(self.seed)
        out = []
        for _ in range(n):
            f = np.full(np.broadcast(u, v).shape, 0.5)
            for _ in range(2):
                kx, ky = rng.uniform(-3.0, 3.0, 2)
                ph = rng.uniform(0, 2 * np.pi)
                f = f + 0.25 * np.sin(2 * np.pi * (kx * u + ky * v) + ph)
            for _ in range(3):
                cx, cy = rng.uniform(0.1, 0.9, 2)
                ax, ay = rng.uniform(0.05, 0.2, 2)
                val = rng.uniform(0, 1)
                inside = ((u - cx) / ax) ** 2 + ((v - cy) / ay) ** 2 <= 1
                f = np.where(inside, val, f)
            out.append(np.clip(f, 0.0, 1.0))
        return out

    def index(
        self, u: NDArray[np.float64], v: NDArray[np.float64]
    ) -> NDArray[np.int64]:
        """Palette entry at region coordinates ``u, v`` (each in [0, 1])."""
        q = self.levels
        if self.kind == "halftone":
            c, m, y = self._fields(u, v, 3)
            ic, im, iy = (np.rint(f * (q - 1)).astype(np.int64) for f in (c, m, y))
            return (ic * q + im) * q + iy
        k = len(self.primaries)
        w = np.stack(self._fields(u, v, k)) ** 3  # sharpen: few pigments dominate
        w /= np.maximum(w.sum(axis=0), 1e-12)
        # largest remainder: integer parts that sum to q
        scaled = w * q
        base = np.floor(scaled).astype(np.int64)
        rem = scaled - base
        short = q - base.sum(axis=0)
        rank = np.argsort(np.argsort(-rem, axis=0), axis=0)
        base += rank < short
        # palette index through a mixed-radix code of the composition
        radix = (q + 1) ** np.arange(k)[::-1]
        lut = np.full((q + 1) ** k, -1, dtype=np.int64)
        comps = np.array([p for p in product(range(q + 1), repeat=k) if sum(p) == q])
        lut[comps @ radix] = np.arange(len(comps))
        code = np.tensordot(radix, base, axes=(0, 0))
        return lut[code]

    def paint(
        self,
        out: NDArray[np.int16],
        x_px: NDArray[np.float64],
        y_px: NDArray[np.float64],
        width_px: int,
        height_px: int,
        first: int,
    ) -> None:
        """Label the board's pixels inside the rectangle with palette materials.

        Uses each pixel's superpixel centre, so the four photosites of a 2 x 2 cell
        get the same material; the chart (frame and patches) is left as it is.
        """
        x0, y0, x1, y1 = self.box_frac
        xs = (np.floor(x_px / 2) * 2 + 0.5) / width_px
        ys = (np.floor(y_px / 2) * 2 + 0.5) / height_px
        cols = np.flatnonzero((xs >= x0) & (xs < x1))
        rows = np.flatnonzero((ys >= y0) & (ys < y1))
        if cols.size == 0 or rows.size == 0:
            return
        u = (xs[cols] - x0) / (x1 - x0)
        v = (ys[rows] - y0) / (y1 - y0)
        idx = self.index(u[None, :], v[:, None]) + first
        sub = out[np.ix_(rows, cols)]
        board = sub == BACKGROUND
        sub[board] = idx[board].astype(np.int16)
        out[np.ix_(rows, cols)] = sub

    def describe(self) -> dict[str, object]:
        """Parameters for the truth file."""
        return {
            "kind": self.kind,
            "box_frac": list(self.box_frac),
            "primaries": list(self.primaries.names),
            "levels": self.levels,
            "seed": self.seed,
        }


def default_regions(grid: Grid = DEFAULT_GRID) -> tuple[MixedRegion, MixedRegion]:
    """A CMY halftone left of the chart and measured-reflectance strokes right of it
    (for the default scene geometry, where the SG spans x = 0.23-0.78)."""
    return (
        MixedRegion.halftone((0.02, 0.1, 0.2, 0.9), grid),
        MixedRegion.strokes((0.8, 0.1, 0.98, 0.9), grid),
    )


def it8_bench_reflectances(
    names: tuple[str, ...], grid: Grid = DEFAULT_GRID, *, seed: int = 0
) -> Spectra:
    """Reflectances for an IT8.7/2 on the bench, drawn from measured sets.

    IT8 reference values are batch-specific (each batch comes with its own CGATS
    file) and not shippable, so the simulated chart takes measured spectra instead:
    every colour field (``A01`` ... ``L22``) one of the 164 measured spectra of the
    ColorChecker SG (ISETCam, MIT) and the ColorChecker 24 (N. Ohta via
    colour-science, BSD-3-Clause), drawn with a seeded generator (all 164 once, 100
    again); the grey scale ``GS00`` ... ``GS23`` the ColorChecker 24's measured white
    (``D1``) at optical densities 0 ... 2.4 in equal steps (GS23 ~ 0.4 %, the
    IT8's Dmax).
    """
    sg = load_colorchecker_sg(grid)
    cc = read_spectra_csv(resource_path("charts", "colorchecker_24.csv"), grid)
    pool = np.vstack([sg.values, cc.values])
    grey_names = [n for n in names if n.startswith("GS")]
    colour_names = [n for n in names if not n.startswith("GS")]
    rng = np.random.default_rng(seed)
    extra = max(len(colour_names) - len(pool), 0)
    order = np.concatenate(
        [rng.permutation(len(pool)), rng.integers(0, len(pool), extra)]
    )[: len(colour_names)]
    white = cc.values[cc.names.index("D1")]
    density = np.linspace(0.0, 2.4, len(grey_names))
    values = dict(zip(colour_names, pool[order], strict=True))
    values.update(zip(grey_names, white[None] * 10.0 ** -density[:, None], strict=True))
    return Spectra(
        sg.wavelength_nm,
        np.array([values[n] for n in names]),
        tuple(names),
        {"source": "IT8 bench: ColorChecker SG (ISETCam) + 24 (Ohta) spectra"},
    )


def _paint_extra_grids(
    block: NDArray[np.int16],
    u: NDArray[np.float32],
    v: NDArray[np.float32],
    lay: TargetLayout,
) -> None:
    """Label the patches of ``lay.extra_grids`` at chart coordinates ``(u, v)`` mm."""
    first = 2 + lay.rows * lay.cols
    for g in lay.extra_grids:
        px = g.pitch_x_mm if g.cols > 1 else g.patch_w_mm
        py = g.pitch_y_mm if g.rows > 1 else g.patch_h_mm
        col = np.floor((u - g.x_mm) / px)
        row = np.floor((v - g.y_mm) / py)
        in_patch = (
            (col >= 0)
            & (col < g.cols)
            & (row >= 0)
            & (row < g.rows)
            & (u - g.x_mm - col * px < g.patch_w_mm)
            & (v - g.y_mm - row * py < g.patch_h_mm)
        )
        block[in_patch] = (first + row * g.cols + col)[in_patch].astype(np.int16)
        first += g.n_patches
