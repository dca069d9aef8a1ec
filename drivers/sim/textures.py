"""Surface reflectance patterns: RGB albedo (0..1) as a function of texture coordinates in mm.

`color(uv, face, base)` gets (N, 2) texture coordinates (see each shape's `uv`), the face index
per point (boxes) and the material's base colour; it returns (N, 3) float64 albedo.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import cv2
import numba
import numpy as np

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)

BLACK_INK = (0.04, 0.04, 0.04)  # printed black: a few percent, never zero
WHITE_PAPER = (0.85, 0.85, 0.85)


class Texture:
    def color(self, uv: np.ndarray, face: np.ndarray, base: np.ndarray) -> np.ndarray:
        raise NotImplementedError


@dataclass
class Uniform(Texture):
    def color(self, uv: np.ndarray, face: np.ndarray, base: np.ndarray) -> np.ndarray:
        return np.broadcast_to(np.asarray(base, np.float64), (len(uv), 3)).copy()


@dataclass
class Patches(Texture):
    """A grid of colour patches (rows of RGB lists) with gaps, origin at its top-left corner."""

    colors: list[list[list[float]]]
    cell_mm: tuple[float, float]
    gap_mm: float = 0.0
    gap_color: tuple[float, float, float] = BLACK_INK
    origin: tuple[float, float] = (0.0, 0.0)

    def color(self, uv: np.ndarray, face: np.ndarray, base: np.ndarray) -> np.ndarray:
        pal = np.ascontiguousarray(self.colors, np.float64)  # (rows, cols, 3)
        out = np.empty((len(uv), 3))
        uv = np.ascontiguousarray(uv, np.float64)
        base = np.ascontiguousarray(np.broadcast_to(np.asarray(base, np.float64), 3))
        cw, ch = self.cell_mm
        gap_color = np.asarray(self.gap_color, np.float64)
        _patches(uv, pal, float(cw), float(ch), *map(float, self.origin), float(self.gap_mm), gap_color, base, out)
        return out


@numba.njit(cache=True, nogil=True)
def _patches(uv, pal, cw, ch, ox, oy, gap_mm, gap_color, base, out):
    """Patches.color per point: the cell's colour, the gap colour within gap_mm / 2 of a cell edge."""
    rows, cols = pal.shape[0], pal.shape[1]
    g = gap_mm / 2
    for k in range(uv.shape[0]):
        x = uv[k, 0] - ox
        y = uv[k, 1] - oy
        i = np.int64(np.floor(y / ch))
        j = np.int64(np.floor(x / cw))
        if not (i >= 0 and i < rows and j >= 0 and j < cols):
            out[k, 0], out[k, 1], out[k, 2] = base[0], base[1], base[2]
            continue
        if gap_mm > 0:
            fx = x - j * cw
            fy = y - i * ch
            if fx < g or fx > cw - g or fy < g or fy > ch - g:
                out[k, 0], out[k, 1], out[k, 2] = gap_color[0], gap_color[1], gap_color[2]
                continue
        out[k, 0], out[k, 1], out[k, 2] = pal[i, j, 0], pal[i, j, 1], pal[i, j, 2]


@dataclass
class Stickers(Texture):
    """A cube's faces: each face a grid x grid of stickers with black gaps (Rubik's cube, Fig. 11).

    `faces` gives, per face 0..5 (-x, +x, -y, +y, -z, +z), one colour or grid*grid colours.
    """

    faces: list[list]
    edge_mm: float
    grid: int = 3
    gap_mm: float = 2.0
    gap_color: tuple[float, float, float] = BLACK_INK

    @cached_property
    def _palette(self) -> np.ndarray:
        pal = np.zeros((6, self.grid * self.grid, 3))
        for f, spec in enumerate(self.faces):
            arr = np.asarray(spec, np.float64)
            pal[f] = arr if arr.ndim == 2 else arr[None, :]
        return pal

    def color(self, uv: np.ndarray, face: np.ndarray, base: np.ndarray) -> np.ndarray:
        out = np.empty((len(uv), 3))
        uv = np.ascontiguousarray(uv, np.float64)
        face = np.ascontiguousarray(face)
        gap_color = np.asarray(self.gap_color, np.float64)
        _stickers(uv, face, self._palette, self.edge_mm / self.grid, self.grid, float(self.gap_mm), gap_color, out)
        return out


