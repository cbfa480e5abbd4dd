"""The uncertainty a spectral image's pixels leave out, tabulated by colour.

A pixel's bin posterior (:class:`~tunespec.core.image.WienerBank`) covers its noise and
what the LEDs cannot resolve; the calibration's uncertainty and a target unlike the
prior set depend on the spectrum, not on the pixel. :func:`systematic_table` computes
the full uncertainty (``core.uncertainty``) of regions sampled over the image and
tabulates its excess by CIELAB cell, for every pixel to add
(:func:`~tunespec.app.pipeline.image_session.finish_uncertainty`). Split from
:mod:`tunespec.app.pipeline.image_session`, whose stages it reads.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from tunespec.app.pipeline.image_session import (
    ImageJob,
    _read_phi,
    illuminants_of,
    read_response_rows,
)
from tunespec.app.pipeline.lighting import estimation_lighting
from tunespec.core.image import WienerBank
from tunespec.core.image_planes import _LAB_CELLS, SystematicTable
from tunespec.core.spectra import Grid, Spectra

__all__ = ["N_SYSTEMATIC_SAMPLES", "SAMPLE_PX", "systematic_table"]

#: Region samples (8 x 8 superpixel means) whose full uncertainty
#: (:func:`tunespec.core.uncertainty.reflectance_uncertainty`) is computed.
N_SYSTEMATIC_SAMPLES = 128
#: Side of a sample region, plane pixels.
SAMPLE_PX = 8


def _samples(
    job: ImageJob, n_samples: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Responses (n, m) and phi (n,) of unclipped 8 x 8 regions spread over the
    image (row bands read from the stack; a few percent of it)."""
    h, w = job.plane_shape
    s = SAMPLE_PX
    n_bands = max(1, min(h // s, 24))
    starts = np.linspace(0, h - s, n_bands).astype(int) if h >= s else np.array([0])
    out_c, out_phi = [], []
    for r0 in starts:
        r1 = min(r0 + s, h)
        c = read_response_rows(job, r0, r1)
        phi = _read_phi(job, r0, r1)
        nb = w // s
        if nb < 1:
            continue
        cc = c[:, :, : nb * s].reshape(c.shape[0], r1 - r0, nb, s)
        means = cc.mean(axis=(1, 3))  # NaN where a region holds a clipped pixel
        pm = phi[:, : nb * s].reshape(r1 - r0, nb, s).mean(axis=(0, 2))
        ok = ~np.isnan(means).any(axis=0)
        out_c.append(means[:, ok].T)
        out_phi.append(pm[ok])
    if not out_c:
        return np.empty((0, job.n_responses)), np.empty(0)
    c_all = np.concatenate(out_c).astype(np.float64)
    phi_all = np.concatenate(out_phi).astype(np.float64)
    if c_all.shape[0] > n_samples:
        # spread over brightness: every k-th region in order of level
        order = np.argsort(c_all.mean(axis=1))
        pick = order[np.linspace(0, order.size - 1, n_samples).astype(int)]
        c_all, phi_all = c_all[pick], phi_all[pick]
    return c_all, phi_all


def systematic_table(
    job: ImageJob,
    bank: WienerBank,
    sensitivity_csv: str,
    meta: dict[str, Any],
    prior: Spectra,
    grid: Grid,
    *,
    n_samples: int = N_SYSTEMATIC_SAMPLES,
) -> SystematicTable:
    """The uncertainty a pixel's own noise and the prior leave out, by colour.

    A pixel's bin posterior (:class:`~tunespec.core.image.WienerBank`) covers its
    noise and what the LEDs cannot resolve under the prior. What it leaves out is
    the calibration's uncertainty (sensitivities and LED corrections, propagated
    through Eq. 1) and a target unlike the prior set; both depend on the spectrum,
    not on the pixel. So for regions sampled over the image (``n_samples`` 8 x 8
    means) the full per-pixel uncertainty is computed by
    :func:`tunespec.core.uncertainty.reflectance_uncertainty` (as ``tunespec
    estimate`` does for a patch, with one pixel's noise: ``n_pixels = 1``), its
    excess over the region's bin posterior is kept and tabulated by CIELAB cell
    (cells without a sample take the nearest sample's). Every pixel adds its cell's
    excess to its own variance.

    Returns
    -------
    SystematicTable
        Zeros when no region is free of clipping.
    """
    from tunespec.core.calibration import Calibration
    from tunespec.core.datasets import read_sensitivities
    from tunespec.core.image import _u_lightness
    from tunespec.core.responses import Responses
    from tunespec.core.uncertainty import reflectance_uncertainty
    from tunespec.core.wiener import prior_on_support, wiener_reflectance

    c, phi = _samples(job, n_samples)
    zeros = np.zeros(_LAB_CELLS)
    if c.shape[0] == 0:
        return SystematicTable(zeros, zeros.copy(), 0)
    n, m = c.shape
    n_i = m // 3
    std = np.sqrt(bank.noise.variance(c, phi[:, None], bank.channel_index))
    names = tuple(f"region{i}" for i in range(n))
    resp = Responses(
        names, job.channels, c.reshape(n, n_i, 3), std.reshape(n, n_i, 3),
        np.ones((n, n_i)),
    )  # fmt: skip
    sensitivity = read_sensitivities(sensitivity_csv)
    # corrected as ``tunespec estimate`` corrects them, on the integration grid
    L, S, fine = estimation_lighting(illuminants_of(job), sensitivity, meta, grid)
    calibration = Calibration.from_meta(sensitivity, meta)
    resp = calibration.linearise(resp)
    prior = prior_on_support(prior, grid, fine.wavelength_nm)
    est = wiener_reflectance(resp, L, S, prior).restricted(grid)
    unc = reflectance_uncertainty(est, resp, illuminants_of(job), calibration)
    bins = bank.bins_of(c.astype(np.float32), phi)
    y = unc.xyz[:, 1]
    u_l_bin = _u_lightness(y, bank.xyz_cov[bins, 1, 1]).astype(np.float64)
    ex_l = np.maximum(unc.lab_std[:, 0] ** 2 - u_l_bin**2, 0.0)
    ex_rms = np.maximum(
        np.mean(unc.reflectance_std**2, axis=1) - bank.var_rms[bins], 0.0
    )
    # nearest sample (in CIELAB) of every cell centre
    nl, na, nb = _LAB_CELLS
    gl = (np.arange(nl) + 0.5) * 100.0 / nl
    ga = (np.arange(na) + 0.5) * 200.0 / na - 100.0
    gb = (np.arange(nb) + 0.5) * 200.0 / nb - 100.0
    cells = np.stack(np.meshgrid(gl, ga, gb, indexing="ij"), axis=-1).reshape(-1, 3)
    d = ((cells[:, None, :] - unc.lab[None, :, :]) ** 2).sum(axis=2)
    near = np.argmin(d, axis=1)
    return SystematicTable(
        ex_l[near].reshape(_LAB_CELLS), ex_rms[near].reshape(_LAB_CELLS), n
    )
