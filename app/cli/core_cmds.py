"""``tunespec calibrate | estimate | evaluate | simulate-responses``: the core on files."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

from tunespec.app.cli.common import (
    Console,
    add_force_option,
    add_grid_option,
    add_output_options,
    add_sensitivities_option,
    plausibility_checks,
    resolve_grid,
    seed_arg,
)
from tunespec.core.calibration import (
    absolute_sensitivities,
    calibrated_sensitivities,
    calibration_curves,
)
from tunespec.core.errors import InputError, check_names, shown_names
from tunespec.core.io.export import read_sensitivity_meta, write_sensitivities_csv
from tunespec.core.io.responses_csv import read_responses_csv, write_responses_csv
from tunespec.core.io.spectral import read_spectral
from tunespec.core.io.spectral_csv import write_spectra_csv
from tunespec.core.limits import dumps_json, valid_number
from tunespec.core.responses import Responses
from tunespec.core.spectra import CALIBRATION_MAX_STEP_NM, Grid, Spectra

#: Largest --noise-std (responses are in full-scale units, 0..1).
MAX_NOISE_STD = 1.0

#: What the spectral options accept (any of these, found from the content).
SPECTRAL_FORMATS = (
    "spectral CSV (any separator; wavelengths down or one spectrum per row), "
    "CGATS (.ti3/.cie/.sp, i1Profiler) or rawtoaces JSON"
)

#: ``core.sensitivity.SENSITIVITY_METHODS``'s keys (a test checks), named here because
#: importing the estimators (scipy) would cost ``tunespec --help`` a third of a second.
METHOD_CHOICES = ("bayes", "pca", "smooth")


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the core subcommands."""
    _add_calibrate(sub)
    _add_estimate(sub)
    _add_evaluate(sub)
    _add_simulate_responses(sub)


def _add_responses_and_illuminants(p: argparse.ArgumentParser) -> None:
    """``--responses`` and ``--illuminants``, as calibrate and estimate take them."""
    p.add_argument("--responses", required=True, type=Path, help="responses CSV")
    p.add_argument(
        "--illuminants",
        required=True,
        type=Path,
        help="LED spectra: " + SPECTRAL_FORMATS,
    )


