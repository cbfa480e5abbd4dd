"""Open devices from spec strings, and a whole bench (light, camera, target stage).

===============================  ==================================================
light source spec                opens
===============================  ==================================================
``sim[?seed=N&warm=1]``          :class:`~tunespec.devices.sim.light.SimLightSource`
``cal1:///dev/ttyUSB0``          a CAL1 on a serial port
``cal1+socket://HOST:PORT``      a CAL1 (or its emulator) over TCP
===============================  ==================================================

===============================  ==================================================
camera spec                      opens
===============================  ==================================================
``sim[?resolution=WxH&seed=N     :class:`~tunespec.devices.sim.camera.SimCamera`
&realtime=1]``                   imaging a :class:`SimScene` (renders with the true
                                 SPD of a simulated light, or with what another
                                 light source reports: :class:`ReportedSpdLight`)
``gphoto2``, ``gphoto2:PORT``    a Canon EOS over USB (``gphoto2:usb:001,004``)
===============================  ==================================================

For hardware the target stage is the operator: :class:`OperatorStage` asks them to put
the white background or the target in place and waits for their confirmation.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Literal
from urllib.parse import parse_qs

from tunespec.core.datasets import resource_path
from tunespec.core.errors import InputError
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.layout import TargetLayout
from tunespec.core.limits import contained_path, shown
from tunespec.core.spectra import DEFAULT_GRID, Grid, Spectra
from tunespec.devices.clock import Clock, RealClock, VirtualClock
from tunespec.devices.protocols import (
    Camera,
    LightSource,
    SimulatedCamera,
    SimulatedStage,
    TargetStage,
)

__all__ = [
    "DEFAULT_SIM_RESOLUTION",
    "Bench",
    "OperatorStage",
    "ReportedSpdLight",
    "layout_reflectances",
    "open_bench",
    "open_camera",
    "open_light_source",
    "parse_resolution",
    "sim_scene",
]

#: Default resolution of the simulated camera (a quarter of the 5D Mark III's sides).
DEFAULT_SIM_RESOLUTION = (1536, 1024)

PromptFn = Callable[[str], None]


#: Largest simulated image, checked before anything is allocated (a 100 MP
#: medium-format sensor is 11648x8736).
MAX_RESOLUTION_SIDE_PX = 12_000
MAX_RESOLUTION_PX = 110_000_000


def parse_resolution(text: str) -> tuple[int, int]:
    """``"WxH"`` -> ``(W, H)`` in pixels.

    Examples
    --------
    >>> parse_resolution("768x512")
    (768, 512)
    """
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise InputError(
            f"bad resolution {shown(text)}: expected WIDTHxHEIGHT, e.g. 768x512"
        ) from None
    if w < 64 or h < 64 or w % 2 or h % 2:
        raise InputError(f"bad resolution {shown(text)}: even, at least 64x64")
    if max(w, h) > MAX_RESOLUTION_SIDE_PX or w * h > MAX_RESOLUTION_PX:
        raise InputError(
            f"bad resolution {shown(text)}: at most {MAX_RESOLUTION_SIDE_PX} pixels a "
            f"side and {MAX_RESOLUTION_PX // 1_000_000} megapixels (the 5D Mark III "
            "has 5760x3840)"
        )
    return w, h


def _split_spec(spec: str) -> tuple[str, dict[str, str]]:
    head, _, query = spec.strip().partition("?")
    return head, {k: v[-1] for k, v in parse_qs(query).items()}


def open_light_source(
    spec: str, *, clock: Clock | None = None, seed: int | None = None
) -> LightSource:
    """A light source from its spec (see the module docstring).

    Raises
    ------
    InputError
        ``spec`` is neither ``sim`` nor a ``cal1`` spec.
    DeviceError
        The CAL1 does not answer (its port or socket cannot be opened).
    """
    head, _ = _split_spec(spec)
    if head in ("sim", "sim://"):
        from tunespec.devices.sim.light import open_sim_light

        return open_sim_light(spec, clock=clock, seed=seed)
    if head.startswith("cal1"):
        from tunespec.devices.cal1.driver import open_cal1

        return open_cal1(spec)
    raise InputError(
        f"unknown light source {shown(spec)}: use sim, cal1:///dev/ttyUSB0 or "
        "cal1+socket://HOST:PORT"
    )


#: A layout's ``meta.reflectances`` that starts so names no file: the chart's data
#: are the user's (a batch-specific IT8.7/2 reference).
SUPPLY_YOUR_OWN = "supply your own"


def layout_reflectances(
    layout: TargetLayout,
    layout_path: str | Path | None = None,
    grid: Grid = DEFAULT_GRID,
) -> Spectra:
    """The patch reflectances a layout names in ``meta["reflectances"]``.

    A path is looked up relative to the layout file, then in the shipped resources
    (``"charts/colorchecker_sg.csv"``); it must stay inside one of them (no absolute
    paths, no ``..`` out of them).

    Raises
    ------
    InputError
        If the layout names none or the file is missing.
    """
    ref = layout.meta.get("reflectances")
    if not ref:
        raise InputError(
            f"layout {layout.name!r} names no reflectances (meta.reflectances); the "
            "simulated camera needs them"
        )
    if ref.strip().lower().startswith(SUPPLY_YOUR_OWN):
        raise InputError(
            f"layout {layout.name!r} ships no reference data ("
            f"{ref.strip()[len(SUPPLY_YOUR_OWN) :].strip(' :')}): give the chart's "
            "reflectances (--reflectances FILE, or reflectances = in the run "
            "configuration's [chart])",
            path=layout_path,
        )
    bases = [resource_path()]
    if layout_path is not None:
        bases.insert(0, Path(layout_path).parent)
    # a path written in a file stays inside that file's folder or the resources
    candidates = contained_path(ref, "meta.reflectances", bases=bases, path=layout_path)
    for c in candidates:
        if c.is_file():
            return read_spectra_csv(c, grid)
    raise InputError(
        f"meta.reflectances: {shown(ref)} not found beside the layout or in the "
        "shipped resources",
        path=layout_path,
    )


def sim_scene(
    layout: TargetLayout,
    reflectances: Spectra | None = None,
    *,
    layout_path: str | Path | None = None,
    **scene_options: Any,
) -> Any:
    """A :class:`~tunespec.devices.sim.scene.SimScene` showing ``layout``."""
    from tunespec.devices.sim.scene import SimScene

    refl = (
        reflectances
        if reflectances is not None
        else layout_reflectances(layout, layout_path)
    )
    return SimScene(layout, refl, **scene_options)


def open_camera(
    spec: str,
    *,
    light: LightSource | None = None,
    scene: Any = None,
    resolution: tuple[int, int] | None = None,
    seed: int | None = None,
    realtime: bool | None = None,
    clock: Clock | None = None,
) -> Camera:
    """A camera from its spec (see the module docstring).

    Parameters
    ----------
    spec
        ``sim[?resolution=WxH&seed=N&realtime=1]`` or ``gphoto2[:PORT]``.
    light
        For ``sim``: the simulated light source it renders with.
    scene
        For ``sim``: the :class:`SimScene` in front of it.
    resolution, seed, realtime
        For ``sim``: override the spec's options.
    clock
        For ``sim``: the clock shared with the light (default the light's).

    Raises
    ------
    InputError
        An unknown spec, or ``sim`` without a simulated light source and a scene.
    DeviceError
        The camera cannot be opened.
    """
    head, opts = _split_spec(spec)
    if head in ("sim", "sim://"):
        from tunespec.devices.sim.camera import SimCamera

        if light is None or not hasattr(light, "emitted_spd"):
            raise InputError(
                "the simulated camera needs the simulated light source (--light sim)"
            )
        if scene is None:
            raise InputError("the simulated camera needs a scene (a target layout)")
        unknown = set(opts) - {"resolution", "seed", "realtime"}
        if unknown:
            raise InputError(
                f"bad camera spec {shown(spec)}: unknown option(s) {sorted(unknown)}"
            )
        res = resolution or parse_resolution(
            opts.get("resolution", "{}x{}".format(*DEFAULT_SIM_RESOLUTION))
        )
        try:
            seed_value = int(opts.get("seed", "0")) if seed is None else int(seed)
        except ValueError:
            raise InputError(
                f"bad camera spec {shown(spec)}: seed must be an integer"
            ) from None
        rt = (
            opts.get("realtime", "0") in ("1", "true", "yes")
            if realtime is None
            else realtime
        )
        cam_clock = (
            clock
            or getattr(light, "clock", None)
            or (RealClock() if rt else VirtualClock())
        )
        return SimCamera(
            light,  # type: ignore[arg-type]
            scene,
            resolution=res,
            clock=cam_clock,
            seed=seed_value,
            realtime=rt,
        )
    if head == "gphoto2" or head.startswith("gphoto2:"):
        from tunespec.devices.canon.gphoto2_camera import Gphoto2Camera

        return Gphoto2Camera.open(spec)
    raise InputError(f"unknown camera {shown(spec)}: use sim, gphoto2 or gphoto2:PORT")


class ReportedSpdLight:
    """What a simulated camera sees of a real light source: its reported SPD.

    ``emitted_spd()`` is the light's own measurement (``measure_spd``) without the
    spectroradiometer's noise floor
    (:func:`~tunespec.core.metering.suppress_meter_floor`: no light is emitted
    there), or zero when it reports every
    level at 0 (a dark frame needs no measurement). Lets
    ``--camera sim`` run with ``--light cal1+socket://...`` (the emulator) or a real
    CAL1, exercising the driver end to end without a camera.

    Parameters
    ----------
    light
        The light source (its owner keeps controlling it).
    """

    def __init__(self, light: LightSource) -> None:
        self._light = light
        self._grid_nm: Any = DEFAULT_GRID.wavelength_nm

    def emitted_spd(self) -> Spectra:
        import numpy as np

        levels = getattr(self._light, "levels", None)
        if levels is not None and not np.any(np.asarray(levels()) > 0):
            return Spectra(
                self._grid_nm, np.zeros((1, len(self._grid_nm))), ("emitted",)
            )
        from tunespec.core.metering import suppress_meter_floor

        spd = suppress_meter_floor(self._light.measure_spd())
        self._grid_nm = spd.wavelength_nm
        return spd


class OperatorStage:
    """The operator as the target stage: asks them to change what the camera sees.

    Parameters
    ----------
    prompt
        Shows a message and returns once the operator confirmed (the CLI waits for
        Enter, the GUI shows a dialog).
    """

    MESSAGES: ClassVar[dict[str, str]] = {
        "white": "Put the white background board in place (no target), then confirm.",
        "target": "Put the target on the board, flat and fully in view, then confirm.",
    }

    def __init__(self, prompt: PromptFn) -> None:
        self._prompt = prompt
        self.presented: str | None = None

    def present(self, what: Literal["white", "target"]) -> None:
        if what not in self.MESSAGES:
            raise ValueError(f"present() takes 'white' or 'target', not {what!r}")
        if what != self.presented:
            self._prompt(self.MESSAGES[what])
            self.presented = what


@dataclass
class Bench:
    """A light source, a camera and a target stage opened together.

    ``truth`` holds what a simulated bench was built with (sensitivities, scene,
    true corners); empty for hardware. Close with :meth:`close` or ``with``.
    """

    light: LightSource
    camera: Camera
    stage: TargetStage
    truth: dict[str, Any] = field(default_factory=dict)

    @property
    def simulated(self) -> bool:
        return bool(self.truth)

    @property
    def sim_camera(self) -> SimulatedCamera:
        """The camera as a :class:`SimulatedCamera` (``TypeError`` on hardware)."""
        if not isinstance(self.camera, SimulatedCamera):
            raise TypeError("not a simulated bench: the camera has no truth")
        return self.camera

    @property
    def sim_stage(self) -> SimulatedStage:
        """The stage as a :class:`SimulatedStage` (``TypeError`` on hardware)."""
        if not isinstance(self.stage, SimulatedStage):
            raise TypeError("not a simulated bench: the stage is the operator")
        return self.stage

    def close(self) -> None:
        """Close the camera, then the light (which switches its LEDs off)."""
        try:
            self.camera.close()
        finally:
            self.light.close()

    def __enter__(self) -> Bench:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def open_bench(
    light: str = "sim",
    camera: str | None = None,
    *,
    layout: TargetLayout | None = None,
    reflectances: Spectra | None = None,
    layout_path: str | Path | None = None,
    resolution: tuple[int, int] | None = None,
    seed: int = 0,
    realtime: bool | None = None,
    warm: bool = True,
    prompt: PromptFn | None = None,
    scene_options: dict[str, Any] | None = None,
) -> Bench:
    """Open a light source, a camera and the stage between them.

    Parameters
    ----------
    light, camera
        Device specs; ``camera`` defaults to ``"sim"`` for a simulated light and
        ``"gphoto2"`` otherwise.
    layout, reflectances, layout_path
        For a simulated camera: the target it sees (reflectances default to the ones
        the layout names). Default the ColorChecker SG.
    resolution, seed, realtime
        Simulated camera options (``seed`` also seeds the simulated light).
    warm
        Start a simulated light warmed up (as an operator would).
    prompt
        For hardware: how to ask the operator (default: print and wait for Enter).
    scene_options
        Extra :class:`SimScene` arguments (geometry, fall-off).

    Returns
    -------
    Bench
        With ``truth`` filled for a simulated camera.
    """
    cam_spec = camera or (
        "sim" if _split_spec(light)[0].startswith("sim") else "gphoto2"
    )
    if _split_spec(cam_spec)[0].startswith("sim"):
        from tunespec.devices.sim.light import open_sim_light

        head, opts = _split_spec(light)
        src: Any
        seen: Any
        if head in ("sim", "sim://"):
            # options in the spec win over the keyword defaults
            src = seen = open_sim_light(
                light,
                seed=None if "seed" in opts else seed,
                warm=None if "warm" in opts else warm,
            )
        else:
            # a real driver (or the CAL1 emulator): the simulated camera sees what
            # its spectroradiometer reports, so the driver runs end to end
            src = open_light_source(light, seed=seed)
            seen = ReportedSpdLight(src)
        try:
            if layout is None:
                layout = TargetLayout.load(
                    resource_path("layouts", "colorchecker_sg.json")
                )
            scene = sim_scene(
                layout, reflectances, layout_path=layout_path, **(scene_options or {})
            )
            cam = open_camera(
                cam_spec,
                light=seen,
                scene=scene,
                resolution=resolution,
                seed=seed,
                realtime=realtime,
            )
        except BaseException:
            src.close()
            raise
        if not isinstance(cam, SimulatedCamera):  # pragma: no cover - sim specs only
            raise TypeError(f"{cam_spec}: not a simulated camera")
        return Bench(src, cam, scene, cam.truth())
    src = open_light_source(light, seed=seed)
    try:
        cam = open_camera(cam_spec)
    except BaseException:
        src.close()
        raise
    return Bench(src, cam, OperatorStage(prompt or _console_prompt))


def _console_prompt(message: str) -> None:
    import sys

    sys.stderr.write(f"\n>>> {message}\n    Press Enter when ready... ")
    sys.stderr.flush()
    if sys.stdin is None or not sys.stdin.isatty():
        raise InputError(
            "the capture needs the operator to change the target, but there is no "
            "terminal to ask; run it interactively or from the GUI"
        )
    sys.stdin.readline()
