"""Compiled ray casts of the moving virtual rig: a chosen subset of rays against one shape.

Each kernel is the numpy `Shape.intersect` of drivers/sim/shapes.py written per ray, operation for
operation (the same products, sums and their order, the same IEEE special cases), so that a
moving frame matches the full re-precomputation (`tests/drivers/sim/test_motion.py` holds them
equal). Rays share one origin (the camera centre, or the projector's for shadow rays); a kernel
walks the rays `sel` of a direction table, skips those whose 2-D direction coordinate `xy` lies
outside `box` (the shape's bounds as seen from that origin, see `view_box`), and lowers
`t_best[j]` (with `sid_best`, `face_best`; or `t_best[sel[j]]`, `by_ray`) where ray `sel[j]` meets
the shape nearer.

`select` finds the rays whose `xy` falls in a box, through per-tile bounds (`tile_bounds`), so a
small object costs only the rays near it.
"""

from __future__ import annotations

import numba
import numpy as np

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)
from drivers.sim.shapes import (
    EPS_T,
    Box,
    Cylinder,
    Ellipsoid,
    Rectangle,
    Relief,
    Shape,
    Sphere,
    relief_march,
)

NO_BOX = np.array([-np.inf, np.inf, -np.inf, np.inf])
TILE = 8  # pixels per tile side

_jit = numba.njit(cache=True, nogil=True, error_model="numpy")


# ----------------------------------------------------------------------------- culling


