"""``tunespec export-cgats | export-rawtoaces | report``: exports and the report from files.

``export-cgats`` writes an ArgyllCMS ``.ti3`` (CGATS) of reflectances with XYZ and
L*a*b* (D50, 2°) and, from a responses CSV, the camera RGB under one illuminant, which
``spec2cie``, ``colverify`` and ``colprof`` read. ``export-rawtoaces`` writes camera
sensitivities in the rawtoaces-data JSON schema. ``report`` writes the HTML and PDF
report of whatever files it is given.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from tunespec.app.cli.common import (
    Console,
    add_grid_option,
    add_output_options,
    add_sensitivities_option,
)
from tunespec.app.cli.record_opts import add_record_options, record_from_args
from tunespec.core.calibration import calibrated_sensitivities
from tunespec.core.datasets import read_sensitivities
from tunespec.core.errors import InputError
from tunespec.core.io.spectral import read_spectral
from tunespec.core.limits import read_json
from tunespec.core.spectra import Grid, Spectra

__all__ = ["register"]

_RESAMPLE_GRID_HELP = (
    "resample onto this grid in nm (default: keep the file's wavelengths)"
)


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``export-cgats``, ``export-rawtoaces`` and ``report``."""
    p = sub.add_parser(
        "export-cgats",
        help="reflectances (+ camera RGB) as an ArgyllCMS .ti3 CGATS file",
        description="Write reflectances as an ArgyllCMS .ti3 (CGATS): SAMPLE_ID, "
        "SAMPLE_NAME, RGB_R/G/B (percent of full scale, from --responses), XYZ "
        "and L*a*b* (D50, CIE 1931 2°, ASTM E308, ICC D50 white) and SPEC_nnn "
        "(percent). ArgyllCMS spec2cie (recomputes XYZ/L*a*b* from the spectra) and "
        "colverify (CIEDE2000 between two such files) read every one; colprof needs "
        "device values, so only a file written with --responses and --illuminant "
        "(COLOR_REP XYZ_RGB); for a camera profile from the whole chart use "
        "'tunespec export-camera' (chart_camera.ti3). TuneSpec's own commands read "
        "it back as reflectances.",
    )
    p.add_argument(
        "--reflectances",
        required=True,
        type=Path,
        help="reflectances, 0-1 or percent (detected): spectral CSV, CGATS or JSON",
    )
    p.add_argument(
        "--responses", type=Path, help="responses CSV: adds RGB_R/G/B (percent)"
    )
    p.add_argument(
        "--illuminant",
        help="whose RGB to write when the responses hold several illuminants",
    )
    add_grid_option(p, _RESAMPLE_GRID_HELP)
    p.add_argument(
        "--no-spectra", action="store_true", help="leave out the SPEC_nnn fields"
    )
    p.add_argument("--descriptor", default="TuneSpec reflectances", help="DESCRIPTOR")
    p.add_argument("-o", "--output", required=True, type=Path, help=".ti3 file")
    add_output_options(p)
    p.set_defaults(func=cmd_export_cgats, output_files=("output",))

    p = sub.add_parser(
        "export-rawtoaces",
        help="camera sensitivities as rawtoaces-data JSON",
        description="Write camera sensitivities (CSV with R, G, B columns) in the "
        "rawtoaces-data camera JSON schema, normalised to peak 1, on 380-780 nm at "
        "5 nm as rawtoaces requires (interpolated linearly; 0 where the file has "
        "no data, which the header's comments say, with the absolute scale). "
        "rawtoaces reads it from its camera data folder; TuneSpec's estimate, "
        "simulate-responses and report read it back on the absolute scale.",
    )
    add_sensitivities_option(
        p,
        "R, G, B sensitivities (the CSV of 'tunespec calibrate', or any format with "
        "those channels); its .meta.json (LED corrections) is copied beside the JSON",
    )
    p.add_argument("--manufacturer", default="", help='e.g. "Canon"')
    p.add_argument("--model", default="", help='e.g. "EOS 5D Mark III"')
    p.add_argument(
        "--absolute", action="store_true", help="keep the scale (no peak-1 norm)"
    )
    p.add_argument(
        "--keep-grid",
        action="store_true",
        help="keep the file's wavelengths (rawtoaces reads 380-780 nm at 5 nm only)",
    )
    p.add_argument(
        "--license",
        default="CC-BY-4.0",
        metavar="SPDX",
        help="the data's usage licence in the header (default CC-BY-4.0)",
    )
    p.add_argument("-o", "--output", required=True, type=Path, help="JSON file")
    add_output_options(p)
    p.set_defaults(func=cmd_export_rawtoaces, output_files=("output",))

    _add_export_camera(sub)

    p = sub.add_parser(
        "report",
        help="HTML and PDF report of a measurement from its files",
        description="Write report.html (self-contained) and report.pdf from the "
        "files given; each part of the report appears when its files are given.",
    )
    p.add_argument("-o", "--out", required=True, type=Path, help="output folder")
    p.add_argument("--title", default="TuneSpec measurement report")
    p.add_argument("--reflectances", type=Path, help="estimated reflectances CSV")
    p.add_argument("--reference", type=Path, help="reference reflectances CSV")
    add_sensitivities_option(p, "estimated sensitivities", required=False)
    p.add_argument(
        "--reference-sensitivities",
        type=Path,
        help="reference (true) sensitivities, CSV or rawtoaces JSON",
    )
    p.add_argument("--illuminants", type=Path, help="LED spectra CSV")
    p.add_argument("--responses", type=Path, help="responses CSV (saturation flags)")
    p.add_argument(
        "--chart",
        type=Path,
        help="chart reflectances of --responses: computes Table 1 with "
        "--sensitivities and --illuminants",
    )
    p.add_argument(
        "--calibration-stats",
        type=Path,
        help="statistics JSON of 'tunespec calibrate --stats' (Table 1)",
    )
    p.add_argument("--session-id", help="session identifier shown in the report")
    add_grid_option(p, _RESAMPLE_GRID_HELP)
    add_record_options(p)
    add_output_options(p)
    p.set_defaults(func=cmd_report, output_dirs=("out",))


