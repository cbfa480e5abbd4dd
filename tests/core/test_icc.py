"""The tone curve an ICC profile embedded in a TIFF declares (``core/io/icc.py``): a
rendered export is refused by ``extract``, a linear one read."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from tunespec.app.pipeline.extract import read_linear_image
from tunespec.core.errors import InputError
from tunespec.core.io.icc import profile_tone

ARGYLL_REF = Path("/usr/share/color/argyll/ref")


def _profile(tags: dict[bytes, bytes]) -> bytes:
    """A matrix/TRC profile's bytes with ``tags`` (signature -> data), as ICC.1 lays
    them out: the 128-byte header, the tag count and table, the data 4-byte aligned."""
    table, data = b"", b""
    start = 128 + 4 + 12 * len(tags)
    for sig, body in tags.items():
        table += struct.pack(">4sII", sig, start + len(data), len(body))
        data += body + b"\0" * (-len(body) % 4)
    body = struct.pack(">I", len(tags)) + table + data
    header = struct.pack(">I", 128 + len(body)) + b"\0" * 124
    return header + body


def _curv(*values: int) -> bytes:
    return b"curv\0\0\0\0" + struct.pack(f">I{len(values)}H", len(values), *values)


def _para(ftype: int, *params: float) -> bytes:
    fixed = [round(p * 65536) for p in params]
    return b"para\0\0\0\0" + struct.pack(f">HH{len(fixed)}i", ftype, 0, *fixed)


def _rgb(curve: bytes) -> bytes:
    return _profile({b"rTRC": curve, b"gTRC": curve, b"bTRC": curve})


#: sRGB's decoding curve as ICC v4 writes it (type 3: gamma 2.4, the linear toe).
SRGB_PARA = _para(3, 2.4, 1 / 1.055, 0.055 / 1.055, 1 / 12.92, 0.04045)


@pytest.mark.parametrize(
    ("curve", "gamma"),
    [
        (_curv(), None),  # the identity
        (_curv(256), None),  # gamma 1.0
        (_curv(563), 563 / 256),  # gamma 2.2 (u8Fixed8)
        (_curv(*np.round(np.linspace(0, 1, 256) ** 1.8 * 65535).astype(int)), 1.8),
        (_curv(*np.round(np.linspace(0, 1, 16) * 65535).astype(int)), None),
        (_para(0, 1.0), None),
        (_para(0, 2.2), 2.2),
        (SRGB_PARA, 2.10),
    ],
)
def test_the_tone_curve_is_read_from_curv_and_para(curve, gamma) -> None:
    found = profile_tone(_rgb(curve))
    if gamma is None:
        assert found is None
    else:
        assert found == pytest.approx(gamma, abs=0.01)


def test_a_profile_without_curves_or_malformed_is_not_judged() -> None:
    assert profile_tone(_profile({b"desc": b"desc\0\0\0\0"})) is None
    assert profile_tone(b"\0" * 40) is None
    cut = _rgb(_curv(563))
    assert profile_tone(cut[:-8]) is None  # a tag beyond the profile's end


@pytest.mark.skipif(not ARGYLL_REF.is_dir(), reason="ArgyllCMS' reference profiles")
@pytest.mark.parametrize(
    ("name", "gamma"),
    [("sRGB", 2.10), ("ProPhoto", 1.80), ("ClayRGB1998", 2.20), ("ProPhotoLin", None)],
)
def test_argylls_reference_profiles(name, gamma) -> None:
    found = profile_tone((ARGYLL_REF / f"{name}.icm").read_bytes())
    assert found == (None if gamma is None else pytest.approx(gamma, abs=0.01))


def test_a_rendered_tiff_is_refused_and_a_linear_one_read(tmp_path) -> None:
    import tifffile

    rgb = np.full((8, 8, 3), 20000, dtype=np.uint16)
    rendered, linear = tmp_path / "rendered.tif", tmp_path / "linear.tif"
    tifffile.imwrite(rendered, rgb, photometric="rgb", iccprofile=_rgb(SRGB_PARA))
    tifffile.imwrite(linear, rgb, photometric="rgb", iccprofile=_rgb(_curv(256)))
    with pytest.raises(InputError) as err:
        read_linear_image(rendered)
    assert str(err.value).startswith(
        f"{rendered}: its ICC profile declares a tone curve (gamma 2.10 at mid-grey)"
    ), err.value
    image = read_linear_image(linear)
    assert np.allclose(image.planes, 20000 / 65535)
