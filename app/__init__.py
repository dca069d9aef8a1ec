"""slscan application layer: patterns, decoding, triangulation, capture, CLI (no device code)."""