def _add_export_camera(
    sub: argparse._SubParsersAction[argparse.ArgumentParser],
) -> None:
    p = sub.add_parser(
        "export-camera",
        help="the chart's camera .ti3 for ArgyllCMS colprof, ACES IDT and 3x3 CCMs",
        description="From a chart's responses under all LEDs and the calibration: "
        "chart_camera.ti3 (every patch's camera RGB under --under, with its "
        "reference spectrum, XYZ and L*a*b* D50), which ArgyllCMS colprof turns into "
        "an ICC input profile ('colprof -a m -O camera.icc chart_camera') and "
        "profcheck checks ('profcheck chart_camera.ti3 camera.icc'); and "
        "camera_transforms.json/.csv: the ACES IDT (colour-science matrix_idt, D55) "
        "and white-preserving 3x3 colour-correction matrices for D50, D65 and A with "
        "their CIEDE2000 training (chart) and test (190 rawtoaces reflectances) "
        "errors.",
    )
    p.add_argument("--responses", required=True, type=Path, help="chart responses CSV")
    p.add_argument(
        "--illuminants", required=True, type=Path, help="the chart's LED spectra"
    )
    p.add_argument(
        "--reflectances",
        required=True,
        type=Path,
        help="the chart's reference reflectances (any format, 0-1 or percent)",
    )
    add_sensitivities_option(p, "calibrated sensitivities")
    p.add_argument(
        "--under",
        default="D50",
        help="the light of the camera RGB: D50, D65 or A (the LEDs mixed to match "
        "it) or one LED's name (its responses as measured); default D50",
    )
    p.add_argument("-o", "--out", required=True, type=Path, help="output folder")
    add_output_options(p)
    p.set_defaults(func=cmd_export_camera, output_dirs=("out",))


