"""Typed camera errors: each message is one line naming the device and what to check."""

from __future__ import annotations

from core.errors import DeviceError
from drivers.base import CameraTimeoutError

__all__ = [
    "CameraStoppedError",
    "CameraTimeoutError",
    "DeviceBusyError",
    "EndOfDumpError",
    "NoDeviceError",
    "NoProducerError",
    "UnsupportedFeatureError",
]


class NoProducerError(DeviceError):
    """No GenTL producer (.cti) found, or a path that is not one."""


class NoDeviceError(DeviceError):
    """No camera matches the selection (serial, model, index, path)."""


class DeviceBusyError(DeviceError):
    """The camera is open elsewhere (this process or another program)."""


class UnsupportedFeatureError(DeviceError):
    """The camera lacks a feature or value the configuration asks for (pixel format, trigger, ...)."""


class CameraStoppedError(DeviceError):
    """grab() on a camera that is not streaming, was stopped meanwhile, or stopped answering."""


class EndOfDumpError(CameraStoppedError):
    """The replay camera has played every frame of its dump (and does not loop)."""
