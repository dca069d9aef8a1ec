"""Typed trigger-box errors: each is a DeviceError, printed by the CLI as one line naming the port."""

from core.errors import DeviceError


class TriggerError(DeviceError):
    """Any trigger-box problem."""


class TriggerPortError(TriggerError):
    """The serial port does not exist, is busy, or cannot be opened."""


class TriggerTimeoutError(TriggerError):
    """The box did not answer (silence) within the timeout."""


class TriggerProtocolError(TriggerError):
    """The box answered, but not in the protocol (garbage, wrong product, inconsistent phase)."""


class TriggerCommandError(TriggerError):
    """The box refused a command (ERR reply); `code` is the protocol error code."""

    def __init__(self, message: str, code: str) -> None:
        super().__init__(message)
        self.code = code


class TriggerResetError(TriggerError):
    """The box reset (power glitch, watchdog, cable): it is stopped and its counter restarted."""


class TriggerDisconnectedError(TriggerError):
    """The port went away while open (unplugged); `reconnect()` reopens it."""
