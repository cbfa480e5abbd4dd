"""Semantic fuzzing: files that parse but mean something else (issue 24).

``tools/fuzz_inputs.py`` mutates syntax; this mutates *meaning* on a measurement's
good files (scale x100 / x1e-2 / x1e6, percent for factors, one typed value, a
truncated wavelength range, a dropped side file, swapped arguments, another chart)
and runs ``estimate``, ``calibrate`` or ``evaluate`` on them. Each case ends as

``refused``        exit != 0 with one line (wanted)
``flagged``        exit 0 with a warning line (wanted: the user is told)
``accepted``       exit 0, no warning, and the estimate within 1 dE00 of the good
                   files' result against the reference (harmless: e.g. x1e-2 on
                   the prior is scale-free)
``accepted_wrong`` exit 0, no warning, and more than 1 dE00 worse (a bug)
``traceback``      an exception escaped, or the error was not one line (a bug)
``hang``           past the case's time limit (a bug)

The inputs come from :func:`build_inputs`: a simulated bench (the shipped camera,
LED set, ColorChecker SG and CMY sample target, with photon and read noise), or the
files of ``tunespec demo`` (``source="demo"``). ``tests/test_mistakes_corpus.py``
builds them once per session; ``python tools/fuzz_inputs.py --semantic --cases N``
runs this fuzzer (exit status 1 on any bug).
"""

from __future__ import annotations

import contextlib
import io
import json
import random
import shutil
import signal
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from tunespec.app.cli import main
from tunespec.core.io.responses_csv import read_responses_csv, write_responses_csv
from tunespec.core.io.spectral import read_spectral
from tunespec.core.io.spectral_csv import write_spectra_csv
from tunespec.core.spectra import Grid, Spectra

OUTCOMES = ("refused", "flagged", "accepted", "accepted_wrong", "traceback", "hang")
BUGS = ("accepted_wrong", "traceback", "hang")
#: How much worse than the good files' estimate counts as wrong (mean CIEDE2000).
WRONG_DE00 = 1.0
#: The simulated bench's grid and camera.
SIM_GRID = Grid(380.0, 730.0, 5.0)
SIM_CAMERA = "Canon EOS 5D Mark III"


@dataclass(frozen=True)
class Inputs:
    """A measurement's good files (paths) and the good estimate's mean dE00."""

    folder: Path
    chart_responses: Path
    chart_illuminants: Path
    chart: Path
    responses: Path
    illuminants: Path
    sensitivities: Path
    reference: Path
    base_de00: float = 0.0


def build_inputs(folder: Path, *, source: str = "sim", seed: int = 0) -> Inputs:
    """Good inputs in ``folder``: a simulated bench (fast) or ``tunespec demo``'s
    exports (``source="demo"``, at 384x256)."""
    folder.mkdir(parents=True, exist_ok=True)
    if source == "demo":
        demo = folder / "demo"
        rc = main(["demo", "--out", str(demo), "--resolution", "384x256",
                   "--no-report", "--no-chart-choice", "-q", "--seed", str(seed)])  # fmt: skip
        if rc != 0:
            raise RuntimeError(f"tunespec demo failed ({rc})")
        e = demo / "export"
        inputs = Inputs(
            folder, e / "chart_responses.csv", e / "chart_illuminants.csv",
            e / "chart_camera.ti3", e / "responses.csv", e / "illuminants.csv",
            e / "sensitivities.csv", e / "reference_reflectances.csv",
        )  # fmt: skip
    else:
        inputs = _simulated(folder, seed)
    good = folder / "good_estimate.csv"
    code, err, de = run_estimate(inputs, good)
    if code != 0 or err.strip():
        raise RuntimeError(f"the good inputs do not estimate cleanly: {err}")
    return Inputs(**{**inputs.__dict__, "base_de00": de})


