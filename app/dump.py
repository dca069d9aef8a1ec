"""`core.dump` under its former name (it moved to core/, below drivers, which use it too)."""

from core.dump import *  # noqa: F403