def _add_calibrate(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The ``calibrate`` subcommand."""
    p = sub.add_parser(
        "calibrate",
        help="estimate camera sensitivities from a chart under all LEDs (Table 1)",
        description="Camera sensitivities from chart responses under all LEDs "
        "(paper Eq. 3-4 and better estimators); prints Table 1.",
    )
    _add_responses_and_illuminants(p)
    p.add_argument(
        "--reflectances",
        required=True,
        type=Path,
        help="chart reflectances, 0-1 or percent (detected): " + SPECTRAL_FORMATS,
    )
    p.add_argument(
        "--names",
        type=Path,
        help="name map CSV (their name,patch) for reflectances named otherwise, e.g. "
        "resources/charts/colorchecker_24_colour_science_names.csv",
    )
    p.add_argument(
        "--method",
        choices=METHOD_CHOICES,
        default="bayes",
        help="bayes (default): evidence-chosen priors and per-LED self-calibration "
        "with uncertainties; smooth: the previous default; pca: the paper's Eq. 4",
    )
    p.add_argument(
        "--self-calibrate",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="bayes: fit each LED's gain and wavelength offset with the sensitivities "
        "(default on); saved in OUTPUT.meta.json and applied by 'tunespec estimate'",
    )
    p.add_argument("--components", type=int, default=4, help="pca: components (4)")
    p.add_argument(
        "--explained-variance",
        type=float,
        default=None,
        help="pca: use as many components as reach this fraction (e.g. 0.97)",
    )
    p.add_argument(
        "--exclude-camera",
        default=None,
        help="pca/smooth: leave this camera out of the database",
    )
    p.add_argument(
        "--fit-spd-shift",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="also fit the spectroradiometer's wavelength shift (default: on for "
        "bayes and smooth, off for pca); saved beside the output as OUTPUT.meta.json, where "
        "'tunespec estimate' picks it up",
    )
    p.add_argument(
        "--hold-out-every",
        type=int,
        default=None,
        metavar="N",
        help="fit without every N-th patch (N >= 2) and report Table 1 on them too",
    )
    p.add_argument(
        "--self-check",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="check the residuals against the noise model, the LED corrections, the "
        "light's reading noise, and predict the patches a second calibration leaves "
        "out (1 in 5, or those of --hold-out-every); findings are warnings (default "
        "on; about doubles the time without --hold-out-every)",
    )
    add_grid_option(p)
    add_force_option(p)
    add_output_options(p)
    p.add_argument("-o", "--output", required=True, type=Path, help="sensitivities CSV")
    p.add_argument("--stats", type=Path, help="write the statistics as JSON")
    p.set_defaults(func=cmd_calibrate, output_files=("output", "stats"))


def _add_estimate(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The ``estimate`` subcommand."""
    p = sub.add_parser(
        "estimate",
        help="Wiener reflectance estimation (Eq. 5-6)",
        description="Reflectances from responses under all LEDs by Wiener estimation "
        "with patch-wise noise covariance (Eq. 5-6).",
    )
    _add_responses_and_illuminants(p)
    add_sensitivities_option(p)
    p.add_argument(
        "--prior", type=Path, help="prior reflectances (default: the SG), any format"
    )
    p.add_argument(
        "--noise-std",
        type=float,
        default=None,
        help="one noise level for all responses (default: per patch, Eq. 6)",
    )
    p.add_argument(
        "--uncentred-prior",
        action="store_true",
        help="use the prior's correlation matrix instead of its covariance",
    )
    p.add_argument("--no-clip", action="store_true", help="do not clip to [0, 1]")
    p.add_argument(
        "--spd-shift-nm",
        type=float,
        default=None,
        help="spectroradiometer wavelength shift to undo on the SPDs (default: from "
        "SENSITIVITIES.meta.json written by calibrate, else 0)",
    )
    p.add_argument(
        "--no-corrections",
        action="store_true",
        help="estimate without the calibration's side file SENSITIVITIES.meta.json "
        "(LED corrections, covariance): worse results and no uncertainties",
    )
    add_grid_option(p)
    add_force_option(p)
    add_output_options(p)
    p.add_argument("-o", "--output", required=True, type=Path)
    p.set_defaults(func=cmd_estimate, output_files=("output",))


def _add_evaluate(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The ``evaluate`` subcommand."""
    p = sub.add_parser(
        "evaluate",
        help="spectral RMS and CIEDE2000 (D50) against references (Table 2)",
    )
    p.add_argument(
        "--estimated",
        required=True,
        type=Path,
        help="reflectances: " + SPECTRAL_FORMATS,
    )
    p.add_argument(
        "--reference", required=True, type=Path, help="references, 0-1 or percent"
    )
    add_grid_option(p)
    add_force_option(p)
    add_output_options(p)
    p.add_argument("--stats", type=Path, help="write the statistics as JSON")
    p.set_defaults(func=cmd_evaluate, output_files=("stats",))


def _add_simulate_responses(
    sub: argparse._SubParsersAction[argparse.ArgumentParser],
) -> None:
    """The ``simulate-responses`` subcommand."""
    p = sub.add_parser(
        "simulate-responses",
        help="forward model (Eq. 1) with photon and read noise",
    )
    add_sensitivities_option(p)
    p.add_argument("--illuminants", required=True, type=Path)
    p.add_argument("--reflectances", required=True, type=Path)
    p.add_argument(
        "--exposure-target",
        type=float,
        default=None,
        metavar="F",
        help="scale each illuminant as if its exposure put the brightest "
        "patch at F of full scale; write the scaled spectra with "
        "--illuminants-out",
    )
    p.add_argument("--illuminants-out", type=Path)
    p.add_argument("--full-well-e", type=float, default=67_000.0)
    p.add_argument("--read-noise-e", type=float, default=30.0)
    p.add_argument("--n-pixels", type=int, default=400)
    p.add_argument("--flat-field-residual", type=float, default=0.003)
    p.add_argument("--no-noise", action="store_true")
    p.add_argument("--seed", type=seed_arg, default=0)
    add_grid_option(p)
    add_output_options(p)
    p.add_argument("-o", "--output", required=True, type=Path)
    p.set_defaults(func=cmd_simulate, output_files=("output", "illuminants_out"))


def _write_json(path: Path | None, data: dict[str, Any]) -> None:
    if path is not None:
        from tunespec.core.atomic import atomic_write_text

        atomic_write_text(path, dumps_json(data))


def _check_names(
    responses: Responses,
    spectra: Spectra,
    what: str,
    path: Path,
    names: tuple[str, ...],
) -> None:
    check_names(
        names,
        spectra.names,
        f"{{n}} {what} name(s) of the responses are not columns here: {{names}}",
        path=path,
        limit=6,
    )


def _resampled(spectra: Spectra, grid: Grid, *, average: bool = False) -> Spectra:
    return spectra.resample(grid, source=spectra.meta.get("source"), average=average)


def cmd_calibrate(args: argparse.Namespace) -> int:
    from tunespec.core import plausibility as pl

    out = Console(args)
    checks = plausibility_checks(args, out)
    if args.hold_out_every is not None and args.hold_out_every < 2:
        raise InputError(
            f"--hold-out-every {args.hold_out_every}: N must be at least 2 (leave "
            "the option out to fit every patch)"
        )
    if args.grid is not None and (
        warning := pl.calibration_grid_warning(
            args.grid.step_nm, CALIBRATION_MAX_STEP_NM
        )
    ):
        out.warn(warning)
    responses, illum_in, illuminants, reflectances, grid = _calibration_inputs(
        args, out, checks
    )
    # the estimators (scipy) are imported once the inputs are known to be good: an
    # error in them is reported at once
    from tunespec.app.pipeline.jobs import fit_calibration

    cal = fit_calibration(
        responses,
        illuminants,
        reflectances,
        reported_illuminants=illum_in,
        hold_out_every=args.hold_out_every,
        check=args.self_check,
        checks=checks,
        progress=out.progress("calibrating"),
        **_fit_options(args),
    )
    est, report, checked = cal.estimate, cal.report, cal.self_check
    # with the checks overridden and the findings below in its side file
    write_sensitivities_csv(args.output, est.sensitivity, est.covariance)
    _print_calibration(out, est, report)
    if checked is not None:
        out.say(checked.format_text())
    for w in est.provenance.get("warnings", ()):
        out.warn(w)
    out.say(f"sensitivities written to {args.output}")
    stats = {
        "method": est.method,
        "grid": str(grid),
        "params": _jsonable(est.params),
        "excluded_patches": list(est.excluded_patches),
        **report.as_dict(),
    }
    if checks.overridden:
        stats["forced"] = list(checks.overridden)
    if checked is not None:
        stats["self_check"] = checked.as_dict()
    _write_json(args.stats, stats)
    out.summary({**stats, "output": str(args.output)})
    return 0


def _calibration_inputs(
    args: argparse.Namespace, out: Console, checks: Any
) -> tuple[Responses, Spectra, Spectra, Spectra, Grid]:
    """``calibrate``'s inputs read and checked: the responses, the illuminants as
    read and on the grid, the reflectances on the grid, and the grid."""
    from tunespec.core import plausibility as pl

    responses = read_responses_csv(args.responses)
    illum_in = read_spectral(args.illuminants, kind="illuminant")
    refl_in = read_spectral(args.reflectances, kind="reflectance")
    if args.names is not None:
        from tunespec.core.io.name_map import read_name_map, rename_spectra

        refl_in = rename_spectra(
            refl_in, read_name_map(args.names), source=str(args.reflectances)
        )
    out.inputs(illum_in, refl_in)
    grid = resolve_grid(
        args,
        [(illum_in, False), (refl_in, True)],
        out,
        max_step_nm=CALIBRATION_MAX_STEP_NM,
    )
    checks(
        pl.check_coverage,
        [
            (f"--illuminants {args.illuminants}", illum_in.wavelength_nm),
            (f"--reflectances {args.reflectances}", refl_in.wavelength_nm),
        ],
        "calibrate",
        grid_nm=grid.wavelength_nm,
    )
    illuminants = _resampled(illum_in, grid, average=True)
    reflectances = _resampled(refl_in, grid)
    # The estimator checks the names of the patches it fits; checking all of them
    # here (held-aside ones included) fails before a fit of several seconds.
    _check_names(
        responses, illuminants, "illuminant", args.illuminants, responses.illuminants
    )
    _check_names(responses, reflectances, "patch", args.reflectances, responses.patches)
    checks(
        pl.check_responses,
        responses.rgb,
        responses.patches,
        responses.illuminants,
        rgb_std=responses.rgb_std,
        saturated=responses.saturated,
        path=args.responses,
    )
    return responses, illum_in, illuminants, reflectances, grid


def _fit_options(args: argparse.Namespace) -> dict[str, Any]:
    """``estimate_camera_sensitivity``'s options from ``calibrate``'s arguments."""
    kwargs: dict[str, Any] = {
        "method": args.method,
        "exclude": args.exclude_camera,
        "fit_spd_shift": args.fit_spd_shift,
    }
    if args.self_calibrate is not None:
        kwargs["self_calibrate"] = args.self_calibrate
    if args.method == "pca":
        # explained_variance, when given, takes precedence over n_components.
        kwargs["n_components"] = args.components
        kwargs["explained_variance"] = args.explained_variance
    return kwargs


def _print_calibration(out: Console, est: Any, report: Any) -> None:
    """Table 1 and the light source's corrections, as text."""
    if est.excluded_patches:
        out.say(f"left out (saturated): {', '.join(est.excluded_patches)}")
    out.say(report.format_text())
    if est.spd_shift_nm:
        out.say(
            f"spectroradiometer wavelength shift fitted: {est.spd_shift_nm:+.2f} nm"
        )
    corr = est.led_correction
    if corr is not None and corr.gain_std:
        out.say("light source self-calibration (gain, wavelength offset per LED):")
        for j, name in enumerate(corr.names):
            out.say(
                f"  {name:<12} gain {corr.gain[j]:.4f} +- {corr.gain_std[j]:.4f}   "
                f"offset {corr.shift_nm[j]:+.2f} +- {corr.shift_std_nm[j]:.2f} nm"
            )


def _prior(path: Path | None) -> Spectra:
    """The Wiener prior: the file given, else the shipped ColorChecker SG."""
    if path is not None:
        return read_spectral(path, kind="reflectance")
    from tunespec.core.datasets import resource_path

    return read_spectral(
        resource_path("charts", "colorchecker_sg.csv"), kind="reflectance"
    )


def cmd_estimate(args: argparse.Namespace) -> int:
    from tunespec.core import plausibility as pl

    out = Console(args)
    checks = plausibility_checks(args, out)
    if args.spd_shift_nm is not None and not np.isfinite(args.spd_shift_nm):
        raise InputError(
            f"--spd-shift-nm: wavelength shift {args.spd_shift_nm} nm is not finite"
        )
    checks(pl.check_spd_shift, args.spd_shift_nm)
    if args.noise_std is not None:  # syntax here, plausibility below
        valid_number(args.noise_std, "--noise-std", lo=0.0, hi=MAX_NOISE_STD)
    responses = read_responses_csv(args.responses)
    checks(pl.check_noise_std, args.noise_std, responses.rgb_std)
    reported = read_spectral(args.illuminants, kind="illuminant")
    sensitivity = absolute_sensitivities(args.sensitivities)
    meta = _corrections(args, out)
    sensitivity = calibration_curves(sensitivity, meta)
    prior = _prior(args.prior)
    out.inputs(reported, sensitivity, prior)
    checks(pl.check_absolute_sensitivities, sensitivity.values, args.sensitivities)
    if args.prior is not None:
        checks(pl.check_prior_size, len(prior.names), args.prior)
    grid = resolve_grid(
        args, [(reported, False), (sensitivity, True), (prior, True)], out
    )
    checks(
        pl.check_coverage,
        [
            (f"--illuminants {args.illuminants}", reported.wavelength_nm),
            (f"--sensitivities {args.sensitivities}", sensitivity.wavelength_nm),
            (
                f"--prior {args.prior}"
                if args.prior
                else "the prior (ColorChecker SG)",
                prior.wavelength_nm,
            ),
        ],
        "estimate",
        grid_nm=grid.wavelength_nm,
    )
    # imported after the inputs are read (scipy): an error in them is reported at once
    from tunespec.app.pipeline.jobs import estimate_reflectance, write_uncertainty

    _check_names(
        responses, reported, "illuminant", args.illuminants, responses.illuminants
    )
    # uncertainties with the calibration's covariance, for its own corrections only
    uncertain = (
        "covariance" in meta and args.spd_shift_nm is None and args.noise_std is None
    )
    estimation = estimate_reflectance(
        responses,
        reported,
        sensitivity,
        prior,
        grid,
        meta=meta,
        spd_shift_nm=args.spd_shift_nm,
        uncertainty_from_meta=uncertain,
        checks=checks,
        responses_path=args.responses,
        noise_std=args.noise_std,
        center_prior=not args.uncentred_prior,
        clip=not args.no_clip,
    )
    est = estimation.wiener
    for line in estimation.warnings:
        out.warn(line)
    write_spectra_csv(est.reflectance, args.output)
    files = {"reflectances": str(args.output)}
    if estimation.uncertainty is not None:
        u_path, lab_path = write_uncertainty(
            estimation,
            args.output.with_name(args.output.stem + "_uncertainty.csv"),
            args.output.with_name(args.output.stem + "_colorimetry.csv"),
        )
        out.say(f"standard uncertainties written to {u_path} and {lab_path}")
        files.update({"uncertainty": str(u_path), "colorimetry": str(lab_path)})
    solved = estimation.solved_grid  # the whole range Eq. 1 integrates
    _write_estimate_meta(args, grid, solved, files, checks.overridden)
    if est.clipped:
        out.warn(
            f"clipped to [0, 1]: {est.n_clipped_samples} sample(s) in "
            f"{len(est.clipped)} patch(es): {shown_names(est.clipped, 10)}"
        )
    # chi-square per response of each patch against Eq. 1 (with the uncertainties)
    chi2 = (
        None
        if estimation.uncertainty is None
        else estimation.uncertainty.chi2_per_response
    )
    if chi2 is not None and (
        misfit := pl.inconsistent_patches(chi2, est.reflectance.names)
    ):
        out.warn(misfit)
    where = "" if solved == grid else f" (solved for on {solved} nm: Eq. 1 reaches)"
    out.say(f"{len(est.reflectance)} reflectances written to {args.output}{where}")
    out.summary(
        {
            "grid": str(grid),
            "patches": list(est.reflectance.names),
            "clipped": list(est.clipped),
            "n_clipped_samples": int(est.n_clipped_samples),
            "files": files,
        }
        | ({} if chi2 is None else {"chi2_per_response": np.round(chi2, 3).tolist()})
    )
    return 0


def _write_estimate_meta(
    args: argparse.Namespace,
    grid: Grid,
    solved: Grid,
    files: dict[str, str],
    forced: list[str],
) -> None:
    """The estimate's side file: the grid reported, the one Eq. 5 solved on."""
    doc: dict[str, Any] = {
        "grid": str(grid),
        "solved_on": str(solved),
        "sensitivities": str(args.sensitivities),
        **files,
    }
    if args.no_corrections:
        doc["corrections"] = "none (--no-corrections)"
    if forced:
        doc["forced"] = list(forced)
    _write_json(_meta_path(args.output), doc)


def _corrections(args: argparse.Namespace, out: Console) -> dict[str, Any]:
    """The calibration's side file (LED corrections, covariance), refused missing
    unless ``--no-corrections``; what the calibration found about itself is repeated
    as warnings."""
    from tunespec.core import plausibility as pl
    from tunespec.core.io.export import sensitivity_meta_path

    side = sensitivity_meta_path(args.sensitivities)
    if args.no_corrections:
        out.warn(
            f"--no-corrections: the calibration's LED corrections and covariance "
            f"({side.name}) are not applied; no uncertainties are written"
        )
        return {}
    meta = read_sensitivity_meta(args.sensitivities)
    if not meta:
        raise InputError(
            f"no LED corrections found next to {args.sensitivities.name} ({side}): "
            "results will be worse (0.07 -> 0.37 dE00 on the demo) and no "
            "uncertainties are written; copy the side file along, or pass "
            "--no-corrections to accept",
            path=args.sensitivities,
        )
    for line in pl.calibration_notes(meta, args.sensitivities):
        out.warn(line)
    return meta


def _meta_path(path: Path) -> Path:
    return path.with_name(path.name + ".meta.json")


def cmd_evaluate(args: argparse.Namespace) -> int:
    from tunespec.core import plausibility as pl
    from tunespec.core.colorimetry import reflectance_stats

    out = Console(args)
    checks = plausibility_checks(args, out)
    estimated = read_spectral(args.estimated, kind="reflectance")
    reference = read_spectral(args.reference, kind="reflectance")
    out.inputs(estimated, reference)
    grid = resolve_grid(args, [(estimated, True), (reference, True)], out)
    checks(
        pl.check_coverage,
        [
            (f"--estimated {args.estimated}", estimated.wavelength_nm),
            (f"--reference {args.reference}", reference.wavelength_nm),
        ],
        "evaluate (CIELAB, ASTM E308)",
        grid_nm=grid.wavelength_nm,
    )
    stats = reflectance_stats(_resampled(estimated, grid), _resampled(reference, grid))
    out.say(stats.format_table())
    doc = {"grid": str(grid), **stats.as_dict()}
    if checks.overridden:
        doc["forced"] = list(checks.overridden)
    _write_json(args.stats, doc)
    out.summary(doc)
    return 0


def cmd_simulate(args: argparse.Namespace) -> int:
    from tunespec.core.simulate import NoiseModel, scale_to_exposure, simulate_responses

    # the noise options, checked before anything is read (inf wrote nan, exit 0)
    valid_number(args.full_well_e, "--full-well-e", lo=0.0, hi=1e9, lo_open=True)
    valid_number(args.read_noise_e, "--read-noise-e", lo=0.0, hi=1e6)
    valid_number(args.n_pixels, "--n-pixels", lo=2, hi=1e9, integer=True)
    valid_number(args.flat_field_residual, "--flat-field-residual", lo=0.0, hi=1.0)
    out = Console(args)
    sens_in, _ = calibrated_sensitivities(args.sensitivities)
    illum_in = read_spectral(args.illuminants, kind="illuminant")
    refl_in = read_spectral(args.reflectances, kind="reflectance")
    out.inputs(sens_in, illum_in, refl_in)
    grid = resolve_grid(
        args, [(sens_in, True), (illum_in, False), (refl_in, True)], out
    )
    sensitivity = _resampled(sens_in, grid)
    illuminants = _resampled(illum_in, grid, average=True)
    reflectances = _resampled(refl_in, grid)
    if args.exposure_target is not None:
        illuminants = scale_to_exposure(
            reflectances, illuminants, sensitivity, target=args.exposure_target
        )
    if args.illuminants_out:
        write_spectra_csv(illuminants, args.illuminants_out)
    noise = (
        None
        if args.no_noise
        else NoiseModel(
            full_well_e=args.full_well_e,
            read_noise_e=args.read_noise_e,
            n_pixels=args.n_pixels,
            flat_field_residual=args.flat_field_residual,
        )
    )
    responses = simulate_responses(
        reflectances,
        illuminants,
        sensitivity,
        noise=noise,
        rng=np.random.default_rng(args.seed),
    )
    write_responses_csv(responses, args.output)
    n_sat = 0 if responses.saturated is None else int(np.sum(responses.saturated > 0))
    out.say(
        f"{len(responses.patches)} patches x {len(responses.illuminants)} illuminants "
        f"written to {args.output}" + (f" ({n_sat} saturated)" if n_sat else "")
    )
    out.summary(
        {
            "grid": str(grid),
            "patches": len(responses.patches),
            "illuminants": len(responses.illuminants),
            "saturated": n_sat,
            "output": str(args.output),
        }
    )
    return 0


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    return obj
