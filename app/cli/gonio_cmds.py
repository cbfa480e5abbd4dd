"""Gonio-imager commands: ``match-illuminant``, ``gonio-plan``, ``gonio-demo`` and the
Zaber emulator (``emulate zaber``, registered by the device commands).

``tunespec match-illuminant --target D50 --illuminants L.csv -o levels.json`` finds the
LED drive levels simulating the target (``core.illuminant_match``), prints Delta u'v',
CIE Ra, TM-30 Rf and the reflectance set's dE00, and writes them with the levels as
JSON. With ``--light SPEC`` it drives that light source to the levels and keeps the
spectrum its spectroradiometer reports (``--measured-out``, spectral CSV).
"""

from __future__ import annotations

import argparse
import sys
import threading
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any, TextIO

from tunespec.app.cli.common import (
    Console,
    add_bench_options,
    add_output_options,
    add_scheduler_option,
    add_sensitivities_option,
    seed_arg,
    serve_until_stopped,
)
from tunespec.core.errors import InputError
from tunespec.core.spectra import Spectra

__all__ = ["add_zaber_emulator", "register", "run_zaber_emulator"]

_SCHEDULER_HELP = (
    "process the geometries on Dask: threads, processes, or a cluster's address "
    "tcp://HOST:PORT (default: one after another)"
)


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the gonio-imager subcommands."""
    _add_match(sub)
    _add_gonio_plan(sub)
    _add_gonio_demo(sub)
    _add_gonio_run(sub)


def _angles(text: str) -> list[float]:
    try:
        return [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated angles in degrees, got {text!r}"
        ) from None


def _mix_arg(p: argparse.ArgumentParser, default: str | None = "d50") -> None:
    p.add_argument(
        "--mix",
        choices=("d50", "camera"),
        default=default,
        help="single-shot LED mix: d50 (the plain D50 match, default) or camera "
        "(that match tuned for the calibrated camera, D50 chromaticity and CIE 51.2 "
        "category B kept)",
    )


def _add_gonio_plan(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "gonio-plan",
        help="write a gonio plan (geometry list, spectral and HDR geometries)",
        description="Write a plan JSON for gonio-demo --plan: the camera at each "
        "THETA_R in the plane of incidence (azimuth --phi-r) with the light at "
        "--theta-i, plus --off-plane THETA_R:PHI_R views; full 22-LED captures at "
        "--spectral angles, HDR brackets from --hdr-from degrees on.",
    )
    p.add_argument("-o", "--output", type=Path, required=True, help="plan JSON")
    p.add_argument("--theta-i", type=float, default=45.0, help="light zenith (45)")
    p.add_argument(
        "--theta-r",
        type=_angles,
        default=[0, 10, 20, 30, 35, 40, 45, 50, 55, 60, 65, 70],
        help="camera zenith angles, e.g. 0,15,30,45,60",
    )
    p.add_argument("--phi-r", type=float, default=180.0, help="camera azimuth (180)")
    p.add_argument(
        "--off-plane",
        action="append",
        default=[],
        metavar="THETA_R:PHI_R",
        help="an extra view (repeatable)",
    )
    p.add_argument(
        "--spectral", type=_angles, default=[0, 20, 45], help="full-capture theta_r"
    )
    p.add_argument("--hdr-from", type=float, default=25.0, help="HDR from this theta_r")
    _mix_arg(p)
    add_output_options(p)
    p.set_defaults(func=cmd_gonio_plan, output_files=("output",))


def cmd_gonio_plan(args: argparse.Namespace) -> int:
    """Run ``gonio-plan``."""
    from tunespec.app.pipeline.gonio import GeometryStep, GonioPlan
    from tunespec.core.limits import valid_number
    from tunespec.devices.goniometer import Geometry

    valid_number(args.hdr_from, "--hdr-from", lo=0.0, hi=90.0)
    valid_number(args.theta_i, "--theta-i", lo=0.0, hi=90.0)
    views = [(t, args.phi_r) for t in args.theta_r]
    for text in args.off_plane:
        try:
            t, ph = (float(v) for v in text.split(":"))
        except ValueError:
            raise InputError(f"--off-plane {text!r}: expected THETA_R:PHI_R") from None
        views.append((t, ph))
    missing = sorted(set(args.spectral) - set(args.theta_r))
    if missing:
        raise InputError(f"--spectral {missing} are not among --theta-r")
    steps = tuple(
        GeometryStep(
            Geometry(args.theta_i, 0.0, t, ph),
            spectral=ph == args.phi_r and t in args.spectral,
            hdr=t >= args.hdr_from,
        )
        for t, ph in views
    )
    plan = GonioPlan(steps, mix=args.mix)
    plan.save(args.output)
    n_s = sum(s.spectral for s in steps)
    out = Console(args)
    out.say(f"{len(steps)} geometries ({n_s} spectral) -> {args.output}")
    out.summary(
        {"n_geometries": len(steps), "n_spectral": n_s, "output": str(args.output)}
    )
    return 0


def _add_gonio_demo(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "gonio-demo",
        help="a multi-geometry session on the simulated gonio bench, end to end",
        description="Calibrate on the SG, match D50, capture a glossy print target at "
        "every geometry of the plan (dark, single shot under the D50 mix, HDR where "
        "planned, 22 LEDs at the spectral geometries), process, fuse and write "
        "gonio.nc, per-geometry CSVs, angles.png and summary.json (scores against "
        "the bench's truth). Killed, it resumes in the same folder with --resume.",
    )
    p.add_argument("-o", "--out", type=Path, required=True, help="session folder")
    p.add_argument(
        "--geometries",
        type=int,
        default=14,
        help="geometries of the default plan (4-14)",
    )
    p.add_argument("--plan", type=Path, help="a plan JSON instead of the default plan")
    _mix_arg(p, default=None)
    p.add_argument("--seed", type=seed_arg, default=0, help="bench seed (default 0)")
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue a session in --out where it stopped",
    )
    add_scheduler_option(p, _SCHEDULER_HELP)
    p.add_argument(
        "--fail-after-moves",
        type=int,
        metavar="N",
        help="(testing) the simulated goniometer fails on its N-th move",
    )
    add_output_options(p)
    p.set_defaults(func=cmd_gonio_demo, output_dirs=("out",))


def cmd_gonio_demo(args: argparse.Namespace) -> int:
    """Run ``gonio-demo``."""
    from tunespec.app.pipeline.gonio_bench import run_gonio_demo
    from tunespec.core.limits import valid_number

    valid_number(args.geometries, "--geometries", lo=4, hi=14, integer=True)
    _start_plan(args)
    out = Console(args)
    try:
        summary = run_gonio_demo(
            args.out,
            n_geometries=args.geometries,
            mix=args.mix or "d50",
            seed=args.seed,
            fail_after_moves=args.fail_after_moves,
            scheduler=args.scheduler,
            progress=out.progress("gonio session"),
        )
    except Exception as exc:
        from tunespec.devices.protocols import DeviceError

        if isinstance(exc, DeviceError):
            raise type(exc)(
                f"{exc}; every frame taken is in {args.out}: continue with --resume"
            ) from exc
        raise
    out.say(
        f"{summary['n_geometries']} geometries ({summary['n_spectral']} spectral): "
        f"spectral RMS full captures {summary['spectral_rms_full_captures']:.4f}, "
        f"fused {summary['spectral_rms_fused']:.4f} "
        f"({summary['rms_ratio_fused_to_full']:.2f}x); D50 dE00 fused mean "
        f"{summary['de00_fused_mean']:.3f} (max {summary['de00_fused_max']:.2f}), "
        f"full captures {summary['de00_full_captures_mean']:.3f}; single shot "
        f"({summary['mix']} mix) at the single-shot-only geometries "
        f"{summary['de00_single_shot_fused_mean']:.3f}"
    )
    _finish(out, args.out, summary)
    return 0


def _add_gonio_run(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "gonio-run",
        help="a multi-geometry session on devices by spec (CAL1, camera, Zaber)",
        description="Capture the plan on real devices - the specs of 'tunespec "
        "capture' for the light and the camera, and a goniometer spec - then process, "
        "fuse and write gonio.nc and per-geometry CSVs. Needs the sensitivities of "
        "'tunespec calibrate'. Each LED is measured once with the light's "
        "spectroradiometer, the mix chosen from those. Killed, it resumes with --resume.",
    )
    p.add_argument("-o", "--out", type=Path, required=True, help="session folder")
    p.add_argument("--plan", type=Path, help="plan JSON (gonio-plan or the GUI editor)")
    add_bench_options(p)
    p.add_argument(
        "--gonio",
        default="sim",
        help="sim | zaber:///dev/ttyUSB0 | zaber+socket://HOST:PORT[?axes=...]",
    )
    add_sensitivities_option(
        p,
        "calibrated sensitivities (tunespec calibrate; needed for a new session)",
        required=False,
    )
    p.add_argument(
        "--layout",
        type=Path,
        help="sample target layout (a new session; a resumed one keeps its own "
        "layout.json)",
    )
    _mix_arg(p, default=None)
    p.add_argument(
        "--resume", action="store_true", help="continue the session in --out"
    )
    add_scheduler_option(p, _SCHEDULER_HELP)
    p.add_argument(
        "--iso",
        type=int,
        default=100,
        help="camera ISO (100); the calibration is scaled to its gain by the "
        "nominal ratio, so the calibration's own ISO is the most accurate",
    )
    add_output_options(p)
    p.set_defaults(func=cmd_gonio_run, output_dirs=("out",))


def _start_plan(args: argparse.Namespace, *, needs: tuple[str, ...] = ()) -> None:
    """Write ``--plan`` (with ``--mix``) into a new session; check a resumed one.

    ``needs``: options a new session cannot do without (e.g. ``plan``).
    """
    from tunespec.app.pipeline.gonio import GonioPlan

    started = (args.out / "plan.json").exists()
    if args.resume and not started:
        raise InputError(
            f"--resume: no gonio session in {args.out} (no plan.json); leave --resume "
            "out to start one"
        )
    if started and not args.resume:
        raise InputError(
            f"{args.out} holds a gonio session already: add --resume to continue it, "
            "or choose another --out"
        )
    if not started:
        missing = [f"--{n}" for n in needs if getattr(args, n) is None]
        if missing:
            raise InputError(f"a new session needs {' and '.join(missing)}")
        if args.plan is not None:
            plan = GonioPlan.load(args.plan)
            args.out.mkdir(parents=True, exist_ok=True)
            replace(plan, mix=args.mix or plan.mix).save(args.out / "plan.json")
        return
    if args.plan is not None:
        raise InputError("--plan is for a new session; a resumed one keeps its plan")
    kept = GonioPlan.load(args.out / "plan.json").mix
    if args.mix is not None and kept != args.mix:
        raise InputError(
            f"--mix {args.mix}: the session in {args.out} uses the {kept} mix"
        )


def cmd_gonio_run(args: argparse.Namespace) -> int:
    """Run ``gonio-run``."""
    from tunespec.app.pipeline.gonio_devices import SESSION_LAYOUT, run_gonio_session
    from tunespec.core.calibration import calibrated_sensitivities
    from tunespec.core.io.spectral import read_spectra_csv
    from tunespec.core.limits import valid_number
    from tunespec.core.plausibility import check_calibration_grid
    from tunespec.devices.protocols import DeviceError

    valid_number(args.iso, "--iso", lo=50, hi=102400, integer=True)
    layout = _session_layout(args)
    saved, side, S = args.out / "calibration.csv", None, None
    # every input read before the session folder gets its plan
    if saved.exists():
        S = read_spectra_csv(saved, allow_negative=True)
    elif args.sensitivities is not None:
        S, side = calibrated_sensitivities(args.sensitivities)  # its LED corrections
        check_calibration_grid(S.wavelength_nm, side)
    _start_plan(args, needs=("plan", "sensitivities", "layout"))
    if layout is None:  # a resumed session from before layout.json was kept
        raise InputError(f"{args.out} has no layout.json: give --layout")
    if S is None:
        raise InputError(f"{args.out} has no calibration.csv yet: give --sensitivities")
    out = Console(args)
    try:
        s = run_gonio_session(
            args.out, light=args.light, camera=args.camera, gonio=args.gonio,
            sensitivity=S, layout=layout, sensitivity_meta=side,
            layout_path=args.layout or args.out / SESSION_LAYOUT,
            resolution=args.resolution, iso=args.iso,
            seed=args.seed,
            scheduler=args.scheduler, progress=out.progress("gonio session"),
        )  # fmt: skip
    except DeviceError as exc:
        raise type(exc)(
            f"{exc}; every frame taken is in {args.out}: continue with --resume"
        ) from exc
    out.say(
        f"{s['n_geometries']} geometries ({s['n_spectral']} spectral, {s['mix']} "
        f"mix), {s['frames_taken_now']} frames taken now"
    )
    _finish(out, args.out, s)
    return 0


def _finish(out: Console, folder: Path, summary: dict[str, Any]) -> None:
    """A processed session's warnings, where its data set went, its summary."""
    for text in summary["warnings"]:
        out.warn(text)
    out.note(f"data set -> {folder / 'gonio.nc'}")
    out.summary({"out": str(folder), **summary})


