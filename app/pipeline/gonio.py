"""A multi-geometry (gonio) session: plan, capture with kill/resume, processing, fusion.

The gonio-imager of the paper's introduction: at every geometry of a plan the
goniometer moves, the camera takes a dark frame and a single shot under the
D50-matched LED mix (HDR brackets where the plan asks), and at the geometries the plan
marks, the full 22-LED sequence. Processing re-finds the target's homography in every
geometry's frames (the projection changes with the viewing angle), merges the
brackets (:mod:`tunespec.core.hdr`), estimates spectra where the 22 LEDs were captured
(Eq. 5-6), single-shot XYZ everywhere (:mod:`tunespec.core.single_shot`) and fuses
both into spectra at every geometry (:mod:`tunespec.core.fusion`).

Folder layout (every file written atomically; a frame exists completely or not at
all)::

    plan.json                 the plan (geometries, which are spectral / HDR)
    mix.json                  the LED levels of the session's mix (plain D50 match or
                              camera-tuned, the plan's ``mix``), the D50 match's
                              metrics, the spectrum the light reported at those levels
                              and its Delta u'v', CIE Ra and TM-30 Rf
    gNN_<label>/position.json the goniometer's read-back at that geometry
    gNN_<label>/spd_<illuminant>.csv   the light's measured SPD
    gNN_<label>/exposure.json base exposure per illuminant
    gNN_<label>/<illuminant>_e<k>.npy  frames (float32, 3 x H x W), k = bracket

A killed capture resumes with the same call: every frame on disk is kept, the
goniometer returns to the geometry where it stopped and only the missing frames are
taken.
"""

from __future__ import annotations

import io
import math
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tunespec.core.errors import InputError, check_names
from tunespec.core.io.session import atomic_write_bytes, atomic_write_text
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.limits import dumps_json, read_json, valid_number
from tunespec.core.progress import ProgressFn, StopFn, check_stop, report
from tunespec.core.spectra import DEFAULT_GRID, Spectra
from tunespec.devices.goniometer import ANGLE_AXES, Geometry
from tunespec.devices.protocols import DeviceError

__all__ = [
    "HDR_EXPOSURES",
    "MIX_KINDS",
    "GeometryStep",
    "GonioPlan",
    "capture_gonio",
    "default_plan",
    "frame_names",
]

#: Relative exposures of an HDR bracket (each 3 stops shorter).
HDR_EXPOSURES = (1.0, 1.0 / 8.0, 1.0 / 64.0)
#: Fraction of full scale a perfect white diffuser reaches at the base exposure.
WHITE_TARGET = 0.8
MIX = "mix"
DARK = "dark"
#: The single-shot mix a plan may choose: ``d50`` the plain D50 match for the eye
#: (:func:`tunespec.core.illuminant_match.match_illuminant`), ``camera`` that match
#: re-optimised for the calibrated camera with D50's chromaticity and CIE 51.2
#: category B metamerism kept (:func:`tunespec.core.single_shot.
#: optimise_mix_for_camera`).
MIX_KINDS = ("d50", "camera")


@dataclass(frozen=True)
class GeometryStep:
    """One geometry of a plan: angles, full spectral capture or not, HDR or not."""

    geometry: Geometry
    spectral: bool = False
    hdr: bool = False

    def to_dict(self) -> dict[str, Any]:
        return {**self.geometry.as_dict(), "spectral": self.spectral, "hdr": self.hdr}


