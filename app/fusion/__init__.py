"""Whole models: registration of the depth stream and its fusion into a TSDF volume (Open3D, `slscan[fusion]`)."""
