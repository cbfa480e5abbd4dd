"""The per-pixel images' Wiener stage: ``r = offset_b + c W_b^T`` bin by bin.

Each pixel's responses (a row of ``c``) are multiplied by the Wiener matrix of its
noise bin (:class:`~tunespec.core.image.WienerBank`), the bin found from the pixel's
level and flat-field factor; the pixels are sorted by bin so that each bin's matrix
multiplies many rows at once (:func:`apply_bank`, for
:func:`tunespec.core.image.estimate_pixels`).
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray
from scipy.linalg.blas import sgemm

from tunespec.core.scratch import scratch

__all__ = ["APPLY_ROWS", "SCATTERED_TILE", "apply_bank"]


class BankArrays(Protocol):
    """What the stage reads of a :class:`tunespec.core.image.WienerBank` (this module
    does not import it: the images' module imports this one)."""

    Wt: NDArray[np.float32]
    offset: NDArray[np.float32]

    @property
    def level_weights(self) -> NDArray[np.float32]: ...

    def bins_of_level(
        self, rho: NDArray[np.floating], phi: NDArray[np.floating]
    ) -> NDArray[np.int64]: ...


#: Pixels per product in :func:`apply_bank`: their responses (gathered) fit in
#: the core's L2 cache beside the bin's matrix, so the product reads them there.
APPLY_ROWS = 4096

#: Pixels binned at a time by :func:`apply_bank`, and sorted at a time where their
#: bins are scattered: their responses and sorted results (17 MB) stay in the
#: last-level cache, so the gathers and the unsorting read it rather than random
#: rows of the whole block.
SCATTERED_TILE = 32768


def apply_bank(
    bank: BankArrays,
    c: NDArray[np.float32],
    phi: NDArray[np.floating],
    out: NDArray[np.float32],
    *,
    clip: bool = False,
) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """``out = offset_b + c W_b^T`` for every pixel (row), ``b`` the bin of its
    level ``rho = c . v`` (:attr:`~tunespec.core.image.WienerBank.level_weights`)
    and of ``phi`` (n,); limited to [0, 1] with ``clip``.

    The block is read in tiles of :data:`SCATTERED_TILE` pixels: a tile's levels
    and bins are computed as it comes from memory, and its rows are gathered for
    the products while it is still in the last-level cache, so the block is read
    from memory once (against a pass of its own for the whole block's levels and a
    clip per run: ``bench_image.py``'s shuffled block 55-61 -> 53-55 ms, 63-66 ->
    55-60 ms with ``clip``, side by side; the one-thread product 29-32 ms). A pixel
    whose level is NaN (a clipped response) is binned at level 0 and flagged: its
    row of ``out`` is NaN, for the caller to replace.

    The pixels are ordered by bin (a stable radix sort of the small bin numbers);
    for each run of up to :data:`APPLY_ROWS` pixels of one bin, their rows of ``c``
    are gathered into a small buffer that stays in the L2 cache and multiplied by
    the bin's matrix into results that hold the bin's offset. Where the
    bins follow the image (over half of a tile's pixels share their right
    neighbour's bin, as in a photograph) the tile waits, and all such tiles of the
    block are sorted at once (long runs), each run's results going from a cached
    buffer straight into their pixels' rows of ``out``. Otherwise (pixels of a bin
    scattered, as in a shuffled test) writing rows at random costs twice the
    reading, so the tile is sorted alone, its results written in sorted order and
    gathered back into pixel order while it is still cached (sorting the whole
    block read and wrote random rows of 64 MB arrays; scattering the tile's sorted
    results into ``out`` took 69-73 ms against 56-60). The buffers are kept per
    thread (:func:`~tunespec.core.scratch.scratch`).

    Returns
    -------
    bins : (n,) int64
        Each pixel's bin.
    nan_level : (n,) bool
        Pixels whose level is NaN.
    """
    n = c.shape[0]
    n_bins = bank.Wt.shape[0]
    v = bank.level_weights
    bins = np.empty(n, dtype=np.int64)
    nan_level = np.empty(n, dtype=bool)
    keys = None  # sort keys of the tiles that wait: n_bins marks those done
    for t0 in range(0, n, SCATTERED_TILE):
        t1 = min(t0 + SCATTERED_TILE, n)
        ct, bt = c[t0:t1], bins[t0:t1]
        rho = ct @ v
        nan = np.isnan(rho, out=nan_level[t0:t1])
        if nan.any():
            rho[nan] = 0.0
        bt[...] = bank.bins_of_level(rho, phi[t0:t1])
        if 2 * np.count_nonzero(bt[1:] == bt[:-1]) > bt.size:
            if keys is None:
                keys = np.full(n, n_bins, dtype=_key_dtype(n_bins))
            keys[t0:t1] = bt
        else:
            _apply_tile(bank, ct, bt.astype(_key_dtype(n_bins)), out[t0:t1], clip)
    if keys is not None:
        _apply_in_order(bank, c, keys, out, clip)
    return bins, nan_level


def _key_dtype(n_bins: int) -> Any:
    """The smallest unsigned type holding ``0 .. n_bins`` (``n_bins``: "done"):
    numpy's stable sort of 8 or 16 bits is a radix sort, O(n)."""
    return np.uint8 if n_bins < 1 << 8 else np.uint16 if n_bins < 1 << 16 else np.intp


def _apply_tile(
    bank: BankArrays,
    c: NDArray[np.float32],
    keys: NDArray[Any],
    out: NDArray[np.float32],
    clip: bool,
) -> None:
    """One tile of scattered bins: the results in sorted order, then gathered into
    pixel order (``out``) while they are cached."""
    n, m = c.shape
    rows = scratch("bin_rows", (min(APPLY_ROWS, n), m))
    ordered = scratch("sorted_r", (n, bank.offset.shape[1]))
    order, runs = _bin_runs(keys, bank.Wt.shape[0])
    # every result starts as its bin's offset: one call for the tile
    bank.offset.take(keys[order], axis=0, out=ordered, mode="clip")
    for b, lo, hi in runs:
        _apply_run(bank, b, c, order[lo:hi], rows[: hi - lo], ordered[lo:hi])
    if clip:  # the whole tile at once: one call rather than one a run (~1000)
        np.clip(ordered, 0.0, 1.0, out=ordered)
    inverse = scratch("bin_inverse", (n,), np.intp)
    inverse[order] = np.arange(n)
    np.take(ordered, inverse, axis=0, mode="clip", out=out)


def _apply_in_order(
    bank: BankArrays,
    c: NDArray[np.float32],
    keys: NDArray[Any],
    out: NDArray[np.float32],
    clip: bool,
) -> None:
    """The pixels of ``keys`` below the bank's bin count (the tiles whose bins
    follow the image), sorted together: each run's results straight into their
    pixels' rows of ``out``."""
    rows = scratch("bin_rows", (min(APPLY_ROWS, c.shape[0]), c.shape[1]))
    results = scratch("bin_results", (rows.shape[0], bank.offset.shape[1]))
    order, runs = _bin_runs(keys, bank.Wt.shape[0])
    for b, lo, hi in runs:
        idx, res = order[lo:hi], results[: hi - lo]
        res[...] = bank.offset[b]
        _apply_run(bank, b, c, idx, rows[: hi - lo], res)
        if clip:
            np.clip(res, 0.0, 1.0, out=res)
        out[idx] = res


def _bin_runs(
    keys: NDArray[Any], n_bins: int
) -> tuple[NDArray[np.intp], list[tuple[int, int, int]]]:
    """The pixels in order of their bin ``keys`` (of :func:`_key_dtype`; a key of
    ``n_bins`` or more sorts last and is in no run), and the runs ``(bin, lo, hi)``
    of that order (each of one bin, at most :data:`APPLY_ROWS` long)."""
    order = np.argsort(keys, kind="stable")
    counts = np.bincount(keys, minlength=n_bins)[:n_bins]
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
) -> None:
    """``res += c[idx] W_b^T``, the rows of ``c`` gathered into ``rows`` (cached)
    first; ``res`` holds the bin's offset.

    The offset is put in ``res`` by the caller and the product added to it by
    BLAS's ``sgemm`` (``beta = 1``, on the transposed, Fortran-ordered views: no
    copies), rather than added after the product in a second pass over the results
    (a shuffled block 45 -> 42 ms; the sums' order moves a result by at most a
    float32 step).
    """
    # indices from argsort are in range: "clip" skips the bounds checks (2x); the
    # method, not np.take's wrapper (about 1000 runs a shuffled block)
    c.take(idx, axis=0, out=rows, mode="clip")
    res_t = res.T
    got = sgemm(1.0, bank.Wt[b].T, rows.T, 1.0, res_t, overwrite_c=True)
    if got is not res_t:  # not updated in place: never seen
        res[...] = got.T