def _session_layout(args: argparse.Namespace) -> Any:
    """The sample layout of ``gonio-run``: a started session's own ``layout.json``
    (a different ``--layout`` is refused), else ``--layout``; None if neither."""
    from tunespec.app.pipeline.gonio_devices import SESSION_LAYOUT
    from tunespec.core.io.cht import load_layout
    from tunespec.core.layout import TargetLayout

    kept = args.out / SESSION_LAYOUT
    if kept.exists() and (args.out / "plan.json").exists():
        layout = TargetLayout.load(kept)
        if args.layout is not None:
            given = load_layout(args.layout)
            if given.to_dict() != layout.to_dict():
                raise InputError(
                    f"--layout {args.layout}: the session in {args.out} uses its own "
                    f"{SESSION_LAYOUT}; leave --layout out to resume it"
                )
        return layout
    return None if args.layout is None else load_layout(args.layout)


def _add_match(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "match-illuminant",
        help="LED levels simulating an illuminant (D50 by default)",
        description="LED drive levels whose mix reproduces a target SPD: chromaticity "
        "pinned to the target's, metamerism of a reflectance set minimised (CIEDE2000, "
        "CIE 1931 2 deg). Prints Delta u'v', CIE Ra, TM-30 Rf, mean/max dE00.",
    )
    p.add_argument(
        "--target",
        default="D50",
        help="a CIE illuminant colour-science knows (D50, D65, A, FL11, ...) or a "
        "spectral CSV (default D50)",
    )
    p.add_argument("--target-column", help="the column of a multi-spectrum target CSV")
    p.add_argument(
        "--illuminants",
        type=Path,
        help="LED spectra CSV at level 1 (default: the shipped 22-LED CAL1 model)",
    )
    p.add_argument(
        "--reflectances",
        type=Path,
        help="reflectance set whose metamerism is minimised (default: ColorChecker SG)",
    )
    p.add_argument(
        "--max-level",
        type=float,
        default=1.0,
        help="upper limit of every channel's level, in (0, 1] (default 1)",
    )
    p.add_argument("-o", "--output", type=Path, required=True, help="levels JSON")
    p.add_argument(
        "--light",
        help="drive this light source (sim, cal1:///dev/ttyUSB0, cal1+socket://H:P) "
        "to the levels and keep its measured SPD",
    )
    p.add_argument(
        "--leds-from-light",
        action="store_true",
        help="with --light: measure every channel at level 1 with the light's "
        "spectroradiometer first and match with those spectra (closes the loop on "
        "a unit whose LEDs differ from the file's)",
    )
    p.add_argument(
        "--measured-out",
        type=Path,
        help="with --light: the measured SPD as spectral CSV "
        "(default OUTPUT with _measured.csv)",
    )
    add_output_options(p)
    p.set_defaults(func=cmd_match, output_files=("output", "measured_out"))


