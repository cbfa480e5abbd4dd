"""The plan of a measurement: every choice of a run in one frozen object.

A :class:`Plan` replaces the keyword arguments the orchestrator used to take: the
bench (``light``/``camera`` specs, simulated resolution and seed), the two targets,
the capture settings, the estimators and their grids, and whether to write the
report. :func:`demo_plan` is ``tunespec demo``; :func:`plan_from_config` reads a
``tunespec run`` configuration (:func:`load_config`, checked by :func:`check_config`).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path
from typing import Any

from tunespec.app.pipeline.record import (
    RECORD_FIELDS,
    MeasurementRecord,
    record_from_mapping,
)
from tunespec.core.datasets import resource_path
from tunespec.core.errors import InputError
from tunespec.core.io.cht import load_layout
from tunespec.core.io.session import MAX_BRACKETS, MAX_DARKS
from tunespec.core.io.spectral import read_spectra_csv, read_spectral
from tunespec.core.layout import TargetLayout
from tunespec.core.limits import (
    check_output_dir,
    contained_path,
    loads_json,
    loads_toml,
    read_text,
    shown,
    valid_number,
    valid_seed,
)
from tunespec.core.spectra import CALIBRATION_GRID, DEFAULT_GRID, Grid, Spectra
from tunespec.devices.registry import (
    DEFAULT_SIM_RESOLUTION,
    layout_reflectances,
    parse_resolution,
)

__all__ = [
    "DEMO_RESOLUTION",
    "ESTIMATION_GRID",
    "METHOD_CHOICES",
    "Plan",
    "chart_layout",
    "check_config",
    "check_scheduler",
    "demo_plan",
    "example_config",
    "load_config",
    "plan_from_config",
    "sample_layout",
    "sample_reference",
]


#: Sensitivity methods a configuration may name (``core.sensitivity.SENSITIVITY_METHODS``
#: without importing scipy; tests/test_cli_startup.py keeps them equal).
METHOD_CHOICES = ("bayes", "pca", "smooth")

#: Default resolution of ``tunespec demo``: a quarter of the 5D Mark III's sides.
DEMO_RESOLUTION = DEFAULT_SIM_RESOLUTION
#: Grid of reflectance estimation and Table 2: the band the 22 LEDs cover (410-700 nm
#: peaks) and CIE colorimetry needs. Outside it no LED carries information and a
#: reflectance is only the prior's extrapolation, so the spectral RMS there measures
#: the prior, not the instrument. Sensitivities are still estimated on the working
#: grid (``DEFAULT_GRID``) for the exports.
ESTIMATION_GRID = Grid(400.0, 700.0, 5.0)


def chart_layout() -> TargetLayout:
    """The shipped ColorChecker SG layout (corners unknown: found in the images)."""
    return TargetLayout.load(resource_path("layouts", "colorchecker_sg.json"))


def sample_layout() -> TargetLayout:
    """The shipped sample target: the eight CMY Neugebauer primaries."""
    return TargetLayout.load(resource_path("layouts", "neugebauer_cmy.json"))


def sample_reference(grid: Grid = DEFAULT_GRID) -> Spectra:
    """Reference reflectances of the shipped sample target (the simulation's truth)."""
    return read_spectra_csv(resource_path("charts", "neugebauer_cmy_model.csv"), grid)


@dataclass(frozen=True, eq=False)
class Plan:
    """Everything a run needs to know before it starts (no devices, no callbacks).

    Parameters
    ----------
    out_dir
        The measurement folder (:class:`~tunespec.app.pipeline.folder.MeasurementFolder`).
    light, camera
        Device specs (``devices.registry.open_bench``); ``camera`` ``None`` picks the
        default for the light.
    resolution, seed
        Simulated camera ``(width, height)`` (``None``: the default) and the seed of
        the simulated bench (the sample's camera gets ``seed + 1``).
    chart_layout, chart_reflectances
        The calibration chart (default the ColorChecker SG and its reflectances).
    sample_layout, sample_reflectances
        The sample target; its reflectances are what a simulated bench renders.
    reference
        Reference reflectances of the sample for Table 2 (``None``: no Table 2).
    exposure, brackets, repeats, n_darks, iso
        Capture settings (``"auto"`` meters every LED on the chart; the sample reuses
        the chart's exposures; :func:`tunespec.devices.capture.new_session`).
    method
        Sensitivity method (``None``: the library's default).
    prior
        Prior of the Wiener estimation (``None``: the ColorChecker SG).
    grid, estimation_grid
        Calibration grid and estimation/Table-2 grid.
    report
        Also write the HTML/PDF report.
    images
        Also estimate the sample's per-pixel images (reflectance cube, XYZ, L*a*b*,
        uncertainty; :func:`tunespec.app.pipeline.image.estimate_images`) into
        ``export/images/``.
    scheduler
        Where the Dask steps compute (the per-pixel images): ``None`` (Dask's local
        threads), a local scheduler's name or a ``dask.distributed`` address
        ``tcp://HOST:PORT`` (:func:`tunespec.app.pipeline.engine.connect`).
    input_files
        The files the plan was read from (configuration, layouts, spectra): the
        report lists them with their SHA-256.
    force
        Accept inputs the plausibility checks refuse (``force = true``, a top-level
        key of the configuration; :mod:`tunespec.core.plausibility`): each override
        is listed in the estimate's warnings.
    chart_choice
        Charts (keys of :data:`tunespec.app.pipeline.chart_choice.CHARTS`) each
        calibrated on a fresh simulated bench of the same seed for the report's
        "Chart choice" section (``export/chart_choice.json``); simulated light only.
    record
        The operator's measurement record (``[provenance]``, the command line's
        ``--operator``...; :mod:`tunespec.app.pipeline.record`): kept in the folder's
        ``record.json``, shown in the report and ``summary.json``.
    """

    out_dir: Path
    light: str = "sim"
    camera: str | None = None
    resolution: tuple[int, int] | None = None
    seed: int = 0
    chart_layout: TargetLayout = field(default_factory=chart_layout)
    chart_reflectances: Spectra | None = None
    sample_layout: TargetLayout = field(default_factory=sample_layout)
    sample_reflectances: Spectra | None = None
    reference: Spectra | None = None
    exposure: str | float | Mapping[str, float] = "auto"
    brackets: tuple[float, ...] = (1.0,)
    repeats: int = 1
    n_darks: int = 1
    iso: int = 100
    method: str | None = None
    prior: Spectra | None = None
    grid: Grid = CALIBRATION_GRID
    estimation_grid: Grid = ESTIMATION_GRID
    report: bool = True
    images: bool = False
    scheduler: str | None = None
    input_files: tuple[Path, ...] = ()
    chart_choice: tuple[str, ...] = ()
    force: bool = False
    record: MeasurementRecord = field(default_factory=MeasurementRecord)


#: The charts ``tunespec demo`` compares for the report (24 vs 140 patches).
DEMO_CHART_CHOICE = ("colorchecker_24", "colorchecker_sg")


def demo_plan(
    out_dir: str | PathLike[str],
    *,
    seed: int = 0,
    resolution: tuple[int, int] = DEMO_RESOLUTION,
    report: bool = True,
    chart_choice: tuple[str, ...] = (),
    record: MeasurementRecord | None = None,
) -> Plan:
    """The plan of ``tunespec demo``: the simulated bench, SG then the CMY target."""
    return Plan(
        Path(out_dir),
        resolution=resolution,
        seed=seed,
        sample_reflectances=sample_reference(),
        reference=sample_reference(),
        report=report,
        chart_choice=tuple(chart_choice),
        record=record if record is not None else MeasurementRecord(),
    )


# -- configuration files ---------------------------------------------------------------
def load_config(path: str | PathLike[str]) -> dict[str, Any]:
    """Read a run configuration (``.json`` or ``.toml``).

    Every key is optional; the example with all of them and their defaults is
    :func:`example_config` (``tunespec run --print-example``). A short one::

        out = "run"                  # the measurement folder, relative to the file

        [bench]
        light = "sim"                # or "cal1:///dev/ttyUSB0"
        camera = "sim"               # or "gphoto2"
        resolution = "1536x1024"     # simulated camera only
        seed = 0

        [capture]
        exposure = "auto"            # or seconds
        brackets = [1.0]
        iso = 100

        [sample]
        reference = "reference.csv"  # reflectances for Table 2

        [calibrate]
        method = "bayes"             # or "smooth", "pca"
        grid = "380:730:5"

    Sections: ``bench``, ``capture``, ``chart`` (``layout``, ``reflectances``),
    ``sample`` (``layout``, ``reflectances``, ``reference``), ``calibrate``
    (``method``, ``grid``), ``estimate`` (``prior``, ``grid``), ``export``
    (``report``, ``images``), ``provenance`` (the measurement record: ``operator``,
    ``sample_id``, ``chart_serial``, instruments' serials and calibration dates...;
    :data:`tunespec.app.pipeline.record.RECORD_FIELDS`); top-level ``out`` and
    ``scheduler`` (:func:`check_scheduler`).

    Raises
    ------
    InputError
        Unreadable file, bad syntax, unknown sections or keys.
    """
    path = Path(path)
    text = read_text(path)
    if path.suffix.lower() == ".toml":
        cfg = loads_toml(text, path=path)
    else:
        cfg = loads_json(text, path=path)
    if not isinstance(cfg, dict):
        raise InputError("expected a table/object at the top", path=path)
    known = {
        "out": None,
        "scheduler": None,
        "force": None,
        "bench": {"light", "camera", "resolution", "seed"},
        "capture": {"exposure", "brackets", "repeats", "darks", "iso"},
        "chart": {"layout", "reflectances"},
        "sample": {"layout", "reflectances", "reference"},
        "calibrate": {"method", "grid"},
        "estimate": {"prior", "grid"},
        "export": {"report", "images"},
        "provenance": set(RECORD_FIELDS),
    }
    for key, value in cfg.items():
        if key not in known:
            raise InputError(
                f"unknown section {shown(key)} (known: {', '.join(known)})", path=path
            )
        allowed = known[key]
        if allowed is not None:
            if not isinstance(value, dict):
                raise InputError(f"{key}: expected a table/object", path=path)
            bad = set(value) - allowed
            if bad:
                raise InputError(
                    f"{key}: unknown key(s) {', '.join(map(shown, sorted(bad)[:8]))} "
                    "(known: "
                    f"{', '.join(sorted(allowed))})",
                    path=path,
                )
    cfg["_path"] = str(path)
    return cfg


def example_config() -> str:
    """The shipped example configuration (``resources/examples/run.toml``): every key
    with its default, measuring on the simulated bench as it is."""
    return read_text(resource_path("examples", "run.toml"))


def plan_from_config(
    config: Mapping[str, Any] | str | PathLike[str],
    *,
    out: str | PathLike[str] | None = None,
    scheduler: str | None = None,
) -> Plan:
    """The :class:`Plan` of a configuration (a file or what :func:`load_config` read).

    Paths in the configuration are relative to its file and stay inside its folder
    (or the shipped resources): a configuration received from someone else cannot
    make TuneSpec read or write elsewhere. ``out`` and ``scheduler`` are the command
    line's (``--out``, ``--scheduler``): they replace the file's, and a scheduler
    address in the file is used only when the command line confirms it. Every value
    is checked (:func:`check_config`) before anything is read.
    """
    cfg = dict(config) if isinstance(config, Mapping) else load_config(config)
    base = Path(cfg.get("_path", ".")).parent if "_path" in cfg else Path(".")
    check_config(cfg, out=out, scheduler=scheduler)

    def rel(p: str | None, key: str = "") -> Path | None:
        return None if p is None else config_file(cfg, p, key)

    bench_cfg = cfg.get("bench", {})
    cap = cfg.get("capture", {})
    cal_cfg = cfg.get("calibrate", {})
    grid = Grid.parse(cal_cfg["grid"]) if "grid" in cal_cfg else CALIBRATION_GRID
    est_cfg = cfg.get("estimate", {})
    est_grid = Grid.parse(est_cfg["grid"]) if "grid" in est_cfg else ESTIMATION_GRID
    chart_cfg, sample_cfg = cfg.get("chart", {}), cfg.get("sample", {})
    chart_path = rel(chart_cfg.get("layout"), "chart.layout")
    sample_path = rel(sample_cfg.get("layout"), "sample.layout")
    c_layout = load_layout(chart_path) if chart_path else chart_layout()
    s_layout = load_layout(sample_path) if sample_path else sample_layout()

    def spectra(p: str | None, key: str) -> Spectra | None:
        q = rel(p, key)
        # reflectances, references and priors: any format, percent detected
        return None if q is None else read_spectral(q, grid, kind="reflectance")

    c_refl = spectra(chart_cfg.get("reflectances"), "chart.reflectances")
    if c_refl is None and chart_path is not None:
        c_refl = layout_reflectances(c_layout, chart_path, grid)
    s_refl = spectra(sample_cfg.get("reflectances"), "sample.reflectances")
    reference = spectra(sample_cfg.get("reference"), "sample.reference")
    light = str(bench_cfg.get("light", "sim"))
    if reference is None and sample_path is None and light.startswith("sim"):
        reference = sample_reference(grid)
    if s_refl is None and light.startswith("sim"):
        s_refl = (
            layout_reflectances(s_layout, sample_path, grid)
            if sample_path
            else sample_reference(grid)
        )
    src = cfg.get("_path")
    exposure = cap.get("exposure", "auto")
    if not isinstance(exposure, str):
        exposure = _cfg_number(exposure, "capture.exposure", src)
    res = bench_cfg.get("resolution")
    brackets = cap.get("brackets", [1.0])
    if not isinstance(brackets, list | tuple):
        raise InputError(
            f"capture.brackets: expected a list of numbers, got {shown(brackets)}",
            path=src,
        )
    return Plan(
        Path(out) if out is not None else base / str(cfg.get("out", "run")),
        light=light,
        camera=bench_cfg.get("camera"),
        resolution=None if res is None else parse_resolution(res),
        seed=_cfg_int(bench_cfg.get("seed", 0), "bench.seed", src),
        chart_layout=c_layout,
        chart_reflectances=c_refl,
        sample_layout=s_layout,
        sample_reflectances=s_refl,
        reference=reference,
        brackets=tuple(_cfg_number(b, "capture.brackets", src) for b in brackets),
        repeats=_cfg_int(cap.get("repeats", 1), "capture.repeats", src),
        n_darks=_cfg_int(cap.get("darks", 1), "capture.darks", src),
        exposure=exposure,
        iso=_cfg_int(cap.get("iso", 100), "capture.iso", src),
        method=cal_cfg.get("method"),
        prior=spectra(est_cfg.get("prior"), "estimate.prior"),
        grid=grid,
        estimation_grid=est_grid,
        report=cfg.get("export", {}).get("report", True),
        images=cfg.get("export", {}).get("images", False),
        scheduler=scheduler if scheduler is not None else cfg.get("scheduler"),
        force=cfg.get("force", False),
        record=record_from_mapping(cfg.get("provenance", {}), path=src),
        input_files=tuple(
            p
            for p in (
                Path(src) if src else None,
                chart_path,
                sample_path,
                rel(chart_cfg.get("reflectances"), "chart.reflectances"),
                rel(sample_cfg.get("reflectances"), "sample.reflectances"),
                rel(sample_cfg.get("reference"), "sample.reference"),
                rel(est_cfg.get("prior"), "estimate.prior"),
            )
            if p is not None
        ),
    )


def config_file(cfg: Mapping[str, Any], value: str, key: str) -> Path:
    """A file named in a configuration: relative to the configuration's folder and
    inside it, or inside the shipped resources (``resources/``); links are
    resolved first, so a link out of the folder is refused too.

    A configuration given as a mapping without its file (by a program) resolves
    against the current folder, unchecked.

    Raises
    ------
    InputError
        Naming the configuration and ``key``: an absolute path, or one leaving the
        folder (``..``, a link).
    """
    src = cfg.get("_path")
    if src is None:
        return Path(value)
    base = Path(src).parent

    def inside(root: Path) -> Path | None:
        try:
            return contained_path(value, key, bases=(root,), path=src)[0]
        except InputError:
            return None

    local = inside(base)
    if local is not None and local.exists():
        return local
    if local is None and not Path(value).is_absolute() and (base / value).is_symlink():
        shipped = None  # a link beside the configuration that leads out of it
    else:
        shipped = inside(resource_path())
    if shipped is not None and shipped.exists():
        return shipped
    if local is not None:
        return local  # not found: named as the configuration's folder's file
    raise InputError(
        f"{key}: {shown(value)} is outside the configuration's folder: paths in "
        "a configuration are relative to its folder and stay inside it (copy "
        "the file beside the configuration)",
        path=src,
    )


def _cfg_number(value: Any, key: str, source: str | None) -> float:
    """A configuration value that must be a number (one-line error otherwise)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"{key}: expected a number, got {shown(value)}", path=source)
    return float(value)


def _cfg_int(value: Any, key: str, source: str | None) -> int:
    """A configuration value that must be an integer (one-line error otherwise)."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise InputError(f"{key}: expected an integer, got {shown(value)}", path=source)
    return value


#: Configuration keys whose values are text (paths, specs, grids, names).
_CONFIG_STRINGS = {
    "bench": ("light", "camera", "resolution"),
    "chart": ("layout", "reflectances"),
    "sample": ("layout", "reflectances", "reference"),
    "calibrate": ("method", "grid"),
    "estimate": ("prior", "grid"),
}


def check_config(
    cfg: Mapping[str, Any],
    *,
    out: str | PathLike[str] | None = None,
    scheduler: str | None = None,
) -> None:
    """Check every value of a configuration before anything runs.

    ``out`` and ``scheduler``: the command line's, as :func:`plan_from_config`
    takes them (the file's ``out`` must stay inside its folder unless the command
    line gives ``--out``; the file's scheduler address needs ``--scheduler``).

    Raises
    ------
    InputError
        Naming the file and the key: a section that is not a table, a text key that
        is not text, a bad seed, resolution, exposure, bracket, ISO, method or grid,
        or an ``out`` that is an existing file.
    """
    src = cfg.get("_path")
    for section, keys in _CONFIG_STRINGS.items():
        table = cfg.get(section, {})
        if not isinstance(table, Mapping):
            raise InputError(f"{section}: expected a table/object", path=src)
        for key in keys:
            value = table.get(key)
            if value is not None and not isinstance(value, str):
                raise InputError(
                    f"{section}.{key}: expected a string, got {shown(value)}", path=src
                )
    cfg_out = cfg.get("out", "run")
    if not isinstance(cfg_out, str | PathLike):
        raise InputError(f"out: expected a folder name, got {shown(cfg_out)}", path=src)
    base = Path(src).parent if src else Path(".")
    if out is not None:
        check_output_dir(out, "--out")
    else:
        if src is not None:
            try:
                contained_path(str(cfg_out), "out", bases=(base,), path=src)
            except InputError:
                raise InputError(
                    f"out: {shown(str(cfg_out))} is outside the configuration's "
                    "folder; name a folder inside it, or give --out on the command "
                    "line",
                    path=src,
                ) from None
        try:
            check_output_dir(base / cfg_out, "out")
        except InputError as exc:
            raise InputError(exc.message, path=src) from None
    # every value checked before anything is captured (a typo must not cost a chart)
    bench = cfg.get("bench", {})
    valid_seed(bench.get("seed", 0), "bench.seed", path=src)
    if bench.get("resolution") is not None:
        try:
            parse_resolution(bench["resolution"])
        except InputError as exc:
            raise InputError(f"bench.resolution: {exc.message}", path=src) from None
    cap = cfg.get("capture", {})
    if not isinstance(cap, Mapping):
        raise InputError("capture: expected a table/object", path=src)
    exposure = cap.get("exposure", "auto")
    if isinstance(exposure, str):
        if exposure != "auto":
            raise InputError(
                f'capture.exposure: expected "auto" or seconds, got {shown(exposure)}',
                path=src,
            )
    else:
        valid_number(exposure, "capture.exposure", path=src, lo=0, hi=1e4, lo_open=True)
    brackets = cap.get("brackets", [1.0])
    if not isinstance(brackets, list | tuple) or not 1 <= len(brackets) <= MAX_BRACKETS:
        raise InputError(
            f"capture.brackets: expected a list of 1 to {MAX_BRACKETS} numbers, got "
            f"{shown(brackets)}",
            path=src,
        )
    for b in brackets:
        valid_number(b, "capture.brackets", path=src, lo=0, hi=1, lo_open=True)
    valid_number(
        cap.get("repeats", 1), "capture.repeats", path=src, lo=1,
        hi=MAX_BRACKETS // len(brackets), integer=True,
    )  # fmt: skip
    valid_number(
        cap.get("darks", 1), "capture.darks", path=src, lo=1, hi=MAX_DARKS,
        integer=True,
    )  # fmt: skip
    valid_number(
        cap.get("iso", 100), "capture.iso", path=src, lo=1, hi=1e7, integer=True
    )
    method = cfg.get("calibrate", {}).get("method")
    if method is not None and method not in METHOD_CHOICES:
        raise InputError(
            f"calibrate.method: {shown(method)} is not one of "
            f"{', '.join(METHOD_CHOICES)}",
            path=src,
        )
    for section in ("calibrate", "estimate"):
        grid = cfg.get(section, {}).get("grid")
        if grid is not None:
            try:
                Grid.parse(grid)
            except InputError as exc:
                raise InputError(f"{section}.grid: {exc.message}", path=src) from None
    for key, default in (("report", True), ("images", False)):
        flag = cfg.get("export", {}).get(key, default)
        if not isinstance(flag, bool):
            raise InputError(
                f"export.{key}: expected true or false, got {shown(flag)}", path=src
            )
    record_from_mapping(cfg.get("provenance", {}), path=src)
    _check_confirmed_scheduler(cfg, scheduler)


def _check_confirmed_scheduler(cfg: Mapping[str, Any], scheduler: str | None) -> None:
    """The file's scheduler, checked; an address in a file needs ``--scheduler``."""
    from tunespec.app.pipeline.engine import LOCAL_SCHEDULERS

    src = cfg.get("_path")
    address = check_scheduler(cfg.get("scheduler"), "scheduler", path=src)
    if scheduler is not None:
        check_scheduler(scheduler, "--scheduler")
    elif src is not None and address is not None and address not in LOCAL_SCHEDULERS:
        # a shared configuration must not send the session's data to any host
        raise InputError(
            f"scheduler: {shown(address)} sends the measurement to that host; "
            f"confirm it on the command line with --scheduler {address} (or "
            'set scheduler = "threads")',
            path=src,
        )
    if not isinstance(cfg.get("force", False), bool):
        raise InputError(
            f"force: expected true or false, got {shown(cfg.get('force'))}", path=src
        )


#: A ``dask.distributed`` scheduler's address: ``tcp://HOST:PORT`` (or ``tls://``,
#: ``ws://``, ``wss://``; a host name, IPv4 or ``[IPv6]``).
_SCHEDULER_ADDRESS = re.compile(
    r"(?:tcp|tls|ws|wss)://(?:\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9][A-Za-z0-9.-]{0,252})"
    r":([0-9]{1,5})"
)


def check_scheduler(value: Any, key: str, path: Any = None) -> str | None:
    """A scheduler as :func:`tunespec.app.pipeline.engine.connect` takes it, checked
    before anything runs (nothing is connected to here).

    Raises
    ------
    InputError
        One line naming ``key``: not text, not a local scheduler's name, or not an
        address ``tcp://HOST:PORT`` with a port in 1-65535.
    """
    from tunespec.app.pipeline.engine import LOCAL_SCHEDULERS

    if value is None or value in LOCAL_SCHEDULERS:
        return value
    m = _SCHEDULER_ADDRESS.fullmatch(value) if isinstance(value, str) else None
    if m is None or not 0 < int(m.group(1)) < 65536:
        raise InputError(
            f"{key}: expected one of {', '.join(LOCAL_SCHEDULERS)} or a "
            f"dask.distributed address such as tcp://HOST:8786, got {shown(value)}",
            path=path,
        )
    return value
