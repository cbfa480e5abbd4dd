"""``tunespec demo | capture | process | run``: measurement sessions on the command line."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from tunespec.app.cli.common import (
    Console,
    add_bench_options,
    add_output_options,
    add_scheduler_option,
    resolution_arg,
    seed_arg,
)
from tunespec.app.cli.record_opts import add_record_options, record_from_args
from tunespec.core.errors import InputError
from tunespec.core.io.cht import load_layout
from tunespec.core.io.session import Session
from tunespec.core.limits import check_output_file

__all__ = ["register"]


def _exposure(text: str) -> str | float:
    if text == "auto":
        return text
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected 'auto' or seconds, got {text!r}"
        ) from None
    if not value > 0:
        raise argparse.ArgumentTypeError("exposure must be > 0 s")
    return value


def _seconds(text: str) -> float:
    """argparse type: a duration in seconds, finite and above 0 (checked before any
    device opens)."""
    value = _exposure(text)
    if value == "auto" or not float(value) < 1e6:
        raise argparse.ArgumentTypeError(f"expected seconds above 0, got {text!r}")
    return float(value)


def _floats(text: str) -> tuple[float, ...]:
    try:
        return tuple(float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated numbers, got {text!r}"
        ) from None


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the session subcommands."""
    _add_demo(sub)
    _add_capture(sub)
    _add_process(sub)
    _add_run(sub)


