"""Scene presets: YAML files in config/scenes/ -> shapes, working volume and rig overrides.

A preset file (`config/scenes/NAME.yaml`):

    description: one line for `slscan sim scenes`
    depth_range_mm: [near, far]     # the working volume (stripe copies are told apart with it)
    rig: {...}                      # optional: Geometry fields (drivers/sim/optics.py)
    effects: {...}                  # optional: RigOptions fields (drivers/sim/rig.py)
    objects:                        # camera coordinates, mm; rotation_deg is a rotation vector
      - {type: plane, center: [x, y, z], size: [w, h], color: [r, g, b], rotation_deg: [..]}
      - {type: box, center: .., size: [w, h, d]}       - {type: sphere, center: .., radius: r}
      - {type: cylinder, center: .., radius: r, height: h}
      - {type: ellipsoid, center: .., semi_axes: [a, b, c]}   # closed; a, b, c along local x, y, z
      - {type: relief, center: .., semi_axes: [a, b], depth: d, bumps: [[x, y, sx, sy, amp], ..]}
      - {type: board, board: {type: checkerboard|charuco, rows, cols, square_mm, ..},
         pose: {rvec: [..] (radians, OpenCV), tvec: [..] (mm)}}
    Optional per object: name, specular, shininess, moves, texture: {type: patches|stickers|bands, ..}.
    Objects with `moves: true` follow the rig's motion options (motion_mm_per_frame,
    rotation_deg_per_frame, ...: drivers/sim/motion.py), given like any option under `effects`.

Every error names the file and the field.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, fields
from pathlib import Path

import cv2
import numpy as np
import yaml

from core.errors import InputError
from core.resources import SCENES_DIR
from core.yamlfile import load_yaml_mapping, parse_yaml
from drivers.sim.optics import Geometry
from drivers.sim.shapes import Box, Cylinder, Ellipsoid, Material, Rectangle, Relief, Shape, Sphere
from drivers.sim.textures import Bands, Charuco, Checkerboard, Patches, Stickers, Texture, Uniform


class SceneError(InputError):
    """A preset that does not exist or a scene file with a bad field."""


@dataclass
class Board:
    """The calibration board of a scene and its current pose (board frame -> camera)."""

    spec: dict  # as in board.yaml: type, rows, cols, square_mm (+ marker_mm, dictionary)
    texture: Checkerboard | Charuco
    shape_index: int  # which of Scene.shapes it is
    rvec: np.ndarray
    tvec: np.ndarray

    def object_points(self) -> np.ndarray:
        """Inner corners in the board frame (N, 3), mm, in OpenCV's order for this board type."""
        return self.texture.corners()

    def board_yaml(self) -> dict:
        """The board as board.yaml (docs/formats.md) describes it (only its documented fields)."""
        keys = ("type", "rows", "cols", "square_mm") + (
            ("marker_mm", "dictionary") if self.spec["type"] == "charuco" else ()
        )
        out = {k: self.spec[k] for k in keys if k in self.spec}
        if self.spec["type"] == "charuco":
            out.setdefault("dictionary", self.texture.dictionary)
        return out


@dataclass
class Scene:
    name: str
    description: str
    depth_range_mm: tuple[float, float]
    shapes: list[Shape]
    geometry: dict = field(default_factory=dict)  # Geometry overrides
    effects: dict = field(default_factory=dict)  # RigOptions overrides
    board: Board | None = None
    path: Path | None = None
    # where the moving object can be, camera mm [x0, x1, y0, y1, z0, z1], without the static stand and wall: what
    # `slscan fuse` keeps of each scan (written to a rendered dump as working_volume_mm); None = not given
    working_volume_mm: tuple[float, ...] | None = None


def list_presets(folder: Path = SCENES_DIR) -> list[tuple[str, str]]:
    """(name, description) of every preset, sorted by name."""
    out = []
    for p in sorted(folder.glob("*.yaml")):
        try:
            data = parse_yaml(p.read_text())
            desc = str(data.get("description", "")).strip() if isinstance(data, dict) else ""
        except (yaml.YAMLError, OSError):
            desc = "(unreadable)"
        out.append((p.stem, desc))
    return out


