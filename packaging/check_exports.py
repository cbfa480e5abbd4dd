"""Open every export of a measurement with the reader the docs name for it.

    python packaging/check_exports.py EXPORT_DIR [IMAGES_DIR ...]

Run by ``packaging/build_and_smoke.sh`` on what the *built* app wrote. Each file is
told by its content, never by its name (``sensitivities.json.meta.json`` is a side
file, not rawtoaces JSON), and opened as what it is:

- rawtoaces JSON (``spectral_data``): validated against the rawtoaces-data schema
  1.0.0 (``tests/data/rawtoaces_schema_1.0.0.json``) with jsonschema, and read back
  by TuneSpec's reader as sensitivities (docs/user-guide.md, "Formats");
- other JSON: parsed; a ``.meta.json`` side file through
  ``core.io.export.read_sensitivity_meta``; ``exports.json`` must list every file of
  its folder and nothing else;
- CGATS (``.ti3``): TuneSpec's CGATS reader, and ArgyllCMS ``spec2cie`` for files
  with spectra when ArgyllCMS is installed;
- spectral CSV (first column of wavelengths): TuneSpec's reader and colour-science's
  ``read_sds_from_csv_file``; responses CSV (``patch,illuminant,R,G,B``): TuneSpec's
  reader; any other CSV: rectangular, every value a finite number or a name;
- HTML report: parses, images inline, no external assets; PDF: header, trailer,
  at least one page; PNG: Pillow;
- ENVI cube (``.hdr``/``.img``): Spectral Python; Zarr cube: ``xarray.open_zarr``;
  TIFFs: tifffile, with the photometric interpretation the docs give (``lab.tif``
  CIELab, ``xyz.tif`` RGB, ``uncertainty.tif`` min-is-black), float samples.

The reflectances are also compared across formats (``reflectances.csv`` against
``reflectances.ti3``; the ENVI cube against the Zarr cube), so a writer that breaks
its numbers fails here too. Prints one line per file; exits 1 naming every failure.
"""

from __future__ import annotations

import csv
import html.parser
import json
import math
import re
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SCHEMA = ROOT / "tests" / "data" / "rawtoaces_schema_1.0.0.json"

#: The photometric interpretation (TIFF tag 262) of each image export, as
#: docs/user-guide.md ("Outputs open in the tools people already use") gives it.
TIFF_PHOTOMETRIC = {
    "lab.tif": "CIELAB",
    "xyz.tif": "RGB",
    "uncertainty.tif": "MINISBLACK",
}


class Bad(Exception):
    """An export that its reader refuses or that says something impossible."""


def _json(path: Path) -> object:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise Bad(f"not JSON: {exc}") from None


def check_rawtoaces(path: Path, doc: dict) -> str:
    import jsonschema

    schema = json.loads(SCHEMA.read_text(encoding="utf-8"))
    errors = sorted(
        jsonschema.Draft4Validator(schema).iter_errors(doc), key=lambda e: e.path
    )
    if errors:
        raise Bad(f"rawtoaces schema 1.0.0: {errors[0].message} (of {len(errors)})")
    from tunespec.core.io.spectral import read_spectral

    s = read_spectral(path, kind="sensitivity")
    if s.names != ("R", "G", "B") or not np.isfinite(s.values).all():
        raise Bad(f"sensitivities read back as {s.names}")
    if not (s.values.max(axis=1) > 0).all():
        raise Bad("a channel is zero everywhere")
    return (
        f"rawtoaces JSON (schema 1.0.0, jsonschema), {len(s.wavelength_nm)} wavelengths"
    )