def _add_demo(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The ``demo`` subcommand."""
    # the registry's constant (pipeline.plan.DEMO_RESOLUTION is the same object):
    # the pipeline imports every step, which ``tunespec --help`` must not pay
    from tunespec.devices.registry import DEFAULT_SIM_RESOLUTION as DEMO_RESOLUTION

    p = sub.add_parser(
        "demo",
        help="the full measurement on the simulated bench (no hardware needed)",
        description="Capture the ColorChecker SG and a CMY sample target under all "
        "22 LEDs of the simulated bench, process, calibrate, estimate reflectances, "
        "and write exports and a report; prints Tables 1 and 2 against the bench's "
        "truth. Re-running on the same folder resumes it.",
    )
    p.add_argument(
        "-o", "--out", type=Path, default=Path("tunespec-demo"), help="folder"
    )
    p.add_argument("--seed", type=seed_arg, default=0, help="simulation seed (0)")
    p.add_argument(
        "--resolution",
        type=resolution_arg,
        default=DEMO_RESOLUTION,
        metavar="WxH",
        help=f"simulated camera resolution (default {DEMO_RESOLUTION[0]}x"
        f"{DEMO_RESOLUTION[1]}; the 5D Mark III has 5760x3840)",
    )
    p.add_argument("--no-report", action="store_true", help="skip the HTML/PDF report")
    p.add_argument(
        "--no-chart-choice",
        action="store_true",
        help="leave out the report's chart comparison (a ColorChecker 24 and the SG "
        "each calibrated on a bench of the same seed, about 20 s more)",
    )
    add_record_options(p)
    add_output_options(p)
    p.set_defaults(func=cmd_demo, output_dirs=("out",))


def _add_capture(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The ``capture`` subcommand."""
    p = sub.add_parser(
        "capture",
        help="capture a session: darks, white background and target under each LED",
        description="Capture (or resume) a measurement session into a folder. Every "
        "frame is saved as it comes; after a crash, --resume takes only what is "
        "missing.",
    )
    add_bench_options(p)
    p.add_argument(
        "--layout", type=Path, help="target layout JSON (needed for a new session)"
    )
    p.add_argument("-o", "--out", required=True, type=Path, help="session folder")
    p.add_argument("--resume", action="store_true", help="continue an existing session")
    p.add_argument(
        "--retake",
        action="append",
        default=[],
        metavar="FRAME_ID",
        help="take this frame again (repeatable; implies --resume)",
    )
    p.add_argument(
        "--exposure",
        type=_exposure,
        default="auto",
        help="'auto' (metered per LED) or seconds for every LED",
    )
    p.add_argument(
        "--max-exposure",
        type=_seconds,
        default=30.0,
        metavar="S",
        help="longest exposure auto may choose (30 s)",
    )
    p.add_argument(
        "--iso",
        type=int,
        default=100,
        help="ISO speed of every frame (100); processing counts its gain in Eq. 1's "
        "illuminants (ISO / 100, nominal), so a chart and a sample may differ",
    )
    p.add_argument(
        "--brackets",
        type=_floats,
        default=(1.0,),
        metavar="1,0.125",
        help="exposure brackets per LED, merged as HDR in processing",
    )
    p.add_argument(
        "--repeats",
        type=int,
        default=1,
        metavar="N",
        help="frames per LED and bracket, averaged in processing (1/N of the noise "
        "variance, for per-pixel images)",
    )
    p.add_argument("--darks", type=int, default=1, help="dark frames per exposure")
    p.add_argument("--channels", default=None, help="comma-separated LED channels")
    p.add_argument(
        "--strict",
        action="store_true",
        help="stop (exit 2) at the first frame that is saturated or under-exposed, "
        "instead of warning and going on (the frame is taken again on --resume)",
    )
    add_output_options(p)
    # None: not given (a resumed session then keeps the seed it was captured with)
    p.set_defaults(func=cmd_capture, output_dirs=("out",), seed=None)


def _add_process(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The ``process`` subcommand."""
    p = sub.add_parser(
        "process",
        help="responses and illuminants of a captured session",
        description="Dark subtraction, flat field (Eq. 2), target corners, central "
        "ROI statistics: writes the responses CSV that calibrate/estimate read, and "
        "the illuminants (measured SPD x exposure).",
    )
    p.add_argument("session", type=Path, help="session folder")
    p.add_argument("-o", "--output", required=True, type=Path, help="responses CSV")
    p.add_argument(
        "--illuminants-out",
        type=Path,
        default=None,
        metavar="L.csv",
        help="illuminants CSV (default: beside the responses)",
    )
    p.add_argument(
        "--layout", type=Path, default=None, help="layout JSON (default: the session's)"
    )
    p.add_argument(
        "--corners",
        default=None,
        help="auto | layout | x1,y1,x2,y2,x3,y3,x4,y4 (TL TR BR BL, px)",
    )
    p.add_argument(
        "--roi-fraction",
        type=float,
        default=None,
        help="ROI area fraction of a patch (layout's, paper: 0.2)",
    )
    p.add_argument(
        "--allow-incomplete",
        action="store_true",
        help="leave out channels with missing frames",
    )
    p.add_argument(
        "--no-verify",
        dest="verify",
        action="store_false",
        help="skip checking every raw and SPD file against its checksum (checked "
        "by default)",
    )
    p.add_argument(
        "--verify", action="store_true", default=True, help=argparse.SUPPRESS
    )  # the default now; kept so older scripts still run
    p.add_argument(
        "--reflectances",
        type=Path,
        default=None,
        help="the chart's reference reflectances for the extraction check (default "
        "the layout's own, if it names a file)",
    )
    p.add_argument(
        "--names",
        type=Path,
        default=None,
        help="name map CSV (their name,patch) for --reflectances named otherwise",
    )
    p.add_argument(
        "--preview", type=Path, default=None, help="PNG of the outline and the ROIs"
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="keep an extraction that fails the check (flagged in the CSV)",
    )
    add_output_options(p)
    p.set_defaults(
        func=cmd_process, output_files=("output", "illuminants_out", "preview")
    )


def _add_run(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The ``run`` subcommand."""
    p = sub.add_parser(
        "run",
        help="capture -> process -> calibrate -> estimate -> export from a config",
        description="Run the whole measurement from a JSON or TOML configuration "
        "(see tunespec.app.pipeline.plan.load_config); existing sessions are resumed.",
    )
    p.add_argument(
        "config", type=Path, nargs="?", help="configuration (.json or .toml)"
    )
    p.add_argument(
        "--print-example",
        action="store_true",
        help="print an example configuration with every key and its default "
        "(it runs on the simulated bench as it is) and exit",
    )
    p.add_argument(
        "-o",
        "--out",
        type=Path,
        default=None,
        metavar="DIR",
        help="the measurement folder (default: the configuration's out, which must "
        "stay inside the configuration's folder)",
    )
    add_scheduler_option(
        p,
        "where the Dask steps compute, replacing the configuration's scheduler; a "
        "dask.distributed address in the configuration is used only when given here "
        "too",
    )
    add_record_options(p)
    add_output_options(p)
    p.set_defaults(func=cmd_run, output_dirs=("out",))


def _print_result(out: Console, result: object, wall_s: float) -> None:
    out.say(result.format_text())  # type: ignore[attr-defined]
    for w in result.warnings:  # type: ignore[attr-defined]
        out.warn(w)
    files = result.files  # type: ignore[attr-defined]
    exports = {p.parent for p in files.values() if p.name != "summary.json"}
    out.say(
        f"\n{len(files)} files in {', '.join(sorted(map(str, exports)))}, e.g. "
        + ", ".join(p.name for p in list(files.values())[:6])
    )
    if "report_html" in files:
        out.say(f"report: {files['report_html']}")
    out.say(f"done in {wall_s:.1f} s")
    out.summary(
        {
            **result.summary(),  # type: ignore[attr-defined]
            "files": {k: str(v) for k, v in files.items()},
        }
    )


def _demo_seed_matches(args: argparse.Namespace) -> None:
    """A demo folder is resumed with its own seed: another ``--seed`` is refused
    (it would return the first seed's tables)."""
    from tunespec.core.limits import read_json

    truth = args.out / "truth" / "truth.json"
    if not truth.is_file():
        return
    doc = read_json(truth)
    camera = doc.get("camera") if isinstance(doc, dict) else None
    seed = camera.get("seed") if isinstance(camera, dict) else None
    if isinstance(seed, int) and seed != args.seed:
        raise InputError(
            f"{args.out} holds a demo of seed {seed}; running it again resumes that "
            f"demo, not --seed {args.seed}: choose another --out (or --seed {seed})",
            path=args.out,
        )


def cmd_demo(args: argparse.Namespace) -> int:
    from tunespec.app.pipeline.run import run_demo

    _demo_seed_matches(args)
    out = Console(args)
    t0 = time.perf_counter()
    result = run_demo(
        args.out,
        progress=out.progress("demo"),
        seed=args.seed,
        resolution=args.resolution,
        report_files=not args.no_report,
        chart_choice=not args.no_chart_choice,
        record=record_from_args(args),
    )
    _print_result(out, result, time.perf_counter() - t0)
    return 0


def cmd_capture(args: argparse.Namespace) -> int:
    from tunespec.app.pipeline.jobs import (
        CaptureInputs,
        CaptureSettings,
        Resume,
        capture_job,
    )

    out = Console(args)
    # resume and retake are the pipeline's (pipeline.capture.open_for_capture): the
    # missing frames are taken with the session's own settings and camera
    resume = args.resume or bool(args.retake)
    result = capture_job(
        CaptureInputs(
            args.out,
            load_layout(args.layout) if args.layout is not None else None,
            CaptureSettings(
                exposure=args.exposure,
                iso=args.iso,
                brackets=tuple(args.brackets),
                n_darks=args.darks,
                repeats=args.repeats,
                channels=tuple(args.channels.split(",")) if args.channels else None,
                max_exposure_s=args.max_exposure,
                strict=args.strict,
            ),
            Resume("continue" if resume else "new", retake=tuple(args.retake)),
            light=args.light,
            camera=args.camera,
            layout_path=args.layout,
            resolution=args.resolution,
            seed=args.seed,
        ),
        progress=out.progress("capturing"),
        on_warning=out.warn,
    )
    out.say(
        f"{len(result.captured)} frame(s) captured, {result.skipped} already there; "
        f"session {args.out} is complete"
    )
    out.summary(
        {
            "captured": len(result.captured),
            "skipped": result.skipped,
            "session": str(args.out),
            "warnings": list(result.warnings),
        }
    )
    return 0


def _corners_arg(text: str | None) -> object:
    if text is None or text in ("auto", "layout"):
        return text
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != 8:
        raise InputError(
            f"--corners: expected auto, layout or 8 numbers x1,y1,...,x4,y4, got {text!r}"
        )
    return [values[i : i + 2] for i in range(0, 8, 2)]


def cmd_process(args: argparse.Namespace) -> int:
    illum = args.illuminants_out or args.output.with_name(
        args.output.stem + "_illuminants.csv"
    )
    check_output_file(illum, "--illuminants-out")
    out = Console(args)
    session = Session.open(args.session)
    layout = load_layout(args.layout) if args.layout else None
    from tunespec.app.pipeline.extract import layout_reference_xyz
    from tunespec.app.pipeline.jobs import ProcessInputs, process_job
    from tunespec.core.io.raw import f_number_text

    use = layout or session.layout
    ref = (
        layout_reference_xyz(use, args.reflectances, args.layout, args.names)
        if use is not None
        else None
    )
    processed = process_job(
        ProcessInputs(
            args.session,
            args.output,
            illum,
            layout=layout,
            corners=_corners_arg(args.corners),
            roi_fraction=args.roi_fraction,
            allow_incomplete=args.allow_incomplete,
            verify=args.verify,
            reference_xyz=ref,
            preview=args.preview,
            force=args.force,
        ),
        progress=out.progress("processing"),
    )
    for w in processed.warnings:
        out.warn(w)
    r = processed.responses
    corners = processed.layout.corners_px or ()
    out.say(
        f"{len(r.patches)} patches x {len(r.illuminants)} illuminants; corners "
        f"({processed.corners_source}): "
        + " ".join(f"({x:.1f},{y:.1f})" for x, y in corners)
    )
    out.say(
        f"responses written to {args.output}, illuminants to {illum} (aperture "
        f"{f_number_text(processed.aperture)})"
    )
    out.summary(
        {
            "patches": len(r.patches),
            "f_number": processed.aperture,
            "illuminants": len(r.illuminants),
            "corners_source": processed.corners_source,
            "corners_px": [list(map(float, c)) for c in corners],
            "warnings": list(processed.warnings),
            "files": {"responses": str(args.output), "illuminants": str(illum)},
        }
    )
    return 0


def cmd_run(args: argparse.Namespace) -> int:
    if args.print_example:
        from tunespec.app.pipeline.plan import example_config

        print(example_config(), end="")
        return 0
    if args.config is None:
        raise InputError(
            "give a configuration file (tunespec run --print-example > run.toml)"
        )
    from tunespec.app.pipeline.run import run_config

    out = Console(args)
    t0 = time.perf_counter()
    result = run_config(
        args.config,
        progress=out.progress("run"),
        out=args.out,
        scheduler=args.scheduler,
        record=record_from_args(args),
    )
    _print_result(out, result, time.perf_counter() - t0)
    return 0