def _simulated(folder: Path, seed: int) -> Inputs:
    from tunespec.app.pipeline.lighting import white_background
    from tunespec.core.datasets import load_camera, load_led_set, resource_path
    from tunespec.core.io.export import write_sensitivities_csv
    from tunespec.core.simulate import NoiseModel, scale_to_exposure, simulate_responses

    rng = np.random.default_rng(seed)
    cam = load_camera(SIM_CAMERA, SIM_GRID)
    sens = cam.with_values(cam.values * 3.4)  # an absolute scale, as calibrate's
    sens = Spectra(sens.wavelength_nm, sens.values, sens.names, {"source": "sim"})
    sg = read_spectral(resource_path("charts", "colorchecker_sg.csv"), SIM_GRID,
                       kind="reflectance")  # fmt: skip
    cmy = read_spectral(resource_path("charts", "neugebauer_cmy_model.csv"), SIM_GRID,
                        kind="reflectance")  # fmt: skip
    leds = load_led_set(SIM_GRID)
    illum = scale_to_exposure(sg, leds, sens, target=0.8)
    noise = NoiseModel(n_pixels=400)
    # the white background board (reflectance 0.9) both sessions are flat-fielded to
    board = Spectra(SIM_GRID.wavelength_nm, np.full((1, SIM_GRID.wavelength_nm.size),
                    0.9), ("background",))  # fmt: skip
    white = simulate_responses(board, illum, sens, noise=None, rng=rng).rgb[0]
    chart = replace(simulate_responses(sg, illum, sens, noise=noise, rng=rng),
                    white_rgb=white)  # fmt: skip
    sample = replace(simulate_responses(cmy, illum, sens, noise=noise, rng=rng),
                     white_rgb=white)  # fmt: skip
    # the chart session's white background by Eq. 1, as calibrate keeps it
    board_by_light = white_background(chart, illum, sens, {})
    sens = Spectra(sens.wavelength_nm, sens.values, sens.names,
                   {**sens.meta, "white_background": json.dumps(board_by_light)})  # fmt: skip
    paths = Inputs(
        folder, folder / "chart_responses.csv", folder / "illuminants.csv",
        folder / "chart.csv", folder / "responses.csv", folder / "illuminants.csv",
        folder / "sensitivities.csv", folder / "reference.csv",
    )  # fmt: skip
    write_responses_csv(chart, paths.chart_responses)
    write_responses_csv(sample, paths.responses)
    write_spectra_csv(illum, paths.illuminants)
    write_spectra_csv(sg, paths.chart)
    write_spectra_csv(cmy, paths.reference)
    write_sensitivities_csv(paths.sensitivities, sens)
    return paths


def run_cli(argv: list[str], time_limit_s: float = 120.0) -> tuple[int, str]:
    """``tunespec ARGV`` in this process: (exit code, stderr). A traceback or a
    hang raises."""
    err = io.StringIO()

    def _alarm(*_: object) -> None:
        raise TimeoutError

    old = signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, time_limit_s)
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            code = main([*argv, "-q"])
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
    return code, err.getvalue()


def mean_de00(estimated: Path, reference: Path) -> float:
    """Mean CIEDE2000 (D50) of ``estimated`` against ``reference``."""
    from tunespec.core.colorimetry import reflectance_stats

    est = read_spectral(estimated, kind="reflectance")
    ref = read_spectral(reference, kind="reflectance")
    grid = Grid(400.0, 700.0, 5.0)
    names = [n for n in ref.names if n in est.names]
    if not names:  # another target's patches: nothing to compare with
        return 0.0
    stats = reflectance_stats(est.select(names).resample(grid),
                              ref.select(names).resample(grid))  # fmt: skip
    return float(stats.as_dict()["average"]["delta_e00"])


def run_estimate(
    inputs: Inputs, out: Path, **over: object
) -> tuple[int, str, float | None]:
    """``tunespec estimate`` with ``inputs`` (``over`` replaces options by name,
    ``extra`` adds arguments): exit code, stderr and, on success, the mean dE00
    against the reference."""
    opts = {
        "--responses": inputs.responses,
        "--illuminants": inputs.illuminants,
        "--sensitivities": inputs.sensitivities,
    }
    for k, v in over.items():
        if k != "extra":
            opts["--" + k.replace("_", "-")] = v
    argv = [str(a) for kv in opts.items() for a in kv if kv[1] is not None]
    argv += [str(a) for a in over.get("extra", ())]  # type: ignore[attr-defined]
    code, err = run_cli(["estimate", *argv, "-o", str(out)])
    de = mean_de00(out, inputs.reference) if code == 0 and out.exists() else None
    return code, err, de