def check_json(path: Path) -> str:
    doc = _json(path)
    if isinstance(doc, dict) and "spectral_data" in doc:
        return check_rawtoaces(path, doc)
    if path.name.endswith(".meta.json"):
        base = path.with_name(path.name[: -len(".meta.json")])
        if not base.is_file():
            raise Bad(f"side file of {base.name}, which is missing")
        from tunespec.core.io.export import read_sensitivity_meta

        meta = read_sensitivity_meta(base)
        if "spd_shift_nm" not in meta:
            raise Bad("side file without the calibration's spd_shift_nm")
        cov = meta.get("covariance")
        if cov is not None and not np.isfinite(cov).all():
            raise Bad("non-finite covariance")
        keys = ", ".join(k for k in sorted(meta) if k != "meta_path")
        return f"side file of {base.name} (read_sensitivity_meta): {keys}"
    if path.name == "exports.json":
        if not isinstance(doc, dict):
            raise Bad("the exports index is not an object")
        listed = set(doc.values())
        there = {p.name for p in path.parent.iterdir()} - {path.name}
        if listed != there:
            raise Bad(
                f"index and folder differ: not written {sorted(listed - there)}, "
                f"not listed {sorted(there - listed)}"
            )
        return f"exports index: {len(listed)} exports, all there"
    if not isinstance(doc, dict | list) or not doc:
        raise Bad("empty JSON document")
    return f"JSON ({len(doc)} top-level entries)"


def check_cgats(path: Path) -> str:
    from tunespec.core.io.cgats import read_cgats

    table = read_cgats(path)
    n = len(table.rows)
    if n == 0:
        raise Bad("CGATS table without data")
    text = path.read_text(encoding="utf-8")
    argyll = ""
    if "SPECTRAL_BANDS" in text and shutil.which("spec2cie"):
        with tempfile.TemporaryDirectory() as tmp:
            out = subprocess.run(
                [
                    "spec2cie",
                    "-n",
                    "-i",
                    "D50",
                    "-o",
                    "1931_2",
                    str(path),
                    f"{tmp}/o.ti3",
                ],
                capture_output=True,
                text=True,
                check=False,
            )
            if out.returncode != 0:
                raise Bad(
                    f"ArgyllCMS spec2cie: {out.stdout.strip()} {out.stderr.strip()}"
                )
        argyll = ", ArgyllCMS spec2cie read it"
    return f"CGATS, {n} sets (TuneSpec reader{argyll})"


_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$|^[+-]?(nan|inf)$", re.I)


def check_csv(path: Path) -> str:
    from tunespec.core.io.spectral_csv import is_wavelength_header

    with path.open(newline="", encoding="utf-8") as fh:
        rows = [r for r in csv.reader(fh) if r and not r[0].startswith("#")]
    if len(rows) < 2:
        raise Bad("CSV without data rows")
    header = rows[0]
    if any(len(r) != len(header) for r in rows):
        raise Bad("rows of different lengths")
    if is_wavelength_header(header[0]):
        from colour.io import read_sds_from_csv_file

        from tunespec.core.io.spectral import read_spectral

        s = read_spectral(path, allow_negative=True)
        if not np.isfinite(s.values).all():
            raise Bad("non-finite spectral values")
        sds = read_sds_from_csv_file(path)
        if sorted(sds) != sorted(s.names):
            raise Bad(f"colour-science reads {sorted(sds)}, TuneSpec {sorted(s.names)}")
        first = sds[s.names[0]]
        if not np.allclose(first.values, s.values[0], rtol=1e-12, atol=0):
            raise Bad("colour-science and TuneSpec read different values")
        return (
            f"spectral CSV, {len(s.names)} spectra x {len(s.wavelength_nm)} wavelengths "
            "(TuneSpec reader, colour-science read_sds_from_csv_file)"
        )
    if header[:5] == ["patch", "illuminant", "R", "G", "B"]:
        from tunespec.core.io.responses_csv import read_responses_csv

        r = read_responses_csv(path)
        if not np.isfinite(r.rgb).all():
            raise Bad("non-finite responses")
        return f"responses CSV, {len(r.patches)} patches x {len(r.illuminants)} lights"
    numbers = 0
    for lineno, row in enumerate(rows[1:], 2):
        for cell in row:
            if _NUMBER.match(cell.strip()):
                if not math.isfinite(float(cell)):
                    raise Bad(f"line {lineno}: {cell}")
                numbers += 1
    if numbers == 0:
        raise Bad("a table without numbers")
    return f"CSV table, {len(rows) - 1} rows x {len(header)} columns"


