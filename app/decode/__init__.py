"""Decoders: frame sets -> StripeMap (projector column per camera pixel, NaN = none).

- `twoshot.TwoShotDecoder`: signs of frame2 - frame1 per pattern channel (the paper's section 4).
- `oneshot.OneShotDecoder`: R/G/B colour classification of one frame (section 3).
- `graycode.GrayCodeDecoder` / `graycode.decode_graycode`: multi-shot reference, columns and rows.
- `pipeline.FrameSetDecoder`: any scheme, plus triangulation, from a pattern export's metadata.
The per-pixel and per-row loops are compiled with numba (`fast/`); `reference.py` is the
plain numpy/Python two-shot reference the tests compare them with.
"""