def preset_path(name: str, folder: Path = SCENES_DIR) -> Path:
    p = Path(name)
    if p.suffix in (".yaml", ".yml") and p.is_file():
        return p  # a scene file given by path
    path = folder / f"{name}.yaml"
    if not path.is_file():
        names = ", ".join(n for n, _ in list_presets(folder))
        raise SceneError(f"unknown scene {name!r} (presets: {names}; or a path to a scene .yaml)")
    return path


def load_scene(name_or_path: str | os.PathLike, folder: Path = SCENES_DIR) -> Scene:
    path = preset_path(str(name_or_path), folder)
    return parse_scene(load_yaml_mapping(path, SceneError), path)


def parse_scene(data: dict, path: Path) -> Scene:
    w = _Where(path)
    desc = w.req(data, "description", str)
    rng = w.req(data, "depth_range_mm", list)
    if not (len(rng) == 2 and all(_is_num(v) for v in rng) and 0 < rng[0] < rng[1]):
        raise SceneError(f"{path}: field 'depth_range_mm' must be [near, far] with 0 < near < far")
    geometry = w.opt(data, "rig", dict, {})
    names = {f.name for f in fields(Geometry)}
    for key in geometry:
        if key not in names:
            raise SceneError(f"{path}: field 'rig.{key}' is unknown (known: {', '.join(sorted(names))})")
    effects = w.opt(data, "effects", dict, {})
    volume = w.opt(data, "working_volume_mm", list, None)
    if volume is not None and not (
        len(volume) == 6 and all(_is_num(v) for v in volume) and all(volume[i] < volume[i + 1] for i in (0, 2, 4))
    ):
        raise SceneError(f"{path}: field 'working_volume_mm' must be [x0, x1, y0, y1, z0, z1] mm with x0 < x1, ...")
    objects = w.req(data, "objects", list)
    if not objects:
        raise SceneError(f"{path}: field 'objects' is empty: a scene needs at least one object")
    shapes: list[Shape] = []
    board: Board | None = None
    for i, obj in enumerate(objects):
        ow = w.child(f"objects[{i}]")
        if not isinstance(obj, dict):
            raise SceneError(f"{path}: field 'objects[{i}]' must be a mapping")
        kind = ow.req(obj, "type", str)
        if kind == "board":
            if board is not None:
                raise SceneError(f"{path}: field 'objects[{i}]': only one board per scene")
            shape, board = _board(obj, ow, len(shapes))
        else:
            shape = _shape(kind, obj, ow)
        shapes.append(shape)
    return Scene(
        name=path.stem,
        description=desc,
        depth_range_mm=(float(rng[0]), float(rng[1])),
        shapes=shapes,
        geometry=geometry,
        effects=effects,
        board=board,
        path=path,
        working_volume_mm=None if volume is None else tuple(float(v) for v in volume),
    )


# ----------------------------------------------------------------------------- helpers


def _is_num(v: object) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and np.isfinite(v)


class _Where:
    """Field access that names the file and the field path in every error."""

    def __init__(self, path: Path, prefix: str = "") -> None:
        self.path, self.prefix = path, prefix

    def child(self, name: str) -> _Where:
        return _Where(self.path, f"{self.prefix}{name}.")

    def err(self, key: str, msg: str) -> SceneError:
        return SceneError(f"{self.path}: field '{self.prefix}{key}' {msg}")

    def req(self, d: dict, key: str, typ: type | tuple) -> object:
        if key not in d or d[key] is None:
            raise SceneError(f"{self.path}: missing field '{self.prefix}{key}'")
        return self._typed(d, key, typ)

    def opt(self, d: dict, key: str, typ: type | tuple, default: object) -> object:
        if key not in d or d[key] is None:
            return default
        return self._typed(d, key, typ)

    def _typed(self, d: dict, key: str, typ: type | tuple) -> object:
        v = d[key]
        if typ is float:
            if not _is_num(v):
                raise self.err(key, f"must be a number, found {v!r}")
            return float(v)
        if not isinstance(v, typ) or (isinstance(v, bool) and typ is not bool):
            name = typ.__name__ if isinstance(typ, type) else "/".join(t.__name__ for t in typ)
            raise self.err(key, f"must be a {name}, found {v!r}")
        return v

    def vec(self, d: dict, key: str, n: int, default: object = ..., positive: bool = False) -> np.ndarray:
        if default is not ... and (key not in d or d[key] is None):
            return np.asarray(default, np.float64)
        v = self.req(d, key, list)
        if len(v) != n or not all(_is_num(x) for x in v):
            raise self.err(key, f"must be a list of {n} numbers, found {v!r}")
        arr = np.asarray(v, np.float64)
        if positive and np.any(arr <= 0):
            raise self.err(key, f"must be > 0, found {v!r}")
        return arr

    def pos(self, d: dict, key: str, default: object = ...) -> float:
        v = self.opt(d, key, float, default) if default is not ... else self.req(d, key, float)
        if not v > 0:
            raise self.err(key, f"must be > 0, found {v!r}")
        return float(v)

    def color(self, v: object, key: str) -> list[float]:
        if not (isinstance(v, list) and len(v) == 3 and all(_is_num(x) and 0 <= x <= 1 for x in v)):
            raise self.err(key, f"must be an RGB reflectance [r, g, b] with values 0..1, found {v!r}")
        return [float(x) for x in v]


