"""Triangulation: camera pixel + projector column -> depth, with per-pixel geometry precomputed.

With lens distortion a projector "column" is a curved surface, not a plane, so instead of column
planes we precompute, once per calibration and depth range, for every camera pixel the projector
column u seen at K inverse depths w = 1/Z spread over the working range (its camera ray is
undistorted, each point projected through the projector model with its distortion). Along a ray
u(w) is a smooth monotone function (a Moebius map without distortion, nearly linear in w), so
the per-frame path only finds the node interval and interpolates linearly in w; K is raised
until the interpolation error at the interval midpoints is below `max_error_px`. The same table
gives each pixel's allowed column interval, which picks between repeated copies of a stripe
sequence and masks everything outside the depth range.

The per-frame path is faster still when u(w) is nearly a Moebius map: with t = (w - w_near) /
(w_far - w_near), u = (a + b t) / (1 + c t) per pixel, fitted through the near, middle and far
nodes, inverts in closed form, t = (u - a) / (b - c u): no search, 12 bytes a pixel instead of
4 K. It is exact without projector distortion; it is used when it stays within half of
max_error_px at the nodes and between them (measured 0.0012 px on the virtual rig's distorted
projector, where the node table is 0.0097 px off), else the node table is used.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numba import njit

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)
from app.errors import InputError
from calibration.model import Calibration


@njit(cache=True, nogil=True)
def _depth_from_column(column, nodes, w0, dw, depth):
    H, W, K = nodes.shape
    for y in range(H):
        for x in range(W):
            u = column[y, x]
            depth[y, x] = 0.0
            if not (u == u):  # NaN
                continue
            n0 = nodes[y, x, 0]
            n1 = nodes[y, x, K - 1]
            if not (n0 == n0):
                continue
            inc = n1 > n0
            if (inc and (u < n0 or u > n1)) or ((not inc) and (u > n0 or u < n1)):
                continue  # outside the depth range
            # initial guess assuming linear u(w), then walk to the bracketing interval
            i = int((u - n0) / (n1 - n0) * (K - 1))
            if i < 0:
                i = 0
            if i > K - 2:
                i = K - 2
            if inc:
                while i > 0 and u < nodes[y, x, i]:
                    i -= 1
                while i < K - 2 and u > nodes[y, x, i + 1]:
                    i += 1
            else:
                while i > 0 and u > nodes[y, x, i]:
                    i -= 1
                while i < K - 2 and u < nodes[y, x, i + 1]:
                    i += 1
            a = nodes[y, x, i]
            b = nodes[y, x, i + 1]
            t = (u - a) / (b - a) if b != a else 0.0
            depth[y, x] = 1.0 / (w0 + (i + t) * dw)


@njit(cache=True, nogil=True, error_model="numpy")
def _depth_from_column_moebius(column, ca, cb, cc, w0, w_span, depth):
    """Z = 1 / (w0 + t w_span) with t = (u - a) / (b - c u), as den / (w0 den + n w_span) (one division).

    In float32 and without a branch, over coefficient planes, so the loop is vectorised (five times faster
    than per-pixel branches over float64 (a, b, c) triples). Depths differ from float64 by ~1e-7 relative
    (up to 5e-6 where the depth range spans only a few columns), and a column within float32 rounding of
    the range's far end may fall either side of it. A NaN column or coefficient, a zero denominator (a ray
    without a monotone column) and t outside [0, 1] (outside the depth range) all give 0."""
    w0f = np.float32(w0)
    wsf = np.float32(w_span)
    for y in range(column.shape[0]):
        moebius_depth_row(column, ca, cb, cc, y, w0f, wsf, depth)


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def moebius_depth_row(column, ca, cb, cc, y, w0f, wsf, depth):
    """Row y of _depth_from_column_moebius (w0f, wsf: float32 w0 and w_span), for the two-shot decoder too: it
    triangulates each row as soon as the row's columns are final, while the row is in cache."""
    for x in range(column.shape[1]):
        u = column[y, x]
        n = u - ca[y, x]
        den = cb[y, x] - cc[y, x] * u
        inside = (((n >= 0) & (n <= den)) | ((n <= 0) & (n >= den))) & (den != 0)  # (0 / 0: no t)
        z = den / (w0f * den + n * wsf)
        depth[y, x] = z if inside else np.float32(0.0)


