"""Analytic ray-cast shapes of the virtual rig, vectorised over many rays.

Each shape has a pose (local -> camera: X = R x + c), a material and a texture. Rays are
given in camera coordinates: origins (3,) or (N, 3), unit directions (N, 3). `intersect` returns
the ray parameter t of the first hit (inf where the ray misses) and an integer `face` per ray
(which face of a box; 0 otherwise). Local conventions: a plane lies in local z = 0 and faces
local -z (the camera, when unrotated); the cylinder's axis is local y (image "down").
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numba
import numpy as np

from drivers.sim.kernels import affine3
from drivers.sim.textures import Texture, Uniform

INF = np.float64(np.inf)
EPS_T = 1e-6  # mm: ignore hits this close to the ray origin (self-intersection on shadow rays)


@dataclass
class Material:
    color: np.ndarray  # diffuse RGB reflectance 0..1 (the texture may override it)
    specular: float = 0.0  # weight of a white Blinn-Phong lobe
    shininess: float = 30.0


@dataclass
class Shape:
    R: np.ndarray  # 3x3 local -> camera
    c: np.ndarray  # (3,) local origin in camera coordinates
    material: Material
    texture: Texture = field(default_factory=lambda: Uniform())
    name: str = ""
    moves: bool = False  # follows the rig's motion (drivers/sim/motion.py)
    antialias: bool = False  # supersample the texture (calibration boards)
    # convex (or flat): a segment from outside to a surface point facing it meets no other point of it
    convex: ClassVar[bool] = False

    # -- frames
    def to_local(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        o = np.asarray(o, np.float64)
        ol = (o - self.c) @ self.R if o.ndim == 1 else affine3(o, self.R, self.c)
        return ol, affine3(d, self.R)

    def point_to_local(self, X: np.ndarray) -> np.ndarray:
        return affine3(X, self.R, self.c)

    def normal_to_camera(self, n_local: np.ndarray) -> np.ndarray:
        if n_local.ndim == 1:
            return self.R @ n_local
        return affine3(n_local, self.R.T)

    # -- interface
    def intersect(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def normal(self, X: np.ndarray, face: np.ndarray) -> np.ndarray:
        """Outward unit normal in camera coordinates (the caller turns it toward the viewer)."""
        raise NotImplementedError

    def uv(self, X: np.ndarray, face: np.ndarray) -> np.ndarray:
        """Texture coordinates in mm (N, 2) of camera-space points on the surface."""
        xl = self.point_to_local(X)
        return xl[:, :2]

    def albedo(self, X: np.ndarray, face: np.ndarray) -> np.ndarray:
        if isinstance(self.texture, Uniform):  # one colour: no texture coordinates to compute
            return np.broadcast_to(np.asarray(self.material.color, np.float64), (len(X), 3)).copy()
        return self.texture.color(self.uv(X, face), face, self.material.color)

    def translated(self, offset: np.ndarray) -> Shape:
        import copy

        s = copy.copy(self)
        s.c = self.c + np.asarray(offset, np.float64)
        return s

    def posed(self, R: np.ndarray, c: np.ndarray) -> Shape:
        """A copy at another pose (local -> camera: X = R x + c); caches of local geometry are shared."""
        import copy

        s = copy.copy(self)
        s.R = np.asarray(R, np.float64)
        s.c = np.asarray(c, np.float64)
        return s

    def local_bounds(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(lo, hi): a box in the local frame holding the whole surface (None: unknown, never culled)."""
        return None


def _first_positive(*ts: np.ndarray) -> np.ndarray:
    out = np.full(ts[0].shape, INF)
    for t in ts:
        ok = (t > EPS_T) & (t < out)
        out = np.where(ok, t, out)
    return out


