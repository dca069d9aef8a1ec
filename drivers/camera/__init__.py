"""Cameras: GenICam (harvesters), V4L2 (OpenCV), replay of a frame dump; see README.md here.

`drivers.camera.spec.open_camera(SPEC or config mapping)` builds any of them (and the virtual
rig's `sim` camera) from the `drivers.base.CAMERAS` registry.
"""
