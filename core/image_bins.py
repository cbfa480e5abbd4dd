"""The per-pixel images' Wiener stage: ``r = offset_b + c W_b^T`` bin by bin.

Each pixel's responses (a row of ``c``) are multiplied by the Wiener matrix of its
noise bin (:class:`~tunespec.core.image.WienerBank`); the pixels are sorted by bin
so that each bin's matrix multiplies many rows at once (:func:`_apply_bins`, for
:func:`tunespec.core.image.estimate_pixels`).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import NDArray
from scipy.linalg.blas import sgemm

from tunespec.core.scratch import scratch

__all__ = ["APPLY_ROWS", "SCATTERED_TILE"]


class BankArrays(Protocol):
    """What the stage reads of a :class:`tunespec.core.image.WienerBank` (this module
    does not import it: the images' module imports this one)."""

    mean: NDArray[np.float64]
    Wt: NDArray[np.float32]
    offset: NDArray[np.float32]


#: Pixels per product in :func:`_apply_bins`: their responses (gathered) fit in
#: the core's L2 cache beside the bin's matrix, so the product reads them there.
APPLY_ROWS = 4096

#: Pixels sorted at a time where a block's bins are scattered (:func:`_apply_bins`):
#: their responses and sorted results (17 MB) stay in the last-level cache, so the
#: gathers and the unsorting read it rather than random rows of the whole block.
SCATTERED_TILE = 32768


def _apply_bins(
    bank: BankArrays,
    c: NDArray[np.float32],
    bins: NDArray[np.int64],
    out: NDArray[np.float32] | None = None,
    *,
    clip: bool = False,
) -> NDArray[np.float32]:
    """``r = offset_b + c W_b^T`` for every pixel (row), bin by bin.

    The pixels are ordered by bin (a stable radix sort of the small bin numbers);
    for each run of up to :data:`APPLY_ROWS` pixels of one bin, their rows of ``c``
    are gathered into a small buffer that stays in the L2 cache, multiplied by the
    bin's matrix, and the offset added (and the result limited to [0, 1] with
    ``clip``) while those rows are still cached. Where the bins follow the image
    (over half of the pixels share their right neighbour's bin, as in a
    photograph) the whole block is sorted at once and each run's results go from a
    second cached buffer straight into their pixels' rows of ``out``. Otherwise
    (pixels of a bin scattered, as in a shuffled test) writing rows at random costs
    twice the reading, so the block is sorted in tiles of :data:`SCATTERED_TILE`
    pixels, each tile's results written in sorted order and gathered back into
    pixel order while the tile is still in the last-level cache (on
    ``bench_image.py``'s shuffled block: 55 -> 48 ms; whole-block sorting read and
    wrote random rows of 64 MB arrays). The buffers are kept per thread
    (:func:`~tunespec.core.scratch.scratch`).
    """
    n, m = c.shape
    n_wl = bank.mean.size
    if out is None:
        out = np.empty((n, n_wl), dtype=np.float32)
    rows = scratch("bin_rows", (min(APPLY_ROWS, n), m))
    if 2 * np.count_nonzero(bins[1:] == bins[:-1]) > n:
        results = scratch("bin_results", (min(APPLY_ROWS, n), n_wl))
        order, runs = _bin_runs(bank, bins)
        for b, lo, hi in runs:
            idx = order[lo:hi]
            _apply_run(bank, b, c, idx, rows[: hi - lo], results[: hi - lo], clip)
            out[idx] = results[: hi - lo]
        return out
    ordered = scratch("sorted_r", (min(SCATTERED_TILE, n), n_wl))
    for t0 in range(0, n, SCATTERED_TILE):
        t1 = min(t0 + SCATTERED_TILE, n)
        order, runs = _bin_runs(bank, bins[t0:t1])
        for b, lo, hi in runs:
            _apply_run(bank, b, c[t0:t1], order[lo:hi], rows[: hi - lo],
                       ordered[lo:hi], clip)  # fmt: skip
        inverse = np.empty_like(order)
        inverse[order] = np.arange(order.size)
        np.take(ordered, inverse, axis=0, mode="clip", out=out[t0:t1])
    return out


def _bin_runs(
    bank: BankArrays, bins: NDArray[np.int64]
) -> tuple[NDArray[np.intp], list[tuple[int, int, int]]]:
    """The pixels in order of their bin, and the runs ``(bin, lo, hi)`` of that
    order (each of one bin, at most :data:`APPLY_ROWS` long)."""
    n_bins = bank.Wt.shape[0]
    # bins are small integers: a stable sort of 8 or 16 bits is numpy's radix
    # sort, O(n) (one pass over the pixels for 8 bits)
    small = np.uint8 if n_bins <= 256 else np.int16
    order = np.argsort(bins.astype(small), kind="stable")
    counts = np.bincount(bins, minlength=n_bins)
    present = np.flatnonzero(counts)
    ends = np.cumsum(counts[present])
    starts = ends - counts[present]
    bounds = zip(present.tolist(), starts.tolist(), ends.tolist(), strict=True)
    if counts.max(initial=0) <= APPLY_ROWS:  # each bin one run (a tile's usually)
        return order, list(bounds)
    runs = []
    for b, start, end in bounds:
        runs.extend((b, lo, min(lo + APPLY_ROWS, end))
                    for lo in range(start, end, APPLY_ROWS))  # fmt: skip
    return order, runs


def _apply_run(
    bank: BankArrays,
    b: int,
    c: NDArray[np.float32],
    idx: NDArray[np.intp],
    rows: NDArray[np.float32],
    res: NDArray[np.float32],
    clip: bool,
) -> None:
    """``res = offset_b + c[idx] W_b^T`` (limited to [0, 1] with ``clip``), the
    rows of ``c`` gathered into ``rows`` (cached) first.

    The offset is put in ``res`` and the product added to it by BLAS's ``sgemm``
    (``beta = 1``, on the transposed, Fortran-ordered views: no copies), rather than
    added after the product in a second pass over the results (a shuffled block
    45 -> 42 ms; the sums' order moves a result by at most a float32 step).
    """
    # indices from argsort are in range: "clip" skips the bounds checks (2x)
    np.take(c, idx, axis=0, out=rows, mode="clip")
    res[...] = bank.offset[b]
    got = sgemm(1.0, bank.Wt[b].T, rows.T, 1.0, res.T, overwrite_c=True)
    if not np.may_share_memory(got, res):  # not updated in place: never seen
        res[...] = got.T
    if clip:
        np.clip(res, 0.0, 1.0, out=res)
