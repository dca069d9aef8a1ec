"""Errors an operator can cause and fix: the CLI prints them as one line and exits with status 2."""


class SlscanError(Exception):
    """Base of every error that is the user's input, a file, or a device (not a bug).

    The message is one line that names the file, field or device and says what to check. A name taken from the
    input may hold a line break or another control character (a file name in an index, a device's answer): they
    are shown escaped, as Python writes them in a string, so the message stays one line.
    """

    def __str__(self) -> str:
        return "".join(c if c.isprintable() or c == " " else repr(c)[1:-1] for c in super().__str__())


class InputError(SlscanError):
    """A bad argument, file or field."""


class DeviceError(SlscanError):
    """A device that is missing, busy, unsupported or stopped answering."""