def cmd_export_camera(args: argparse.Namespace) -> int:
    from tunespec.core.io.camera_export import export_camera_characterisation
    from tunespec.core.io.responses_csv import read_responses_csv

    out = Console(args)
    responses = read_responses_csv(args.responses)
    illuminants = read_spectral(args.illuminants, kind="illuminant")
    chart = read_spectral(args.reflectances, kind="reflectance")
    sens, _ = calibrated_sensitivities(args.sensitivities)
    out.inputs(illuminants, chart, sens)
    done = export_camera_characterisation(
        args.out,
        under=args.under,
        sensitivity=sens,
        chart=chart,
        responses=responses,
        illuminants=illuminants,
    )
    table, transforms, paths = done.table, done.transforms, done.paths
    ti3 = paths["chart_camera_ti3"]
    out.say(f"{len(table)} patches with camera RGB under {args.under}: {ti3}")
    for t in transforms:
        out.say(
            f"{t.kind:<8} {t.illuminant:<4} CIEDE2000 mean/max: training "
            f"{t.training['mean_de00']:.2f}/{t.training['max_de00']:.2f} "
            f"({t.training['set']}), test {t.test['mean_de00']:.2f}/"
            f"{t.test['max_de00']:.2f} ({t.test['set']})"
        )
    out.summary(
        {
            "patches": len(table),
            "under": args.under,
            "transforms": [t.as_dict() for t in transforms],
            "files": {k: str(v) for k, v in paths.items()},
        }
    )
    return 0


def cmd_export_cgats(args: argparse.Namespace) -> int:
    from tunespec.core.io.cgats import write_cgats
    from tunespec.core.io.export import reflectance_ti3
    from tunespec.core.io.responses_csv import read_responses_csv

    out = Console(args)
    reflectance = read_spectral(args.reflectances, args.grid, kind="reflectance")
    out.inputs(reflectance)
    responses = None if args.responses is None else read_responses_csv(args.responses)
    if args.illuminant and responses is None:
        raise InputError("--illuminant needs --responses")
    table = reflectance_ti3(
        reflectance,
        responses=responses,
        illuminant=args.illuminant,
        descriptor=args.descriptor,
        spectra=not args.no_spectra,
    )
    write_cgats(table, args.output)
    fields = "names" + (", RGB" if table.rgb is not None else "") + ", XYZ, Lab"
    fields += "" if args.no_spectra else f", {reflectance.wavelength_nm.size} bands"
    out.say(f"{len(table)} patches ({fields}) written to {args.output}")
    out.summary(
        {
            "patches": len(table),
            "rgb": table.rgb is not None,
            "bands": 0 if args.no_spectra else int(reflectance.wavelength_nm.size),
            "output": str(args.output),
        }
    )
    return 0


def cmd_export_rawtoaces(args: argparse.Namespace) -> int:
    from tunespec.core.atomic import atomic_write_text
    from tunespec.core.io.export import (
        RAWTOACES_GRID,
        curves_document,
        sensitivity_meta_path,
        tunespec_version,
        write_sensitivity_json,
    )
    from tunespec.core.limits import dumps_json

    out = Console(args)
    sens = read_sensitivities(args.sensitivities, None)
    grid = None if args.keep_grid else RAWTOACES_GRID
    write_sensitivity_json(
        sens,
        args.output,
        manufacturer=args.manufacturer,
        model=args.model,
        normalize=not args.absolute,
        measurement_equipment=f"TuneSpec {tunespec_version()}",
        grid=grid,
        license=args.license,
    )
    side = sensitivity_meta_path(args.sensitivities)
    if side.is_file():
        # LED corrections and covariance, and the curves the JSON holds resampled
        # (those of a JSON's side file already): 'estimate' finds them beside it
        doc = read_json(side)
        if isinstance(doc, dict) and grid is not None and "sensitivity" not in doc:
            doc |= curves_document(sens)
        atomic_write_text(sensitivity_meta_path(args.output), dumps_json(doc))
    wl = sens.wavelength_nm if grid is None else grid.wavelength_nm
    out.say(
        f"sensitivities ({wl.size} wavelengths, {wl[0]:g}-{wl[-1]:g} nm) written to "
        f"{args.output}"
    )
    out.summary(
        {
            "wavelengths": int(wl.size),
            "range_nm": [float(wl[0]), float(wl[-1])],
            "output": str(args.output),
        }
    )
    return 0


