"""Zaber motorised stages over Zaber's ASCII protocol: driver and emulator."""

from tunespec.devices.zaber.driver import ZaberAxis, ZaberGoniometer, open_zaber

__all__ = ["ZaberAxis", "ZaberGoniometer", "open_zaber"]
