"""The tone curve an ICC profile embedded in an image declares.

A TIFF exported by a raw converter carries the profile of the space it was rendered
into (sRGB, Adobe RGB, ProPhoto: a tone curve of gamma 1.8-2.4); a linear export
carries none, or one whose curve is the identity. Eq. 1 needs linear camera data, so
:func:`profile_tone` tells the two apart from the matrix/TRC profile's red, green and
blue tone curves (``rTRC``, ``gTRC``, ``bTRC``; ``kTRC`` for grey), as the ICC
specification defines them: ``curv`` (identity, one gamma, or a sampled table) and
``para`` (the five parametric functions). Profiles that describe their curves only
through lookup tables (``A2B0``) are not judged.

References
----------
International Color Consortium, *ICC.1:2022 Image technology colour management:
Architecture, profile format and data structure*, 7.2 (header), 7.3 (tag table),
10.6 (``curveType``), 10.18 (``parametricCurveType``).
"""

from __future__ import annotations

import struct

import numpy as np

__all__ = ["LINEAR_TOLERANCE", "profile_tone"]

#: Largest relative departure from the identity, at mid-grey and in the shadows,
#: of a tone curve still called linear (a table's 16-bit rounding is 1e-5).
LINEAR_TOLERANCE = 0.02
#: The tag table starts after the 128-byte header; each entry is 12 bytes.
_HEADER_BYTES = 128
_TRC_TAGS = (b"rTRC", b"gTRC", b"bTRC", b"kTRC")
#: The inputs the curve is judged at: shadows, mid-grey, half scale.
_PROBES = np.array([0.05, 0.18, 0.5])
#: Parameters of ``para``'s function types 0-4 (ICC.1 table 68).
_PARA_COUNTS = {0: 1, 1: 3, 2: 4, 3: 5, 4: 7}


def profile_tone(profile: bytes) -> float | None:
    """The gamma of the profile's tone curves at mid-grey, ``log TRC(0.18) / log
    0.18`` (a TRC decodes the file's values to linear light: sRGB's gives 2.1,
    ProPhoto's 1.8), when they are not the identity within
    :data:`LINEAR_TOLERANCE`; ``None`` for a linear profile, or one this cannot
    judge (no TRC tags, a malformed one)."""
    try:
        tags = _tag_table(profile)
        curves = [_curve(profile, *tags[sig]) for sig in _TRC_TAGS if sig in tags]
    except (struct.error, ValueError, KeyError):
        return None
    for curve in curves:
        y = curve(_PROBES)
        if np.any(np.abs(y - _PROBES) > LINEAR_TOLERANCE * _PROBES):
            return float(np.log(max(y[1], 1e-12)) / np.log(_PROBES[1]))
    return None


def _tag_table(profile: bytes) -> dict[bytes, tuple[int, int]]:
    (count,) = struct.unpack_from(">I", profile, _HEADER_BYTES)
    if count > 1000:
        raise ValueError("implausible tag count")
    table = {}
    for k in range(count):
        sig, offset, size = struct.unpack_from(
            ">4sII", profile, _HEADER_BYTES + 4 + 12 * k
        )
        if offset + size > len(profile):
            raise ValueError("tag beyond the profile")
        table[sig] = (offset, size)
    return table


def _curve(profile: bytes, offset: int, size: int):
    """The tone curve at ``offset`` as a function of inputs in [0, 1]."""
    kind = profile[offset : offset + 4]
    if kind == b"curv":
        (n,) = struct.unpack_from(">I", profile, offset + 8)
        if n == 0:
            return lambda x: x
        if n == 1:
            (g,) = struct.unpack_from(">H", profile, offset + 12)
            return lambda x: x ** (g / 256.0)
        if 12 + 2 * n > size:
            raise ValueError("curv table beyond its tag")
        table = np.frombuffer(profile, ">u2", n, offset + 12) / 65535.0
        return lambda x: np.interp(x, np.linspace(0.0, 1.0, n), table)
    if kind == b"para":
        (ftype,) = struct.unpack_from(">H", profile, offset + 8)
        n = _PARA_COUNTS[ftype]
        p = [v / 65536.0 for v in struct.unpack_from(f">{n}i", profile, offset + 12)]
        return _parametric(ftype, *p, *[0.0] * (7 - n))
    raise ValueError("not a curve")


def _parametric(ftype: int, g: float, a: float, b: float, c: float, d: float,
                e: float, f: float):  # fmt: skip
    """``parametricCurveType``'s function ``ftype`` (ICC.1 table 68)."""
    if ftype == 0:
        return lambda x: x**g
    # types 1-2 switch at -b/a, types 3-4 at d; below it 0, c, c x or c x + f
    at = -b / a if ftype in (1, 2) and a else d

    def curve(x):
        top = np.maximum(a * x + b, 0.0) ** g + (c if ftype == 2 else 0.0)
        top = top + (e if ftype == 4 else 0.0)
        low = {1: 0.0 * x, 2: c + 0.0 * x, 3: c * x, 4: c * x + f}[ftype]
        return np.where(x >= at, top, low)

    return curve