@dataclass(frozen=True)
class GonioPlan:
    """The geometry list of a session, the LED channels of the spectral captures and
    the single-shot mix (one of :data:`MIX_KINDS`)."""

    steps: tuple[GeometryStep, ...]
    leds: tuple[str, ...] = field(default=())
    mix: str = "d50"

    def __post_init__(self) -> None:
        if not self.steps:
            raise InputError("a gonio plan needs at least one geometry")
        if self.mix not in MIX_KINDS:
            raise InputError(
                f"mix: expected one of {', '.join(MIX_KINDS)}, got {self.mix!r}"
            )
        seen = set()
        for s in self.steps:
            if s.geometry in seen:
                raise InputError(f"geometry {s.geometry.label} is in the plan twice")
            seen.add(s.geometry)

    def folder(self, index: int) -> str:
        """The geometry's folder name, e.g. ``g03_ti45_pi0_tr30_pr180``."""
        return f"g{index:02d}_{self.steps[index].geometry.label}"

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": "tunespec-gonio-plan",
            "version": 1,
            "geometries": [s.to_dict() for s in self.steps],
            "leds": list(self.leds),
            "mix": self.mix,
        }

    @classmethod
    def from_dict(cls, doc: Any, *, source: str | None = None) -> GonioPlan:
        """Validate a plan document (one clear line naming the key on error)."""
        if not isinstance(doc, dict) or doc.get("format") != "tunespec-gonio-plan":
            raise InputError(
                "not a gonio plan (format: tunespec-gonio-plan)", path=source
            )
        rows = doc.get("geometries")
        if not isinstance(rows, list) or not 1 <= len(rows) <= 1000:
            raise InputError(
                "geometries: expected a list of 1-1000 entries", path=source
            )
        steps = []
        for i, row in enumerate(rows):
            key = f"geometries[{i}]"
            if not isinstance(row, dict):
                raise InputError(f"{key}: expected an object", path=source)
            angles = {
                a: valid_number(row.get(a), f"{key}.{a}", path=source, lo=-360, hi=360)
                for a in ANGLE_AXES
            }
            flags = {f: row.get(f, False) for f in ("spectral", "hdr")}
            if not all(isinstance(v, bool) for v in flags.values()):
                raise InputError(
                    f"{key}: spectral and hdr must be true/false", path=source
                )
            try:
                g = Geometry(**angles)
            except InputError as exc:
                raise InputError(f"{key}: {exc.message}", path=source) from None
            steps.append(GeometryStep(g, **flags))
        leds = doc.get("leds", [])
        if not isinstance(leds, list) or not all(isinstance(n, str) for n in leds):
            raise InputError("leds: expected a list of channel names", path=source)
        mix = doc.get("mix", "d50")
        if mix not in MIX_KINDS:
            raise InputError(
                f"mix: expected one of {', '.join(MIX_KINDS)}, got {mix!r}", path=source
            )
        return cls(tuple(steps), tuple(leds), mix)

    def save(self, path: str | Path) -> None:
        atomic_write_text(path, dumps_json(self.to_dict()))

    @classmethod
    def load(cls, path: str | Path) -> GonioPlan:
        return cls.from_dict(read_json(path), source=str(path))


def default_plan(
    n_geometries: int = 14, theta_i: float = 45.0, mix: str = "d50"
) -> GonioPlan:
    """An in-plane scan through the specular direction plus two out-of-plane views.

    Light at ``theta_i`` (azimuth 0); camera at ``theta_r`` in the plane of incidence
    on the specular side (azimuth 180) from 0 to 70 deg, densest around the specular
    peak, then two off-plane views. Spectral captures at 0 deg (the 0/45 of the
    paper), 20 deg and at the specular peak; HDR from 25 deg on in the plane (the
    lobe of the smoothest patch saturates a single exposure up to 70 deg).
    """
    if n_geometries < 4:
        raise InputError("a gonio plan needs at least 4 geometries")
    in_plane = [0, 10, 20, 30, 35, 40, 45, 50, 55, 60, 65, 70]
    off_plane = [(30.0, 90.0), (45.0, 0.0)]
    angles = [(float(t), 180.0) for t in in_plane] + off_plane
    steps = []
    for tr, pr in angles[:n_geometries]:
        g = Geometry(theta_i, 0.0, tr, pr)
        spec = pr == 180.0 and tr in (0.0, 20.0, theta_i)
        hdr = pr == 180.0 and tr >= 25.0
        steps.append(GeometryStep(g, spectral=spec, hdr=hdr))
    return GonioPlan(tuple(steps), mix=mix)


def frame_names(step: GeometryStep, leds: Sequence[str]) -> list[tuple[str, int]]:
    """The frames of one geometry, in capture order: ``(illuminant, bracket)``."""
    n = len(HDR_EXPOSURES) if step.hdr else 1
    out = [(DARK, 0)] + [(MIX, k) for k in range(n)]
    if step.spectral:
        out += [(led, k) for led in leds for k in range(n)]
    return out


def _save_frame(path: Path, frame: NDArray[np.float32]) -> None:
    buf = io.BytesIO()
    np.save(buf, frame.astype(np.float32), allow_pickle=False)
    atomic_write_bytes(path, buf.getvalue())


def _write_spd(path: Path, spd: Spectra) -> None:
    lines = ["wavelength_nm,measured"]
    lines += [
        f"{w:g},{v!r}"
        for w, v in zip(spd.wavelength_nm, spd.values[0].tolist(), strict=True)
    ]
    atomic_write_text(path, "\n".join(lines) + "\n")