def cmd_match(args: argparse.Namespace) -> int:
    """Run ``match-illuminant``."""
    from tunespec.core.datasets import load_colorchecker_sg, resource_path
    from tunespec.core.illuminant_match import (
        colour_rendering,
        illuminant_spd,
        match_illuminant,
        spd_delta_uv,
    )
    from tunespec.core.io.session import atomic_write_text
    from tunespec.core.io.spectral import read_spectra_csv
    from tunespec.core.limits import MAX_REFLECTANCE, dumps_json, valid_number

    max_level = valid_number(
        args.max_level, "--max-level", lo=0.0, hi=1.0, lo_open=True
    )
    if args.leds_from_light and not args.light:
        raise InputError("--leds-from-light needs --light SPEC")
    led_path = args.illuminants or resource_path("leds", "cal1_model_22.csv")
    leds = read_spectra_csv(led_path)
    if args.leds_from_light:
        leds, led_path = _measure_leds(args.light), f"measured from {args.light}"
    target = illuminant_spd(args.target, args.target_column)
    refl = (
        read_spectra_csv(args.reflectances, max_value=MAX_REFLECTANCE)
        if args.reflectances
        else load_colorchecker_sg()
    )
    match = match_illuminant(leds, target, refl, max_level=max_level)
    out = match.as_dict()
    out["illuminants"] = str(led_path)
    out["target_source"] = str(args.target)
    if args.light:
        path, spd = _drive_and_measure(args, match.levels, leds.names)
        out["measured_spd"] = str(path)
        out["metrics"]["measured_delta_uv"] = spd_delta_uv(spd, target)
        out["metrics"]["measured_cri_ra"], out["metrics"]["measured_tm30_rf"] = (
            colour_rendering(spd)
        )
    atomic_write_text(args.output, dumps_json(out))
    con = Console(args)
    m = out["metrics"]
    if "measured_delta_uv" in m:
        con.say(
            f"measured by the light source: Delta u'v' {m['measured_delta_uv']:.2e}, "
            f"CIE Ra {m['measured_cri_ra']:.2f}, TM-30 Rf {m['measured_tm30_rf']:.2f}"
        )
    con.say(
        f"{target.names[0]} from {len(leds)} LEDs: Delta u'v' {m['delta_uv']:.2e}, "
        f"CIE Ra {m['cri_ra']:.2f}, TM-30 Rf {m['tm30_rf']:.2f}, dE00 over "
        f"{m['n_reflectances']} reflectances mean {m['mean_de00']:.3f} max "
        f"{m['max_de00']:.3f}"
    )
    if not match.pinned:
        con.warn(
            f"the LEDs cannot reach the chromaticity of {target.names[0]} "
            f"(Delta u'v' {m['delta_uv']:.4f}): the best fit is written"
        )
    con.note(f"levels -> {args.output}")
    con.summary({"output": str(args.output), **out})
    return 0