def _rotation(obj: dict, w: _Where) -> np.ndarray:
    rv = w.vec(obj, "rotation_deg", 3, default=(0.0, 0.0, 0.0))
    R, _ = cv2.Rodrigues(np.deg2rad(rv))
    return R


def _material(obj: dict, w: _Where, default_color: tuple = (0.8, 0.8, 0.8)) -> Material:
    color = w.color(obj.get("color", list(default_color)), "color")
    spec = w.opt(obj, "specular", float, 0.0)
    shin = w.opt(obj, "shininess", float, 30.0)
    if spec < 0 or shin <= 0:
        raise w.err("specular", "must be >= 0 (and shininess > 0)")
    return Material(np.asarray(color), spec, shin)


def _texture(obj: dict, w: _Where, kind: str, size: np.ndarray | None) -> Texture:
    spec = w.opt(obj, "texture", dict, None)
    if spec is None:
        return Uniform()
    tw = w.child("texture")
    ttype = tw.req(spec, "type", str)
    if ttype == "patches":
        colors = tw.req(spec, "colors", list)
        rows = [[tw.color(c, f"colors[{i}][{j}]") for j, c in enumerate(row)] for i, row in enumerate(colors)]
        if not rows or any(not isinstance(r, list) or len(r) != len(rows[0]) or not r for r in rows):
            raise tw.err("colors", "must be rows of equal length of RGB colours")
        if "cell_mm" in spec:
            cell = tuple(tw.vec(spec, "cell_mm", 2, positive=True))
        elif size is not None and kind == "plane":
            cell = (size[0] / len(rows[0]), size[1] / len(rows))
        else:
            raise SceneError(f"{w.path}: missing field '{tw.prefix}cell_mm'")
        origin = (-size[0] / 2, -size[1] / 2) if size is not None and kind == "plane" else (0.0, 0.0)
        gap = tw.opt(spec, "gap_mm", float, 0.0)
        return Patches(rows, cell, gap, tuple(tw.color(spec.get("gap_color", [0.04] * 3), "gap_color")), origin)
    if ttype == "stickers":
        if kind != "box" or size is None or not np.allclose(size, size[0]):
            raise tw.err("type", "'stickers' needs a box with equal sides (a cube)")
        faces = tw.req(spec, "faces", list)
        grid = int(tw.opt(spec, "grid", int, 3))
        if len(faces) != 6:
            raise tw.err("faces", f"must list 6 faces (-x, +x, -y, +y, -z, +z), found {len(faces)}")
        parsed = []
        for f, face in enumerate(faces):
            if isinstance(face, list) and face and isinstance(face[0], list):
                if len(face) != grid * grid:
                    raise tw.err(f"faces[{f}]", f"must be one colour or {grid * grid} colours")
                parsed.append([tw.color(c, f"faces[{f}][{j}]") for j, c in enumerate(face)])
            else:
                parsed.append(tw.color(face, f"faces[{f}]"))
        gap = tw.opt(spec, "gap_mm", float, 2.0)
        gap_color = tuple(tw.color(spec.get("gap_color", [0.04] * 3), "gap_color"))
        return Stickers(parsed, float(size[0]), grid, gap, gap_color)
    if ttype == "bands":
        colors = tw.req(spec, "colors", list)
        pal = [tw.color(c, f"colors[{i}]") for i, c in enumerate(colors)]
        if not pal:
            raise tw.err("colors", "must not be empty")
        return Bands(pal, tw.pos(spec, "band_mm"))
    raise tw.err("type", f"is {ttype!r}; expected patches, stickers or bands")


