"""Fuzz every input TuneSpec reads and count what goes wrong (issue 12).

Each case takes a valid seed file of one kind, mutates it (bytes, lines, numbers,
nesting, encodings, or -- for JSON -- one value anywhere in the document), hands it
to the reader and classifies the outcome:

``refused``       an :class:`~tunespec.core.errors.InputError` (one line: wanted)
``accepted``      read, and what was read passes the invariants below
``traceback``     any other exception (a bug)
``hang``          the case ran past its time limit (a bug)
``accepted_bad``  read although it must not be: a hostile value in a field that
                  must refuse it, a non-finite or out-of-range value in what was read,
                  output that is not standard JSON, files outside the session touched,
                  or a damaged frame not reported for retaking (a bug)

Kinds: spectral CSV, responses CSV, CGATS, session manifest, target layout, run
configuration (TOML and JSON), session folders (damaged files, links out of the
folder), and ``commands``: whole commands (estimate, calibrate, evaluate,
simulate-responses, the exports, report, match-illuminant, gonio-plan, capture) run
in-process with a damaged input file, a hostile option value, files swapped or
replaced, or an option dropped or repeated; exit 0 must write standard JSON and no
nan/inf. Run ``python tools/fuzz_inputs.py --cases 10000`` (every kind; prints the
counts; exit status 1 if any bug was found). The test suite runs a small seeded
part of it.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import random
import re
import shutil
import signal
import sys
import tempfile
import time
import traceback
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from tunespec.app.pipeline.plan import check_config, load_config
from tunespec.core.errors import TuneSpecError
from tunespec.core.io.cgats import read_cgats, ti3_table, write_cgats
from tunespec.core.io.cht import load_layout
from tunespec.core.io.responses_csv import read_responses_csv, write_responses_csv
from tunespec.core.io.session import CaptureSettings, Session, plan_frames
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.io.spectral_csv import write_spectra_csv
from tunespec.core.layout import TargetLayout
from tunespec.core.limits import MAX_VALUE
from tunespec.core.responses import Responses
from tunespec.core.spectra import DEFAULT_GRID, Spectra
from tunespec.devices.registry import layout_reflectances

KINDS = ("spectra", "responses", "cgats", "manifest", "layout", "config", "session")
#: Whole commands run in-process with mutated options and input files (slower: not
#: in the default :data:`KINDS`; ``--kinds`` picks them, ``all`` means both).
COMMAND_KINDS = ("commands",)
OUTCOMES = ("refused", "accepted", "traceback", "hang", "accepted_bad")
BUGS = ("traceback", "hang", "accepted_bad")

HOSTILE_NUMBERS = [
    "nan", "NaN", "inf", "-inf", "Infinity", "-Infinity", "1e400", "-1e400", "-1",
    "0", "1e30", "1e200", "-1e200", "true", "false", "9" * 5000, "", "1e-400", "-0",
    "0x10", "1_000", "١٢", "²",
]  # fmt: skip
HOSTILE_VALUES: list[Any] = [
    None, True, False, -1, 0, 1e30, 10**30, -(10**19), "x", "", [], {}, [1, 2],
    {"a": 1}, "nan", 1e308, -1e308, float("nan"), float("inf"), float("-inf"),
    "../../etc/passwd", "/etc/passwd", "a" * 5000, 0.5, 2**63, 3,
]  # fmt: skip
INSERTS = [
    b"\xff\xfe", b"\x00", b",", b"\n", b'"', b"[", b"{", b"]", b"nan", b"inf",
    b"1e400", b"-1", b"true", b"9" * 5000, b"\r", b"\xe9", b"\t", b"#", b"'''",
    b'"""', b"=", b"\\", b"\xef\xbb\xbf",
]  # fmt: skip
_NUMBER = re.compile(rb"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")


class _Hang(Exception):
    pass


#: Seconds a whole command may take before it counts as a hang (a calibration or a
#: report on the small seeds takes a few).
COMMAND_TIME_LIMIT_S = 60.0


