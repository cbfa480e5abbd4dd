"""``tunespec estimate-image | batch``: per-pixel reflectance images of sessions."""

from __future__ import annotations

import argparse
from pathlib import Path

from tunespec.app.cli.common import (
    Console,
    add_grid_option,
    add_output_options,
    add_scheduler_option,
    add_sensitivities_option,
)
from tunespec.core.errors import InputError
from tunespec.core.spectra import Grid


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the image subcommands."""
    p = sub.add_parser(
        "estimate-image",
        help="per-pixel reflectance cube, XYZ/L*a*b* and uncertainty images",
        description="Per 2x2 Bayer superpixel: dark, flat field (Eq. 2), Wiener "
        "estimation (Eq. 5) with a photon + read noise model. Writes an ENVI and a "
        "Zarr cube, XYZ, L*a*b* (D50) and uncertainty TIFFs (--formats), an sRGB "
        "PNG and provenance.json into OUT.",
    )
    p.add_argument("session", type=Path, help="a captured session folder")
    _common(p)
    p.set_defaults(func=cmd_estimate_image, output_dirs=("out",))

    b = sub.add_parser(
        "batch",
        help="estimate-image for every session in a folder (resumable)",
        description="Images of every session (a folder with manifest.json, one or "
        "two levels down) with one calibration; OUT/<session path>/ per session. A "
        "session already finished (its provenance.json matches the session and "
        "the calibration) is skipped, so an interrupted batch resumes.",
    )
    b.add_argument("folder", type=Path, help="folder of sessions")
    _common(b)
    b.add_argument(
        "--sessions-at-once",
        type=int,
        default=2,
        metavar="N",
        help="sessions in one Dask graph (default 2)",
    )
    b.set_defaults(func=cmd_batch, output_dirs=("out",))


def _common(p: argparse.ArgumentParser) -> None:
    add_sensitivities_option(
        p, "calibrate's sensitivities CSV (its .meta.json: LED corrections)"
    )
    p.add_argument("-o", "--out", required=True, type=Path, help="output folder")
    p.add_argument(
        "--formats",
        type=formats_arg,
        default=("envi", "zarr", "tiff"),
        metavar="LIST",
        help="files to write, comma-separated from envi (cube.hdr/.img: ENVI, GDAL, "
        "Spectral Python), zarr (cube.zarr: xarray.open_zarr, dask) and tiff "
        "(xyz.tif, lab.tif, uncertainty.tif); default envi,zarr,tiff. The sRGB "
        "preview and provenance.json are always written",
    )
    p.add_argument(
        "--rectify",
        action="store_true",
        help="resample to the target's plane through the session's homography",
    )
    add_scheduler_option(p)
    p.add_argument("--no-clip", action="store_true", help="do not clip to [0, 1]")
    p.add_argument(
        "--noise-model",
        type=noise_model_arg,
        default=None,
        metavar="MODEL",
        help="the camera's photon + read noise: 'photon-transfer' (default: fitted "
        "to the session's white frames) or 'camera:FULL_WELL_E,READ_NOISE_E[,"
        "ISO_GAIN]' (the sensor's figures, e.g. camera:67000,30; ISO_GAIN = session "
        "ISO / base ISO)",
    )
    p.add_argument(
        "--dark",
        choices=("pixel", "smooth"),
        default="pixel",
        help="'pixel' (default): subtract the mean dark frame pixel by pixel; "
        "'smooth': its 15 px box mean, hot pixels kept, which takes the dark "
        "frame's read noise out of every pixel (with one dark frame: a third of "
        "the per-pixel dE00 on the simulated bench)",
    )
    p.add_argument(
        "--level-bins",
        type=int,
        default=None,
        metavar="N",
        help="Wiener matrices per signal level (default 32; see tunespec.core.image)",
    )
    p.add_argument(
        "--phi-bins",
        type=int,
        default=None,
        metavar="N",
        help="Wiener matrices per flat-field factor (default 4)",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="accept a session on another scale than the calibration's chart (its "
        "white background by Eq. 1), listed in provenance.json's 'forced'",
    )
    add_grid_option(p)
    add_output_options(p)
    p.set_defaults(grid=None)  # None: the pipeline's estimation grid, 400:700:5


def formats_arg(text: str) -> tuple[str, ...]:
    """argparse type for ``--formats envi,zarr,tiff``."""
    from tunespec.core.errors import TuneSpecError
    from tunespec.core.io.image_formats import valid_formats

    try:
        return valid_formats(text)
    except TuneSpecError:
        raise argparse.ArgumentTypeError(
            f"expected a comma-separated list of envi, zarr, tiff, got {text!r}"
        ) from None


def noise_model_arg(text: str) -> object:
    """argparse type for ``--noise-model``: ``photon-transfer`` (None: fitted) or
    ``camera:FULL_WELL_E,READ_NOISE_E[,ISO_GAIN]`` (:class:`SensorFigures`)."""
    from tunespec.core.errors import TuneSpecError
    from tunespec.core.image import SensorFigures

    if text == "photon-transfer":
        return None
    kind, _, figures = text.partition(":")
    try:
        values = [float(v) for v in figures.split(",")]
        if kind != "camera" or len(values) not in (2, 3):
            raise ValueError
        return SensorFigures(*values)
    except TuneSpecError as exc:  # before ValueError: InputError is one
        raise argparse.ArgumentTypeError(str(exc)) from None
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected 'photon-transfer' or 'camera:FULL_WELL_E,READ_NOISE_E"
            f"[,ISO_GAIN]' (e.g. camera:67000,30), got {text!r}"
        ) from None


def _settings(args: argparse.Namespace) -> object:
    from tunespec.app.pipeline.image import ImageSettings

    grid: Grid | None = args.grid
    bins = {
        k: v
        for k, v in (("n_levels", args.level_bins), ("n_phi", args.phi_bins))
        if v is not None
    }
    return ImageSettings(
        grid=grid,
        rectify=args.rectify,
        clip=not args.no_clip,
        noise=args.noise_model,
        dark=args.dark,
        formats=args.formats,
        force=args.force,
        **bins,
    )


def cmd_estimate_image(args: argparse.Namespace) -> int:
    from tunespec.app.pipeline.image import estimate_images

    if not (args.session / "manifest.json").is_file():
        raise InputError("not a session folder (no manifest.json)", path=args.session)
    out = Console(args)
    prov = estimate_images(
        args.session,
        args.sensitivities,
        args.out,
        settings=_settings(args),  # type: ignore[arg-type]
        scheduler=args.scheduler,
        progress=out.progress("estimating images"),
        warn=out.warn,
    )
    rows, cols = prov["shape"]
    files = ", ".join(v.split(" ")[0] for v in prov["files"].values())
    out.say(f"{cols}x{rows} px x {len(prov['channels'])} LEDs -> {args.out} ({files})")
    out.summary({"out": str(args.out), **prov})
    return 0


def cmd_batch(args: argparse.Namespace) -> int:
    from tunespec.app.pipeline.image import batch_images

    if args.sessions_at_once < 1:
        raise InputError(f"--sessions-at-once {args.sessions_at_once}: must be >= 1")
    out = Console(args)
    result = batch_images(
        args.folder,
        args.sensitivities,
        args.out,
        settings=_settings(args),  # type: ignore[arg-type]
        scheduler=args.scheduler,
        sessions_at_once=args.sessions_at_once,
        progress=out.progress("batch"),
        warn=out.warn,
    )
    for s in result["skipped"]:
        out.say(f"skipped (already done): {s}")
    for s in result["done"]:
        out.say(f"done: {s}")
    out.say(
        f"{len(result['done'])} session(s) estimated, {len(result['skipped'])} skipped"
    )
    out.summary(result)
    return 0
