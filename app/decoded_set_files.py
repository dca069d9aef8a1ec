"""The files of one frame set decoded from a dump (`slscan decode`): stripes, depth TIFF, PLY with normals, the
16-bit depth PNG and the preview on request, and the scan_NNNNNN.yaml sidecar (docs/formats.md, "Decoder outputs")."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from app.decode.pipeline import DecodedSet, FrameSetDecoder
from app.export import (
    DEPTH_PNG_SCALE,
    depth_preview,
    stripe_colours,
    write_depth_png16,
    write_depth_tiff,
    write_ply,
    write_png,
)
from app.normals import point_normals
from app.scan_info import CALIBRATION_COPY, dump_scan_info
from core.dump import Dump
from core.scan_sidecar import write_scan_info

__all__ = ["CALIBRATION_COPY", "write_decoded_set"]


def write_decoded_set(
    folder: Path,
    n: int,
    res: DecodedSet,
    dump: Dump,
    indices: Sequence[int],
    decoder: FrameSetDecoder,
    texture_index: int | None,
    png16: bool = False,
    preview: bool = False,
    depth_range_mm: tuple[float, float] | None = None,
    depth_scale: float = DEPTH_PNG_SCALE,
    calibration_source: str | None = None,
) -> None:
    """Set n's files in folder; indices: its frames among dump.frames (pattern order); texture_index: the texture
    frame that coloured it; the calibration's copy (CALIBRATION_COPY) is the caller's, once per folder."""
    files = {"stripes": f"stripes_{n:06d}.png"}
    write_png(folder / files["stripes"], stripe_colours(res.stripes.stripe))
    if res.depth is not None and res.cloud is not None and decoder.triangulator is not None:
        files["depth"], files["cloud"] = f"depth_{n:06d}.tiff", f"cloud_{n:06d}.ply"
        write_depth_tiff(folder / files["depth"], res.depth)
        res.cloud.normals = point_normals(res.depth, decoder.triangulator.ray)
        write_ply(folder / files["cloud"], res.cloud)
        if png16:
            files["depth_png"] = f"depth_{n:06d}.png"
            write_depth_png16(folder / files["depth_png"], res.depth, depth_scale)
        if preview:
            files["preview"] = f"preview_{n:06d}.png"
            write_png(folder / files["preview"], depth_preview(res.depth, depth_range_mm))
    info = dump_scan_info(dump, indices, files, decoder.calibration, calibration_source, depth_scale, texture_index)
    write_scan_info(folder / f"scan_{n:06d}.yaml", info)