# -- mutations -----------------------------------------------------------------------
def scaled_responses(src: Path, dst: Path, factor: float, where=None, *,
                     white_too: bool = False) -> Path:  # fmt: skip
    """Responses (and their standard deviations) times ``factor`` (all, or the rows
    ``where(patch_index, illuminant_index)``); ``white_too``: their white level too
    (a whole session on another scale)."""
    r = read_responses_csv(src)
    mask = np.ones(r.rgb.shape[:2], dtype=bool)
    if where is not None:
        mask = np.array([[where(p, i) for i in range(mask.shape[1])]
                         for p in range(mask.shape[0])])  # fmt: skip
    f = np.where(mask[..., None], factor, 1.0)
    std = None if r.rgb_std is None else r.rgb_std * f
    white = r.white_rgb
    if white_too and white is not None:
        white = white * factor
    write_responses_csv(replace(r, rgb=r.rgb * f, rgb_std=std, white_rgb=white), dst)
    return dst


def edited_responses(src: Path, dst: Path, edit: Callable) -> Path:
    """Responses with ``edit(responses) -> responses``."""
    write_responses_csv(edit(read_responses_csv(src)), dst)
    return dst


def scaled_spectra(src: Path, dst: Path, factor: float, kind: str = "spectra",
                   columns: slice | None = None) -> Path:  # fmt: skip
    """Spectra times ``factor`` (all, or ``columns`` of them), as a CSV."""
    s = read_spectral(src, kind=kind)
    v = s.values.copy()
    v[columns if columns is not None else slice(None)] *= factor
    write_spectra_csv(Spectra(s.wavelength_nm, v, s.names, {}), dst)
    return dst


def truncated_spectra(src: Path, dst: Path, lo_nm: float, hi_nm: float,
                      kind: str = "spectra") -> Path:  # fmt: skip
    """Spectra cut to ``lo_nm``-``hi_nm``."""
    s = read_spectral(src, kind=kind)
    keep = (s.wavelength_nm >= lo_nm) & (s.wavelength_nm <= hi_nm)
    write_spectra_csv(Spectra(s.wavelength_nm[keep], s.values[:, keep], s.names, {}),
                      dst)  # fmt: skip
    return dst


def typo_spectra(src: Path, dst: Path, k: int, j: int, value: float,
                 kind: str = "reflectance") -> Path:  # fmt: skip
    """One value of spectrum ``k`` at wavelength index ``j`` typed as ``value``."""
    s = read_spectral(src, kind=kind)
    v = s.values.copy()
    v[k, j] = value
    write_spectra_csv(Spectra(s.wavelength_nm, v, s.names, {}), dst)
    return dst


def copy_without_side_file(src: Path, dst: Path) -> Path:
    """A sensitivities CSV copied without its ``.meta.json``."""
    shutil.copyfile(src, dst)
    return dst


def with_side_file(src: Path, dst: Path) -> Path:
    """``dst`` (a rewritten sensitivities file) gets ``src``'s side file."""
    side = src.with_name(src.name + ".meta.json")
    if side.exists():
        shutil.copyfile(side, dst.with_name(dst.name + ".meta.json"))
    return dst


def cgats_sensitivities(src: Path, dst: Path) -> Path:
    """Sensitivities written as CGATS ``SPEC_nnn`` fields, values as they are."""
    s = read_spectral(src, kind="sensitivity")
    wl = [f"{w:g}" for w in s.wavelength_nm]
    fields = " ".join(f"SPEC_{w}" for w in wl)
    rows = "\n".join(f"{n} " + " ".join(repr(float(x)) for x in row)
                     for n, row in zip(s.names, s.values, strict=True))  # fmt: skip
    dst.write_text(
        f"CGATS.17\nNUMBER_OF_FIELDS {len(wl) + 1}\nBEGIN_DATA_FORMAT\n"
        f"SAMPLE_ID {fields}\nEND_DATA_FORMAT\nNUMBER_OF_SETS 3\nBEGIN_DATA\n"
        f"{rows}\nEND_DATA\n"
    )
    return with_side_file(src, dst)


