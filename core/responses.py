"""Camera responses per patch and illuminant.

Their long-format CSV is read and written in :mod:`tunespec.core.io.responses_csv`
(``read_responses_csv``, ``write_responses_csv``; this module imports no reader). CSV columns: ``patch,illuminant,R,G,B`` and optionally ``R_std,G_std,B_std`` (per-pixel
standard deviation inside the patch ROI, as Eq. 6 of the paper uses), ``n_pixels`` and
``saturated`` (fraction of ROI pixels at or above the white level) and
``white_R,white_G,white_B`` (the white background's level under the row's
illuminant, the same on each of its rows). Values are linear,
dark-corrected and flat-fielded, in units of full scale (1.0 = saturation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tunespec.core.errors import InputError, check_names

__all__ = ["CHANNELS", "Responses"]

CHANNELS = ("R", "G", "B")
_STD = tuple(f"{c}_std" for c in CHANNELS)


@dataclass(frozen=True, eq=False)
class Responses:
    """RGB responses of patches under illuminants.

    Parameters
    ----------
    patches : n_p names
    illuminants : n_i names, matching the illuminant spectra's names
    rgb : (n_p, n_i, 3)
        Mean response in units of full scale.
    rgb_std : (n_p, n_i, 3) or None
        Per-pixel standard deviation inside the ROI.
    n_pixels : (n_p, n_i) or None
        Pixels averaged (per colour plane).
    saturated : (n_p, n_i) or None
        Fraction of ROI pixels that were clipped.
    white_rgb : (n_i, 3) or None
        The white background's level under each illuminant that the responses are
        flat-fielded to (Eq. 2's mean ``A_B``, full scale): the scale a session's
        responses share with its chart's (``core.plausibility.check_white_scale``).
    """

    patches: tuple[str, ...]
    illuminants: tuple[str, ...]
    rgb: NDArray[np.float64]
    rgb_std: NDArray[np.float64] | None = None
    n_pixels: NDArray[np.float64] | None = None
    saturated: NDArray[np.float64] | None = None
    white_rgb: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        shape = (len(self.patches), len(self.illuminants))
        object.__setattr__(self, "patches", tuple(self.patches))
        object.__setattr__(self, "illuminants", tuple(self.illuminants))
        for what, names in (("patch", self.patches), ("illuminant", self.illuminants)):
            if len(set(names)) != len(names):
                dup = sorted({n for n in names if names.count(n) > 1})
                raise InputError(f"duplicate {what} names: {', '.join(dup[:8])}")
        rgb = np.asarray(self.rgb, dtype=np.float64)
        if rgb.shape != (*shape, 3):
            raise InputError(f"rgb shape {rgb.shape}, expected {(*shape, 3)}")
        object.__setattr__(self, "rgb", rgb)
        for name, want in (
            ("rgb_std", (*shape, 3)),
            ("n_pixels", shape),
            ("saturated", shape),
            ("white_rgb", (shape[1], 3)),
        ):
            arr = getattr(self, name)
            if arr is not None:
                arr = np.asarray(arr, dtype=np.float64)
                if arr.shape != want:
                    raise InputError(f"{name} shape {arr.shape}, expected {want}")
                object.__setattr__(self, name, arr)

    @property
    def clipped(self) -> NDArray[np.bool_]:
        """(n_p, n_i): which patch's responses under which illuminant had clipped
        pixels (a ``saturated`` fraction above 0; unknown, NaN, counts as not; all
        False without ``saturated``)."""
        if self.saturated is None:
            return np.zeros((len(self.patches), len(self.illuminants)), dtype=bool)
        return np.nan_to_num(self.saturated, nan=0.0) > 0

    def subset(
        self, patches: list[str] | None = None, illuminants: list[str] | None = None
    ) -> Responses:
        """The responses of some patches and/or illuminants, in the given order.

        ``None`` keeps all of them; an empty list keeps none.

        Raises
        ------
        InputError
            Names that are not in the responses.
        """
        pi = _indices(self.patches, patches, "patch")
        ii = _indices(self.illuminants, illuminants, "illuminant")

        def take(a: NDArray[np.float64] | None) -> NDArray[np.float64] | None:
            return None if a is None else a[np.ix_(pi, ii)]

        return Responses(
            tuple(self.patches[i] for i in pi),
            tuple(self.illuminants[i] for i in ii),
            take(self.rgb),  # type: ignore[arg-type]
            take(self.rgb_std),
            take(self.n_pixels),
            take(self.saturated),
            None if self.white_rgb is None else self.white_rgb[ii],
        )


def _indices(have: tuple[str, ...], names: list[str] | None, what: str) -> list[int]:
    if names is None:
        return list(range(len(have)))
    check_names(names, have, f"{{n}} {what} name(s) not in the responses: {{names}}")
    return [have.index(n) for n in names]