@dataclass
class Rectangle(Shape):
    """A flat rectangle in local z = 0 covering [x0, x1] x [y0, y1] (mm)."""

    convex: ClassVar[bool] = True
    extent: tuple[float, float, float, float] = (-100.0, 100.0, -100.0, 100.0)

    def intersect(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ol, dl = self.to_local(o, d)
        ol = np.broadcast_to(ol, dl.shape)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -ol[:, 2] / dl[:, 2]
        x = ol[:, 0] + t * dl[:, 0]
        y = ol[:, 1] + t * dl[:, 1]
        x0, x1, y0, y1 = self.extent
        ok = np.isfinite(t) & (t > EPS_T) & (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
        return np.where(ok, t, INF), np.zeros(len(t), np.int8)

    def normal(self, X: np.ndarray, face: np.ndarray) -> np.ndarray:
        return np.broadcast_to(self.normal_to_camera(np.array([0.0, 0.0, -1.0])), X.shape).copy()

    def local_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        x0, x1, y0, y1 = self.extent
        return np.array([x0, y0, 0.0]), np.array([x1, y1, 0.0])


@dataclass
class Box(Shape):
    """An oriented box with half sizes `half` (mm); faces 0..5 = -x, +x, -y, +y, -z, +z."""

    convex: ClassVar[bool] = True
    half: tuple[float, float, float] = (50.0, 50.0, 50.0)

    def intersect(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ol, dl = self.to_local(o, d)
        ol = np.broadcast_to(ol, dl.shape)
        h = np.asarray(self.half)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / dl
            t1 = (-h - ol) * inv
            t2 = (h - ol) * inv
        tmin = np.fmin(t1, t2)
        tmax = np.fmax(t1, t2)
        t_near = np.max(tmin, axis=1)
        t_far = np.min(tmax, axis=1)
        axis_near = np.argmax(tmin, axis=1)
        axis_far = np.argmin(tmax, axis=1)
        hit = (t_far >= t_near) & (t_far > EPS_T)
        outside = t_near > EPS_T
        t = np.where(outside, t_near, t_far)
        axis = np.where(outside, axis_near, axis_far)
        rows = np.arange(len(t))
        # which side: the sign of the local coordinate of the hit on that axis
        coord = ol[rows, axis] + t * dl[rows, axis]
        face = (2 * axis + (coord > 0)).astype(np.int8)
        return np.where(hit, t, INF), face

    def local_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        h = np.asarray(self.half, np.float64)
        return -h, h

    def normal(self, X: np.ndarray, face: np.ndarray) -> np.ndarray:
        n = np.zeros((len(face), 3))
        axis = face // 2
        n[np.arange(len(face)), axis] = np.where(face % 2 == 1, 1.0, -1.0)
        return self.normal_to_camera(n)

    def uv(self, X: np.ndarray, face: np.ndarray) -> np.ndarray:
        """Per face: the two other local axes, origin at the face's corner, in mm."""
        xl = self.point_to_local(X) + np.asarray(self.half)
        axis = face // 2
        u = np.where(axis == 0, xl[:, 2], xl[:, 0])
        v = np.where(axis == 1, xl[:, 2], xl[:, 1])
        return np.stack([u, v], axis=1)


@dataclass
class Sphere(Shape):
    convex: ClassVar[bool] = True
    radius: float = 50.0

    def intersect(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        oc = np.asarray(o, np.float64) - self.c
        oc = np.broadcast_to(oc, d.shape)
        b = np.einsum("ij,ij->i", oc, d)
        cc = np.einsum("ij,ij->i", oc, oc) - self.radius**2
        disc = b * b - cc
        with np.errstate(invalid="ignore"):
            s = np.sqrt(disc)
        t = _first_positive(np.where(disc >= 0, -b - s, -1.0), np.where(disc >= 0, -b + s, -1.0))
        return t, np.zeros(len(t), np.int8)

    def normal(self, X: np.ndarray, face: np.ndarray) -> np.ndarray:
        return (X - self.c) / self.radius

    def local_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        r = np.full(3, float(self.radius))
        return -r, r

    def uv(self, X: np.ndarray, face: np.ndarray) -> np.ndarray:
        xl = self.point_to_local(X)
        return np.stack([np.arctan2(xl[:, 0], -xl[:, 2]) * self.radius, xl[:, 1]], axis=1)


@dataclass
class Cylinder(Shape):
    """A capped cylinder around local y, from y = -height/2 to +height/2."""

    convex: ClassVar[bool] = True
    radius: float = 40.0
    height: float = 120.0

    def intersect(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ol, dl = self.to_local(o, d)
        ol = np.broadcast_to(ol, dl.shape)
        hh = self.height / 2
        a = dl[:, 0] ** 2 + dl[:, 2] ** 2
        b = ol[:, 0] * dl[:, 0] + ol[:, 2] * dl[:, 2]
        cc = ol[:, 0] ** 2 + ol[:, 2] ** 2 - self.radius**2
        disc = b * b - a * cc
        with np.errstate(invalid="ignore", divide="ignore"):
            s = np.sqrt(disc)
            ta = (-b - s) / a
            tb = (-b + s) / a
            tc1 = (-hh - ol[:, 1]) / dl[:, 1]
            tc2 = (hh - ol[:, 1]) / dl[:, 1]
        cands = []
        for t in (ta, tb):
            y = ol[:, 1] + t * dl[:, 1]
            cands.append(np.where((disc >= 0) & (a > 1e-15) & (np.abs(y) <= hh), t, -1.0))
        for t in (tc1, tc2):
            x = ol[:, 0] + t * dl[:, 0]
            z = ol[:, 2] + t * dl[:, 2]
            cands.append(np.where(np.isfinite(t) & (x * x + z * z <= self.radius**2), t, -1.0))
        t = _first_positive(*cands)
        y = ol[:, 1] + t * dl[:, 1]
        face = np.where(np.abs(np.abs(y) - hh) < 1e-6 * max(1.0, hh), 1, 0).astype(np.int8)
        return t, face

    def local_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        r, hh = float(self.radius), self.height / 2
        return np.array([-r, -hh, -r]), np.array([r, hh, r])

    def normal(self, X: np.ndarray, face: np.ndarray) -> np.ndarray:
        xl = self.point_to_local(X)
        side = np.stack([xl[:, 0], np.zeros(len(xl)), xl[:, 2]], axis=1) / self.radius
        cap = np.stack([np.zeros(len(xl)), np.sign(xl[:, 1]), np.zeros(len(xl))], axis=1)
        return self.normal_to_camera(np.where((face == 1)[:, None], cap, side))

    def uv(self, X: np.ndarray, face: np.ndarray) -> np.ndarray:
        xl = self.point_to_local(X)
        return np.stack([np.arctan2(xl[:, 0], -xl[:, 2]) * self.radius, xl[:, 1] + self.height / 2], axis=1)


@dataclass
class Ellipsoid(Shape):
    """A closed ellipsoid with local semi-axes (a, b, c) along x, y (image down), z (mm).

    Texture coordinates: the arc along the equator about local y (longitude times the mean of
    a and c), from 0 at the back (local +z) round to 2 pi (a + c) / 2, the front (local -z)
    half-way; and the height from the bottom (local y + b).
    """

    convex: ClassVar[bool] = True
    semi_axes: tuple[float, float, float] = (50.0, 60.0, 50.0)

    def intersect(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ol, dl = self.to_local(o, d)
        ol = np.broadcast_to(ol, dl.shape)
        ia, ib, ic = (1.0 / float(x) for x in self.semi_axes)  # drivers/sim/cast.py: the same products
        ox, oy, oz = ol[:, 0] * ia, ol[:, 1] * ib, ol[:, 2] * ic
        dx, dy, dz = dl[:, 0] * ia, dl[:, 1] * ib, dl[:, 2] * ic
        qa = dx * dx + dy * dy + dz * dz
        qb = ox * dx + oy * dy + oz * dz
        qc = ox * ox + oy * oy + oz * oz - 1.0
        disc = qb * qb - qa * qc
        with np.errstate(invalid="ignore", divide="ignore"):
            s = np.sqrt(disc)
            t_in = (-qb - s) / qa
            t_out = (-qb + s) / qa
        t = _first_positive(np.where(disc >= 0, t_in, -1.0), np.where(disc >= 0, t_out, -1.0))
        return t, np.zeros(len(t), np.int8)

    def normal(self, X: np.ndarray, face: np.ndarray) -> np.ndarray:
        out = np.empty((len(X), 3))
        _ellipsoid_normals(np.ascontiguousarray(X, np.float64), self.R, self.c, np.asarray(self.semi_axes), out)
        return out

    def uv(self, X: np.ndarray, face: np.ndarray) -> np.ndarray:
        out = np.empty((len(X), 2))
        _ellipsoid_uv(np.ascontiguousarray(X, np.float64), self.R, self.c, np.asarray(self.semi_axes), out)
        return out

    def local_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        h = np.asarray(self.semi_axes, np.float64)
        return -h, h


@dataclass
class Relief(Shape):
    """A smooth bumpy surface z = -h(x, y) (toward the camera) over an elliptical support.

    h is an ellipsoidal cap of height `depth` plus Gaussian bumps [(x, y, sigma_x, sigma_y, amp)],
    all in mm: a "face-like" surface (forehead, brows, nose, cheeks, lips, chin).
    """

    semi_axes: tuple[float, float] = (70.0, 95.0)
    depth: float = 60.0
    bumps: tuple[tuple[float, float, float, float, float], ...] = ()

    def height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        a, b = self.semi_axes
        r2 = (x / a) ** 2 + (y / b) ** 2
        h = self.depth * np.sqrt(np.clip(1.0 - r2, 0.0, None))
        for bx, by, sx, sy, amp in self.bumps:
            h = h + amp * np.exp(-0.5 * (((x - bx) / sx) ** 2 + ((y - by) / sy) ** 2)) * (r2 < 1)
        return h

    def _grid(self) -> tuple[np.ndarray, float, float, float]:
        """The height on a 0.25 mm grid (-1 outside the support), for a fast first march."""
        if getattr(self, "_grid_cache", None) is None:
            a, b = self.semi_axes
            step = 0.25
            xs = np.arange(-a - step, a + 2 * step, step)
            ys = np.arange(-b - step, b + 2 * step, step)
            x, y = np.meshgrid(xs, ys)
            inside = (x / a) ** 2 + (y / b) ** 2 < 1.0
            grid = np.where(inside, self.height(x, y), -1.0)
            self._grid_cache = (np.ascontiguousarray(grid), float(xs[0]), float(ys[0]), step)
        return self._grid_cache

    def _hmax(self) -> float:
        """Highest point of the relief (sampled finely) plus a margin: bounds the march."""
        if getattr(self, "_hmax_cache", None) is None:
            a, b = self.semi_axes
            x, y = np.meshgrid(np.linspace(-a, a, 301), np.linspace(-b, b, 301))
            self._hmax_cache = float(self.height(x, y).max()) + 2.0
        return self._hmax_cache

    def local_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        a, b = self.semi_axes
        return np.array([-a, -b, -self._hmax()]), np.array([a, b, 0.0])

    def intersect(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ol, dl = self.to_local(o, d)
        ol = np.broadcast_to(ol, dl.shape)
        n = len(dl)
        t_out = np.full(n, INF)
        # bracket the slab -hmax <= z <= 0 that contains the surface
        with np.errstate(divide="ignore", invalid="ignore"):
            ta = (-self._hmax() - ol[:, 2]) / dl[:, 2]
            tb = (0.0 - ol[:, 2]) / dl[:, 2]
        t0 = np.clip(np.fmin(ta, tb), EPS_T, None)
        t1 = np.fmax(ta, tb)
        ok = np.isfinite(t0) & np.isfinite(t1) & (t1 > t0)
        # cheap rejection: rays whose slab segment misses the support ellipse's bounding box
        a, b = self.semi_axes
        with np.errstate(invalid="ignore"):
            p0 = ol + np.where(ok, t0, 0)[:, None] * dl
            p1 = ol + np.where(ok, t1, 0)[:, None] * dl
        ok &= ~((np.minimum(p0[:, 0], p1[:, 0]) > a) | (np.maximum(p0[:, 0], p1[:, 0]) < -a))
        ok &= ~((np.minimum(p0[:, 1], p1[:, 1]) > b) | (np.maximum(p0[:, 1], p1[:, 1]) < -b))
        idx = np.nonzero(ok)[0]
        if idx.size:
            bumps = np.asarray(self.bumps, np.float64).reshape(-1, 5)
            grid, x0, y0, step = self._grid()
            t_out[idx] = _relief_hits(
                np.ascontiguousarray(ol[idx]),
                np.ascontiguousarray(dl[idx]),
                t0[idx],
                t1[idx],
                a,
                b,
                self.depth,
                bumps,
                grid,
                x0,
                y0,
                step,
            )
        return t_out, np.zeros(n, np.int8)

    def normal(self, X: np.ndarray, face: np.ndarray) -> np.ndarray:
        xl = self.point_to_local(X)
        bumps = np.asarray(self.bumps, np.float64).reshape(-1, 5)
        a, b = self.semi_axes
        hx, hy = _relief_gradient(
            np.ascontiguousarray(xl[:, 0]), np.ascontiguousarray(xl[:, 1]), a, b, self.depth, bumps
        )
        # surface z = -h: outward (toward the camera) normal is (-(dz/dx), -(dz/dy), 1) flipped to -z
        n = np.stack([-hx, -hy, -np.ones_like(hx)], axis=1)
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        return self.normal_to_camera(n)


@numba.njit(cache=True, nogil=True)
def _ellipsoid_normals(X: np.ndarray, R: np.ndarray, c: np.ndarray, axes: np.ndarray, out: np.ndarray) -> None:
    """Outward unit normals (camera frame) at points X on the ellipsoid (R, c, semi-axes)."""
    a2, b2, c2 = axes[0] * axes[0], axes[1] * axes[1], axes[2] * axes[2]
    for i in range(X.shape[0]):
        p0, p1, p2 = X[i, 0] - c[0], X[i, 1] - c[1], X[i, 2] - c[2]
        # the gradient of the local quadric, then back to the camera frame
        g0 = (p0 * R[0, 0] + p1 * R[1, 0] + p2 * R[2, 0]) / a2
        g1 = (p0 * R[0, 1] + p1 * R[1, 1] + p2 * R[2, 1]) / b2
        g2 = (p0 * R[0, 2] + p1 * R[1, 2] + p2 * R[2, 2]) / c2
        s = 1.0 / np.sqrt(g0 * g0 + g1 * g1 + g2 * g2)
        for k in range(3):
            out[i, k] = (R[k, 0] * g0 + R[k, 1] * g1 + R[k, 2] * g2) * s


_ATAN = (  # atan(z) = z * P(z^2) on |z| <= tan(pi / 8), least squares: error < 2e-11 rad
    0.99999999988799326,
    -0.33333330714193798,
    0.19999823291876273,
    -0.1428045216819375,
    0.11030125646498276,
    -0.084108850160481738,
    0.046312861283977137,
)


@numba.njit(cache=True, nogil=True)
def fast_atan2(y: float, x: float) -> float:
    """np.arctan2(y, x) to 2e-11 rad, several times faster (texture coordinates need no more)."""
    ax, ay = abs(x), abs(y)
    big = max(ax, ay)
    if big == 0.0:
        return 0.0
    a = min(ax, ay) / big
    base = 0.0
    if a > 0.41421356237309503:  # tan(pi / 8): atan(a) = pi / 4 + atan((a - 1) / (a + 1))
        a = (a - 1.0) / (a + 1.0)
        base = 0.78539816339744831
    z2 = a * a
    c = _ATAN
    r = base + a * (c[0] + z2 * (c[1] + z2 * (c[2] + z2 * (c[3] + z2 * (c[4] + z2 * (c[5] + z2 * c[6]))))))
    if ay > ax:
        r = 1.5707963267948966 - r
    if x < 0:
        r = 3.141592653589793 - r
    return np.copysign(r, y)  # the sign of y, as arctan2 (-0.0 included)


@numba.njit(cache=True, nogil=True)
def _ellipsoid_uv(X: np.ndarray, R: np.ndarray, c: np.ndarray, axes: np.ndarray, out: np.ndarray) -> None:
    """Ellipsoid.uv: (longitude about local y from the back, + pi) * (a + c) / 2, and local y + b."""
    half_girth = 0.5 * (axes[0] + axes[2])
    for i in range(X.shape[0]):
        p0, p1, p2 = X[i, 0] - c[0], X[i, 1] - c[1], X[i, 2] - c[2]
        x = p0 * R[0, 0] + p1 * R[1, 0] + p2 * R[2, 0]
        y = p0 * R[0, 1] + p1 * R[1, 1] + p2 * R[2, 1]
        z = p0 * R[0, 2] + p1 * R[1, 2] + p2 * R[2, 2]
        out[i, 0] = (fast_atan2(x, -z) + np.pi) * half_girth
        out[i, 1] = y + axes[1]


@numba.njit(cache=True)
def _relief_exact(x: float, y: float, a: float, b: float, depth: float, bumps: np.ndarray) -> tuple:
    """Height and gradient (h, dh/dx, dh/dy); h = -1 outside the support."""
    r2 = (x / a) ** 2 + (y / b) ** 2
    if r2 >= 1.0:
        return -1.0, 0.0, 0.0
    root = np.sqrt(1.0 - r2)
    h = depth * root
    hx = -depth * x / (a * a * max(root, 1e-9))
    hy = -depth * y / (b * b * max(root, 1e-9))
    for k in range(bumps.shape[0]):
        dx = (x - bumps[k, 0]) / bumps[k, 2]
        dy = (y - bumps[k, 1]) / bumps[k, 3]
        e = bumps[k, 4] * np.exp(-0.5 * (dx * dx + dy * dy))
        h += e
        hx -= e * dx / bumps[k, 2]
        hy -= e * dy / bumps[k, 3]
    return h, hx, hy


@numba.njit(cache=True)
def _grid_height(x: float, y: float, grid: np.ndarray, x0: float, y0: float, step: float) -> float:
    """Bilinear height from the precomputed grid (-1 outside the support)."""
    gx = (x - x0) / step
    gy = (y - y0) / step
    if gx < 0 or gy < 0 or gx >= grid.shape[1] - 1 or gy >= grid.shape[0] - 1:
        return -1.0
    ix = int(gx)
    iy = int(gy)
    fx = gx - ix
    fy = gy - iy
    h00 = grid[iy, ix]
    h01 = grid[iy, ix + 1]
    h10 = grid[iy + 1, ix]
    h11 = grid[iy + 1, ix + 1]
    if h00 < 0 or h01 < 0 or h10 < 0 or h11 < 0:
        return -1.0
    return (h00 * (1 - fx) + h01 * fx) * (1 - fy) + (h10 * (1 - fx) + h11 * fx) * fy


@numba.njit(cache=True)
def _relief_hits(
    o: np.ndarray,
    d: np.ndarray,
    t0: np.ndarray,
    t1: np.ndarray,
    a: float,
    b: float,
    depth: float,
    bumps: np.ndarray,
    grid: np.ndarray,
    x0: float,
    y0: float,
    step: float,
) -> np.ndarray:
    """First crossing of each ray with the relief surface z = -h(x, y) (see `relief_march`)."""
    n = o.shape[0]
    out = np.full(n, np.inf)
    for i in range(n):
        out[i] = relief_march(
            o[i, 0], o[i, 1], o[i, 2], d[i, 0], d[i, 1], d[i, 2], t0[i], t1[i], a, b, depth, bumps, grid, x0, y0, step
        )
    return out


@numba.njit(cache=True, nogil=True)
def relief_march(
    o0: float,
    o1: float,
    o2: float,
    d0: float,
    d1: float,
    d2: float,
    t_start: float,
    t_end: float,
    a: float,
    b: float,
    depth: float,
    bumps: np.ndarray,
    grid: np.ndarray,
    x0: float,
    y0: float,
    step: float,
) -> float:
    """First crossing of one ray (local frame) with the relief surface z = -h(x, y); inf if none.

    March (adaptive steps) on the gridded height to bracket the first crossing, then Newton on the
    exact analytic height (bisection fallback) to ~1e-7 mm. The moving rig's cast
    (drivers/sim/cast.py) calls this same function, so both paths find the same hits.
    """
    t = t_start
    prev_t = t
    prev_f = 1.0
    first = True
    while True:
        x = o0 + t * d0
        y = o1 + t * d1
        h = _grid_height(x, y, grid, x0, y0, step)
        fv = 1.0 if h < 0 else -(o2 + t * d2) - h
        if not first and prev_f > 0 and fv <= 0:
            lo, hi = prev_t, t
            # Newton on the exact surface from the bracket's interpolated root
            tn = hi - fv * (hi - lo) / (fv - prev_f)
            for _ in range(12):
                x = o0 + tn * d0
                y = o1 + tn * d1
                h, hx, hy = _relief_exact(x, y, a, b, depth, bumps)
                if h < 0:
                    break
                f = -(o2 + tn * d2) - h
                df = -d2 - hx * d0 - hy * d1
                if abs(f) < 1e-9:
                    return tn
                if df == 0:
                    break
                tn = tn - f / df
                if tn < lo - 1.0 or tn > hi + 1.0:
                    break
            # fallback: bisection on the exact surface within the bracket
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                x = o0 + mid * d0
                y = o1 + mid * d1
                h, hx, hy = _relief_exact(x, y, a, b, depth, bumps)
                fm = 1.0 if h < 0 else -(o2 + mid * d2) - h
                if fm > 0:
                    lo = mid
                else:
                    hi = mid
                if hi - lo < 1e-7:
                    break
            return 0.5 * (lo + hi)
        if t >= t_end:
            return np.inf
        prev_t, prev_f = t, fv
        first = False
        # adaptive march: half the height gap above the surface, 0.25..4 mm; 1 mm off the support
        t = min(t + (min(max(0.5 * fv, 0.25), 4.0) if h >= 0 else 1.0), t_end)


@numba.njit(cache=True)
def _relief_gradient(
    x: np.ndarray, y: np.ndarray, a: float, b: float, depth: float, bumps: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    hx = np.zeros(x.shape[0])
    hy = np.zeros(x.shape[0])
    for i in range(x.shape[0]):
        _, gx, gy = _relief_exact(x[i], y[i], a, b, depth, bumps)
        hx[i] = gx
        hy[i] = gy
    return hx, hy