@_jit
def tile_bounds(xy: np.ndarray, w: int, h: int, tile: int) -> np.ndarray:
    """Per tile of tile x tile pixels: [x min, x max, y min, y max] of the finite xy (N = w*h, 2)."""
    ty = (h + tile - 1) // tile
    tx = (w + tile - 1) // tile
    out = np.empty((ty, tx, 4))
    for j in range(ty):
        for i in range(tx):
            out[j, i, 0] = np.inf
            out[j, i, 1] = -np.inf
            out[j, i, 2] = np.inf
            out[j, i, 3] = -np.inf
    for y in range(h):
        for x in range(w):
            p = y * w + x
            u = xy[p, 0]
            v = xy[p, 1]
            if not (np.isfinite(u) and np.isfinite(v)):
                continue
            b = out[y // tile, x // tile]
            b[0] = min(b[0], u)
            b[1] = max(b[1], u)
            b[2] = min(b[2], v)
            b[3] = max(b[3], v)
    return out


@_jit
def select(
    bounds: np.ndarray, xy: np.ndarray, w: int, h: int, tile: int, box: np.ndarray, skip: np.ndarray
) -> np.ndarray:
    """Pixel indices (row-major order) whose xy lies in box [x0, x1, y0, y1] (NaN never does), but
    not those flagged in `skip` (one flag per pixel; an empty array skips none)."""
    use_skip = skip.shape[0] > 0
    out = np.empty(w * h, np.int64)
    n = 0
    x0, x1, y0, y1 = box[0], box[1], box[2], box[3]
    for j in range(bounds.shape[0]):
        for i in range(bounds.shape[1]):
            b = bounds[j, i]
            if b[0] > x1 or b[1] < x0 or b[2] > y1 or b[3] < y0:
                continue
            for y in range(j * tile, min((j + 1) * tile, h)):
                for x in range(i * tile, min((i + 1) * tile, w)):
                    p = y * w + x
                    u = xy[p, 0]
                    v = xy[p, 1]
                    if u >= x0 and u <= x1 and v >= y0 and v <= y1 and not (use_skip and skip[p]):
                        out[n] = p
                        n += 1
    return out[:n]


def view_box(shape: Shape, R: np.ndarray, T: np.ndarray, margin: float = 1e-7) -> np.ndarray:
    """[x0, x1, y0, y1]: the normalised image coordinates (x/z, y/z) of the shape's local bounds in
    a view X_view = R X_camera + T, widened by `margin`; NO_BOX when unknown or not all in front."""
    b = shape.local_bounds()
    if b is None:
        return NO_BOX
    lo, hi = b
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    Xc = corners @ shape.R.T + shape.c
    Xv = Xc @ np.asarray(R).T + np.asarray(T)
    if np.any(Xv[:, 2] <= 1e-3 * (1.0 + np.abs(Xv[:, :2]).max())):
        return NO_BOX
    u = Xv[:, 0] / Xv[:, 2]
    v = Xv[:, 1] / Xv[:, 2]
    # a small relative margin covers the rounding of the rays' own coordinates
    m = margin * (1.0 + max(np.abs(u).max(), np.abs(v).max()))
    return np.array([u.min() - m, u.max() + m, v.min() - m, v.max() + m])


def distance_bound(shape: Shape, point: np.ndarray) -> float:
    """A lower bound of the distance from a point to the shape's surface (0 when unknown or inside)."""
    b = shape.local_bounds()
    if b is None:
        return 0.0
    q = (np.asarray(point, np.float64) - shape.c) @ shape.R
    gap = np.maximum(np.maximum(b[0] - q, q - b[1]), 0.0)
    return float(np.sqrt(gap @ gap)) * (1.0 - 1e-9)


def outside(shape: Shape, point: np.ndarray) -> bool:
    """Whether the point lies clearly outside the shape's local bounds."""
    return distance_bound(shape, point) > 1e-3


def union_box(boxes: list[np.ndarray]) -> np.ndarray:
    if not boxes:
        return np.array([np.inf, -np.inf, np.inf, -np.inf])  # selects nothing
    b = np.stack(boxes)
    return np.array([b[:, 0].min(), b[:, 1].max(), b[:, 2].min(), b[:, 3].max()])


# ----------------------------------------------------------------------------- kernels


@_jit
def _inside(xy: np.ndarray, i: int, box: np.ndarray) -> bool:
    u = xy[i, 0]
    v = xy[i, 1]
    return u >= box[0] and u <= box[1] and v >= box[2] and v <= box[3]


@_jit
def _dir(d: np.ndarray, i: int, R: np.ndarray) -> tuple:
    """affine3(d, R) for one ray: (d - 0) @ R + 0, as drivers/sim/kernels.py computes it."""
    x0 = d[i, 0] - 0.0
    x1 = d[i, 1] - 0.0
    x2 = d[i, 2] - 0.0
    return (
        x0 * R[0, 0] + x1 * R[1, 0] + x2 * R[2, 0] + 0.0,
        x0 * R[0, 1] + x1 * R[1, 1] + x2 * R[2, 1] + 0.0,
        x0 * R[0, 2] + x1 * R[1, 2] + x2 * R[2, 2] + 0.0,
    )


@_jit
def _first_positive2(ta: float, tb: float) -> float:
    out = np.inf
    if ta > EPS_T and ta < out:
        out = ta
    if tb > EPS_T and tb < out:
        out = tb
    return out


@_jit
def cast_rectangle(ol, R, ext, d, sel, xy, box, t_best, sid_best, face_best, sid, by_ray):
    x0, x1, y0, y1 = ext[0], ext[1], ext[2], ext[3]
    for j in range(sel.shape[0]):
        i = sel[j]
        if not _inside(xy, i, box):
            continue
        k = i if by_ray else j
        dl0, dl1, dl2 = _dir(d, i, R)
        t = -ol[2] / dl2
        x = ol[0] + t * dl0
        y = ol[1] + t * dl1
        if np.isfinite(t) and t > EPS_T and x >= x0 and x <= x1 and y >= y0 and y <= y1 and t < t_best[k]:
            t_best[k] = t
            sid_best[k] = sid
            face_best[k] = 0


@_jit
def cast_box(ol, R, half, d, sel, xy, box, t_best, sid_best, face_best, sid, by_ray):
    tmin = np.empty(3)
    tmax = np.empty(3)
    dl = np.empty(3)
    for j in range(sel.shape[0]):
        i = sel[j]
        if not _inside(xy, i, box):
            continue
        k = i if by_ray else j
        dl[0], dl[1], dl[2] = _dir(d, i, R)
        nan = False
        for ax in range(3):
            inv = 1.0 / dl[ax]
            t1 = (-half[ax] - ol[ax]) * inv
            t2 = (half[ax] - ol[ax]) * inv
            tmin[ax] = np.fmin(t1, t2)
            tmax[ax] = np.fmax(t1, t2)
            if np.isnan(tmin[ax]) or np.isnan(tmax[ax]):
                nan = True
        if nan:  # np.max / np.min propagate NaN: `t_far >= t_near` fails, a miss
            continue
        axis_near = 0
        t_near = tmin[0]
        axis_far = 0
        t_far = tmax[0]
        for ax in range(1, 3):
            if tmin[ax] > t_near:
                t_near = tmin[ax]
                axis_near = ax
            if tmax[ax] < t_far:
                t_far = tmax[ax]
                axis_far = ax
        if not (t_far >= t_near and t_far > EPS_T):
            continue
        if t_near > EPS_T:
            t = t_near
            axis = axis_near
        else:
            t = t_far
            axis = axis_far
        if t < t_best[k]:
            coord = ol[axis] + t * dl[axis]
            t_best[k] = t
            sid_best[k] = sid
            face_best[k] = 2 * axis + (1 if coord > 0 else 0)


@_jit
def _dot_einsum(a0: float, a1: float, a2: float, b0: float, b1: float, b2: float) -> float:
    """np.einsum("ij,ij->i") of one row of three, in the order numpy sums it here: (0 + 2) + 1."""
    return (a0 * b0 + a2 * b2) + a1 * b1


@_jit
def cast_sphere(oc, cc, d, sel, xy, box, t_best, sid_best, face_best, sid, by_ray):
    for j in range(sel.shape[0]):
        i = sel[j]
        if not _inside(xy, i, box):
            continue
        k = i if by_ray else j
        b = _dot_einsum(oc[0], oc[1], oc[2], d[i, 0], d[i, 1], d[i, 2])
        disc = b * b - cc
        if not disc >= 0:
            continue
        s = np.sqrt(disc)
        t = _first_positive2(-b - s, -b + s)
        if t < t_best[k]:
            t_best[k] = t
            sid_best[k] = sid
            face_best[k] = 0


@_jit
def cast_cylinder(ol, R, r2, height, cc, d, sel, xy, box, t_best, sid_best, face_best, sid, by_ray):
    hh = height / 2
    for j in range(sel.shape[0]):
        i = sel[j]
        if not _inside(xy, i, box):
            continue
        k = i if by_ray else j
        dl0, dl1, dl2 = _dir(d, i, R)
        a = dl0 * dl0 + dl2 * dl2
        b = ol[0] * dl0 + ol[2] * dl2
        disc = b * b - a * cc
        s = np.sqrt(disc)
        ta = (-b - s) / a
        tb = (-b + s) / a
        tc1 = (-hh - ol[1]) / dl1
        tc2 = (hh - ol[1]) / dl1
        out = np.inf
        side_ok = disc >= 0 and a > 1e-15
        y = ol[1] + ta * dl1
        t = ta if side_ok and abs(y) <= hh else -1.0
        if t > EPS_T and t < out:
            out = t
        y = ol[1] + tb * dl1
        t = tb if side_ok and abs(y) <= hh else -1.0
        if t > EPS_T and t < out:
            out = t
        x = ol[0] + tc1 * dl0
        z = ol[2] + tc1 * dl2
        t = tc1 if np.isfinite(tc1) and x * x + z * z <= r2 else -1.0
        if t > EPS_T and t < out:
            out = t
        x = ol[0] + tc2 * dl0
        z = ol[2] + tc2 * dl2
        t = tc2 if np.isfinite(tc2) and x * x + z * z <= r2 else -1.0
        if t > EPS_T and t < out:
            out = t
        if out < t_best[k]:
            y = ol[1] + out * dl1
            t_best[k] = out
            sid_best[k] = sid
            face_best[k] = 1 if abs(abs(y) - hh) < 1e-6 * max(1.0, hh) else 0


@_jit
def cast_ellipsoid(ol, R, axes, d, sel, xy, box, t_best, sid_best, face_best, sid, by_ray):
    ia, ib, ic = 1.0 / axes[0], 1.0 / axes[1], 1.0 / axes[2]
    ox = ol[0] * ia
    oy = ol[1] * ib
    oz = ol[2] * ic
    qc = ox * ox + oy * oy + oz * oz - 1.0
    for j in range(sel.shape[0]):
        i = sel[j]
        if not _inside(xy, i, box):
            continue
        k = i if by_ray else j
        dl0, dl1, dl2 = _dir(d, i, R)
        dx = dl0 * ia
        dy = dl1 * ib
        dz = dl2 * ic
        qa = dx * dx + dy * dy + dz * dz
        qb = ox * dx + oy * dy + oz * dz
        disc = qb * qb - qa * qc
        if not disc >= 0:
            continue
        s = np.sqrt(disc)
        t = _first_positive2((-qb - s) / qa, (-qb + s) / qa)
        if t < t_best[k]:
            t_best[k] = t
            sid_best[k] = sid
            face_best[k] = 0


@_jit
def cast_relief(
    ol, R, a, b, hmax, depth, bumps, grid, gx0, gy0, step, d, sel, xy, box, t_best, sid_best, face_best, sid, by_ray
):
    for j in range(sel.shape[0]):
        i = sel[j]
        if not _inside(xy, i, box):
            continue
        k = i if by_ray else j
        dl0, dl1, dl2 = _dir(d, i, R)
        ta = (-hmax - ol[2]) / dl2
        tb = (0.0 - ol[2]) / dl2
        t0 = np.fmin(ta, tb)
        if not np.isnan(t0):
            t0 = max(t0, EPS_T)
        t1 = np.fmax(ta, tb)
        if not (np.isfinite(t0) and np.isfinite(t1) and t1 > t0):
            continue
        p0x = ol[0] + t0 * dl0
        p1x = ol[0] + t1 * dl0
        p0y = ol[1] + t0 * dl1
        p1y = ol[1] + t1 * dl1
        if min(p0x, p1x) > a or max(p0x, p1x) < -a or min(p0y, p1y) > b or max(p0y, p1y) < -b:
            continue
        # a segment whose xy stays clearly outside the support ellipse meets nothing (the march
        # finds no height there: a grid cell with a corner outside has none, and the ellipse is
        # convex), so skip it: its point nearest the ellipse's centre, in the ellipse's metric
        qa = (dl0 * dl0) / (a * a) + (dl1 * dl1) / (b * b)
        if qa > 0:
            qb = (ol[0] * dl0) / (a * a) + (ol[1] * dl1) / (b * b)
            tm = min(max(-qb / qa, t0), t1)
            xm = ol[0] + tm * dl0
            ym = ol[1] + tm * dl1
            if xm * xm / (a * a) + ym * ym / (b * b) >= 1.0 + 1e-6:
                continue
        t = relief_march(ol[0], ol[1], ol[2], dl0, dl1, dl2, t0, t1, a, b, depth, bumps, grid, gx0, gy0, step)
        if t < t_best[k]:
            t_best[k] = t
            sid_best[k] = sid
            face_best[k] = 0


# ----------------------------------------------------------------------------- dispatch


def cast(
    shape: Shape,
    sid: int,
    origin: np.ndarray,
    d: np.ndarray,
    sel: np.ndarray,
    xy: np.ndarray,
    box: np.ndarray,
    t_best: np.ndarray,
    sid_best: np.ndarray,
    face_best: np.ndarray,
    by_ray: bool = False,
) -> None:
    """Lower t_best[j] (and set sid_best, face_best) where ray sel[j] (origin, direction d[sel[j]])
    meets `shape` nearer; rays whose xy lies outside box are skipped. by_ray: the outputs are
    indexed by ray (t_best[sel[j]]) rather than by position in sel."""
    if sel.size == 0:
        return
    o = np.asarray(origin, np.float64)
    R = np.ascontiguousarray(shape.R, np.float64)
    ol = np.ascontiguousarray((o - shape.c) @ shape.R)  # Shape.to_local, for one origin
    args = (d, sel, xy, box, t_best, sid_best, face_best, sid, by_ray)
    if isinstance(shape, Rectangle):
        cast_rectangle(ol, R, np.asarray(shape.extent, np.float64), *args)
    elif isinstance(shape, Box):
        cast_box(ol, R, np.asarray(shape.half, np.float64), *args)
    elif isinstance(shape, Sphere):
        oc = np.ascontiguousarray(o - shape.c)
        cc = float(np.einsum("ij,ij->i", oc[None], oc[None])[0] - shape.radius**2)
        cast_sphere(oc, cc, *args)
    elif isinstance(shape, Cylinder):
        o1 = ol[None]
        cc = float((o1[:, 0] ** 2 + o1[:, 2] ** 2 - shape.radius**2)[0])
        cast_cylinder(ol, R, float(shape.radius**2), float(shape.height), cc, *args)
    elif isinstance(shape, Ellipsoid):
        cast_ellipsoid(ol, R, np.asarray(shape.semi_axes, np.float64), *args)
    elif isinstance(shape, Relief):
        a, b = shape.semi_axes
        grid, gx0, gy0, step = shape._grid()
        bumps = np.ascontiguousarray(np.asarray(shape.bumps, np.float64).reshape(-1, 5))
        cast_relief(ol, R, a, b, shape._hmax(), shape.depth, bumps, grid, gx0, gy0, step, *args)
    else:  # a shape without a kernel: its own numpy intersect on the rays in the box
        u, v = xy[sel, 0], xy[sel, 1]
        js = np.nonzero((u >= box[0]) & (u <= box[1]) & (v >= box[2]) & (v <= box[3]))[0]
        t, f = shape.intersect(o, d[sel[js]])
        js = sel[js] if by_ray else js
        closer = t < t_best[js]
        t_best[js[closer]] = t[closer]
        sid_best[js[closer]] = sid
        face_best[js[closer]] = f[closer]


def warm_up() -> None:
    """Compile (or load from the cache) every kernel now, on tiny arrays."""
    d = np.array([[0.0, 0.0, 1.0]])
    sel = np.zeros(1, np.int64)
    xy = np.zeros((1, 2))
    t, s, f = np.full(1, np.inf), np.full(1, -1, np.int32), np.zeros(1, np.int8)
    args = (d, sel, xy, NO_BOX, t, s, f, 0, False)
    o, R = np.array([0.0, 0.0, -5.0]), np.eye(3)
    cast_rectangle(o, R, np.array([-1.0, 1.0, -1.0, 1.0]), *args)
    cast_box(o, R, np.ones(3), *args)
    cast_sphere(o, 24.0, *args)
    cast_cylinder(o, R, 1.0, 2.0, 24.0, *args)
    cast_ellipsoid(o, R, np.ones(3), *args)
    grid = np.zeros((4, 4))
    cast_relief(o, R, 1.0, 1.0, 1.0, 1.0, np.zeros((0, 5)), grid, -2.0, -2.0, 1.0, *args)
    tb = tile_bounds(np.zeros((4, 2)), 2, 2, TILE)
    select(tb, np.zeros((4, 2)), 2, 2, TILE, NO_BOX, np.zeros(0, np.bool_))