# -- the fuzzer ----------------------------------------------------------------------
def _case(inputs: Inputs, rng: random.Random, d: Path) -> tuple[str, str, list[str]]:
    """One random semantic mutation: (label, command, argv without -o)."""
    x = inputs
    # scale mistakes that make the signal look larger, or smaller than any sample
    # reflecting 2 %; a factor of 10 darker is a darker sample as far as any check
    # can tell (responses x0.1 = sensitivities or illuminants x10), and is left out
    up_resp = rng.choice([3.0, 10.0, 100.0, 1e3, 1e6, 1e-2, 1e-3, 1e-6])
    scale = rng.choice([100.0, 1e3, 1e6, 1 / 3, 0.1, 1e-2, 1e-6])
    kind = rng.randrange(12)
    est = ["--responses", x.responses, "--illuminants", x.illuminants,
           "--sensitivities", x.sensitivities]  # fmt: skip
    if kind == 0:
        p = scaled_responses(x.responses, d / "r.csv", up_resp)
        return (
            f"responses x{up_resp:g}",
            "estimate",
            [*est[:0], "--responses", p, *est[2:]],
        )
    if kind == 1:
        p = scaled_spectra(x.illuminants, d / "i.csv", scale, "illuminant")
        return (
            f"illuminants x{scale:g}",
            "estimate",
            [*est[:2], "--illuminants", p, *est[4:]],
        )
    if kind == 2:
        s = read_spectral(x.illuminants, kind="illuminant")
        c = rng.randrange(len(s.names))
        f = rng.choice([3.0, 1 / 3, 10.0, 0.1, 100.0, 1e-2, 1e6])
        p = scaled_spectra(x.illuminants, d / "i.csv", f, "illuminant", slice(c, c + 1))
        return (
            f"one illuminant x{f:g}",
            "estimate",
            [*est[:2], "--illuminants", p, *est[4:]],
        )
    if kind == 3:
        p = with_side_file(
            x.sensitivities,
            scaled_spectra(x.sensitivities, d / "s.csv", scale, "sensitivity"),
        )
        return f"sensitivities x{scale:g}", "estimate", [*est[:4], "--sensitivities", p]
    if kind == 4:
        s = read_spectral(x.sensitivities, kind="sensitivity")
        p = with_side_file(
            x.sensitivities,
            scaled_spectra(
                x.sensitivities, d / "s.csv", 1 / s.values.max(), "sensitivity"
            ),
        )
        return (
            "sensitivities normalised to peak 1",
            "estimate",
            [*est[:4], "--sensitivities", p],
        )
    if kind == 5:
        lo = rng.choice([380, 420, 450, 480, 500])
        hi = rng.choice([600, 650, 680, 730])
        which = rng.choice(["illuminants", "sensitivities", "prior"])
        if which == "prior":
            p = truncated_spectra(x.chart, d / "p.csv", lo, hi, "reflectance")
            return f"prior {lo}-{hi} nm", "estimate", [*est, "--prior", p]
        src = x.illuminants if which == "illuminants" else x.sensitivities
        p = truncated_spectra(src, d / f"{which}.csv", lo, hi)
        if which == "sensitivities":
            with_side_file(src, p)
        flag = f"--{which}"
        argv = list(est)
        argv[argv.index(flag) + 1] = p
        return f"{which} {lo}-{hi} nm", "estimate", argv
    if kind == 6:
        r = read_responses_csv(x.responses)
        p_i, i_i, c_i = (
            rng.randrange(len(r.patches)),
            rng.randrange(len(r.illuminants)),
            rng.randrange(3),
        )
        value = rng.choice([-0.2, -0.05, 5.0, 50.0, 1e3])

        def edit(resp):
            rgb = resp.rgb.copy()
            rgb[p_i, i_i, c_i] = value
            return type(resp)(resp.patches, resp.illuminants, rgb, resp.rgb_std,
                              resp.n_pixels, resp.saturated)  # fmt: skip

        p = edited_responses(x.responses, d / "r.csv", edit)
        return f"one response {value:g}", "estimate", ["--responses", p, *est[2:]]
    if kind == 7:
        share = rng.choice([0.3, 0.5, 1.0])

        def sat(resp):
            s = np.zeros(resp.rgb.shape[:2])
            s.flat[: round(share * s.size)] = 1.0
            return type(resp)(resp.patches, resp.illuminants, resp.rgb, resp.rgb_std,
                              resp.n_pixels, s)  # fmt: skip

        p = edited_responses(x.responses, d / "r.csv", sat)
        return f"saturated share {share:.0%}", "estimate", ["--responses", p, *est[2:]]
    if kind == 8:
        what = rng.choice(
            ["side file", "prior 3", "spd shift", "cgats sens", "swap", "noise"]
        )
        if what == "noise":
            v = rng.choice([0.1, 0.5, 1.0, 10.0])
            return f"--noise-std {v:g}", "estimate", [*est, "--noise-std", v]
        if what == "side file":
            p = copy_without_side_file(x.sensitivities, d / "nometa.csv")
            return (
                "sensitivities without side file",
                "estimate",
                [*est[:4], "--sensitivities", p],
            )
        if what == "prior 3":
            s = read_spectral(x.chart, kind="reflectance")
            n = rng.choice([1, 2, 3, 4, 5])
            write_spectra_csv(s.select(list(s.names[:n])), d / "p.csv")
            return f"prior of {n}", "estimate", [*est, "--prior", d / "p.csv"]
        if what == "spd shift":
            v = rng.choice([8.0, -20.0, 500.0, 1e4])
            return f"--spd-shift-nm {v:g}", "estimate", [*est, "--spd-shift-nm", v]
        if what == "cgats sens":
            p = cgats_sensitivities(x.sensitivities, d / "s.ti3")
            return (
                "sensitivities as CGATS",
                "estimate",
                [*est[:4], "--sensitivities", p],
            )
        return (
            "responses and illuminants swapped",
            "estimate",
            ["--responses", x.illuminants, "--illuminants", x.responses, *est[4:]],
        )
    if kind == 9:
        ref = read_spectral(x.chart, kind="reflectance")
        k, j = rng.randrange(len(ref.names)), rng.randrange(ref.wavelength_nm.size)
        value = rng.choice([3.0, 5.0, 10.0, 2.0, 1.6])
        p = typo_spectra(x.chart, d / "c.csv", k, j, value)
        cmd = rng.choice(["estimate", "calibrate"])
        if cmd == "estimate":
            return f"prior typo {value:g}", "estimate", [*est, "--prior", p]
        return f"chart typo {value:g}", "calibrate", [
            "--responses", x.chart_responses, "--illuminants", x.chart_illuminants,
            "--reflectances", p]  # fmt: skip
    if kind == 10:
        what = rng.choice(["grid", "coverage", "hold", "saturated", "negative"])
        cal = ["--responses", x.chart_responses, "--illuminants", x.chart_illuminants,
               "--reflectances", x.chart]  # fmt: skip
        if what == "grid":
            step = rng.choice([5, 10, 20])
            return (
                f"calibrate --grid step {step}",
                "calibrate",
                [*cal, "--grid", f"400:700:{step}"],
            )
        if what == "coverage":
            lo, hi = rng.choice([(450, 650), (420, 680), (400, 600), (500, 730)])
            p = truncated_spectra(x.chart, d / "c.csv", lo, hi, "reflectance")
            return f"chart {lo}-{hi} nm", "calibrate", [*cal[:4], "--reflectances", p]
        if what == "hold":
            n = rng.choice([0, 1, -3])
            return f"--hold-out-every {n}", "calibrate", [*cal, "--hold-out-every", n]
        if what == "saturated":
            p = edited_responses(
                x.chart_responses,
                d / "cr.csv",
                lambda r: replace(r, saturated=np.ones(r.rgb.shape[:2])),
            )
            return "chart all saturated", "calibrate", ["--responses", p, *cal[2:]]

        def negate(r):
            rgb = r.rgb.copy()
            rgb[3] *= -1.0
            return replace(r, rgb=rgb)

        p = edited_responses(x.chart_responses, d / "cr.csv", negate)
        return "chart negative patch", "calibrate", ["--responses", p, *cal[2:]]
    # evaluate: a reference or estimate with a scale or unit mistake
    what = rng.choice(["typo", "truncated", "x100 one"])
    if what == "typo":
        ref = read_spectral(x.reference, kind="reflectance")
        p = typo_spectra(x.reference, d / "ref.csv", rng.randrange(len(ref.names)),
                         rng.randrange(ref.wavelength_nm.size), rng.choice([3.0, 7.0]))  # fmt: skip
        return (
            "reference typo",
            "evaluate",
            ["--estimated", x.folder / "good_estimate.csv", "--reference", p],
        )
    if what == "truncated":
        p = truncated_spectra(x.reference, d / "ref.csv", 450, 650, "reflectance")
        return (
            "reference 450-650 nm",
            "evaluate",
            ["--estimated", x.folder / "good_estimate.csv", "--reference", p],
        )
    ref = read_spectral(x.reference, kind="reflectance")
    v = ref.values.copy()
    k = int(np.argmax(np.median(v, axis=1)))  # the brightest spectrum, in percent
    v[k] *= 100
    write_spectra_csv(Spectra(ref.wavelength_nm, v, ref.names, {}), d / "ref.csv")
    return (
        "reference one spectrum in percent",
        "evaluate",
        ["--estimated", x.folder / "good_estimate.csv", "--reference", d / "ref.csv"],
    )


