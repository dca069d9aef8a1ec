"""What every layer shares: the errors an operator can fix, the stable file formats (pattern export,
frame dump v1, calibration YAML, images, YAML reading) and the pattern synthesis they describe.

core imports nothing from drivers/, calibration/ or app/: drivers and the application both build
on it (docs/architecture.md).
"""