def _shape(kind: str, obj: dict, w: _Where) -> Shape:
    center = w.vec(obj, "center", 3)
    common = {
        "R": _rotation(obj, w),
        "c": center,
        "material": _material(obj, w),
        "name": str(obj.get("name", kind)),
        "moves": bool(w.opt(obj, "moves", bool, False)),
    }
    if kind == "plane":
        size = w.vec(obj, "size", 2, positive=True)
        tex = _texture(obj, w, kind, size)
        return Rectangle(**common, texture=tex, extent=(-size[0] / 2, size[0] / 2, -size[1] / 2, size[1] / 2))
    if kind == "box":
        size = w.vec(obj, "size", 3, positive=True)
        return Box(**common, texture=_texture(obj, w, kind, size), half=tuple(size / 2))
    if kind == "sphere":
        return Sphere(**common, texture=_texture(obj, w, kind, None), radius=w.pos(obj, "radius"))
    if kind == "cylinder":
        tex = _texture(obj, w, kind, None)
        return Cylinder(**common, texture=tex, radius=w.pos(obj, "radius"), height=w.pos(obj, "height"))
    if kind == "ellipsoid":
        axes3 = w.vec(obj, "semi_axes", 3, positive=True)
        return Ellipsoid(**common, texture=_texture(obj, w, kind, None), semi_axes=tuple(float(x) for x in axes3))
    if kind == "relief":
        axes = w.vec(obj, "semi_axes", 2, positive=True)
        bumps = w.opt(obj, "bumps", list, [])
        parsed = []
        for j, b in enumerate(bumps):
            if not (isinstance(b, list) and len(b) == 5 and all(_is_num(x) for x in b) and b[2] > 0 and b[3] > 0):
                raise w.err(f"bumps[{j}]", "must be [x, y, sigma_x, sigma_y, amplitude] in mm, sigmas > 0")
            parsed.append(tuple(float(x) for x in b))
        return Relief(
            **common,
            texture=_texture(obj, w, kind, None),
            semi_axes=tuple(axes),
            depth=w.pos(obj, "depth"),
            bumps=tuple(parsed),
        )
    raise w.err("type", f"is {kind!r}; expected plane, box, sphere, cylinder, ellipsoid, relief or board")


BOARD_TYPES = ("checkerboard", "charuco")


def make_board_texture(spec: dict, w: _Where) -> Checkerboard | Charuco:
    btype = w.req(spec, "type", str)
    if btype not in BOARD_TYPES:
        raise w.err("type", f"is {btype!r}; expected checkerboard or charuco")
    rows = w.req(spec, "rows", int)
    cols = w.req(spec, "cols", int)
    if not (2 <= rows <= 100 and 2 <= cols <= 100):
        raise w.err("rows", f"and cols must be 2..100, found {rows}x{cols}")
    square = w.pos(spec, "square_mm")
    margin = w.opt(spec, "margin_mm", float, 10.0)
    if btype == "checkerboard":
        return Checkerboard(rows, cols, square, margin)
    marker = w.pos(spec, "marker_mm")
    if marker >= square:
        raise w.err("marker_mm", f"must be smaller than square_mm ({square}), found {marker}")
    dictionary = w.opt(spec, "dictionary", str, "DICT_5X5_100")
    if not hasattr(cv2.aruco, dictionary):
        raise w.err("dictionary", f"is {dictionary!r}, not an OpenCV aruco dictionary (e.g. DICT_5X5_100)")
    return Charuco(rows, cols, square, marker, dictionary, margin)


def _board(obj: dict, w: _Where, index: int) -> tuple[Shape, Board]:
    spec = w.req(obj, "board", dict)
    tex = make_board_texture(spec, w.child("board"))
    pose = w.req(obj, "pose", dict)
    pw = w.child("pose")
    rvec = pw.vec(pose, "rvec", 3)
    tvec = pw.vec(pose, "tvec", 3)
    R, _ = cv2.Rodrigues(rvec)
    shape = Rectangle(
        R=R,
        c=tvec,
        material=_material(obj, w, (1.0, 1.0, 1.0)),
        texture=tex,
        name=str(obj.get("name", "board")),
        antialias=True,
        extent=tex.extent,
    )
    return shape, Board(dict(spec), tex, index, rvec, tvec)
