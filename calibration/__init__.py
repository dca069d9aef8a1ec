"""Camera–projector calibration: model and YAML I/O, Gray-code correspondence, solvers, wizard."""
