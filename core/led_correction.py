"""Per-LED metering corrections of the light source: ``i_j(l) = g_j i'_j(l + d_j)``.

The spectroradiometer reports ``i'_j``; the true spectrum of LED ``j`` is taken to be
its report scaled by a gain ``g_j`` and moved by a wavelength offset ``d_j``
(:mod:`tunespec.core.sensitivity_bayes` fits them with the sensitivities).
:class:`LedCorrection` holds a calibration's corrections and applies them
(:func:`apply_led_corrections`).

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source (the paper in
``shared/reference``), Eq. 1 and 3.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import CubicSpline

from tunespec.core.errors import InputError
from tunespec.core.spectra import Spectra

__all__ = ["LedCorrection", "apply_led_corrections"]


@dataclass(frozen=True)
class LedCorrection:
    """Per-LED metering corrections of the light source found by the self-calibration.

    The true spectrum of LED ``names[j]`` is ``gain[j] * reported(l + shift_nm[j])``;
    a spectrum of any other name gets the common offset ``common_shift_nm`` only.
    ``gain_std`` and ``shift_std_nm`` are their standard uncertainties.
    """

    names: tuple[str, ...]
    gain: tuple[float, ...]
    shift_nm: tuple[float, ...]
    common_shift_nm: float = 0.0
    gain_std: tuple[float, ...] = ()
    shift_std_nm: tuple[float, ...] = ()

    def lookup(
        self, names: Sequence[str]
    ) -> tuple[NDArray[np.intp], NDArray[np.float64], NDArray[np.float64]]:
        """For each LED of ``names``: its row here, its gain and its shift; an LED not
        fitted has row -1, which picks the appended gain 1 and the common shift."""
        index = {n: j for j, n in enumerate(self.names)}
        rows = np.array([index.get(n, -1) for n in names], dtype=np.intp)
        gain = np.append(np.asarray(self.gain, float), 1.0)[rows]
        shift = np.append(np.asarray(self.shift_nm, float), self.common_shift_nm)[rows]
        return rows, gain, shift

    def apply(self, illuminants: Spectra) -> Spectra:
        """``illuminants`` with the corrections undone (same names and grid).

        Examples
        --------
        >>> import numpy as np
        >>> wl = np.arange(400.0, 501.0, 5.0)
        >>> led = Spectra(wl, [np.exp(-0.5 * ((wl - 451.0) / 10.0) ** 2)], ("A",))
        >>> fix = LedCorrection(("A",), (1.1,), (1.0,))
        >>> round(float(fix.apply(led).values.max()), 3)
        1.1
        """
        _, gain, shift = self.lookup(illuminants.names)
        if np.all(gain == 1.0) and np.all(shift == 0.0):
            return illuminants
        values = apply_led_corrections(
            illuminants.wavelength_nm, illuminants.values, gain, shift
        )
        return illuminants.with_values(values)

    def as_dict(self) -> dict[str, Any]:
        """JSON-friendly form (see :meth:`from_dict`)."""
        return {
            "common_shift_nm": float(self.common_shift_nm),
            "leds": [
                {
                    "name": n,
                    "gain": float(self.gain[j]),
                    "shift_nm": float(self.shift_nm[j]),
                    **({"gain_std": float(self.gain_std[j])} if self.gain_std else {}),
                    **(
                        {"shift_std_nm": float(self.shift_std_nm[j])}
                        if self.shift_std_nm
                        else {}
                    ),
                }
                for j, n in enumerate(self.names)
            ],
        }

    @classmethod
    def from_dict(cls, doc: Any, path: str | None = None) -> LedCorrection:
        """Read :meth:`as_dict`'s form back; one-line :class:`InputError` if it is not."""
        try:
            leds = doc["leds"]
            if not isinstance(leds, list) or len(leds) > 10_000:
                raise TypeError("leds must be a list")
            names = tuple(str(d["name"]) for d in leds)
            gain = tuple(_finite(d["gain"], 1e-3, 1e3) for d in leds)
            shift = tuple(_finite(d["shift_nm"], -50.0, 50.0) for d in leds)
            common = _finite(doc.get("common_shift_nm", 0.0), -50.0, 50.0)
            gstd = tuple(
                _finite(d["gain_std"], 0, 1e3) for d in leds if "gain_std" in d
            )
            sstd = tuple(
                _finite(d["shift_std_nm"], 0, 1e3) for d in leds if "shift_std_nm" in d
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(
                f"led_correction: expected {{'leds': [{{'name', 'gain', 'shift_nm'}}, "
                f"...]}} with finite numbers ({exc})",
                path=path,
            ) from None
        if len(set(names)) != len(names):
            raise InputError("led_correction: duplicate LED names", path=path)
        return cls(
            names,
            gain,
            shift,
            common,
            gstd if len(gstd) == len(names) else (),
            sstd if len(sstd) == len(names) else (),
        )


def _finite(value: Any, lo: float, hi: float) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise TypeError(f"{value!r} is not a number")
    v = float(value)
    if not (np.isfinite(v) and lo <= v <= hi):
        raise ValueError(f"{v!r} is outside [{lo:g}, {hi:g}]")
    return v


def apply_led_corrections(
    wavelength_nm: NDArray[np.float64],
    reported: NDArray[np.float64],
    gain: NDArray[np.float64],
    shift_nm: NDArray[np.float64],
) -> NDArray[np.float64]:
    """True spectra from reported ones: ``gain_j * reported_j(l + shift_j)``, >= 0.

    Cubic-spline interpolation (a narrowband LED spans few samples of a 5 nm grid),
    end values held outside the grid.

    References
    ----------
    The paper, Eq. 1 and 3, with per-LED gain and wavelength-offset corrections.

    Examples
    --------
    >>> import numpy as np
    >>> wl = np.arange(400.0, 501.0, 5.0)
    >>> led = np.exp(-0.5 * ((wl - 451.0) / 10.0) ** 2)[None]
    >>> out = apply_led_corrections(wl, led, np.array([2.0]), np.array([1.0]))
    >>> float(wl[np.argmax(out[0])]), round(float(out.max()), 3)
    (450.0, 1.999)
    """
    values, _ = _corrected(wavelength_nm, reported, gain, shift_nm)
    return values


def _corrected(
    wl: NDArray[np.float64],
    reported: NDArray[np.float64],
    gain: NDArray[np.float64],
    shift_nm: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Corrected spectra and their derivative with respect to the shift."""
    x = np.clip(wl[None, :] + shift_nm[:, None], wl[0], wl[-1])
    val = np.empty(reported.shape)
    der = np.empty(reported.shape)
    for j, row in enumerate(np.asarray(reported, dtype=np.float64)):
        spline = CubicSpline(wl, row)  # each LED at its own shifted wavelengths
        val[j], der[j] = spline(x[j]), spline(x[j], 1)
    inside = (wl[None, :] + shift_nm[:, None] >= wl[0]) & (
        wl[None, :] + shift_nm[:, None] <= wl[-1]
    )
    der = np.where(inside & (val > 0), der, 0.0)
    return np.maximum(val, 0.0) * gain[:, None], der * gain[:, None]