def classify(inputs: Inputs, command: str, argv: list[str], d: Path,
             time_limit_s: float) -> tuple[str, str]:  # fmt: skip
    """Run one case: its outcome and the line that explains it."""
    out = d / ("out.csv" if command != "evaluate" else "stats.json")
    if out.exists():
        out.unlink()
    flag = "--stats" if command == "evaluate" else "-o"
    try:
        code, err = run_cli([command, *map(str, argv), flag, str(out)], time_limit_s)
    except TimeoutError:
        return "hang", ""
    except SystemExit as exc:  # argparse: a usage error is a refusal
        return ("refused", "argparse") if exc.code == 2 else ("traceback", str(exc))
    except Exception as exc:
        return "traceback", f"{type(exc).__name__}: {exc}"
    lines = [ln for ln in err.splitlines() if ln.strip()]
    if code != 0:
        if code in (2, 3, 4) and len(lines) == 1 and "Traceback" not in err:
            return "refused", lines[0]
        return "traceback", err[-400:]
    if any(ln.startswith("warning:") for ln in lines):
        return "flagged", next(ln for ln in lines if ln.startswith("warning:"))
    if command == "estimate":
        de = mean_de00(out, inputs.reference)
        if de > inputs.base_de00 + WRONG_DE00:
            return (
                "accepted_wrong",
                f"mean dE00 {de:.2f} (good files {inputs.base_de00:.2f})",
            )
        return "accepted", f"mean dE00 {de:.2f}"
    if command == "calibrate":
        code, err, de = run_estimate(inputs, d / "e.csv", sensitivities=out,
                                     extra=["--no-corrections"])  # fmt: skip
        if code != 0:
            return "flagged", "its result is refused by estimate"
        if de is not None and de > inputs.base_de00 + WRONG_DE00:
            return "accepted_wrong", f"estimate with it: mean dE00 {de:.2f}"
        return "accepted", ""
    stats = json.loads(out.read_text())
    de = float(stats["average"]["delta_e00"])
    if de > inputs.base_de00 + WRONG_DE00:
        return (
            "accepted_wrong",
            f"evaluate reports {de:.2f}, the truth {inputs.base_de00:.2f}",
        )
    return "accepted", ""