def fit_moebius(nodes: np.ndarray) -> tuple[np.ndarray, float]:
    """Per pixel (a, b, c) of u(t) = (a + b t) / (1 + c t) through the first, middle and last of K nodes
    (t = 0, 1/2, 1), and the largest deviation from the other nodes in px (NaN rays excluded)."""
    K = nodes.shape[2]
    u0 = nodes[:, :, 0].astype(np.float64)
    um = nodes[:, :, (K - 1) // 2].astype(np.float64)
    u1 = nodes[:, :, K - 1].astype(np.float64)
    tm = ((K - 1) // 2) / (K - 1)
    # a = u0; (a + b) = u1 (1 + c); (a + b tm) = um (1 + c tm)  ->  c = (u0 - um + tm (u1 - u0)) / (tm (um - u1))
    with np.errstate(divide="ignore", invalid="ignore"):
        c = (u0 - um + tm * (u1 - u0)) / (tm * (um - u1))
        b = u1 * (1 + c) - u0
        coef = np.stack([u0, b, c], axis=2)
        worst = 0.0
        for i in range(1, K - 1):
            t = i / (K - 1)
            pred = (u0 + b * t) / (1 + c * t)
            dev = np.abs(pred - nodes[:, :, i])
            if np.isfinite(dev).any():
                worst = max(worst, float(np.nanmax(dev)))
    return coef.astype(np.float32), worst


FIELD_MARGIN = 0.25  # share of the projector's field added on each side: the image's edge columns stay inside it


def _projector_field(calibration: Calibration) -> tuple[float, float, float, float]:
    """(x0, x1, y0, y1): a box in the projector's undistorted normalised coordinates around its image, widened by
    FIELD_MARGIN. Every column the projector can show is inside it; far outside it a distortion polynomial folds back
    (u stops being monotone along a ray), and those depths can never be lit anyway."""
    w, h = calibration.projector_size
    t = np.linspace(0.0, 1.0, 33)
    border = np.concatenate(
        [
            np.stack([t * (w - 1), np.zeros_like(t)], 1),
            np.stack([t * (w - 1), np.full_like(t, h - 1)], 1),
            np.stack([np.zeros_like(t), t * (h - 1)], 1),
            np.stack([np.full_like(t, w - 1), t * (h - 1)], 1),
        ]
    ).reshape(-1, 1, 2)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10)
    und = cv2.undistortPoints(
        border, calibration.projector_matrix, calibration.projector_distortion, None, None, None, crit
    ).reshape(-1, 2)
    (x0, y0), (x1, y1) = und.min(axis=0), und.max(axis=0)
    mx, my = FIELD_MARGIN * (x1 - x0), FIELD_MARGIN * (y1 - y0)
    return float(x0 - mx), float(x1 + mx), float(y0 - my), float(y1 + my)


def _extend_outside(nodes: np.ndarray, inside: np.ndarray) -> np.ndarray:
    """The nodes with those outside the projector's field replaced by a linear extension (in the node index, i.e. in
    inverse depth) of the first and last lit intervals: a ray's column stays monotone past the field's edge, where
    the true column may fold back, and moves away from the image, so no decoded column falls there. A ray lit at
    fewer than two nodes (it grazes the field) gets NaN."""
    K = nodes.shape[2]
    out = nodes.copy()
    idx = np.arange(K)
    lit_count = inside.sum(axis=2)
    first = np.argmax(inside, axis=2)
    last = K - 1 - np.argmax(inside[:, :, ::-1], axis=2)
    ok = lit_count >= 2
    f = np.minimum(first, K - 2)
    lmax = np.maximum(last, 1)
    a0 = np.take_along_axis(nodes, f[..., None], 2)[..., 0]
    a1 = np.take_along_axis(nodes, (f + 1)[..., None], 2)[..., 0]
    b0 = np.take_along_axis(nodes, (lmax - 1)[..., None], 2)[..., 0]
    b1 = np.take_along_axis(nodes, lmax[..., None], 2)[..., 0]
    with np.errstate(invalid="ignore"):
        before = a0[..., None] + (idx - f[..., None]) * (a1 - a0)[..., None]
        after = b1[..., None] + (idx - lmax[..., None]) * (b1 - b0)[..., None]
    out = np.where(idx < first[..., None], before, out)
    out = np.where(idx > last[..., None], after, out)
    out[~ok] = np.nan
    return out.astype(np.float32)


@dataclass
class PointCloud:
    xyz: np.ndarray  # (N, 3) float32 mm, camera coordinates
    rgb: np.ndarray  # (N, 3) uint8
    normals: np.ndarray | None = (
        None  # (N, 3) float32 unit normals facing the camera, 0 0 0 = none; None = not computed
    )


class Triangulator:
    """Per-calibration precomputation; `depth(column)` is the per-frame path."""

    def __init__(
        self,
        calibration: Calibration,
        depth_range_mm: tuple[float, float] = (100.0, 5000.0),
        max_error_px: float = 0.01,
        max_nodes: int = 33,
    ) -> None:
        near, far = float(depth_range_mm[0]), float(depth_range_mm[1])
        if not 0 < near < far:
            raise InputError(f"depth range {depth_range_mm} must be [near, far] with 0 < near < far")
        self.calibration = calibration
        self.depth_range_mm = (near, far)
        w, h = calibration.camera_size
        ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
        pts = np.stack([xs.ravel(), ys.ravel()], axis=1).reshape(-1, 1, 2)
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10)
        und = cv2.undistortPoints(pts, calibration.camera_matrix, calibration.camera_distortion, None, None, None, crit)
        self.ray = und.reshape(h, w, 2).astype(np.float32)  # normalised (x/z, y/z) per pixel
        self._field = _projector_field(calibration)
        # The table spans only the depths at which some camera ray meets the projector's field: beyond them nothing
        # is lit, and a range reaching far past them (a near end of 50 mm on the virtual rig) spread the nodes over
        # depths no stripe can come from, losing the interpolation budget there.
        lit = self._lit_range(near, far)
        if lit is None:
            raise InputError(
                f"depth range {near:g}-{far:g} mm: no camera pixel sees the projector's image at these depths "
                "(check depth_range_mm and the calibration)"
            )
        t_near, t_far = lit
        self.table_range_mm = (t_near, t_far)
        self.w0 = 1.0 / t_near
        K = 9
        while True:
            self.dw = (1.0 / t_far - 1.0 / t_near) / (K - 1)
            nodes = np.empty((h, w, K), np.float32)
            inside = np.empty((h, w, K), bool)
            for i in range(K):
                nodes[:, :, i], inside[:, :, i] = self._project_u(self.ray, self.w0 + i * self.dw, with_inside=True)
            err = self._midpoint_error(nodes, inside, K)
            if err <= max_error_px or K >= max_nodes:
                break
            K = 2 * K - 1
        self.interp_error_px = err
        self.nodes = _extend_outside(nodes, inside)
        inc = self.nodes[:, :, -1] > self.nodes[:, :, 0]
        steps = np.diff(self.nodes, axis=2)
        monotone = np.where(inc, (steps > 0).all(axis=2), (steps < 0).all(axis=2))
        self.nodes[~monotone] = np.nan  # rays along which the projector column is not monotone where it is lit
        nodes = self.nodes
        self.column_lo = np.minimum(nodes[:, :, 0], nodes[:, :, -1]).astype(np.float32)
        self.column_hi = np.maximum(nodes[:, :, 0], nodes[:, :, -1]).astype(np.float32)
        coef, dev = fit_moebius(self.nodes)
        # also between the nodes, on the subsample the node table's error is measured on
        sub = coef[::8, ::8].astype(np.float64)
        with np.errstate(invalid="ignore"):
            for i in range(K - 1):
                t = (i + 0.5) / (K - 1)
                true = self._project_u(self.ray[::8, ::8], self.w0 + (i + 0.5) * self.dw)
                pred = (sub[..., 0] + sub[..., 1] * t) / (1 + sub[..., 2] * t)
                d = np.where(inside[::8, ::8, i] & inside[::8, ::8, i + 1], np.abs(pred - true), np.nan)
                if np.isfinite(d).any():
                    dev = max(dev, float(np.nanmax(d)))
        self.moebius_error_px = dev
        # the closed form only well inside the table's error budget, kept as float32 planes a, b, c (what the
        # per-frame pass reads)
        self.moebius = None
        if dev <= 0.5 * max_error_px:
            self.moebius = np.ascontiguousarray(coef.transpose(2, 0, 1), np.float32)

    def _project_u(
        self, ray: np.ndarray, w: float, with_inside: bool = False
    ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Distorted projector column of the points at inverse depth w on the given camera rays; with_inside, also
        whether each point lies in the projector's field (in front of it, undistorted within _projector_field)."""
        cal = self.calibration
        r = ray.astype(np.float64)
        Rm = cal.R
        z = 1.0 / w
        # X_p = R (z * (x, y, 1)) + T
        X = z * (Rm[0, 0] * r[..., 0] + Rm[0, 1] * r[..., 1] + Rm[0, 2]) + cal.T[0]
        Y = z * (Rm[1, 0] * r[..., 0] + Rm[1, 1] * r[..., 1] + Rm[1, 2]) + cal.T[1]
        Z = z * (Rm[2, 0] * r[..., 0] + Rm[2, 1] * r[..., 1] + Rm[2, 2]) + cal.T[2]
        with np.errstate(divide="ignore", invalid="ignore"):
            x = X / Z
            y = Y / Z
        k1, k2, p1, p2, k3 = cal.projector_distortion
        r2 = x * x + y * y
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        K = cal.projector_matrix
        u = K[0, 0] * xd + K[0, 1] * yd + K[0, 2]
        if not with_inside:
            return u
        x0, x1, y0, y1 = self._field
        return u, (Z > 0) & (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)

    def _lit_range(self, near: float, far: float, steps: int = 257) -> tuple[float, float] | None:
        """The part of [near, far] mm in which some camera ray (of a subsample) meets the projector's field, widened
        by one step of a fine grid in inverse depth; None if no ray does."""
        ws = np.linspace(1.0 / far, 1.0 / near, steps)
        sub = self.ray[::4, ::4]
        seen = np.array([self._project_u(sub, w, with_inside=True)[1].any() for w in ws])
        if not seen.any():
            return None
        idx = np.flatnonzero(seen)
        lo, hi = max(idx[0] - 1, 0), min(idx[-1] + 1, steps - 1)  # ws rises: lo is the far end
        return (near if hi == steps - 1 else 1.0 / ws[hi]), (far if lo == 0 else 1.0 / ws[lo])

    def _midpoint_error(self, nodes: np.ndarray, inside: np.ndarray, K: int) -> float:
        """The largest error of linear interpolation at the interval midpoints, over intervals lit at both ends
        (outside the projector's field the nodes are extended, not interpolated: _extend_outside)."""
        sub = self.ray[::8, ::8]
        worst = 0.0
        for i in range(K - 1):
            true = self._project_u(sub, self.w0 + (i + 0.5) * self.dw)
            interp = 0.5 * (nodes[::8, ::8, i] + nodes[::8, ::8, i + 1])
            both = inside[::8, ::8, i] & inside[::8, ::8, i + 1]
            if both.any():
                worst = max(worst, float(np.nanmax(np.abs(true - interp)[both])))
        return worst

    @property
    def column_range(self) -> tuple[np.ndarray, np.ndarray]:
        """Per pixel, the projector columns that fall inside the depth range."""
        return self.column_lo, self.column_hi

    @property
    def moebius_geometry(self) -> tuple[np.ndarray, float, float] | None:
        """(planes (3, H, W), w0, w_span) of the closed form that depth() uses, None where it uses the node table
        (what the two-shot decoder takes to triangulate row by row: TwoShotDecoder.decode_depth)."""
        if self.moebius is None:
            return None
        return self.moebius, self.w0, (self.nodes.shape[2] - 1) * self.dw

    def depth(self, column: np.ndarray) -> np.ndarray:
        """Depth Z in mm (float32, 0 = none) from a projector column map (NaN = none)."""
        h, w = self.ray.shape[:2]
        if column.shape != (h, w):
            raise InputError(f"column map is {column.shape[1]}x{column.shape[0]}, calibration camera is {w}x{h}")
        out = np.empty((h, w), np.float32)
        column = np.ascontiguousarray(column, np.float32)
        geometry = self.moebius_geometry
        if geometry is not None:
            (ca, cb, cc), w0, w_span = geometry
            _depth_from_column_moebius(column, ca, cb, cc, w0, w_span, out)
        else:
            _depth_from_column(column, self.nodes, self.w0, self.dw, out)
        return out

    def points(self, depth: np.ndarray, image: np.ndarray | None = None) -> PointCloud:
        """Camera-frame 3D points (mm) of the pixels with depth, coloured from `image` (RGB)."""
        if image is not None and image.dtype != np.uint8:
            image = (image >> 8).astype(np.uint8)
        depth = np.ascontiguousarray(depth, np.float32)
        n = int(np.count_nonzero(depth > 0))
        xyz = np.empty((n, 3), np.float32)
        rgb = np.empty((n, 3), np.uint8)
        img = np.ascontiguousarray(image) if image is not None else _WHITE
        _gather_points(depth, self.ray, img, image is not None, xyz, rgb)
        return PointCloud(xyz, rgb)


_WHITE = np.full((1, 1, 3), 255, np.uint8)


@njit(cache=True, nogil=True)
def _gather_points(depth, ray, image, coloured, xyz, rgb):
    """One pass in row-major order (the order of boolean-mask indexing) instead of five masked gathers."""
    H, W = depth.shape
    i = 0
    for y in range(H):
        for x in range(W):
            z = depth[y, x]
            if not (z > 0):
                continue
            xyz[i, 0] = ray[y, x, 0] * z
            xyz[i, 1] = ray[y, x, 1] * z
            xyz[i, 2] = z
            for c in range(3):
                rgb[i, c] = image[y, x, c] if coloured else 255
            i += 1
