"""`core.imageio` under its former name (it moved to core/, below drivers, which use it too)."""

from core.imageio import *  # noqa: F403