def family(label: str) -> str:
    """A case's mutation without its numbers (``"prior 450-650 nm"`` -> ``"prior
    range"``), for the counts."""
    import re

    out = re.sub(r" ?-?[\d.]+(e[-+]?\d+)?-[\d.]+ nm", " range", label)
    out = re.sub(r" x?-?[\d./]+(e[-+]?\d+)?%?", "", out)
    return out.strip()


def fuzz_semantic(
    n_cases: int,
    *,
    seed: int = 0,
    source: str = "sim",
    time_limit_s: float = 60.0,
    workdir: Path | None = None,
    report: Callable[[str], None] | None = None,
) -> tuple[Counter, list[tuple[int, str, str, str]]]:
    """Run ``n_cases`` semantic mutations: the counts per outcome (and per label)
    and the bugs as ``(case, label, outcome, detail)``."""
    import tempfile

    rng = random.Random(seed)
    counts: Counter = Counter()
    bugs: list[tuple[int, str, str, str]] = []
    with tempfile.TemporaryDirectory(prefix="tunespec-semantic-") as tmp:
        root = Path(workdir or tmp)
        inputs = build_inputs(root / "inputs", source=source, seed=seed)
        d = root / "case"
        d.mkdir(parents=True, exist_ok=True)
        t0 = time.monotonic()
        for i in range(n_cases):
            label, command, argv = _case(inputs, rng, d)
            outcome, detail = classify(inputs, command, argv, d, time_limit_s)
            counts[outcome] += 1
            counts[f"{family(label)}:{outcome}"] += 1
            if outcome in BUGS:
                bugs.append((i, label, outcome, detail))
            if report is not None and (i + 1) % 500 == 0:
                report(f"{i + 1} cases, {time.monotonic() - t0:.0f} s: "
                       + ", ".join(f"{o} {counts[o]}" for o in OUTCOMES))  # fmt: skip
    return counts, bugs
