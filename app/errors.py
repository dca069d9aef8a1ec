"""The operator's errors, for app code: they live in `core.errors` (drivers raise them too)."""

from core.errors import DeviceError, InputError, SlscanError

__all__ = ["DeviceError", "InputError", "SlscanError"]
