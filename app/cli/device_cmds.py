"""Device commands of the ``tunespec`` CLI.

``tunespec emulate cal1 --port N [--leds FILE] [--seed S] [--warm]`` serves the
(assumed) CAL1 protocol on ``127.0.0.1:N`` until Ctrl-C, so the application (or
``open_cal1``) can be tried without the hardware: use the light source spec
``cal1+socket://127.0.0.1:N``.
"""

from __future__ import annotations

import argparse
import sys
import threading
from collections.abc import Mapping, Sequence
from typing import Any, TextIO

from tunespec.app.cli.common import seed_arg, serve_until_stopped
from tunespec.core.errors import InputError

__all__ = ["register", "run_cal1_emulator"]

#: How long before start a ``--warm`` emulated unit was switched on.
WARM_POWER_ON_AGO_S = 3600.0


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``emulate`` (with ``emulate cal1``) to the ``tunespec`` subcommands."""
    emulate = sub.add_parser(
        "emulate",
        help="run a device emulator",
        description="Run a device emulator until Ctrl-C.",
    )
    devices = emulate.add_subparsers(dest="device", metavar="DEVICE", required=True)
    cal1 = devices.add_parser(
        "cal1",
        help="emulate the CAL1 light source on a local TCP port",
        description=(
            "Serve the CAL1 protocol (devices/cal1/PROTOCOL.md) on 127.0.0.1:PORT "
            "with simulated LED physics. Connect with the light source spec "
            "cal1+socket://127.0.0.1:PORT."
        ),
    )
    cal1.add_argument(
        "--port", type=_port, default=0, help="TCP port (default: a free one)"
    )
    cal1.add_argument(
        "--leds",
        metavar="FILE",
        help="LED spectral CSV (wavelength column, one column per LED) "
        "instead of the shipped 22-LED CAL1 model",
    )
    cal1.add_argument(
        "--seed", type=seed_arg, default=0, help="unit and noise seed (default 0)"
    )
    cal1.add_argument(
        "--warm",
        action="store_true",
        help="start warmed up (as if switched on an hour ago)",
    )
    cal1.add_argument(
        "--fault",
        action="append",
        default=[],
        type=_fault,
        metavar="KIND[,command=CMD][,skip=N][,delay=S][,code=N]",
        help="inject a fault once (repeatable, in order): KIND is delay (answer "
        "after delay=S seconds), no_reply, drop (close the link), garbage (line "
        "noise) or error (ERR code=N); command= limits it to one wire keyword "
        "(e.g. MEAS:SPD?), skip=N serves N matching requests normally first",
    )
    cal1.add_argument(
        "--disconnect-after",
        type=int,
        default=None,
        metavar="N",
        help="drop the connection on the request after the N-th",
    )
    cal1.set_defaults(func=_emulate_cal1)
    from tunespec.app.cli.gonio_cmds import add_zaber_emulator

    add_zaber_emulator(devices, _port)


FAULT_KINDS = ("delay", "no_reply", "drop", "garbage", "error")


def _fault(text: str) -> dict[str, object]:
    """argparse type of ``--fault``: ``KIND[,key=value...]`` -> inject_fault kwargs."""
    kind, *opts = text.split(",")
    kind = kind.strip().replace("-", "_")
    if kind not in FAULT_KINDS:
        raise argparse.ArgumentTypeError(
            f"unknown fault {kind!r}: use {', '.join(FAULT_KINDS)}"
        )
    out: dict[str, object] = {"kind": kind}
    for opt in opts:
        key, _, value = opt.partition("=")
        key = key.strip()
        try:
            if key == "command" and value:
                out["command"] = value.strip()
            elif key in ("skip", "code") and 0 <= int(value) <= 1_000_000:
                out[key] = int(value)
            elif key == "delay" and 0 <= float(value) <= 3600:
                out["delay_s"] = float(value)
            else:
                raise ValueError
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"bad fault option {opt!r}: command=CMD, skip=N, delay=S (0-3600) "
                "or code=N"
            ) from None
    return out


def _port(text: str) -> int:
    """argparse type: a TCP port 0-65535 (0 = any free one)."""
    try:
        port = int(text)
    except ValueError:
        port = -1
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"expected a port 0-65535, got {text!r}")
    return port


def _emulate_cal1(args: argparse.Namespace) -> int:
    faults = list(args.fault)
    if args.disconnect_after is not None:
        if args.disconnect_after < 0:
            raise InputError("--disconnect-after: expected N >= 0")
        faults.append({"kind": "drop", "skip": args.disconnect_after})
    return run_cal1_emulator(
        port=args.port, leds=args.leds, seed=args.seed, warm=args.warm, faults=faults
    )


def run_cal1_emulator(
    *,
    port: int = 0,
    leds: str | None = None,
    seed: int = 0,
    warm: bool = False,
    stop: threading.Event | None = None,
    out: TextIO | None = None,
    faults: Sequence[Mapping[str, Any]] = (),
) -> int:
    """Serve a CAL1 emulator until Ctrl-C (or until ``stop`` is set); exit code 0.

    ``faults`` are :meth:`Cal1Emulator.inject_fault` keyword sets, injected in order
    before the first client connects.

    Prints the spec to connect with, e.g. ``cal1+socket://127.0.0.1:5025``.

    Raises
    ------
    InputError
        For a bad LED file, or a port that cannot be bound (e.g. in use).
    """
    out = out if out is not None else sys.stdout
    # imported here, not at the top: ``tunespec --help`` imports every command module
    from tunespec.core.io.spectral import read_spectra_csv
    from tunespec.devices.cal1.emulator import Cal1Emulator
    from tunespec.devices.clock import RealClock
    from tunespec.devices.sim.led_physics import LedPhysics

    spectra = read_spectra_csv(leds) if leds else None
    clock = RealClock()
    power_on_s = clock.now_s() - WARM_POWER_ON_AGO_S if warm else None
    physics = LedPhysics(spectra, clock=clock, seed=seed, power_on_s=power_on_s)
    stop = stop if stop is not None else threading.Event()
    try:
        emulator = Cal1Emulator(port, physics)
    except (OSError, OverflowError) as exc:
        raise InputError(
            f"cannot listen on 127.0.0.1:{port} ({exc}); choose another --port or "
            "0 for a free one"
        ) from None
    with emulator as emu:
        for fault in faults:
            emu.inject_fault(**fault)
        source = leds or "shipped 22-LED CAL1 model"
        out.write(
            f"CAL1 emulator ({physics.n_channels} LEDs from {source}, seed {seed}) "
            f"listening on {emu.host}:{emu.port}\n"
            f"light source spec: {emu.spec}\n"
            "press Ctrl-C to stop\n"
        )
        serve_until_stopped(stop, out)
    return 0