class _Html(html.parser.HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.images: list[str] = []
        self.external: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        if tag == "img":
            self.images.append(a.get("src") or "")
        for key in ("src", "href"):
            v = a.get(key) or ""
            if (
                tag in ("img", "script", "link")
                and key in a
                and not v.startswith("data:")
            ):
                self.external.append(f"<{tag} {key}={v[:60]}>")


def check_html(path: Path) -> str:
    p = _Html()
    p.feed(path.read_text(encoding="utf-8"))
    p.close()
    if p.external:
        raise Bad(f"external assets: {p.external[:3]}")
    inline = [s for s in p.images if s.startswith("data:image/")]
    if not inline:
        raise Bad("no inline images")
    return f"HTML report, {len(inline)} inline images, self-contained"


def check_pdf(path: Path) -> str:
    data = path.read_bytes()
    if b"%%EOF" not in data[-1024:]:
        raise Bad("no PDF trailer (cut short?)")
    pages = len(re.findall(rb"/Type\s*/Page\b", data))
    if pages == 0:
        raise Bad("a PDF without pages")
    return f"PDF, {pages} pages, {len(data) / 1e3:.0f} kB"


def check_png(path: Path) -> str:
    from PIL import Image

    with Image.open(path) as im:
        im.verify()
    with Image.open(path) as im:
        im.load()
        if min(im.size) < 1:
            raise Bad("an empty image")
        return f"PNG {im.size[0]}x{im.size[1]} {im.mode} (Pillow)"


def check_tiff(path: Path) -> str:
    import tifffile

    with tifffile.TiffFile(path) as tif:
        page = tif.pages[0]
        photometric = page.photometric.name
        data = page.asarray()
    want = TIFF_PHOTOMETRIC.get(path.name)
    if want is not None and photometric != want:
        raise Bad(f"photometric {photometric}, the docs say {want}")
    if data.dtype.kind != "f" or not np.isfinite(data).all():
        raise Bad(f"samples {data.dtype}, finite {np.isfinite(data).all()}")
    return f"TIFF {photometric} {data.shape} {data.dtype} (tifffile)"


def check_envi(path: Path) -> tuple[str, np.ndarray]:
    from spectral import envi

    img = envi.open(str(path))
    cube = np.asarray(img.load())
    wl = [float(w) for w in img.metadata.get("wavelength", [])]
    if len(wl) != cube.shape[2]:
        raise Bad(f"{len(wl)} wavelengths for {cube.shape[2]} bands")
    if not np.isfinite(cube).all():
        raise Bad("non-finite reflectances")
    return f"ENVI {cube.shape} {wl[0]:g}-{wl[-1]:g} nm (Spectral Python)", cube


def check_zarr(path: Path) -> tuple[str, np.ndarray]:
    import xarray as xr

    ds = xr.open_zarr(path)
    r = ds["reflectance"]
    if r.dims != ("y", "x", "wavelength"):
        raise Bad(f"dimensions {r.dims}")
    units = ds["wavelength"].attrs.get("units")
    if units != "nm":
        raise Bad(f"wavelength units {units!r}")
    cube = r.values
    if not np.isfinite(cube).all():
        raise Bad("non-finite reflectances")
    return f"Zarr {r.dims} {cube.shape} (xarray.open_zarr)", cube


def _kind(path: Path) -> str:
    if path.is_dir():
        return "zarr" if (path / "zarr.json").is_file() else "folder"
    head = path.read_bytes()[:16]
    if head.startswith(b"%PDF-"):
        return "pdf"
    if head.startswith(b"\x89PNG"):
        return "png"
    if head[:4] in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+"):
        return "tiff"
    if head.startswith(b"ENVI"):
        return "envi"
    text = head.decode("latin-1").lstrip()
    if text.startswith(("{", "[")):
        return "json"
    if text.lower().startswith(("<!doctype html", "<html")):
        return "html"
    if re.match(r"^(CTI[123]|CGATS|IT8\.)", text):
        return "cgats"
    if path.suffix.lower() == ".img" and path.with_suffix(".hdr").is_file():
        return "envi-data"
    lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    if lines and "," in lines[0]:
        return "csv"
    return "unknown"


CHECKS: dict[str, Callable[[Path], str]] = {
    "json": check_json,
    "cgats": check_cgats,
    "csv": check_csv,
    "html": check_html,
    "pdf": check_pdf,
    "png": check_png,
    "tiff": check_tiff,
}


def _same_reflectances(folder: Path) -> str | None:
    csv_path, ti3_path = folder / "reflectances.csv", folder / "reflectances.ti3"
    if not (csv_path.is_file() and ti3_path.is_file()):
        return None
    from tunespec.core.io.spectral import read_spectral

    a = read_spectral(csv_path)
    b = read_spectral(ti3_path)  # CGATS SPEC_nnn: percent, read as factors
    common = np.intersect1d(a.wavelength_nm, b.wavelength_nm)
    if a.names != b.names or len(common) < 10:
        raise Bad(
            f"reflectances.csv and .ti3 differ in names/grid: {a.names} {b.names}"
        )
    ia = np.searchsorted(a.wavelength_nm, common)
    ib = np.searchsorted(b.wavelength_nm, common)
    diff = float(np.abs(a.values[:, ia] - b.values[:, ib]).max())
    if diff > 1e-4:  # the .ti3 holds percent to 4 decimals
        raise Bad(f"reflectances.csv and reflectances.ti3 differ by {diff:.2g}")
    return f"reflectances.csv = reflectances.ti3 within {diff:.1g} at {len(common)} nm"


def check_folder(folder: Path) -> list[str]:
    """Check every file of ``folder``; returns the failures (printing each line)."""
    failures: list[str] = []
    cubes: dict[str, np.ndarray] = {}

    def report(name: str, fn: Callable[[], str]) -> None:
        try:
            line = fn()
        except Bad as exc:
            failures.append(f"{folder / name}: {exc}")
            print(f"  FAIL {name}: {exc}")
        except Exception as exc:  # a reader's own error: the export is unreadable
            failures.append(f"{folder / name}: {type(exc).__name__}: {exc}")
            print(f"  FAIL {name}: {type(exc).__name__}: {exc}")
        else:
            print(f"  ok   {name}: {line}")

    entries = sorted(folder.iterdir())
    if not entries:
        failures.append(f"{folder}: no exports")
    for path in entries:
        if path.is_file() and path.stat().st_size == 0:
            report(path.name, lambda: (_ for _ in ()).throw(Bad("empty file")))
            continue
        kind = _kind(path)
        if kind in CHECKS:
            report(path.name, lambda p=path, k=kind: CHECKS[k](p))
        elif kind in ("envi", "zarr"):

            def cube(p: Path = path, k: str = kind) -> str:
                line, values = (check_envi if k == "envi" else check_zarr)(p)
                cubes[k] = values
                return line

            report(path.name, cube)
        elif kind == "envi-data":
            print(f"  ok   {path.name}: ENVI data (read with its .hdr)")
        else:
            report(
                path.name,
                lambda p=path: (_ for _ in ()).throw(Bad(f"no reader for {p.name}")),
            )
    report(
        "(reflectances)", lambda: _same_reflectances(folder) or "no reflectances here"
    )
    if len(cubes) == 2:

        def same_cube() -> str:
            d = float(np.abs(cubes["envi"] - cubes["zarr"]).max())
            if d > 1e-6:
                raise Bad(f"the ENVI and Zarr cubes differ by {d:.2g}")
            return f"ENVI cube = Zarr cube within {d:.1g}"

        report("(cubes)", same_cube)
    return failures


def main(argv: list[str]) -> int:
    if not argv:
        print(__doc__.split("\n\n")[1], file=sys.stderr)
        return 2
    failures: list[str] = []
    for arg in argv:
        folder = Path(arg)
        print(f"{folder}:")
        if not folder.is_dir():
            failures.append(f"{folder}: not a folder")
            continue
        failures += check_folder(folder)
    if failures:
        print(f"{len(failures)} export(s) failed:", file=sys.stderr)
        for f in failures:
            print("  " + f, file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
