"""The fast (numba-compiled) stripe decoders, in the paper's order.

bundles      the named tuples the stages take
differences  two-shot frame differences and the tables they read (pack_tables, pair_tables)
classify     per-pixel codes (twoshot_classify, oneshot_classify, classify_row)
lacking      a raw mosaic's lacking channel: its signs from the G edges
runs         runs of a row and the links between them (pixel_runs, event_runs)
lookup       window lookup and confirmed labels
chains       chains, their nodes and the copy vote
lacking_edges  a raw mosaic's lacking channel: its edges from the G edges
columns      the column write (and the vertical votes counted with it)
check        the vertical check and the merge of two maps (vertical_check)
rows         the row loop (label_rows, twoshot_rows)
texture      the two-shot pair's texture (average_frames)

`app/decode/reference.py` implements the same steps in plain numpy; the tests compare both. The gather, append
and fill primitives are in `app/decode/primitives.py`, the vector intrinsics they emit in `app/decode/simd.py`.
Why the code is written as it is (vector loops, gathers, no reference counting, inlining): docs/performance.md.
"""

from app.decode.fast.bundles import Classifier, FrameTables, Geometry, LabelSettings, StripeCode
from app.decode.fast.check import vertical_check
from app.decode.fast.classify import oneshot_classify, twoshot_classify
from app.decode.fast.differences import pack_tables, pair_tables
from app.decode.fast.rows import MODES, label_rows, twoshot_rows
from app.decode.fast.texture import average_frames

__all__ = [
    "MODES",
    "Classifier",
    "FrameTables",
    "Geometry",
    "LabelSettings",
    "StripeCode",
    "average_frames",
    "label_rows",
    "oneshot_classify",
    "pack_tables",
    "pair_tables",
    "twoshot_classify",
    "twoshot_rows",
    "vertical_check",
]
