"""The pattern export format: PNGs plus `patterns.yaml` (docs/formats.md)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import yaml

from core.errors import InputError
from core.imageio import read_rgb, write_rgb
from core.patterns import CHANNEL_INDEX, PALETTE, SCHEMES, PatternSet, check_window_keys, window_table
from core.yamlfile import load_yaml_mapping

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
    meta = load_yaml_mapping(path)
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
    _check_stripe_fields(meta, path)
    return meta


SHOTS = {"one-shot": 1, "two-shot": 2}  # images per export of the stripe schemes


def _is_int(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _check_stripe_fields(meta: dict, path: Path) -> None:
    """Types and values of the fields a decoder relies on: a bad export is refused here, not mid-decode."""
    scheme = meta["scheme"]
    if scheme == "graycode":
        frames = meta["frames"]
        if not (isinstance(frames, list) and len(frames) == len(meta["images"])):
            raise InputError(f"{path}: field 'frames' must list one role per image")
        for i, role in enumerate(frames):
            if not (isinstance(role, dict) and role.get("kind") in ("white", "black", "column", "row")):
                raise InputError(f"{path}: frames[{i}] must have kind white, black, column or row")
            if role["kind"] in ("column", "row") and not (
                _is_int(role.get("bit")) and 0 <= role["bit"] < 16 and isinstance(role.get("inverse"), bool)
            ):
                raise InputError(f"{path}: frames[{i}] needs bit (0..15) and inverse (true/false)")
        return
    k, width, seq = meta["k"], meta["stripe_width"], meta["sequence"]
    if not (_is_int(k) and 1 <= k <= 32):
        raise InputError(f"{path}: field 'k' must be a whole number from 1 to 32")
    if not (_is_int(width) and width >= 1):
        raise InputError(f"{path}: field 'stripe_width' must be a whole number >= 1")
    if scheme == "two-shot":
        channels = meta["channels"]
        if not (
            isinstance(channels, str)
            and channels
            and set(channels) <= set(CHANNEL_INDEX)
            and len(set(channels)) == len(channels)
        ):
            raise InputError(f"{path}: field 'channels' must be distinct letters from RGB (e.g. GB)")
        n_codes = 2 ** len(channels)
    else:
        colors = meta["colors"]
        if not (
            isinstance(colors, str)
            and len(colors) >= 2
            and set(colors) <= set(PALETTE)
            and len(set(colors)) == len(colors)
        ):
            raise InputError(f"{path}: field 'colors' must be 2 or more distinct letters from {''.join(PALETTE)}")
        n_codes = len(colors)
    check_window_keys(n_codes, k, f"{path}: field 'k'")
    if not (isinstance(seq, list) and len(seq) >= k and all(_is_int(c) and 0 <= c < n_codes for c in seq)):
        raise InputError(f"{path}: field 'sequence' must be a list of at least k codes from 0 to {n_codes - 1}")
    try:
        window_table(seq, k)
    except ValueError:
        raise InputError(f"{path}: field 'sequence' repeats a window of k={k} stripes: it cannot be decoded") from None
    if "period" in meta and meta["period"] != len(seq):
        raise InputError(
            f"{path}: field 'period' is {meta['period']!r} but the sequence has {len(seq)} stripes (the period is the "
            "sequence's length)"
        )
    shots = SHOTS[scheme]
    if len(meta["images"]) != shots:
        raise InputError(f"{path}: field 'images' lists {len(meta['images'])} image(s); a {scheme} export has {shots}")
    if k * width > meta["size"][0]:
        raise InputError(
            f"{path}: field 'stripe_width' {width} is too wide: one window of k={k} stripes needs {k * width} "
            f"projector columns, the patterns have {meta['size'][0]}"
        )


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
