"""Canon cameras over USB through libgphoto2 (optional extra ``tunespec[gphoto2]``)."""

from tunespec.devices.canon.gphoto2_camera import Gphoto2Camera

__all__ = ["Gphoto2Camera"]