# -- seed files ------------------------------------------------------------------------
def make_seeds(folder: Path) -> dict[str, Path]:
    """One valid file (or folder) per kind in ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    wl = np.arange(380.0, 741.0, 20.0)
    rng = np.random.default_rng(0)
    spectra = Spectra(wl, rng.uniform(0.05, 0.9, (3, wl.size)), ("A1", "A2", "B1"))
    write_spectra_csv(spectra, folder / "spectra.csv")
    resp = Responses(("A1", "A2"), ("L1", "L2"), rng.uniform(0.1, 0.8, (2, 2, 3)),
                     rng.uniform(0.001, 0.01, (2, 2, 3)))  # fmt: skip
    write_responses_csv(resp, folder / "responses.csv")
    write_cgats(
        ti3_table(["A1", "A2", "B1"], reflectance=spectra.resample(DEFAULT_GRID)),
        folder / "table.ti3",
    )
    layout = TargetLayout(
        "fuzz", 2, 2, 40.0, 40.0, margin_mm=(1.0, 1.0, 1.0, 1.0),
        patch_names=("A1", "A2", "B1", "B2"), meta={"reflectances": "spectra.csv"},
        corners_px=((10.0, 10.0), (90.0, 12.0), (88.0, 90.0), (12.0, 88.0)),
    )  # fmt: skip
    layout.save(folder / "layout.json")
    (folder / "config.toml").write_text(
        'out = "run"\n[bench]\nlight = "sim"\nseed = 3\nresolution = "384x256"\n'
        '[capture]\nexposure = "auto"\nbrackets = [1.0, 0.25]\niso = 100\n'
        '[calibrate]\nmethod = "smooth"\ngrid = "380:730:5"\n'
        '[estimate]\ngrid = "400:700:5"\n[export]\nreport = false\n'
    )
    (folder / "config.json").write_text(
        json.dumps(load_config(folder / "config.toml") | {"_path": None}, indent=1)
    )
    settings = CaptureSettings(
        ("L1", "L2"), exposure_mode="fixed", exposures_s={"L1": (0.5,), "L2": (2.0,)},
        n_darks=2,
    )  # fmt: skip
    session = Session.create(folder / "session", settings=settings, layout=layout)
    spd = Spectra(wl, rng.uniform(0.001, 0.02, (1, wl.size)), ("measured",))
    for spec in plan_frames(settings):
        raw = session.temp_stem(spec.id).with_suffix(".dng")
        raw.write_bytes(rng.bytes(256))
        session.commit_frame(spec, raw, spd=None if spec.kind == "dark" else spd)
    return {
        "spectra": folder / "spectra.csv",
        "responses": folder / "responses.csv",
        "cgats": folder / "table.ti3",
        "layout": folder / "layout.json",
        "config": folder / "config.toml",
        "config_json": folder / "config.json",
        "session": folder / "session",
        "manifest": folder / "session" / "manifest.json",
    }


# -- mutations -------------------------------------------------------------------------
def mutate_bytes(data: bytes, rng: random.Random) -> bytes:
    """One to three byte-, line- or token-level mutations."""
    for _ in range(rng.randint(1, 3)):
        op = rng.randrange(12)
        n = len(data)
        i = rng.randrange(n + 1)
        if op == 0 and n:
            j = rng.randrange(n)
            data = data[:j] + bytes([data[j] ^ (1 << rng.randrange(8))]) + data[j + 1 :]
        elif op == 1:
            data = data[:i] + data[min(n, i + rng.randint(1, 64)) :]
        elif op == 2:
            data = data[:i] + rng.choice(INSERTS) + data[i:]
        elif op == 3:
            data = data[:i]
        elif op in (4, 5):
            lines = data.split(b"\n")
            a, b = rng.randrange(len(lines)), rng.randrange(len(lines))
            if op == 4:
                lines.insert(a, lines[b])
            else:
                lines[a], lines[b] = lines[b], lines[a]
            data = b"\n".join(lines)
        elif op in (6, 7):
            nums = list(_NUMBER.finditer(data))
            if nums:
                m = rng.choice(nums)
                data = (
                    data[: m.start()]
                    + rng.choice(HOSTILE_NUMBERS).encode()
                    + data[m.end() :]
                )
        elif op == 8:
            data = data[:i] + b"x" * rng.choice([70_000, 140_000, 300_000]) + data[i:]
        elif op == 9:
            k = rng.choice([40, 1000, 60_000])
            opener = rng.choice([b"[", b"{", b'{"a":'])
            closer = b"]" if opener == b"[" else b"}"
            data = data[:i] + opener * k + closer * k + data[i:]
        elif op == 10:
            data = rng.choice([b"", b"\n", b"\xef\xbb\xbf", b"\x00" * 10])
        else:
            data = (
                data[:i] + b"\n".join([b"z,1,2,3"] * rng.choice([10, 3000])) + data[i:]
            )
    return data


def _paths(doc: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    out = [prefix]
    if isinstance(doc, dict):
        for k, v in doc.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc[:20]):
            out += _paths(v, (*prefix, i))
    return out


def mutate_json(doc: Any, rng: random.Random) -> tuple[Any, tuple[Any, ...], Any]:
    """Set one value anywhere in ``doc`` to a hostile one: (doc, path, value)."""
    doc = json.loads(json.dumps(doc))
    paths = [p for p in _paths(doc) if p]
    path = rng.choice(paths)
    value: Any = rng.choice(HOSTILE_VALUES)
    if rng.random() < 0.05:
        value = [
            [[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[1]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]
        ]
    parent = doc
    for k in path[:-1]:
        parent = parent[k]
    if rng.random() < 0.1 and isinstance(parent, dict):
        del parent[path[-1]]
        value = "<deleted>"
    else:
        parent[path[-1]] = value
    return doc, path, value


def _bad_number(v: Any, *, lo: float = 0.0, integer: bool = False) -> bool:
    """True if ``v`` must never pass as such a number."""
    if isinstance(v, bool) or not isinstance(v, int | float):
        return True
    if integer and not isinstance(v, int):
        return True
    return not math.isfinite(v) or v < lo or abs(v) > 1e15


def must_refuse(kind: str, path: tuple[Any, ...], value: Any) -> bool:
    """Whether a structured mutation makes the document invalid for certain."""
    if value == "<deleted>":
        return kind == "layout" and path[0] in ("format", "name", "rows", "cols")
    key = path[0]
    if kind == "layout":
        if key in ("rows", "cols"):
            return _bad_number(value, lo=1, integer=True) or value != 2
        if key in ("width_mm", "height_mm"):
            return _bad_number(value) or value <= 2
        if key in ("roi_fraction", "patch_fraction"):
            return _bad_number(value) or not 0 < value <= 1
        if key == "version":
            return _bad_number(value, integer=True) or value > 1
        if key == "margin_mm":
            return len(path) == 1 or _bad_number(value) or value >= 38
        if key == "patch_names":
            if len(path) == 1:  # [] means the default names
                return value != []
            return not isinstance(value, str) or not value.strip()
        if key == "meta":
            if len(path) == 1:  # {} or an object of texts is a valid meta
                return not (
                    isinstance(value, dict)
                    and all(isinstance(v, str) for v in value.values())
                )
            return not isinstance(value, str)
        if key == "format":
            return True
        if key == "name":
            return not isinstance(value, str) or not value.strip()
        if key == "corners_px":
            if len(path) == 1:
                return value is not None
            if len(path) == 2:
                return not (
                    isinstance(value, list)
                    and len(value) == 2
                    and not any(_bad_number(v, lo=-1e6) for v in value)
                )
            return _bad_number(value, lo=-1e6)
        return False
    if kind == "manifest":
        if key in ("format", "frames") and len(path) == 1:
            return True
        if key == "version":
            return _bad_number(value, integer=True) or value > 1
        if key == "settings" and len(path) >= 2:
            field = path[1]
            if field in ("n_darks", "iso"):
                return _bad_number(value, lo=1, integer=True) or value > 100
            if field == "target_level":
                return _bad_number(value) or not 0.05 <= value <= 0.95
            if field == "channels":
                return len(path) == 2 or not isinstance(value, str) or not value
            if field in ("exposures_s", "requested_s") and len(path) == 4:
                return _bad_number(value) or value <= 0
        if key == "frames" and len(path) == 3:
            field = path[2]
            if field == "exposure_s":
                return _bad_number(value) or value <= 0
            if field in ("iso", "bracket"):
                return _bad_number(value, integer=True)
            if field == "file":
                return not isinstance(value, str) or ".." in value or value[:1] == "/"
        return False
    if kind == "config":
        if len(path) == 2 and path == ("bench", "seed"):
            return _bad_number(value, integer=True) or value > 2**32 - 1
        if len(path) == 2 and path == ("capture", "iso"):
            return _bad_number(value, lo=1, integer=True)
        if len(path) == 2 and path == ("calibrate", "method"):
            return value not in ("smooth", "pca", None)
        if len(path) == 2 and path == ("export", "report"):
            return not isinstance(value, bool)
        if len(path) == 1:  # a section: must be a table
            return key != "out" and not isinstance(value, dict)
        return False
    return False


# -- readers and invariants ------------------------------------------------------------
def _finite(a: Any, limit: float = MAX_VALUE) -> bool:
    arr = np.asarray(a, dtype=float)
    return bool(np.all(np.isfinite(arr)) and np.all(np.abs(arr) <= limit))


def _names_ok(names: Any) -> bool:
    return all(isinstance(n, str) and n.strip() for n in names)


def _std_json(obj: Any) -> bool:
    try:
        json.dumps(obj, allow_nan=False)
    except (ValueError, TypeError):
        return False
    return True


def read_case(kind: str, path: Path, root: Path) -> str:
    """Read one (mutated) input; "" if what was read is sound, else what is wrong."""
    if kind == "spectra":
        for grid in (None, DEFAULT_GRID):
            s = read_spectra_csv(path, grid)
            if not (_finite(s.values) and _names_ok(s.names)):
                return "non-finite values or bad names"
        return ""
    if kind == "responses":
        r = read_responses_csv(path)
        ok = _finite(r.rgb) and _names_ok(r.patches) and _names_ok(r.illuminants)
        return "" if ok else "non-finite responses or bad names"
    if kind == "cgats":
        t = read_cgats(path)
        s = t.spectra()
        if s is not None and not _finite(s.values):
            return "non-finite spectra"
        for arr in (t.rgb, t.xyz, t.lab):
            if arr is not None and not _finite(arr):
                return "non-finite colour values"
        return "" if _names_ok(t.sample_names) or not t.sample_names else "bad names"
    if kind == "layout":
        lay = load_layout(path)
        if not _std_json(lay.to_dict()) or not _names_ok(lay.patch_names):
            return "layout not standard JSON or bad names"
        if lay.corners_px is not None:
            lay.roi_quads_px()
        with contextlib.suppress(TuneSpecError):
            s = layout_reflectances(lay, path)
            src = Path(s.meta["source"]).resolve()
            if root.resolve() not in src.parents and "resources" not in src.parts:
                return f"read a file outside the project: {src}"
        return ""
    if kind == "manifest":
        s = Session.open(path.parent)
        if not _std_json(s.manifest):
            return "manifest not standard JSON"
        s.missing()
        if len(s.plan()) > 100_000:
            return "absurd plan accepted"
        for f in s.frames:
            if path.parent.resolve() not in s.path_of(f).resolve().parents:
                return "frame outside the session"
        return ""
    if kind == "config":
        cfg = load_config(path)
        check_config(cfg)
        return "" if _std_json(cfg) else "config not JSON"
    raise ValueError(kind)


# -- session folders -------------------------------------------------------------------
def session_case(folder: Path, rng: random.Random) -> str:
    """Damage a copied session folder; "" if it was handled soundly."""
    victim = folder.parent / "victim"
    victim.mkdir()
    (victim / "keep.txt").write_text("keep")
    s = Session.open(folder)
    frames = list(s.frames)
    rec = rng.choice(frames)
    damaged: set[str] = set()
    op = rng.randrange(8)
    raw = s.path_of(rec)
    spd = None if rec.spd_file is None else folder / rec.spd_file
    if op in (0, 1):
        f = raw if op == 0 or spd is None else spd
        before = f.read_bytes()
        after = mutate_bytes(before, rng)
        f.write_bytes(after)
        if after != before:
            damaged.add(rec.id)
    elif op == 2:
        (spd if spd is not None and rng.random() < 0.5 else raw).unlink()
        damaged.add(rec.id)
    elif op == 3:
        tmp = folder / "tmp"
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.symlink_to(victim, target_is_directory=True)
    elif op == 4:
        (folder / "tmp").mkdir(exist_ok=True)
        (folder / "tmp" / "link").symlink_to(victim / "keep.txt")
        (folder / "tmp" / "sub").symlink_to(victim, target_is_directory=True)
    elif op == 5:
        raw.unlink()
        raw.mkdir()
        damaged.add(rec.id)
    elif op == 6 and spd is not None:
        spd.write_text("wavelength_nm,measured\n400,nan\n500,1\n")
        damaged.add(rec.id)
    else:
        (folder / "tmp").mkdir(exist_ok=True)
        (folder / "tmp" / f"x.{os.getpid()}.dng").write_bytes(b"half")
    changed = {f.id for f in frames if f.id in damaged}
    s = Session.open(folder)
    s.clean_temp()
    s.temp_stem("probe")
    if (victim / "keep.txt").read_text() != "keep":
        return "a file outside the session was changed"
    missing = {f.id for f in s.missing()}
    if not changed <= missing:
        return f"damaged frame(s) not reported: {sorted(changed - missing)}"
    return ""


# -- whole commands (issue 24: the audit's command targets) ----------------------------
def make_command_seeds(folder: Path) -> dict[str, Path]:
    """Small valid inputs for the commands: 24 SG patches under 6 LEDs on a 10 nm
    grid, their simulated responses and a smooth calibration from them."""
    from tunespec.app.cli import main as cli
    from tunespec.core.datasets import (
        load_camera,
        load_colorchecker_sg,
        load_led_set,
        resource_path,
    )

    folder.mkdir(parents=True, exist_ok=True)
    sg = load_colorchecker_sg()
    write_spectra_csv(sg.select(sg.names[:24]), folder / "chart.csv")
    write_spectra_csv(sg.select(sg.names[60:72]), folder / "sample.csv")
    leds = load_led_set()
    write_spectra_csv(leds.select(leds.names[1:22:4]), folder / "leds.csv")
    write_spectra_csv(load_camera(), folder / "camera.csv")
    shutil.copy(
        resource_path("layouts", "colorchecker_sg.json"), folder / "layout.json"
    )
    quiet = ["-q"]
    with contextlib.redirect_stdout(None), contextlib.redirect_stderr(None):
        for argv in (
            ["simulate-responses", "--sensitivities", "camera.csv", "--illuminants",
             "leds.csv", "--reflectances", "chart.csv", "--exposure-target", "0.8",
             "--illuminants-out", "illum.csv", "-o", "responses.csv"],
            ["simulate-responses", "--sensitivities", "camera.csv", "--illuminants",
             "illum.csv", "--reflectances", "sample.csv", "-o", "sample_resp.csv"],
            ["calibrate", "--responses", "responses.csv", "--illuminants",
             "illum.csv", "--reflectances", "chart.csv", "--method", "smooth",
             "--grid", "400:700:10", "-o", "sens.csv", *quiet],
            ["estimate", "--responses", "sample_resp.csv", "--illuminants",
             "illum.csv", "--sensitivities", "sens.csv", "--grid", "400:700:10",
             "-o", "est.csv", *quiet],
            ["export-rawtoaces", "--sensitivities", "sens.csv", "-o", "sens.json",
             *quiet],
            ["export-cgats", "--reflectances", "chart.csv", "-o", "chart.ti3", *quiet],
        ):  # fmt: skip
            with _cwd(folder):
                rc = cli(argv)
            if rc != 0:
                raise RuntimeError(f"seed command failed: {argv}")
    return {p.name: p for p in folder.iterdir() if p.is_file()}


@contextlib.contextmanager
def _cwd(folder: Path) -> Any:
    old = os.getcwd()
    os.chdir(folder)
    try:
        yield
    finally:
        os.chdir(old)


#: (command line, weight): input files by name (copied into the case's folder),
#: ``@out`` an output name. Weights keep the slow ones (report, match-illuminant,
#: capture) rarer.
COMMAND_TARGETS: list[tuple[list[str], int]] = [
    (["estimate", "--responses", "sample_resp.csv", "--illuminants", "illum.csv",
      "--sensitivities", "sens.csv", "--grid", "400:700:10", "--noise-std", "0.01",
      "-o", "@out.csv"], 6),
    (["estimate", "--responses", "sample_resp.csv", "--illuminants", "illum.csv",
      "--sensitivities", "sens.json", "--prior", "chart.csv", "--spd-shift-nm", "0",
      "-o", "@out.csv"], 4),
    (["calibrate", "--responses", "responses.csv", "--illuminants", "illum.csv",
      "--reflectances", "chart.csv", "--method", "smooth", "--grid", "400:700:10",
      "--hold-out-every", "4", "-o", "@out.csv", "--stats", "@stats.json"], 4),
    (["calibrate", "--responses", "responses.csv", "--illuminants", "illum.csv",
      "--reflectances", "chart.ti3", "--method", "pca", "--components", "3",
      "--grid", "400:700:10", "-o", "@out.csv"], 2),
    (["evaluate", "--estimated", "est.csv", "--reference", "sample.csv",
      "--grid", "400:700:10", "--stats", "@stats.json"], 4),
    (["simulate-responses", "--sensitivities", "camera.csv", "--illuminants",
      "illum.csv", "--reflectances", "chart.csv", "--full-well-e", "67000",
      "--read-noise-e", "30", "--n-pixels", "400", "--flat-field-residual",
      "0.003", "-o", "@out.csv"], 5),
    (["export-cgats", "--reflectances", "est.csv", "--responses",
      "sample_resp.csv", "--illuminant", "LED540", "-o", "@out.ti3"], 3),
    (["export-rawtoaces", "--sensitivities", "sens.csv", "--manufacturer", "X",
      "--model", "Y", "-o", "@out.json"], 3),
    (["export-camera", "--responses", "responses.csv", "--illuminants", "illum.csv",
      "--reflectances", "chart.csv", "--sensitivities", "sens.csv", "-o",
      "@outdir"], 1),
    (["gonio-plan", "-o", "@plan.json", "--theta-i", "45", "--theta-r", "0,30",
      "--phi-r", "0", "--spectral", "30", "--hdr-from", "60"], 3),
    (["match-illuminant", "--illuminants", "leds.csv", "--reflectances",
      "sample.csv", "--max-level", "1", "-o", "@levels.json"], 1),
    (["report", "-o", "@rep", "--reflectances", "est.csv", "--reference",
      "sample.csv", "--sensitivities", "sens.csv"], 1),
    (["capture", "--layout", "layout.json", "--resolution", "128x96", "--channels",
      "LED450", "--exposure", "1", "--darks", "1", "--out", "@session", "-q"], 1),
]  # fmt: skip

#: Option values a user (or a fuzzer) types.
HOSTILE_OPTIONS = [
    *HOSTILE_NUMBERS[:22], "1e300", "-1e300", "0.0175", "400:700:0.0175",
    "700:400:10", "400:700:-5", "100000x100000", "3x3", "../../etc/passwd",
    "/etc/passwd", "/proc/self/environ", "", " ", "a" * 300, "LED999", "A1,A1",
    "tcp://203.0.113.9:8786", "-", "--", "D50", "bayes", "1,0.125", "0,0,0",
]  # fmt: skip


def command_case(
    seeds: dict[str, Path], rng: random.Random, work: Path
) -> tuple[list[str], Callable[[], str]]:
    """A mutated command line (files copied into ``work``) and the check of what
    it wrote when it exits 0."""
    targets = [t for t, w in COMMAND_TARGETS for _ in range(w)]
    argv = list(rng.choice(targets))
    for name, path in seeds.items():
        shutil.copy(path, work / name)
    files = [i for i, a in enumerate(argv) if a in seeds]
    values = [i for i, a in enumerate(argv) if i > 0 and argv[i - 1].startswith("--")
              and not a.startswith("@") and a not in seeds]  # fmt: skip
    op = rng.randrange(6)
    if op in (0, 1) and files:  # a damaged input file
        f = work / argv[rng.choice(files)]
        f.write_bytes(mutate_bytes(f.read_bytes(), rng))
    elif op == 2 and values:  # a hostile option value
        argv[rng.choice(values)] = rng.choice(HOSTILE_OPTIONS)
    elif op == 3 and len(files) >= 2:  # two input files swapped
        a, b = rng.sample(files, 2)
        argv[a], argv[b] = argv[b], argv[a]
    elif op == 4 and files:  # another kind of file, a folder, a missing one
        i = rng.choice(files)
        argv[i] = rng.choice([*seeds, ".", "missing.csv", "sens.csv.meta.json"])
    else:  # an option dropped, or a value given twice
        i = rng.randrange(1, len(argv))
        if rng.random() < 0.5:
            del argv[i]
        else:
            argv.insert(i, argv[i])
    outputs = [work / a[1:] for a in argv if a.startswith("@")]
    argv = [str(work / a[1:]) if a.startswith("@") else a for a in argv]

    def check() -> str:
        for out in outputs:
            for f in [out] if out.is_file() else sorted(out.rglob("*")):
                if not f.is_file() or f.suffix not in (".csv", ".json", ".ti3"):
                    continue
                text = f.read_text(encoding="utf-8", errors="replace")
                if f.suffix == ".json" and not _std_json_text(text):
                    return f"exit 0 with a non-standard JSON {f.name}"
                cells = re.split(r"[,\s]+", text.lower())
                if f.suffix != ".json" and _NON_FINITE & set(cells):
                    return f"exit 0 with nan/inf written to {f.name}"
        return ""

    return argv, check


_NON_FINITE = {"nan", "-nan", "inf", "-inf", "+inf", "infinity", "-infinity"}


def _std_json_text(text: str) -> bool:
    try:
        json.loads(text, parse_constant=_bad_constant)
    except ValueError:
        return False
    return True


def _bad_constant(name: str) -> Any:
    raise ValueError(name)


def run_command(argv: list[str], work: Path) -> tuple[int, str]:
    """``tunespec ARGV`` in-process in ``work``: (exit status, stderr)."""
    import io

    from tunespec.app.cli import main as cli

    err = io.StringIO()
    with _cwd(work), contextlib.redirect_stdout(io.StringIO()), \
            contextlib.redirect_stderr(err):  # fmt: skip
        try:
            rc = cli(argv)
        except SystemExit as exc:  # argparse: usage and one error line, status 2
            rc = exc.code if isinstance(exc.code, int) else 2
    return rc, err.getvalue()


def _shown_argv(argv: list[str]) -> str:
    return " ".join(
        a if len(a) <= 60 else a[:40] + f"...({len(a)} chars)" for a in argv
    )


def _classify_command(
    argv: list[str], work: Path, check: Callable[[], str]
) -> tuple[str, str]:
    cmd = _shown_argv(argv)
    try:
        rc, err = run_command(argv, work)
    except _Hang:
        return "hang", cmd
    except Exception:
        return "traceback", f"{cmd}\n{traceback.format_exc(limit=-3)}"
    last = err.strip().splitlines()[-1] if err.strip() else ""
    if "Traceback" in err or rc not in (0, 2, 3, 4):
        return "traceback", f"exit {rc}: {cmd}: {err[-600:]}"
    if rc != 0:
        if len(last) > 2000:
            return "traceback", f"huge message: {cmd}: {last[:200]!r}"
        return "refused", ""
    problem = check()
    if problem:
        return "accepted_bad", f"{cmd}: {problem}"
    return "accepted", ""


# -- the loop --------------------------------------------------------------------------
def run_one(
    kind: str, seeds: dict[str, Path], rng: random.Random, work: Path
) -> tuple[str, str]:
    """One case of ``kind``: (outcome, detail)."""
    if kind == "commands":
        argv, check = command_case(seeds["commands"], rng, work)  # type: ignore[arg-type]
        return _classify_command(argv, work, check)
    if kind == "session":
        folder = work / "session"
        shutil.copytree(seeds["session"], folder, symlinks=True)
        return _classify(lambda: session_case(folder, rng), None)
    if kind == "manifest":
        folder = work / "session"
        shutil.copytree(seeds["session"], folder, symlinks=True)
        target = folder / "manifest.json"
    else:
        target = work / seeds[kind].name
    src = seeds[kind]
    strict = False
    if kind in ("layout", "manifest", "config") and rng.random() < 0.5:
        if kind == "config":
            doc = json.loads(seeds["config_json"].read_text())
            doc.pop("_path", None)
            target = work / "config.json"
        else:
            doc = json.loads(src.read_text())
        doc, path, value = mutate_json(doc, rng)
        strict = must_refuse(kind, path, value)
        target.write_text(json.dumps(doc))
    else:
        target.write_bytes(mutate_bytes(src.read_bytes(), rng))
    if kind == "layout":
        shutil.copy(seeds["spectra"], work / "spectra.csv")
    return _classify(lambda: read_case(kind, target, work), strict)


def _classify(call: Callable[[], str], strict: bool | None) -> tuple[str, str]:
    try:
        problem = call()
    except _Hang:
        return "hang", ""
    except TuneSpecError as exc:
        text = str(exc)
        if "\n" in text or len(text) > 2000:
            return "traceback", f"multi-line or huge message: {text[:200]!r}"
        return "refused", ""
    except Exception:
        return "traceback", traceback.format_exc(limit=-3)
    if problem:
        return "accepted_bad", problem
    if strict:
        return "accepted_bad", "a hostile value in a checked field was accepted"
    return "accepted", ""


def fuzz(
    n_cases: int,
    *,
    seed: int = 0,
    kinds: tuple[str, ...] = KINDS,
    time_limit_s: float = 5.0,
    report: Callable[[str], None] | None = None,
) -> tuple[Counter[str], list[tuple[str, int, str, str]]]:
    """Run ``n_cases`` cases round-robin over ``kinds``; (counts, bugs found).

    Each bug is ``(kind, case number, outcome, detail)``; a case is reproduced with
    the same ``seed`` (case ``i`` uses ``random.Random(f"{seed}:{i}")``).
    """
    counts: Counter[str] = Counter(dict.fromkeys(OUTCOMES, 0))
    bugs: list[tuple[str, int, str, str]] = []
    use_alarm = hasattr(signal, "setitimer")

    def on_alarm(signum: int, frame: object) -> None:
        raise _Hang

    with tempfile.TemporaryDirectory(prefix="tunespec-fuzz-") as tmp:
        seeds: dict[str, Any] = make_seeds(Path(tmp) / "seeds")
        if "commands" in kinds:
            seeds["commands"] = make_command_seeds(Path(tmp) / "command_seeds")
        old = signal.signal(signal.SIGALRM, on_alarm) if use_alarm else None
        try:
            for i in range(n_cases):
                kind = kinds[i % len(kinds)]
                rng = random.Random(f"{seed}:{i}")
                work = Path(tmp) / f"case{i}"
                work.mkdir()
                if use_alarm:  # a whole command gets more time than a reader
                    limit = max(time_limit_s, COMMAND_TIME_LIMIT_S) if kind in (
                        COMMAND_KINDS) else time_limit_s  # fmt: skip
                    signal.setitimer(signal.ITIMER_REAL, limit)
                try:
                    outcome, detail = run_one(kind, seeds, rng, work)
                except _Hang:
                    outcome, detail = "hang", ""
                finally:
                    if use_alarm:
                        signal.setitimer(signal.ITIMER_REAL, 0)
                counts[outcome] += 1
                counts[f"{kind}:{outcome}"] += 1
                if outcome in BUGS:
                    bugs.append((kind, i, outcome, detail))
                    if report is not None:
                        report(f"case {i} ({kind}): {outcome}: {detail}")
                shutil.rmtree(work, ignore_errors=True)
        finally:
            if use_alarm:
                signal.signal(signal.SIGALRM, old)
    return counts, bugs


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=10_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--kinds",
        default="all",
        help="comma-separated, of: " + ", ".join(KINDS + COMMAND_KINDS) + " (all: "
        "every one)",
    )
    parser.add_argument("--time-limit", type=float, default=5.0, help="s per case")
    parser.add_argument(
        "--semantic",
        action="store_true",
        help="mutate meaning instead of syntax (tools/fuzz_semantic.py): scales, "
        "units, typos, truncated ranges, dropped side files, swapped arguments",
    )
    parser.add_argument(
        "--source",
        choices=("sim", "demo"),
        default="sim",
        help="--semantic: the good files from a simulated bench or tunespec demo",
    )
    args = parser.parse_args(argv)
    if args.semantic:
        return _main_semantic(args)
    kinds = (
        KINDS + COMMAND_KINDS if args.kinds == "all" else tuple(args.kinds.split(","))
    )
    t0 = time.perf_counter()
    counts, bugs = fuzz(
        args.cases,
        seed=args.seed,
        kinds=kinds,
        time_limit_s=args.time_limit,
        report=lambda m: print(m, file=sys.stderr),
    )
    wall_s = time.perf_counter() - t0
    print(f"{args.cases} cases (seed {args.seed}) in {wall_s:.0f} s")
    for o in OUTCOMES:
        print(f"  {o:<13} {counts[o]}")
    print("per kind:")
    for k in kinds:
        print(f"  {k:<10} " + " ".join(f"{o}={counts[f'{k}:{o}']}" for o in OUTCOMES))
    return 1 if bugs else 0


def _main_semantic(args: argparse.Namespace) -> int:
    """``--semantic``: :func:`fuzz_semantic.fuzz_semantic`, its counts printed."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from fuzz_semantic import OUTCOMES as SEMANTIC_OUTCOMES
    from fuzz_semantic import fuzz_semantic

    t0 = time.perf_counter()
    counts, bugs = fuzz_semantic(
        args.cases,
        seed=args.seed,
        source=args.source,
        time_limit_s=max(args.time_limit, 60.0),
        report=lambda m: print(m, file=sys.stderr),
    )
    wall_s = time.perf_counter() - t0
    print(
        f"{args.cases} semantic cases (seed {args.seed}, {args.source}) in {wall_s:.0f} s"
    )
    for o in SEMANTIC_OUTCOMES:
        print(f"  {o:<15} {counts[o]}")
    print("per mutation:")
    labels = sorted({k.split(":")[0] for k in counts if ":" in k})
    for label in labels:
        row = " ".join(
            f"{o}={counts[f'{label}:{o}']}"
            for o in SEMANTIC_OUTCOMES
            if counts[f"{label}:{o}"]
        )
        print(f"  {label:<36} {row}")
    for i, label, outcome, detail in bugs[:20]:
        print(f"  bug: case {i}: {label}: {outcome}: {detail[:300]}")
    return 1 if bugs else 0


if __name__ == "__main__":
    sys.exit(main())
