"""Per-pixel Wiener estimation: a reflectance spectrum for every superpixel (Eq. 5).

The patch-wise estimate (:mod:`tunespec.core.wiener`) solves Eq. 5 once per patch
with the noise covariance ``K_e`` of Eq. 6. An image has millions of pixels, each
with its own, signal-dependent noise, and one linear solve per pixel would cost a
66 x 66 factorisation per pixel. This module makes the per-pixel estimate a batched
matrix product:

**Noise model (photon + read).** The dark-subtracted plane value ``s`` of a
superpixel (full-scale units, :mod:`tunespec.core.io.raw`) has variance
``a_k + b_k s`` per colour channel ``k``: ``b_k`` the photon (shot) term, one over
the electrons per full scale (halved for G, the mean of two photosites), ``a_k`` the
read noise of the frame and of the subtracted dark. :class:`NoiseModel` holds
``a, b``; :func:`photon_transfer_fit` fits them to the session's own white frames
(a photon-transfer curve, EMVA 1288 Sec. 6) where the sensor is unknown, and
:meth:`NoiseModel.from_camera` takes them from the sensor's figures. After the flat
field (Eq. 2) a response is ``c = f s`` with ``f = mean(A_B) / A_B`` the flat-field
factor, so ``var(c) = f^2 a + f b c``.

**The approximation (binning by signal level).** Per pixel the noise variances of
the ``3 n_i`` responses follow from two scalars: the flat-field factor ``phi`` of
the pixel (common to all responses: the light field's shape is the LEDs' common
geometry and the lens's vignetting) and its level ``rho = sum_k c_k / sum_k w_k``
(``w_k`` the white board's Eq. 2 normaliser, so ``rho`` is a brightness relative to
the white board, dominated by the bright responses and so hardly noisy). Responses are modelled as
``c_k ~= rho w_k``, so ``K_e(rho, phi) = diag(phi^2 a + phi b rho w)``, and
``(rho, phi)`` is quantised into bins (levels uniform in ``sqrt(rho)``, as photon
noise is; ``phi`` geometric). Each bin has one Wiener matrix ``W_b = K F^T (F K F^T +
K_e)^-1``; every pixel of the bin is one column of ``W_b C``. What the
approximation neglects is the colour of a pixel (its responses are not all
``rho w``) and the spread of ``(rho, phi)`` within a bin;
:func:`wiener_pixels_exact` solves each pixel with its own
``K_e = diag(phi^2 a + phi b c)`` for measuring that error
(``benchmarks/bench_image.py`` reports it, a test bounds it).

**Uncertainty.** The posterior covariance of bin ``b``,
``P_b = K - K F^T (F K F^T + K_e)^-1 F K``, is the error covariance of the pixels
of the bin (prior and modelled noise, the flat-field residual
:data:`~tunespec.core.uncertainty.FLAT_FIELD_RESIDUAL` included in ``K_e``). Its mean
diagonal gives the RMS uncertainty of the spectrum and ``T^T P_b T`` (ASTM E308 D50
weights ``T``) that of XYZ, from which ``u(L*)`` follows by the derivative of L*.
The flat-field residual is also added as what it physically is, a ratio of
irradiances common to all responses of a pixel (``u(Y) = 0.003 Y``), which the
averaging over LEDs does not reduce.

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source (``shared/reference``),
Eq. 1, 2, 5 and 6. EMVA Standard 1288, Release 4.0 (2021), Sec. 6 (photon transfer).
JCGM 100:2008 (GUM) Sec. 5 (propagation of uncertainty).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tunespec.core.errors import InputError, SingularSystemError
from tunespec.core.image_bins import apply_bank
from tunespec.core.scratch import scratch
from tunespec.core.wiener import solve_with_noise

__all__ = [
    "DEFAULT_LEVEL_BINS",
    "DEFAULT_PHI_BINS",
    "NoiseModel",
    "PixelEstimate",
    "SensorFigures",
    "WienerBank",
    "block_noise_stats",
    "build_wiener_bank",
    "estimate_pixels",
    "lab_from_xyz",
    "photon_transfer_fit",
    "srgb8_from_xyz_d50",
    "wiener_pixels_exact",
]

#: Bins of the level ``rho`` (uniform in sqrt(rho) from 0 to the brightest level).
DEFAULT_LEVEL_BINS = 32
#: Bins of the flat-field factor ``phi`` (geometric over the session's range).
DEFAULT_PHI_BINS = 4
#: Relative floor of the noise variances (as ``core.wiener.RIDGE_RELATIVE``).
RIDGE_RELATIVE = 1e-10
#: Variance given to a saturated response in the exact solve (full scale^2).
SATURATED_VARIANCE = 1e6
#: Pixels per batched solve in :func:`wiener_pixels_exact`.
_EXACT_CHUNK = 512
#: CIE L* constants (CIE 015:2018): ``f(t) = t^(1/3)`` above ``(6/29)^3``.
_LAB_EPS = (6.0 / 29.0) ** 3
#: ICC D50 white (Y = 100), as :func:`tunespec.core.colorimetry.xyz_to_lab_d50`.
_D50_WHITE = np.array([96.42, 100.0, 82.49])
#: XYZ (D50) to linear sRGB: Bradford D50 -> D65 then IEC 61966-2-1's matrix.
_XYZ_D50_TO_SRGB = np.array(
    [
        [3.1338561, -1.6168667, -0.4906146],
        [-0.9787684, 1.9161415, 0.0334540],
        [0.0719453, -0.2289914, 1.4052427],
    ]
)


# -- noise model -----------------------------------------------------------------------
@dataclass(frozen=True)
class NoiseModel:
    """Photon and read noise of dark-subtracted plane values, per colour channel.

    ``var(s_k) = read_var[k] + shot_gain[k] * s_k`` for a plane value ``s_k``
    (full-scale units, dark subtracted) of channel ``k`` = R, G, B.

    Parameters
    ----------
    read_var : (3,)
        Signal-independent variance, full scale^2 (read noise of the frame and of the
        subtracted dark average, quantisation).
    shot_gain : (3,)
        Variance per unit signal, full scale (one over the electrons per full scale,
        halved for the two-photosite G plane).
    source : str
        Where it came from: ``"camera"`` or ``"photon-transfer fit"``.
    fit_rms : float
        Relative RMS residual of the photon-transfer fit (0 for a camera model).
    """

    read_var: NDArray[np.float64]
    shot_gain: NDArray[np.float64]
    source: str = "camera"
    fit_rms: float = 0.0

    def __post_init__(self) -> None:
        a = np.asarray(self.read_var, dtype=np.float64).reshape(3)
        b = np.asarray(self.shot_gain, dtype=np.float64).reshape(3)
        if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
            raise InputError("noise model: non-finite read or shot variance")
        if np.any(a < 0) or np.any(b < 0) or not np.any(a + b > 0):
            raise InputError("noise model: variances must be >= 0 and not all zero")
        object.__setattr__(self, "read_var", a)
        object.__setattr__(self, "shot_gain", b)

    @classmethod
    def from_camera(
        cls,
        *,
        full_well_e: float,
        read_noise_e: float,
        n_darks: int = 1,
        iso_gain: float = 1.0,
        n_frames: int = 1,
    ) -> NoiseModel:
        """The model of a sensor from its figures.

        Parameters
        ----------
        full_well_e
            Electrons at full scale (white level) at the base ISO.
        read_noise_e
            Read noise, electrons RMS.
        n_darks
            Dark frames averaged and subtracted (their read noise adds
            ``1 / n_darks`` of a frame's).
        iso_gain
            ISO / base ISO (electrons per full scale shrink by it).
        n_frames
            Frames averaged at each exposure (repeats): their photon and read
            noise variance is ``1 / n_frames`` of one frame's.

        Examples
        --------
        >>> m = NoiseModel.from_camera(full_well_e=67000, read_noise_e=30)
        >>> float(m.shot_gain[0] * 67000), float(m.shot_gain[1] * 67000)
        (1.0, 0.5)
        """
        fs_e = float(full_well_e) / float(iso_gain)
        if not (fs_e > 0 and read_noise_e >= 0 and n_darks >= 1 and n_frames >= 1):
            raise InputError(
                "noise model: full well > 0, read noise >= 0, n_darks >= 1, "
                "n_frames >= 1"
            )
        sites = np.array([1.0, 2.0, 1.0])  # photosites averaged per plane (R, G, B)
        read = (float(read_noise_e) / fs_e) ** 2 * (1.0 / n_frames + 1.0 / n_darks)
        return cls(read / sites, (1.0 / fs_e) / sites / n_frames, "camera")

    def variance(
        self, signal: ArrayLike, phi: ArrayLike = 1.0, channel_index: ArrayLike = ...
    ) -> NDArray[np.float64]:
        """``phi^2 a + phi b c`` for flat-fielded responses ``c`` (negative -> 0).

        Parameters
        ----------
        signal : (..., 3) or (..., m) with ``channel_index`` (m,)
            Flat-fielded responses.
        phi
            Flat-field factor(s), broadcast against ``signal``.
        channel_index
            For responses ordered otherwise than R, G, B: the channel of each.
        """
        c = np.maximum(np.asarray(signal, dtype=np.float64), 0.0)
        a = self.read_var if channel_index is ... else self.read_var[channel_index]
        b = self.shot_gain if channel_index is ... else self.shot_gain[channel_index]
        p = np.asarray(phi, dtype=np.float64)
        return p * p * a + p * b * c


@dataclass(frozen=True)
class SensorFigures:
    """A sensor's data-sheet figures; :meth:`model` is its :class:`NoiseModel` once
    the number of averaged darks is known (from the session).

    Parameters
    ----------
    full_well_e
        Electrons at full scale at the base ISO.
    read_noise_e
        Read noise, electrons RMS.
    iso_gain
        ISO of the session / base ISO.
    """

    full_well_e: float
    read_noise_e: float
    iso_gain: float = 1.0

    def __post_init__(self) -> None:
        ok = [math.isfinite(float(v)) for v in (self.full_well_e, self.read_noise_e)]
        if not (
            all(ok)
            and self.full_well_e > 0
            and self.read_noise_e >= 0
            and self.iso_gain > 0
        ):
            raise InputError(
                f"sensor figures: full well {self.full_well_e:g} e- (> 0), read noise "
                f"{self.read_noise_e:g} e- (>= 0), ISO gain {self.iso_gain:g} (> 0)"
            )

    def model(self, n_darks: int = 1, n_frames: int = 1) -> NoiseModel:
        """The noise model with ``n_darks`` dark frames averaged and subtracted from
        the mean of ``n_frames`` repeated frames."""
        return NoiseModel.from_camera(
            full_well_e=self.full_well_e,
            read_noise_e=self.read_noise_e,
            n_darks=n_darks,
            iso_gain=self.iso_gain,
            n_frames=n_frames,
        )


def block_noise_stats(
    planes: NDArray[np.floating],
    saturated: NDArray[np.bool_] | None = None,
    block_px: int = 16,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Mean level and noise variance of flat image blocks (one photon-transfer point
    per block and channel).

    The variance is half the variance of the differences of horizontally adjacent
    pixels (EMVA 1288's difference method, applied within a frame): a smooth light
    field only shifts the differences' mean, the noise of both pixels adds.

    Parameters
    ----------
    planes : (3, H, W)
        Dark-subtracted planes of a uniformly lit frame (the white board).
    saturated : (H, W) bool, optional
        Clipped cells; blocks holding one are left out.
    block_px
        Block side in plane pixels.

    Returns
    -------
    level, variance : (3, n_blocks)
    """
    _, h, w = planes.shape
    hb, wb = h // block_px, w // block_px
    if hb < 1 or wb < 1:
        raise InputError(f"planes {w}x{h} are smaller than one {block_px} px block")
    # every ``row_step``-th row of blocks: a few thousand blocks per frame are plenty
    row_step = max(1, (hb * wb) // 4000)
    rows = np.arange(0, hb, row_step)
    x = planes[:, : hb * block_px, : wb * block_px].reshape(
        3, hb, block_px, wb, block_px
    )
    # float32 (numpy's pairwise sums and two-pass variance keep ~1e-7 relative over
    # a block's 256 values): float64 copies of the rows cost more in fresh pages
    # than the statistics themselves. Each block's pixels contiguous: the sums run
    # along the last axis (a third faster than over two strided axes). The blocks
    # and their differences in this thread's scratch buffers (12 MB each: fresh
    # pages every frame cost as much as the sums)
    shape = (3, rows.size, wb, block_px, block_px)
    blocks = scratch("ptc_blocks", shape)
    for k in range(3):  # strided views of the rows: no copy of them first
        np.copyto(blocks[k], x[k, ::row_step].transpose(0, 2, 1, 3))
    n = rows.size * wb
    level = blocks.reshape(3, n, -1).mean(axis=2, dtype=np.float64)
    d = scratch("ptc_diff", (*shape[:4], block_px - 1))
    np.subtract(blocks[..., 1:], blocks[..., :-1], out=d)
    d = d.reshape(3, n, -1)
    # the variance (not the mean square) of the differences: a gradient of the
    # light field across the block shifts their mean, not their spread. Two
    # passes, the deviations in float32 and their squares summed in float64
    # (numpy's var makes a float64 copy of the deviations: 25 MB fresh a frame)
    d -= d.mean(axis=2, dtype=np.float64).astype(np.float32)[..., None]
    var = 0.5 / d.shape[2] * np.einsum("ijk,ijk->ij", d, d, dtype=np.float64)
    keep = np.ones(rows.size * wb, dtype=bool)
    if saturated is not None:
        s = saturated[: hb * block_px, : wb * block_px].reshape(
            hb, block_px, wb, block_px
        )
        keep = ~s[rows].any(axis=(1, 3)).ravel()
    return level[:, keep], var[:, keep]


def photon_transfer_fit(
    level: ArrayLike, variance: ArrayLike, *, n_bins: int = 40
) -> NoiseModel:
    """Fit ``variance = a_k + b_k level`` per channel (photon transfer curve).

    The points (e.g. :func:`block_noise_stats` of every white frame of a session,
    each LED giving other levels) are grouped into ``n_bins`` level bins whose
    median variance is fitted by weighted least squares (weights 1 / variance^2,
    so the read-noise floor is not swamped by the bright end); the median makes the
    fit robust against blocks with structure (dust, an edge).

    Parameters
    ----------
    level, variance : (3, n)
        Mean level and noise variance of flat blocks, full-scale units.
    n_bins
        Level bins per channel.

    Returns
    -------
    NoiseModel
        ``source = "photon-transfer fit"``; ``fit_rms`` the relative RMS residual.

    Raises
    ------
    InputError
        Fewer than 3 populated level bins in a channel, or a fit without a positive
        photon term.

    References
    ----------
    EMVA Standard 1288, Release 4.0 (2021), Sec. 6.3 (photon transfer method).

    Examples
    --------
    >>> import numpy as np
    >>> lv = np.tile(np.linspace(0.01, 0.8, 200), (3, 1))
    >>> m = photon_transfer_fit(lv, 1e-6 + 2e-5 * lv)
    >>> np.allclose(m.shot_gain, 2e-5), np.allclose(m.read_var, 1e-6)
    (True, True)
    """
    lv = np.asarray(level, dtype=np.float64)
    vr = np.asarray(variance, dtype=np.float64)
    if lv.shape != vr.shape or lv.ndim != 2 or lv.shape[0] != 3:
        raise InputError(f"photon transfer: expected (3, n) levels, got {lv.shape}")
    a = np.zeros(3)
    b = np.zeros(3)
    resid: list[float] = []
    for k in range(3):
        ok = np.isfinite(lv[k]) & np.isfinite(vr[k]) & (lv[k] > 0) & (vr[k] > 0)
        x, y = lv[k, ok], vr[k, ok]
        if x.size < 3:
            raise InputError(
                f"photon transfer fit: only {x.size} usable white-frame block(s) in "
                f"channel {'RGB'[k]}"
            )
        edges = np.quantile(x, np.linspace(0.0, 1.0, n_bins + 1))
        idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, n_bins - 1)
        xs, ys = [], []
        for i in range(n_bins):
            sel = idx == i
            if np.count_nonzero(sel) >= 3:
                xs.append(np.median(x[sel]))
                ys.append(np.median(y[sel]))
        if len(xs) < 3:
            raise InputError(
                f"photon transfer fit: the white frames cover too few levels in "
                f"channel {'RGB'[k]}"
            )
        X = np.array(xs)
        Y = np.array(ys)
        w = 1.0 / Y
        A = np.stack([np.ones_like(X), X], axis=1) * w[:, None]
        coef, *_ = np.linalg.lstsq(A, Y * w, rcond=None)
        a[k], b[k] = max(coef[0], 0.0), coef[1]
        if not b[k] > 0:
            raise InputError(
                f"photon transfer fit: no photon noise found in channel {'RGB'[k]} "
                "(the white frames' noise does not grow with the signal)"
            )
        resid.extend(((a[k] + b[k] * X) / Y - 1.0).tolist())
    return NoiseModel(
        a, b, "photon-transfer fit", float(np.sqrt(np.mean(np.square(resid))))
    )


# -- the bank of Wiener matrices -------------------------------------------------------
@dataclass(frozen=True, eq=False)
class WienerBank:
    """Wiener matrices of Eq. 5 for a grid of noise levels (see the module notes).

    Parameters
    ----------
    wavelength_nm : (n_wl,)
        The samples the pixels' spectra are reported on.
    F : (m, n_s)
        Lighting matrix of Eq. 5 (``m = 3 n_i``, illuminant-major), on the samples
        Eq. 5 solves for (:func:`tunespec.core.wiener.support_grid`: ``n_s >=
        n_wl``, the reported ones among them).
    mean : (n_s,)
        Prior mean.
    K : (n_s, n_s)
        Prior covariance.
    white : (m,)
        ``w``: the white board's Eq. 2 normaliser of each response (full scale).
    channel_index : (m,) int
        Colour channel (0, 1, 2) of each response.
    noise : NoiseModel
    flat_residual : float
        Relative flat-field residual added to ``K_e`` (and so to the uncertainty).
    level_edges : (n_lev + 1,)
        Bin edges of ``rho``; ``phi_edges`` : (n_phi + 1,) those of ``phi``.
    Wt : (n_bins, m, n_wl) float32
        The bins' Wiener matrices, transposed (pixels are rows: ``r^T = c^T W^T``),
        ``b = level_bin * n_phi + phi_bin``.
    offset : (n_bins, n_wl) float32
        ``mean - W F mean``: the estimate is ``offset + W c``.
    var_rms : (n_bins,)
        Mean diagonal of the posterior covariance ``P_b``.
    xyz_cov : (n_bins, 3, 3)
        ``T^T P_b T`` with the ASTM E308 D50 weights ``T`` (XYZ on 0..100).
    T : (n_wl, 3)
        The D50 weights, ``XYZ = r @ T``.
    report : (n_wl,) int or None
        Where the reported samples lie among Eq. 5's (``None``: they are the same).
    """

    wavelength_nm: NDArray[np.float64]
    F: NDArray[np.float64]
    mean: NDArray[np.float64]
    K: NDArray[np.float64]
    white: NDArray[np.float64]
    channel_index: NDArray[np.int64]
    noise: NoiseModel
    flat_residual: float
    level_edges: NDArray[np.float64]
    phi_edges: NDArray[np.float64]
    Wt: NDArray[np.float32]
    offset: NDArray[np.float32]
    var_rms: NDArray[np.float64]
    xyz_cov: NDArray[np.float64]
    T: NDArray[np.float64]
    params: dict[str, Any] = field(default_factory=dict)
    report: NDArray[np.intp] | None = None

    def reported(
        self, values: NDArray[np.float64], *, covariance: bool = False
    ) -> NDArray[np.float64]:
        """Spectra (..., n_s), or ``covariance`` matrices (..., n_s, n_s), of Eq.
        5's samples on the reported ones."""
        if self.report is None:
            return values
        if covariance:
            values = values[..., self.report, :]
        return values[..., self.report]

    @property
    def n_phi(self) -> int:
        return self.phi_edges.size - 1

    @property
    def level_weights(self) -> NDArray[np.float32]:
        """``v`` with ``rho = v . c = sum(c) / sum(w)``, (m,) float32.

        The white-weighted mean of ``c_k / w_k``: the bright responses dominate, so
        the level is not as noisy as a plain mean of the ratios would be (a weak
        LED's ratio is mostly read noise).
        """
        return np.full(self.white.size, 1.0 / self.white.sum(), dtype=np.float32)

    def bins_of(
        self, c: NDArray[np.float32], phi: NDArray[np.floating]
    ) -> NDArray[np.int64]:
        """Bin index of each pixel, ``c`` (n, m) without NaN, ``phi`` (n,)."""
        return self.bins_of_level(c @ self.level_weights, phi)

    def bins_of_level(
        self, rho: NDArray[np.floating], phi: NDArray[np.floating]
    ) -> NDArray[np.int64]:
        """Bin index from the level ``rho`` (n,) and ``phi`` (n,)."""
        lev = _bin_index(np.sqrt(np.maximum(rho, 0.0)), np.sqrt(self.level_edges))
        ph = _bin_index(np.log(np.maximum(phi, 1e-6)), np.log(self.phi_edges))
        return lev * self.n_phi + ph

    def centres(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``rho`` and ``phi`` at which each bin's ``K_e`` is modelled, (n_bins,)."""
        s = np.sqrt(self.level_edges)
        rho = (0.5 * (s[:-1] + s[1:])) ** 2
        lp = np.log(self.phi_edges)
        phi = np.exp(0.5 * (lp[:-1] + lp[1:]))
        return np.repeat(rho, phi.size), np.tile(phi, rho.size)

    def noise_variance(
        self, c: NDArray[np.floating], phi: NDArray[np.floating]
    ) -> NDArray[np.float64]:
        """Exact per-pixel ``K_e`` diagonal for responses ``c`` (n, m), ``phi`` (n,):
        the noise model at each response plus the flat-field residual, (n, m)."""
        cc = np.asarray(c, dtype=np.float64)
        p = np.asarray(phi, dtype=np.float64)[:, None]
        var = self.noise.variance(cc, p, self.channel_index)
        var += (self.flat_residual * cc) ** 2
        return var


def _bin_index(
    x: NDArray[np.floating], edges: NDArray[np.float64]
) -> NDArray[np.int64]:
    """Index of the bin of ``x`` between equidistant ``edges`` (outside: the end
    bins); arithmetic rather than a search, one pass over the pixels."""
    n = edges.size - 1
    if n == 1:
        return np.zeros(np.shape(x), dtype=np.int64)
    step = (edges[-1] - edges[0]) / n
    idx = (np.asarray(x, dtype=np.float32) - np.float32(edges[0])) * np.float32(
        1 / step
    )
    np.clip(idx, 0, n - 1, out=idx)
    return idx.astype(np.int64)


def build_wiener_bank(
    F: ArrayLike,
    prior: ArrayLike,
    white: ArrayLike,
    noise: NoiseModel,
    wavelength_nm: ArrayLike,
    *,
    phi_range: tuple[float, float] = (1.0, 1.0),
    level_max: float | None = None,
    n_levels: int = DEFAULT_LEVEL_BINS,
    n_phi: int = DEFAULT_PHI_BINS,
    flat_residual: float | None = None,
    report_nm: ArrayLike | None = None,
) -> WienerBank:
    """The Wiener matrices (Eq. 5) of every (level, flat-field factor) bin.

    Parameters
    ----------
    F : (m, n_wl)
        Lighting matrix (:func:`tunespec.core.forward_model.lighting_matrix`), in
        the units of the flat-fielded responses.
    prior : (n_train, n_wl)
        Training reflectances; centred prior (mean and covariance, ddof=1), as
        :func:`tunespec.core.wiener.wiener_reflectance`'s default.
    white : (m,)
        The Eq. 2 normaliser of each response (the white board's centre mean).
    noise
        Photon and read noise of the dark-subtracted planes.
    wavelength_nm : (n_wl,)
        Equidistant grid of ``F`` and ``prior``: the samples Eq. 5 solves for.
    phi_range
        Smallest and largest flat-field factor in the image.
    level_max
        Largest level ``rho`` binned (default 1.25: a little brighter than the
        white board); brighter pixels use the last bin.
    n_levels, n_phi
        Number of bins (``n_phi`` is 1 when the range is within 1 %).
    flat_residual
        Relative flat-field residual (default
        :data:`tunespec.core.uncertainty.FLAT_FIELD_RESIDUAL`).
    report_nm
        The samples the pixels are reported on, some of ``wavelength_nm``
        (default: all; :func:`tunespec.core.wiener.support_grid`): the matrices, the
        posteriors and the D50 weights are theirs.

    Returns
    -------
    WienerBank

    Raises
    ------
    InputError
        Shapes that do not match, non-positive white levels.
    SingularSystemError
        A prior without variance or an ``F K F^T`` that is zero.

    References
    ----------
    Trichromatic Reflectance Capture Using a Tunable Light Source, Eq. 5 and 6.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> F = rng.uniform(0, 1, (6, 31)); P = rng.uniform(0, 1, (20, 31))
    >>> nm = NoiseModel([1e-6] * 3, [1e-5] * 3)
    >>> bank = build_wiener_bank(F, P, F @ np.full(31, 0.9), nm,
    ...                          np.arange(400.0, 701.0, 10.0), n_levels=4)
    >>> bank.Wt.shape, bank.n_phi
    ((4, 6, 31), 1)
    """
    from tunespec.core.colorimetry import astm_e308_weights_d50
    from tunespec.core.uncertainty import FLAT_FIELD_RESIDUAL
    from tunespec.core.wiener import _prior_moments, sample_indices

    F, P, w, wl = _bank_inputs(F, prior, white, wavelength_nm)
    m = F.shape[0]
    keep = sample_indices(wl, wl if report_nm is None else np.asarray(report_nm))
    report = None if keep.size == wl.size else keep
    n_wl = keep.size
    flat_residual = FLAT_FIELD_RESIDUAL if flat_residual is None else flat_residual
    mean, K = _prior_moments(P, True)
    level_edges, phi_edges = _bank_edges(phi_range, level_max, n_levels, n_phi)
    channel = np.tile(np.arange(3), m // 3)
    FK = F @ K
    G = FK @ F.T
    G = 0.5 * (G + G.T)
    scale = float(np.trace(G)) / m
    if not (np.isfinite(scale) and scale > 0):
        raise SingularSystemError("F K F^T is zero: dark illuminants or no prior")
    T = astm_e308_weights_d50(wl[keep])
    bank = WienerBank(
        wl[keep], F, mean, K, w, channel, noise, float(flat_residual), level_edges,
        phi_edges, np.empty((0, m, n_wl), np.float32), np.empty((0, n_wl), np.float32),
        np.empty(0), np.empty((0, 3, 3)), T, report=report,
    )  # fmt: skip
    rho, phi = bank.centres()
    c_model = rho[:, None] * w[None, :]  # (n_bins, m): c ~= rho w
    Ke = np.maximum(bank.noise_variance(c_model, phi), RIDGE_RELATIVE * scale)
    sol, P_post = _bin_solutions(G, FK, K, Ke)
    P_post = bank.reported(P_post, covariance=True)
    W = sol.transpose(0, 2, 1)  # K F^T A^-1 (A, K symmetric)
    var_rms = np.maximum(np.einsum("bll->b", P_post) / n_wl, 0.0)
    xyz_cov = T.T[None] @ P_post @ T[None]
    offset = bank.reported(mean[None] - W @ (F @ mean))
    return WienerBank(
        wl[keep], F, mean, K, w, channel, noise, float(flat_residual), level_edges,
        phi_edges, np.ascontiguousarray(bank.reported(sol), dtype=np.float32),
        offset.astype(np.float32), var_rms, xyz_cov,
        T, {"n_levels": n_levels, "n_phi": int(phi_edges.size - 1),
            "level_max": float(level_edges[-1]), "ridge": RIDGE_RELATIVE * scale},
        report,
    )  # fmt: skip


def _bank_inputs(
    F: ArrayLike, prior: ArrayLike, white: ArrayLike, wavelength_nm: ArrayLike
) -> tuple[NDArray[np.float64], ...]:
    """``F``, the prior, the white levels and the wavelengths as float64, checked."""
    F = np.asarray(F, dtype=np.float64)
    P = np.asarray(prior, dtype=np.float64)
    w = np.asarray(white, dtype=np.float64).ravel()
    wl = np.asarray(wavelength_nm, dtype=np.float64)
    m, n_wl = F.shape
    if m % 3 or w.size != m or P.ndim != 2 or P.shape[1] != n_wl or wl.size != n_wl:
        raise InputError(
            f"Wiener bank: F {F.shape}, prior {P.shape}, white {w.shape} and "
            f"{wl.size} wavelengths do not fit together"
        )
    if not np.all(np.isfinite(w) & (w > 0)):
        raise InputError("Wiener bank: the white board's levels must be positive")
    return F, P, w, wl


def _bank_edges(
    phi_range: tuple[float, float],
    level_max: float | None,
    n_levels: int,
    n_phi: int,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Bin edges of the level (uniform in sqrt) and of ``phi`` (geometric; one bin
    when the range is within 1 %)."""
    lo, hi = sorted(float(v) for v in phi_range)
    if not (lo > 0 and math.isfinite(hi)):
        raise InputError(f"Wiener bank: flat-field factors {phi_range} must be > 0")
    if hi / lo < 1.01:
        n_phi = 1
    phi_edges = np.exp(np.linspace(math.log(lo), math.log(hi) + 1e-9, n_phi + 1))
    top = 1.25 if level_max is None else float(level_max)
    level_edges = np.linspace(0.0, math.sqrt(top), n_levels + 1) ** 2
    return level_edges, phi_edges


def _bin_solutions(
    G: NDArray[np.float64],
    FK: NDArray[np.float64],
    K: NDArray[np.float64],
    Ke: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Per bin ``(G + diag K_e)^-1 F K`` (n_bins, m, n_wl) and the posterior
    covariance ``K - K F^T (G + K_e)^-1 F K`` (n_bins, n_wl, n_wl), symmetrised."""
    sol = solve_with_noise(G, Ke, FK)
    P_post = K[None] - np.einsum("jl,bjk->blk", FK, sol)
    return sol, 0.5 * (P_post + P_post.transpose(0, 2, 1))


# -- estimation ------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class PixelEstimate:
    """Per-pixel results of :func:`estimate_pixels` for ``n`` pixels (pixels are rows,
    as in a band-interleaved-by-pixel image).

    Parameters
    ----------
    reflectance : (n, n_wl) float32
        Reflectance factors (clipped to [0, 1] if asked).
    xyz, lab : (n, 3) float32
        CIE XYZ (D50, 1931 2 degree, Y of the perfect diffuser 100) and CIELAB
        (ICC D50 white) of the reflectance.
    u_lab_l : (n,) float32
        Standard uncertainty of L*.
    u_rms : (n,) float32
        RMS over wavelength of the spectrum's standard uncertainty.
    saturated : (n,) bool
        Pixels with at least one clipped response (solved exactly, the clipped
        responses left out).
    bins : (n,) int
        The bin each pixel used (-1: solved exactly).
    """

    reflectance: NDArray[np.float32]
    xyz: NDArray[np.float32]
    lab: NDArray[np.float32]
    u_lab_l: NDArray[np.float32]
    u_rms: NDArray[np.float32]
    saturated: NDArray[np.bool_]
    bins: NDArray[np.int64]


def estimate_pixels(
    bank: WienerBank,
    c: NDArray[np.float32],
    phi: NDArray[np.floating],
    *,
    clip: bool = True,
    exact: bool = False,
    out: NDArray[np.float32] | None = None,
) -> PixelEstimate:
    """Eq. 5 for every pixel: ``r = offset_b + W_b c`` with the pixel's bin ``b``.

    Parameters
    ----------
    bank
        From :func:`build_wiener_bank`.
    c : (n, m) float32
        Flat-fielded responses of ``n`` pixels, one row each (illuminant-major
        columns, as the rows of ``F``); NaN marks a clipped response.
    phi : (n,)
        Flat-field factor of each pixel.
    clip
        Limit the reflectances to [0, 1] (XYZ and L*a*b* are those of the clipped
        spectrum, as the patch-wise estimate's).
    exact
        Solve every pixel with its own ``K_e`` (:func:`wiener_pixels_exact`) instead
        of its bin's matrix: for measuring the binning error.
    out : (n, n_wl) float32, optional
        Where the reflectances go (e.g. a :func:`~tunespec.core.scratch.scratch` buffer); the result's
        ``reflectance`` is then this array.

    Returns
    -------
    PixelEstimate

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> F = rng.uniform(0, 1, (6, 31)); P = rng.uniform(0, 1, (20, 31))
    >>> nm = NoiseModel([1e-6] * 3, [1e-5] * 3)
    >>> bank = build_wiener_bank(F, P, F @ np.full(31, 0.9), nm,
    ...                          np.arange(400.0, 701.0, 10.0))
    >>> est = estimate_pixels(bank, (P[:3] @ F.T).astype(np.float32), np.ones(3))
    >>> est.reflectance.shape, est.lab.shape
    ((3, 31), (3, 3))
    """
    c = np.asarray(c, dtype=np.float32)
    phi = np.asarray(phi)
    n, m = c.shape
    if m != bank.F.shape[0] or phi.shape != (n,):
        raise InputError(
            f"pixels: responses {c.shape} and phi {phi.shape} do not fit the "
            f"bank's {bank.F.shape[0]} responses"
        )
    n_wl = bank.wavelength_nm.size
    if out is not None and (out.shape != (n, n_wl) or out.dtype != np.float32):
        raise InputError(f"pixels: output {out.shape} is not ({n}, {n_wl})")
    est = np.empty((n, n_wl), dtype=np.float32) if out is None else out
    if exact:
        sat = np.isnan(c @ bank.level_weights)
        bins = np.full(n, -1, dtype=np.int64)
        rest = np.arange(n)
    else:
        # every pixel through its bin (no copies of the unclipped ones); a NaN
        # (clipped) response makes its pixel's level NaN, and its row (NaN) is
        # replaced by its exact solution below
        bins, sat = apply_bank(bank, c, phi, est, clip=clip)
        rest = np.flatnonzero(sat)
        bins[rest] = -1
    if rest.size:
        exact_rows = bank.reported(wiener_pixels_exact(bank, c[rest], phi[rest]))
        exact_rows = exact_rows.astype(np.float32)
        est[rest] = np.clip(exact_rows, 0.0, 1.0) if clip else exact_rows
    xyz = est @ bank.T.astype(np.float32)
    lab = lab_from_xyz(xyz.T).T
    var_rms, var_y = _bin_variances(bank, c, phi, bins, rest)
    # the flat field's residual is a ratio of irradiances, common to all responses
    # of a pixel: it scales the whole estimate (no averaging over the LEDs)
    fr2 = bank.flat_residual**2
    var_y += fr2 * xyz[:, 1].astype(np.float64) ** 2
    var_rms += fr2 / est.shape[1] * np.einsum("ij,ij->i", est, est)
    u_l = _u_lightness(xyz[:, 1], var_y)
    u_rms = np.minimum(np.sqrt(var_rms), 0.5).astype(np.float32)
    return PixelEstimate(est, xyz, np.ascontiguousarray(lab), u_l, u_rms, sat, bins)


def _bin_variances(
    bank: WienerBank,
    c: NDArray[np.float32],
    phi: NDArray[np.floating],
    bins: NDArray[np.int64],
    rest: NDArray[np.int64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Per pixel: the RMS spectral variance and the variance of Y (from the bin's
    posterior; exactly solved pixels get their own)."""
    safe = np.maximum(bins, 0)
    var_rms = bank.var_rms[safe]
    var_y = bank.xyz_cov[safe, 1, 1]
    if rest.size:
        P = bank.reported(_posterior_exact(bank, c[rest], phi[rest]), covariance=True)
        var_rms[rest] = np.einsum("pll->p", P) / P.shape[1]
        t = bank.T[:, 1]
        var_y[rest] = np.einsum("l,plk,k->p", t, P, t)
    return var_rms, var_y


def _u_lightness(
    Y: NDArray[np.floating], var_y: NDArray[np.float64]
) -> NDArray[np.float32]:
    """``u(L*)`` from ``u(Y)``: ``dL*/dY = 116 f'(Y / Yn) / Yn`` (CIE 015:2018)."""
    t = np.maximum(np.asarray(Y, dtype=np.float64) / _D50_WHITE[1], 0.0)
    # t^(1/3) above (6/29)^3, the linear segment t / (3 (6/29)^2) + 4/29 below
    dfdt = np.where(
        t > _LAB_EPS,
        (1.0 / 3.0) * np.cbrt(np.maximum(t, _LAB_EPS)) ** -2,
        1.0 / (3.0 * (6.0 / 29.0) ** 2),
    )
    u = 116.0 * dfdt / _D50_WHITE[1] * np.sqrt(np.maximum(var_y, 0.0))
    return u.astype(np.float32)


def _exact_system(
    bank: WienerBank, c: NDArray[np.floating], phi: NDArray[np.floating]
) -> tuple[
    NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]
]:
    """``c`` without NaN, each pixel's ``K_e`` diagonal, ``F K`` and ``F K F^T``."""
    c64 = np.asarray(c, dtype=np.float64)
    nan = np.isnan(c64)
    c64 = np.where(nan, 0.0, c64)
    var = bank.noise_variance(c64, phi)
    var[nan] = SATURATED_VARIANCE
    var = np.maximum(var, bank.params.get("ridge", 0.0))
    FK = bank.F @ bank.K
    G = FK @ bank.F.T
    return c64, var, FK, 0.5 * (G + G.T)


def wiener_pixels_exact(
    bank: WienerBank, c: NDArray[np.floating], phi: NDArray[np.floating]
) -> NDArray[np.float64]:
    """Eq. 5 solved per pixel with its own ``K_e`` (no binning).

    ``K_e = diag(phi^2 a + phi b c + (flat_residual c)^2)`` from the pixel's own
    responses (as Eq. 6 takes a patch's own spread); a NaN (clipped) response gets
    :data:`SATURATED_VARIANCE`, which removes it from the estimate.

    Parameters
    ----------
    bank
        For ``F``, the prior and the noise model.
    c : (n, m)
    phi : (n,)

    Returns
    -------
    (n, n_s) float64
        On Eq. 5's samples (:meth:`WienerBank.reported` gives the reported ones).
    """
    c64, var, FK, G = _exact_system(bank, c, phi)
    n = c64.shape[0]
    out = np.empty((n, bank.mean.size))
    resid = c64 - bank.F @ bank.mean
    for lo in range(0, n, _EXACT_CHUNK):
        hi = min(lo + _EXACT_CHUNK, n)
        x = solve_with_noise(G, var[lo:hi], resid[lo:hi, :, None])[..., 0]
        out[lo:hi] = bank.mean + x @ FK
    return out


def _posterior_exact(
    bank: WienerBank, c: NDArray[np.floating], phi: NDArray[np.floating]
) -> NDArray[np.float64]:
    """Posterior covariances (n, n_s, n_s) of exactly solved pixels."""
    _, var, FK, G = _exact_system(bank, c, phi)
    n = var.shape[0]
    n_wl = bank.K.shape[0]
    out = np.empty((n, n_wl, n_wl))
    for lo in range(0, n, _EXACT_CHUNK):
        hi = min(lo + _EXACT_CHUNK, n)
        sol = solve_with_noise(G, var[lo:hi], FK)
        out[lo:hi] = bank.K[None] - np.einsum("jl,pjk->plk", FK, sol)
    return out


# -- colour ------------------------------------------------------------------------------
def lab_from_xyz(xyz: NDArray[np.floating]) -> NDArray[np.float32]:
    """CIELAB (ICC D50 white) of XYZ (3, n) on 0..100, float32 (CIE 015:2018).

    The same formulas as :func:`tunespec.core.colorimetry.xyz_to_lab_d50` (which
    calls colour-science), written out for (3, n) float32 tiles.

    Examples
    --------
    >>> import numpy as np
    >>> lab_from_xyz(np.array([[96.42], [100.0], [82.49]])).ravel().round(4).tolist()
    [100.0, 0.0, 0.0]
    """
    t = np.asarray(xyz, dtype=np.float64) / _D50_WHITE[:, None]
    f = np.where(
        t > _LAB_EPS,
        np.cbrt(np.maximum(t, _LAB_EPS)),
        t / (3.0 * (6.0 / 29.0) ** 2) + 4.0 / 29.0,
    )
    out = np.empty(t.shape, dtype=np.float32)
    out[0] = 116.0 * f[1] - 16.0
    out[1] = 500.0 * (f[0] - f[1])
    out[2] = 200.0 * (f[1] - f[2])
    return out


def srgb8_from_xyz_d50(xyz: NDArray[np.floating]) -> NDArray[np.uint8]:
    """8-bit sRGB (IEC 61966-2-1) of XYZ (3, n) D50 on 0..100, shape (n, 3).

    D50 is adapted to sRGB's D65 with the Bradford transform (folded into the
    matrix, as ICC v4 does), out-of-gamut values clipped, then the sRGB curve.
    """
    rgb = _XYZ_D50_TO_SRGB @ (np.asarray(xyz, dtype=np.float64) / 100.0)
    rgb = np.clip(rgb, 0.0, 1.0)
    v = np.where(rgb <= 0.0031308, 12.92 * rgb, 1.055 * np.power(rgb, 1 / 2.4) - 0.055)
    return np.round(v.T * 255.0).astype(np.uint8)
