"""SIGTERM stops a command the way Ctrl-C does: the same clean stop, the same summary.

Without a handler SIGTERM ends the process at once: a dump stays readable (its writer is crash-safe) but
nobody is told what was recorded. With this one, SIGTERM raises `Terminated` (a KeyboardInterrupt) on the
main thread, so every command's Ctrl-C path runs: devices closed, the recording finalised, the summary
printed; the exit status is 143 (128 + SIGTERM) instead of Ctrl-C's 130.
"""

from __future__ import annotations

import signal
import threading
from types import FrameType

EXIT_STATUS = 128 + signal.SIGTERM


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where Ctrl-C's KeyboardInterrupt would be."""


def _raise_terminated(signum: int, frame: FrameType | None) -> None:
    raise Terminated()


def stop_cleanly_on_sigterm() -> None:
    """Install the handler (main thread only; a SIGTERM the caller chose to ignore stays ignored)."""
    if threading.current_thread() is threading.main_thread() and signal.getsignal(signal.SIGTERM) == signal.SIG_DFL:
        signal.signal(signal.SIGTERM, _raise_terminated)


def exit_status(exc: KeyboardInterrupt) -> int:
    """143 for SIGTERM, 130 for Ctrl-C."""
    return EXIT_STATUS if isinstance(exc, Terminated) else 130


def stopped_by(exc: KeyboardInterrupt) -> str:
    """What the operator is told: "terminated" (SIGTERM) or "interrupted" (Ctrl-C)."""
    return "terminated" if isinstance(exc, Terminated) else "interrupted"
