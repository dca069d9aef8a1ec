"""`core.patterns` under its former name (it moved to core/, below drivers, which use it too)."""

from core.patterns import *  # noqa: F403