def _table1_from_json(path: Path) -> tuple[Any, Any, tuple[str, ...]]:
    doc = read_json(path)
    if not isinstance(doc, dict) or not isinstance(doc.get("training"), dict):
        raise InputError(
            "expected the statistics JSON of 'tunespec calibrate --stats' "
            '(with a "training" table)',
            path=path,
        )
    return doc["training"], doc.get("held_out"), tuple(doc.get("excluded_patches", ()))


def cmd_report(args: argparse.Namespace) -> int:
    from tunespec.app.report.report import ReportData, write_report
    from tunespec.core.io.raw import f_number_text, stated_f_number
    from tunespec.core.io.responses_csv import read_responses_csv

    grid = args.grid
    data: dict[str, Any] = {
        "title": args.title,
        "session_id": args.session_id,
        "record": record_from_args(args),
    }
    if args.reflectances:
        data["reflectance"] = read_spectral(args.reflectances, grid, kind="reflectance")
    if args.reference:
        data["reflectance_reference"] = read_spectral(
            args.reference, grid, kind="reflectance"
        )
    if args.sensitivities:
        data["sensitivity"] = read_sensitivities(args.sensitivities, grid)
    if args.reference_sensitivities:
        data["sensitivity_reference"] = read_sensitivities(
            args.reference_sensitivities, grid
        )
    if args.illuminants:
        data["illuminants"] = read_spectral(args.illuminants, grid, kind="illuminant")
        # the aperture of the session they came from (process keeps it with them)
        f_number = stated_f_number(data["illuminants"].meta)
        data["provenance"] = {"aperture (--illuminants)": f_number_text(f_number)}
    if args.responses:
        data["responses"] = read_responses_csv(args.responses)
    if "reflectance" in data and "reflectance_reference" in data:
        from tunespec.core.colorimetry import reflectance_stats

        data["table2"] = reflectance_stats(
            data["reflectance"], data["reflectance_reference"]
        )
    if args.calibration_stats:
        t1, held, excluded = _table1_from_json(args.calibration_stats)
        data.update(table1=t1, table1_held_out=held, excluded_patches=excluded)
    elif args.chart:
        data["table1"] = _table1_from_files(args, data, grid)
    html_path, pdf_path = write_report(args.out, ReportData(**data))
    out = Console(args)
    out.say(f"report written to {html_path} and {pdf_path}")
    doc: dict[str, Any] = {"html": str(html_path), "pdf": str(pdf_path)}
    for key in ("table1", "table2"):
        if hasattr(data.get(key), "as_dict"):
            doc[key] = data[key].as_dict()
    out.summary(doc)
    return 0


def _table1_from_files(
    args: argparse.Namespace, data: dict[str, Any], grid: Grid | None
) -> Any:
    from tunespec.app.pipeline.jobs import predicted_table1
    from tunespec.core.io.export import read_sensitivity_meta

    need = [n for n in ("sensitivity", "illuminants", "responses") if n not in data]
    if need:
        opts = {
            "sensitivity": "--sensitivities",
            "illuminants": "--illuminants",
            "responses": "--responses",
        }
        raise InputError(f"--chart needs {', '.join(opts[n] for n in need)}")
    responses = data["responses"]
    sens: Spectra = data["sensitivity"]
    work = sens.grid if grid is None else grid
    chart = read_spectral(args.chart, work, kind="reflectance").select(
        responses.patches, source=str(args.chart)
    )
    illum = data["illuminants"].resample(work, source=str(args.illuminants))
    illum = illum.select(responses.illuminants, source=str(args.illuminants))
    # The SPD shift fitted with the sensitivities (their .meta.json) is undone on the
    # LED spectra, as 'calibrate' did for its Table 1 and 'estimate' does.
    meta = read_sensitivity_meta(args.sensitivities)
    sens = sens.resample(work, source=str(args.sensitivities))
    return predicted_table1(responses, sens, illum, chart, meta)
