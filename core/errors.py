"""Errors an operator can cause and fix: the CLI prints them as one line and exits with status 2."""


class SlscanError(Exception):
    """Base of every error that is the user's input, a file, or a device (not a bug).

    The message is one line that names the file, field or device and says what to check.
    """


class InputError(SlscanError):
    """A bad argument, file or field."""


class DeviceError(SlscanError):
    """A device that is missing, busy, unsupported or stopped answering."""