def _measure_leds(spec: str) -> Spectra:
    """Each channel of the light at level 1, as its spectroradiometer reports it."""
    from tunespec.app.pipeline.gonio_devices import measure_led_spectra
    from tunespec.devices.registry import open_light_source

    light = open_light_source(spec)
    try:
        return measure_led_spectra(light)
    finally:
        light.close()


def _drive_and_measure(
    args: argparse.Namespace, levels: object, names: tuple[str, ...]
) -> tuple[Path, Spectra]:
    """Set the light to ``levels`` and write the SPD its spectroradiometer reports."""
    import numpy as np

    from tunespec.core.io.spectral_csv import write_spectra_csv
    from tunespec.devices.registry import open_light_source

    path = args.measured_out or args.output.with_name(
        args.output.stem + "_measured.csv"
    )
    light = open_light_source(args.light)
    try:
        channels = [c.name for c in light.channels()]
        if len(channels) != len(names):
            raise InputError(
                f"the light source has {len(channels)} channels, the LED file "
                f"{len(names)}: they must be the same LEDs in the same order"
            )
        light.set_levels(np.asarray(levels, dtype=np.float64))
        spd = light.measure_spd()
        write_spectra_csv(spd, path)
    finally:
        light.close()
    return path, spd


def add_zaber_emulator(
    devices: argparse._SubParsersAction[argparse.ArgumentParser],
    port_type: Callable[[str], int],
) -> None:
    """``tunespec emulate zaber``: added to ``emulate`` by the device commands."""
    p = devices.add_parser(
        "zaber",
        help="emulate Zaber rotary stages (ASCII protocol) on a local TCP port",
        description="Serve Zaber's ASCII protocol for daisy-chained rotary stages on "
        "127.0.0.1:PORT (devices/zaber/emulator.py). Connect with the goniometer "
        "spec zaber+socket://127.0.0.1:PORT.",
    )
    p.add_argument("--port", type=port_type, default=0, help="TCP port (0: a free one)")
    p.add_argument(
        "--devices", type=int, default=4, help="stages on the chain, 1-9 (default 4)"
    )
    p.set_defaults(func=lambda a: run_zaber_emulator(port=a.port, n_devices=a.devices))


def run_zaber_emulator(
    *,
    port: int = 0,
    n_devices: int = 4,
    stop: threading.Event | None = None,
    out: TextIO | None = None,
) -> int:
    """Serve the Zaber emulator until Ctrl-C (or ``stop``); exit code 0."""
    from tunespec.devices.zaber.emulator import ZaberEmulator

    if not 1 <= n_devices <= 9:
        raise InputError(f"--devices: expected 1-9 stages, got {n_devices}")
    out = out if out is not None else sys.stdout
    stop = stop if stop is not None else threading.Event()
    try:
        emulator = ZaberEmulator(port, n_devices=n_devices)
    except (OSError, OverflowError) as exc:
        raise InputError(f"cannot listen on 127.0.0.1:{port} ({exc})") from None
    with emulator as emu:
        out.write(
            f"Zaber emulator ({n_devices} stages) listening on {emu.host}:{emu.port}\n"
            f"goniometer spec: {emu.spec()}\npress Ctrl-C to stop\n"
        )
        serve_until_stopped(stop, out)
    return 0
