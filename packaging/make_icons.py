"""Draw the TuneSpec icon: a spectrum under a smooth spectral curve on a dark tile.

Writes ``resources/icons/tunespec.svg`` (vector), ``tunespec.png`` (256 px) plus
``tunespec-<n>.png`` (16 ... 512 px, for the Linux icon theme) and ``tunespec.ico``
(16 ... 256 px, Windows). Needs only numpy and Pillow; run from the repository root::

    python packaging/make_icons.py

The generated files are committed; rerun after changing the design.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

OUT = Path(__file__).resolve().parents[1] / "resources" / "icons"
MASTER_PX = 1024
SIZES_PNG = (16, 24, 32, 48, 64, 128, 256, 512)
SIZES_ICO = (16, 24, 32, 48, 64, 128, 256)

BACKGROUND = (29, 36, 51)  # dark slate
FRAME = (70, 82, 104)
CORNER = 0.18  # corner radius / size
LEFT, RIGHT, BASE, TOP = 0.14, 0.86, 0.80, 0.20  # plot box, fractions of the size
WL0, WL1 = 400.0, 700.0


def wavelength_rgb(wl_nm: float) -> tuple[int, int, int]:
    """Approximate display colour of a wavelength (Dan Bruton's piecewise model)."""
    if wl_nm < 440:
        r, g, b = -(wl_nm - 440) / 60, 0.0, 1.0
    elif wl_nm < 490:
        r, g, b = 0.0, (wl_nm - 440) / 50, 1.0
    elif wl_nm < 510:
        r, g, b = 0.0, 1.0, -(wl_nm - 510) / 20
    elif wl_nm < 580:
        r, g, b = (wl_nm - 510) / 70, 1.0, 0.0
    elif wl_nm < 645:
        r, g, b = 1.0, -(wl_nm - 645) / 65, 0.0
    else:
        r, g, b = 1.0, 0.0, 0.0
    # Dim the ends of the visible range, as the eye sees them.
    fade = 0.45 + 0.55 * min(1.0, (wl_nm - 380) / 40, (780 - wl_nm) / 80)
    return tuple(round(255 * (c * fade) ** 0.8) for c in (r, g, b))  # type: ignore[return-value]


def curve(wl_nm: np.ndarray) -> np.ndarray:
    """Height 0..1 of the drawn spectrum: two overlapping bands, like a reflectance."""
    g = lambda mu, s: np.exp(-0.5 * ((wl_nm - mu) / s) ** 2)  # noqa: E731
    y = 0.55 * g(455.0, 32.0) + 0.95 * g(590.0, 55.0) + 0.12
    return y / y.max()


def draw_png(size: int) -> Image.Image:
    """The icon at ``size`` px (drawn at 1024 px and downsampled for anti-aliasing)."""
    s = MASTER_PX
    img = Image.new("RGBA", (s, s), (0, 0, 0, 0))
    d = ImageDraw.Draw(img)
    d.rounded_rectangle(
        (0, 0, s - 1, s - 1),
        radius=int(CORNER * s),
        fill=BACKGROUND,
        outline=FRAME,
        width=int(0.012 * s),
    )
    x0, x1 = int(LEFT * s), int(RIGHT * s)
    base, top = BASE * s, TOP * s
    xs = np.arange(x0, x1 + 1)
    wl = WL0 + (xs - x0) / (x1 - x0) * (WL1 - WL0)
    heights = curve(wl)
    for x, w, h in zip(xs, wl, heights, strict=True):
        y = base - h * (base - top)
        d.line([(int(x), int(y)), (int(x), int(base))], fill=wavelength_rgb(float(w)))
    pts = [
        (float(x), float(base - h * (base - top)))
        for x, h in zip(xs, heights, strict=True)
    ]
    d.line(pts, fill=(245, 245, 245), width=int(0.022 * s), joint="curve")
    d.line([(x0, base), (x1, base)], fill=(245, 245, 245), width=int(0.018 * s))
    return img.resize((size, size), Image.Resampling.LANCZOS)


def svg() -> str:
    """The same design as SVG (100 x 100 user units)."""
    n = 61
    wl = np.linspace(WL0, WL1, n)
    h = curve(wl)
    x = 100 * (LEFT + (RIGHT - LEFT) * (wl - WL0) / (WL1 - WL0))
    y = 100 * (BASE - h * (BASE - TOP))
    stops = "\n".join(
        f'      <stop offset="{(w - WL0) / (WL1 - WL0):.4f}" '
        f'stop-color="#{"".join(f"{c:02x}" for c in wavelength_rgb(float(w)))}"/>'
        for w in np.arange(WL0, WL1 + 1, 10.0)
    )
    line = " ".join(f"{a:.2f},{b:.2f}" for a, b in zip(x, y, strict=True))
    area = f"M{x[0]:.2f},{100 * BASE:.2f} L{line} L{x[-1]:.2f},{100 * BASE:.2f} Z"
    bg = "#{:02x}{:02x}{:02x}".format(*BACKGROUND)
    frame = "#{:02x}{:02x}{:02x}".format(*FRAME)
    return f"""<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 100 100" width="256" height="256">
  <title>TuneSpec</title>
  <defs>
    <linearGradient id="spectrum" x1="{100 * LEFT:.1f}" x2="{100 * RIGHT:.1f}" y1="0" y2="0"
                    gradientUnits="userSpaceOnUse">
{stops}
    </linearGradient>
  </defs>
  <rect x="0.6" y="0.6" width="98.8" height="98.8" rx="{100 * CORNER:.1f}" fill="{bg}"
        stroke="{frame}" stroke-width="1.2"/>
  <path d="{area}" fill="url(#spectrum)"/>
  <polyline points="{line}" fill="none" stroke="#f5f5f5" stroke-width="2.2"
            stroke-linejoin="round" stroke-linecap="round"/>
  <line x1="{100 * LEFT:.1f}" y1="{100 * BASE:.1f}" x2="{100 * RIGHT:.1f}" y2="{100 * BASE:.1f}"
        stroke="#f5f5f5" stroke-width="1.8" stroke-linecap="round"/>
</svg>
"""


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "tunespec.svg").write_text(svg(), encoding="utf-8")
    master = draw_png(MASTER_PX)
    for n in SIZES_PNG:
        draw_png(n).save(OUT / f"tunespec-{n}.png", optimize=True)
    draw_png(256).save(OUT / "tunespec.png", optimize=True)
    master.save(OUT / "tunespec.ico", sizes=[(n, n) for n in SIZES_ICO])
    print(f"icons written to {OUT}")


if __name__ == "__main__":
    main()