@numba.njit(cache=True, nogil=True)
def _stickers(uv, face, pal, cell, grid, gap_mm, gap_color, out):
    """Stickers.color per point: the face's sticker, the gap colour within gap_mm / 2 of its edge."""
    g = gap_mm / 2
    for k in range(uv.shape[0]):
        j = np.int64(min(max(np.floor(uv[k, 0] / cell), 0.0), grid - 1.0))
        i = np.int64(min(max(np.floor(uv[k, 1] / cell), 0.0), grid - 1.0))
        fx = uv[k, 0] - j * cell
        fy = uv[k, 1] - i * cell
        if fx < g or fx > cell - g or fy < g or fy > cell - g:
            out[k, 0], out[k, 1], out[k, 2] = gap_color[0], gap_color[1], gap_color[2]
        else:
            f, q = np.int64(face[k]), i * grid + j
            out[k, 0], out[k, 1], out[k, 2] = pal[f, q, 0], pal[f, q, 1], pal[f, q, 2]


@dataclass
class Bands(Texture):
    """Colour bands along the second texture coordinate (a cylinder's height), from v = 0."""

    colors: list[list[float]]
    band_mm: float

    def color(self, uv: np.ndarray, face: np.ndarray, base: np.ndarray) -> np.ndarray:
        pal = np.asarray(self.colors, np.float64)
        k = np.floor(uv[:, 1] / self.band_mm).astype(np.int64)
        inside = (k >= 0) & (k < len(pal))
        out = np.broadcast_to(np.asarray(base, np.float64), (len(uv), 3)).copy()
        out[inside] = pal[k[inside]]
        return out


@dataclass
class Checkerboard(Texture):
    """A printed checkerboard with rows x cols inner corners, OpenCV's object-point frame.

    Origin at the first (top-left) inner corner, x along cols, y along rows, mm; the square
    just above-left of the origin is black. A white margin of `margin_mm` surrounds the squares.
    """

    rows: int
    cols: int
    square_mm: float
    margin_mm: float = 10.0
    black: tuple[float, float, float] = BLACK_INK
    white: tuple[float, float, float] = WHITE_PAPER

    @property
    def extent(self) -> tuple[float, float, float, float]:
        s, m = self.square_mm, self.margin_mm
        return (-s - m, self.cols * s + m, -s - m, self.rows * s + m)

    def corners(self) -> np.ndarray:
        """Inner corners (rows*cols, 3) in the board frame, row by row (findChessboardCorners' order)."""
        j, i = np.meshgrid(np.arange(self.cols), np.arange(self.rows))
        return np.stack([j.ravel() * self.square_mm, i.ravel() * self.square_mm, np.zeros(j.size)], axis=1)

    def color(self, uv: np.ndarray, face: np.ndarray, base: np.ndarray) -> np.ndarray:
        s = self.square_mm
        cx = np.floor(uv[:, 0] / s).astype(np.int64)
        cy = np.floor(uv[:, 1] / s).astype(np.int64)
        squares = (cx >= -1) & (cx <= self.cols - 1) & (cy >= -1) & (cy <= self.rows - 1)
        black = squares & ((cx + cy) % 2 == 0)
        return np.where(black[:, None], np.asarray(self.black), np.asarray(self.white))


@dataclass
class Charuco(Texture):
    """An OpenCV ChArUco board (rows x cols squares), origin at its outer top-left corner, mm."""

    rows: int
    cols: int
    square_mm: float
    marker_mm: float
    dictionary: str = "DICT_5X5_100"
    margin_mm: float = 10.0
    px_per_mm: float = 20.0
    black: tuple[float, float, float] = BLACK_INK
    white: tuple[float, float, float] = WHITE_PAPER
    _image: np.ndarray | None = field(default=None, repr=False)

    @property
    def extent(self) -> tuple[float, float, float, float]:
        m = self.margin_mm
        return (-m, self.cols * self.square_mm + m, -m, self.rows * self.square_mm + m)

    def board(self) -> cv2.aruco.CharucoBoard:
        d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        return cv2.aruco.CharucoBoard((self.cols, self.rows), self.square_mm, self.marker_mm, d)

    def corners(self) -> np.ndarray:
        """ChArUco inner corners (ids 0..) in the board frame, as OpenCV defines them."""
        return np.asarray(self.board().getChessboardCorners(), np.float64).reshape(-1, 3)

    def image(self) -> np.ndarray:
        if self._image is None:
            w = round(self.cols * self.square_mm * self.px_per_mm)
            h = round(self.rows * self.square_mm * self.px_per_mm)
            self._image = self.board().generateImage((w, h), marginSize=0, borderBits=1)
        return self._image

    def color(self, uv: np.ndarray, face: np.ndarray, base: np.ndarray) -> np.ndarray:
        img = self.image()
        h, w = img.shape
        px = np.floor(uv[:, 0] * self.px_per_mm).astype(np.int64)
        py = np.floor(uv[:, 1] * self.px_per_mm).astype(np.int64)
        inside = (px >= 0) & (px < w) & (py >= 0) & (py < h)
        ink = np.zeros(len(uv), bool)
        ink[inside] = img[py[inside], px[inside]] < 128
        return np.where(ink[:, None], np.asarray(self.black), np.asarray(self.white))
