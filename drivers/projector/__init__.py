"""Projectors: the fullscreen pyglet window (`window.py`, registered as "pyglet"), screen listing.

Importing this package registers the driver but does not import pyglet: that happens only when a
window or a display is opened, so slscan runs without a display.
"""

from drivers.projector.screens import NoDisplayError, ScreenNotFoundError, list_screens
from drivers.projector.window import ProjectorSetupError, PygletProjector

__all__ = ["NoDisplayError", "ProjectorSetupError", "PygletProjector", "ScreenNotFoundError", "list_screens"]
