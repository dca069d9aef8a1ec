"""The pattern export format: PNGs plus `patterns.yaml` (see ARCHITECTURE.md, File formats)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import yaml

from app.errors import InputError
from app.imageio import read_rgb, write_rgb
from app.patterns import SCHEMES, PatternSet

FILENAME = "patterns.yaml"


def write_patterns(patterns: PatternSet, folder: str | os.PathLike) -> Path:
    """Write the images and `patterns.yaml` into an existing empty folder."""
    folder = Path(folder)
    for name, img in zip(patterns.names, patterns.images, strict=True):
        write_rgb(folder / name, img)
    meta = {
        "scheme": patterns.scheme,
        "size": list(patterns.size),
        "images": list(patterns.names),
        **patterns.params,
    }
    (folder / FILENAME).write_text(yaml.safe_dump(meta, sort_keys=False, width=120, default_flow_style=None))
    return folder / FILENAME


def read_patterns_meta(folder: str | os.PathLike) -> dict:
    """Read and check `patterns.yaml` (not the images)."""
    path = Path(folder) / FILENAME
    if not path.is_file():
        raise InputError(f"{path}: not found (a pattern export needs patterns.yaml)")
    try:
        meta = yaml.safe_load(path.read_text())
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: not valid YAML ({str(exc).splitlines()[0]})") from None
    if not isinstance(meta, dict):
        raise InputError(f"{path}: expected a mapping at the top level")
    for key in ("scheme", "size", "images"):
        if key not in meta:
            raise InputError(f"{path}: missing field '{key}'")
    if meta["scheme"] not in SCHEMES:
        raise InputError(f"{path}: field 'scheme' is {meta['scheme']!r}, expected one of {', '.join(SCHEMES)}")
    size = meta["size"]
    if not (isinstance(size, list) and len(size) == 2 and all(isinstance(v, int) and v > 0 for v in size)):
        raise InputError(f"{path}: field 'size' must be [W, H] with positive integers")
    images = meta["images"]
    if not (isinstance(images, list) and images and all(isinstance(n, str) for n in images)):
        raise InputError(f"{path}: field 'images' must be a non-empty list of file names")
    for name in images:
        if Path(name).is_absolute() or ".." in Path(name).parts:
            raise InputError(f"{path}: image name {name!r} leaves the pattern folder")
    needed = {
        "one-shot": ("k", "stripe_width", "sequence", "colors"),
        "two-shot": ("k", "stripe_width", "sequence", "channels"),
        "graycode": ("frames",),
    }[meta["scheme"]]
    for key in needed:
        if key not in meta:
            raise InputError(f"{path}: missing field '{key}' for scheme {meta['scheme']}")
    return meta


def read_patterns(folder: str | os.PathLike) -> PatternSet:
    """Read a pattern export back into a PatternSet, checking every image's size."""
    folder = Path(folder)
    meta = read_patterns_meta(folder)
    w, h = meta["size"]
    images: list[np.ndarray] = []
    for name in meta["images"]:
        img = read_rgb(folder / name)
        if img.dtype != np.uint8 or img.shape != (h, w, 3):
            raise InputError(
                f"{folder / name}: expected {w}x{h} 8-bit RGB, found {img.shape[1]}x{img.shape[0]} {img.dtype}"
            )
        images.append(img)
    params = {k: v for k, v in meta.items() if k not in ("scheme", "size", "images")}
    return PatternSet(meta["scheme"], (w, h), images, list(meta["images"]), params)