def _levels_for(
    name: str, channels: Sequence[str], mix: NDArray[np.float64]
) -> NDArray[np.float64]:
    if name == MIX:
        return mix
    levels = np.zeros(len(channels))
    if name != DARK:
        levels[list(channels).index(name)] = 1.0
    return levels


def _base_exposure(spd: Spectra, sensitivity: Spectra, theta_i: float) -> float:
    """Exposure putting a perfect white diffuser at :data:`WHITE_TARGET`."""
    i = spd.resample(DEFAULT_GRID, average=True).values[0]
    white = (
        (sensitivity.values @ i)
        * DEFAULT_GRID.step_nm
        * math.cos(math.radians(theta_i))
    )
    if not white.max() > 0:
        raise InputError("the light gives no signal: check the levels")
    return WHITE_TARGET / float(white.max())


def capture_gonio(
    plan: GonioPlan,
    folder: str | Path,
    bench: Any,
    sensitivity: Spectra,
    mix_levels: NDArray[np.float64],
    *,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
    on_frame: Callable[[Path], None] | None = None,
) -> list[Path]:
    """Capture (or resume) every geometry of ``plan`` into ``folder``.

    ``bench`` has ``light`` (a LightSource), ``gonio`` (a Goniometer) and
    ``capture(exposure) -> (3, H, W)`` (the camera). Returns the frames taken now.
    Frames already on disk are never taken again; a geometry all of whose frames
    exist is not visited.
    """
    root = Path(folder)
    root.mkdir(parents=True, exist_ok=True)
    plan.save(root / "plan.json")
    channels = [c.name for c in bench.light.channels()]
    leds = list(plan.leds) or channels
    check_names(leds, channels, "plan leds: {n} channel(s) the light lacks: {names}")
    taken: list[Path] = []
    if not bench.gonio.is_homed():
        bench.gonio.home()
    for gi, step in enumerate(plan.steps):
        check_stop(should_stop)
        gdir = root / plan.folder(gi)
        todo = [
            (n, k)
            for n, k in frame_names(step, leds)
            if not (gdir / f"{n}_e{k}.npy").exists()
        ]
        if todo:
            try:
                taken += _capture_geometry(
                    step, gdir, bench, sensitivity, mix_levels, channels, todo, on_frame
                )
            except (InputError, DeviceError) as exc:
                raise _naming_geometry(exc, gi, step) from exc
        report(progress, (gi + 1) / len(plan.steps))
    bench.light.all_off()
    return taken


def _naming_geometry(exc: Exception, index: int, step: GeometryStep) -> Exception:
    """``exc`` (same type) with the geometry it happened at in front of its message:
    ``geometry 3 (theta_i 45, theta_r 30): ...`` (the plan's angles)."""
    g = step.geometry
    label = f"geometry {index + 1} (theta_i {g.theta_i:g}, theta_r {g.theta_r:g})"
    try:
        return type(exc)(f"{label}: {exc}")
    except TypeError:  # an exception type with other arguments: unchanged
        return exc


def _capture_geometry(
    step: GeometryStep,
    gdir: Path,
    bench: Any,
    sensitivity: Spectra,
    mix: NDArray[np.float64],
    channels: Sequence[str],
    todo: Sequence[tuple[str, int]],
    on_frame: Callable[[Path], None] | None,
) -> list[Path]:
    got = bench.gonio.move_to(step.geometry.as_dict())
    atomic_write_text(gdir / "position.json", dumps_json(got))
    theta_i = abs(got["theta_i"])
    exp_path = gdir / "exposure.json"
    exposures: dict[str, float] = read_json(exp_path) if exp_path.exists() else {}
    taken = []
    for name, k in todo:
        bench.light.set_levels(_levels_for(name, channels, mix))
        spd_path = gdir / f"spd_{name}.csv"
        if name != DARK and not spd_path.exists():
            _write_spd(spd_path, bench.light.measure_spd())
        if name not in exposures:
            exposures[name] = (
                1.0 if name == DARK
                else _base_exposure(read_spectra_csv(spd_path), sensitivity, theta_i)
            )  # fmt: skip
            atomic_write_text(exp_path, dumps_json(exposures))
        rel = HDR_EXPOSURES[k] if step.hdr else 1.0
        path = gdir / f"{name}_e{k}.npy"
        key = zlib.crc32(f"{gdir.name}/{path.name}".encode())
        _save_frame(path, bench.capture(exposures[name] * rel, key=key))
        taken.append(path)
        if on_frame is not None:
            on_frame(path)
    return taken
