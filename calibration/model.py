"""`core.calibration` under its former name (the model moved to core/: the virtual rig's drivers use it)."""

from core.calibration import *  # noqa: F403
