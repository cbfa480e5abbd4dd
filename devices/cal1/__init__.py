"""Image Engineering CAL1 tunable LED light source: driver, transports, emulator.

- :func:`open_cal1` / :class:`Cal1LightSource` - the driver (a ``LightSource``);
- :mod:`~tunespec.devices.cal1.commands` - the (assumed) command table, one module;
- :mod:`~tunespec.devices.cal1.transport` - the pyserial/socket transport (scripted
  fakes for tests: :mod:`tunespec.devices.testing`);
- :class:`Cal1Emulator` - the protocol served on a local TCP port.

See ``PROTOCOL.md`` in this folder for what is assumed about the protocol.
"""

from tunespec.devices.cal1.driver import Cal1LightSource, open_cal1, parse_cal1_spec
from tunespec.devices.cal1.emulator import Cal1Emulator
from tunespec.devices.cal1.transport import SerialTransport, Transport

__all__ = [
    "Cal1Emulator",
    "Cal1LightSource",
    "SerialTransport",
    "Transport",
    "open_cal1",
    "parse_cal1_spec",
]
