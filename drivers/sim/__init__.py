"""The virtual rig: a simulated projector, camera and trigger over a ray-cast scene, with ground truth.

Start at `drivers.sim.rig.VirtualRig` (rendering) and `drivers.sim.devices` (the Camera /
Projector / Trigger drivers registered as "sim"). Scene presets live in config/scenes/.
"""
