"""``tunespec extract``: a chart's patch responses from one photograph."""

from __future__ import annotations

import argparse
from pathlib import Path

from tunespec.app.cli.common import Console, add_output_options
from tunespec.core.errors import InputError


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the ``extract`` subcommand."""
    p = sub.add_parser(
        "extract",
        help="patch responses of a chart in one raw file or linear TIFF",
        description="Finds the chart (its patch grid; any background, rotation, "
        "moderate perspective) in a camera raw file (CR2, DNG, anything LibRaw "
        "reads) or a linear 16-bit TIFF, and writes per-patch mean, std, pixel "
        "count and clipped fraction as a responses CSV (one illuminant: the file's "
        "stem). The extraction is checked (ROI uniformity, the neutrals' order, "
        "the G-to-reference-Y correlation, the 3x3 camera-to-XYZ residual, the "
        "outline's fit to the patches seen); a failing one is refused (exit 2) "
        "unless --force, which keeps it flagged in a 'quality' column.",
    )
    p.add_argument("image", type=Path, help="raw file (CR2, DNG, ...) or linear TIFF")
    p.add_argument(
        "--layout",
        required=True,
        help="chart layout: a JSON or Argyll .cht file, or a shipped layout's name "
        "(colorchecker_24, colorchecker_passport, colorchecker_sg, it8_7_2)",
    )
    p.add_argument("-o", "--output", required=True, type=Path, help="responses CSV")
    p.add_argument("--preview", type=Path, help="PNG of the outline and the ROIs")
    p.add_argument(
        "--corners",
        help="the layout's outer corners TL,TR,BR,BL as x,y,x,y,x,y,x,y in the "
        "file's pixels (mosaic pixels of a raw file); default found automatically",
    )
    p.add_argument(
        "--reflectances",
        type=Path,
        help="the chart's reference reflectances (any spectral format; default the "
        "layout's own) for the consistency check",
    )
    p.add_argument(
        "--names",
        type=Path,
        help="name map CSV (their name,patch) for --reflectances named otherwise",
    )
    p.add_argument("--illuminant", help="illuminant name in the CSV (default: stem)")
    p.add_argument(
        "--save-layout",
        type=Path,
        help="write the layout with the corners found (JSON) for process/the GUI",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="keep an extraction that fails the check (flagged in the CSV)",
    )
    add_output_options(p)
    p.set_defaults(func=cmd_extract, output_files=("output", "preview", "save_layout"))


def corners_arg(text: str) -> list[list[float]]:
    """``x,y,x,y,x,y,x,y`` -> four (x, y) pairs."""
    from tunespec.core.limits import valid_number

    parts = [t.strip() for t in text.split(",")]
    if len(parts) != 8:
        raise InputError(
            f"--corners: expected 8 numbers x,y,... (TL, TR, BR, BL), got {len(parts)}"
        )
    try:
        values = [float(t) for t in parts]
    except ValueError:
        raise InputError(f"--corners: not numbers: {text!r}") from None
    for v in values:
        valid_number(v, "--corners", lo=-1e6, hi=1e6)
    return [values[k : k + 2] for k in range(0, 8, 2)]


def cmd_extract(args: argparse.Namespace) -> int:
    from tunespec.app.pipeline.extract import (
        extract_chart,
        layout_reference,
        write_extraction,
    )
    from tunespec.core.io.cht import load_layout

    layout = load_layout(args.layout)
    corners = corners_arg(args.corners) if args.corners else None
    refl = layout_reference(layout, args.reflectances, args.layout, args.names)
    ex = extract_chart(
        args.image,
        layout,
        corners_px=corners,
        reflectances=refl,
        illuminant=args.illuminant,
        force=args.force,
        preview=args.preview,
    )
    write_extraction(ex, args.output)
    if args.save_layout is not None:
        ex.layout.save(args.save_layout)
    m = ex.check.metrics
    figures = ", ".join(
        f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}" for k, v in m.items()
    )
    out = Console(args)
    out.say(
        f"{layout.name}: {layout.n_patches} patches ({ex.method} outline) -> "
        f"{args.output}; check: {ex.check.summary()} ({figures})"
    )
    for note in ex.check.notes:
        out.note(note)
    if ex.forced:
        out.warn(f"kept with --force although the check failed: {ex.check.summary()}")
    out.summary(
        {
            "layout": layout.name,
            "patches": layout.n_patches,
            "outline": ex.method,
            "output": str(args.output),
            "check": {
                "ok": ex.check.ok,
                "problems": list(ex.check.problems),
                "notes": list(ex.check.notes),
                "metrics": dict(m),
            },
            "forced": bool(ex.forced),
        }
    )
    return 0
