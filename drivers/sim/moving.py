"""The virtual rig's frames with moving objects: a static layer computed once, the moving part per frame.

What the full precomputation (`VirtualRig._precompute`) does for every pixel, this does in two parts:

- Once per scene (and board pose): the static shapes alone, with the same numpy code as a still
  scene: camera hits, reflectance, shading, projector coordinates, shadows among them, the frame
  buffers and ground truth; plus, per lit pixel, its shadow ray toward the projector.
- Per frame: the moving shapes at that frame's pose (drivers/sim/motion.py), against only the
  rays that can meet them (their bounds seen from the camera; drivers/sim/cast.py). Where a
  moving surface is nearer than the static one, it is shaded (normals and texture by the shapes'
  own code, the rest by `_shade_geometry` / `_shade_finish` below, the numpy formulas written per
  pixel) with shadow rays against every shape. Static pixels whose shadow ray can meet a moving
  shape (seen from the projector) are tested against it. The pixels changed in the previous frame
  are restored from the static layer first.

With the rig option render_ahead there are two sets of frame buffers: while the caller uses one
frame, the next is composed into the other set on a background thread (drivers/sim/rig.py).

`static lit and not shadowed by a moving shape` is exactly the full computation's test
(min over all shapes of the shadow-ray hit >= the distance to the projector, less a margin), and
a pixel's nearest hit is the nearest of the static and the moving one, ties to the earlier shape,
as `_cast` orders them; so a frame equals the full computation at that step, to the last bit
where the compiled arithmetic matches numpy's (tests/drivers/sim/test_motion.py).
"""

from __future__ import annotations

import numba
import numpy as np

import core.jit  # noqa: F401  (numba's vector width, before anything compiles)
from drivers.sim import cast
from drivers.sim.shapes import Shape

_jit = numba.njit(cache=True, nogil=True, error_model="numpy")


@_jit
def _dot(a: np.ndarray, i: int, b: np.ndarray, j: int) -> float:
    """np.einsum("ij,ij->i") of rows a[i], b[j], in the order numpy sums three terms: (0 + 2) + 1."""
    return (a[i, 0] * b[j, 0] + a[i, 2] * b[j, 2]) + a[i, 1] * b[j, 1]


@_jit
def _shade_geometry(X, n, rays, pix, Cp, RT, T, K, dist5, lim, wp, hp, dist, lvec, neg_lvec, cos_i, xn, uvp, cand):
    """Per moving hit: normal toward the camera, projector direction, incidence, projector coordinates."""
    k1, k2, p1, p2, k3 = dist5[0], dist5[1], dist5[2], dist5[3], dist5[4]
    for i in range(X.shape[0]):
        p = pix[i]
        if _dot(n, i, rays, p) > 0:
            n[i, 0] *= -1
            n[i, 1] *= -1
            n[i, 2] *= -1
        L0 = Cp[0] - X[i, 0]
        L1 = Cp[1] - X[i, 1]
        L2 = Cp[2] - X[i, 2]
        dd = np.sqrt((L0 * L0 + L1 * L1) + L2 * L2)
        dist[i] = dd
        lvec[i, 0] = L0 / dd
        lvec[i, 1] = L1 / dd
        lvec[i, 2] = L2 / dd
        neg_lvec[i, 0] = -lvec[i, 0]
        neg_lvec[i, 1] = -lvec[i, 1]
        neg_lvec[i, 2] = -lvec[i, 2]
        c = _dot(n, i, lvec, i)
        cos_i[i] = c
        x0 = X[i, 0] - 0.0
        x1 = X[i, 1] - 0.0
        x2 = X[i, 2] - 0.0
        q0 = x0 * RT[0, 0] + x1 * RT[1, 0] + x2 * RT[2, 0] + T[0]
        q1 = x0 * RT[0, 1] + x1 * RT[1, 1] + x2 * RT[2, 1] + T[1]
        q2 = x0 * RT[0, 2] + x1 * RT[1, 2] + x2 * RT[2, 2] + T[2]
        x = q0 / q2
        y = q1 / q2
        xn[i, 0] = x
        xn[i, 1] = y
        in_front = q2 > 1.0 and abs(x) < lim and abs(y) < lim
        u = np.nan
        v = np.nan
        if in_front:  # drivers/sim/optics.py: project, distort_normalized
            r2 = x * x + y * y
            radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
            xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
            yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
            u = K[0, 0] * xd + K[0, 1] * yd + K[0, 2]
            v = K[1, 1] * yd + K[1, 2]
        uvp[i, 0] = u
        uvp[i, 1] = v
        in_image = u >= -0.5 and u < wp - 0.5 and v >= -0.5 and v < hp - 0.5
        cand[i] = in_front and in_image and c > 1e-6


@_jit
def _shade_finish(
    n, rays, pix, rho, ks, shin, lvec, dist, cos_i, uvp, lit, d_ref, shading, specular, exposure, amb3,
    coef_img, amb_img, maps,
):  # fmt: skip
    """Per moving hit: shading, specular lobe, ambient, projector pixel: the frame buffers."""
    for i in range(pix.shape[0]):
        p = pix[i]
        q = d_ref / dist[i]
        falloff = q * q
        g = max(cos_i[i], 0.0) * falloff if shading else 1.0
        c0 = rho[i, 0] * g
        c1 = rho[i, 1] * g
        c2 = rho[i, 2] * g
        if specular and ks[i] > 0 and lit[i]:  # unlit coefficients are zero whatever the lobe
            h0 = lvec[i, 0] - rays[p, 0]
            h1 = lvec[i, 1] - rays[p, 1]
            h2 = lvec[i, 2] - rays[p, 2]
            hn = np.sqrt((h0 * h0 + h1 * h1) + h2 * h2)
            h0 /= hn
            h1 /= hn
            h2 /= hn
            dot = (n[i, 0] * h0 + n[i, 2] * h2) + n[i, 1] * h1
            lobe = ks[i] * max(dot, 0.0) ** shin[i] * falloff
            c0 += lobe
            c1 += lobe
            c2 += lobe
        if not lit[i]:
            c0 = c1 = c2 = 0.0
        coef_img[p, 0] = np.float32(c0 * exposure)
        coef_img[p, 1] = np.float32(c1 * exposure)
        coef_img[p, 2] = np.float32(c2 * exposure)
        amb_img[p, 0] = np.float32(rho[i, 0] * amb3[0] * exposure)
        amb_img[p, 1] = np.float32(rho[i, 1] * amb3[1] * exposure)
        amb_img[p, 2] = np.float32(rho[i, 2] * amb3[2] * exposure)
        if lit[i]:
            maps[p, 0] = np.int16(np.floor(uvp[i, 0] + 0.5))
            maps[p, 1] = np.int16(np.floor(uvp[i, 1] + 0.5))
        else:
            maps[p, 0] = -1
            maps[p, 1] = -1


@_jit
def _collect_nearer(touched, t, sid, face, st_t, st_sid, mark):
    """The pixels (once each) among `touched` whose moving hit (t, sid, face, per pixel) is nearer
    than the static one, ties to the earlier shape; the per-pixel scratch is reset to no hit."""
    n_out = 0
    pix = np.empty(touched.shape[0], np.int64)
    tt = np.empty(touched.shape[0])
    ss = np.empty(touched.shape[0], np.int32)
    ff = np.empty(touched.shape[0], np.int8)
    for p in touched:
        if mark[p]:
            continue
        mark[p] = True
        tp = t[p]
        ts = st_t[p]
        if tp < ts or (tp == ts and sid[p] >= 0 and sid[p] < st_sid[p]):
            pix[n_out] = p
            tt[n_out] = tp
            ss[n_out] = sid[p]
            ff[n_out] = face[p]
            n_out += 1
    for p in touched:
        mark[p] = False
        t[p] = np.inf
        sid[p] = -1
    return pix[:n_out], tt[:n_out], ss[:n_out], ff[:n_out]


@_jit
def _collect_shadowed(touched, tsh, dist, mark):
    """The pixels (once each) among `touched` whose shadow-ray hit tsh (per pixel) is nearer than
    their distance to the projector, less the margin; tsh is reset to no hit."""
    out = np.empty(touched.shape[0], np.int64)
    n = 0
    for p in touched:
        if mark[p]:
            continue
        mark[p] = True
        d = dist[p]
        if tsh[p] < d - (0.01 + 1e-5 * d):
            out[n] = p
            n += 1
    for p in touched:
        mark[p] = False
        tsh[p] = np.inf
    return out[:n]


@_jit
def _flag(pix, flags, value):
    for p in pix:
        flags[p] = value


@_jit
def _group(sid, n_shapes):
    """A stable order of the hits by shape (a counting sort), and each shape's [start, end)."""
    count = np.zeros(n_shapes + 1, np.int64)
    for s in sid:
        count[s + 1] += 1
    for k in range(n_shapes):
        count[k + 1] += count[k]
    start = count[:-1].copy()
    order = np.empty(sid.shape[0], np.int64)
    for j in range(sid.shape[0]):
        order[count[sid[j]]] = j
        count[sid[j]] += 1
    return order, start, count[:-1]


@_jit
def _points(rays, pix, t):
    """The hit points rays[pix] * t (N, 3), as numpy's broadcast product computes them."""
    X = np.empty((pix.shape[0], 3))
    for i in range(pix.shape[0]):
        p = pix[i]
        X[i, 0] = rays[p, 0] * t[i]
        X[i, 1] = rays[p, 1] * t[i]
        X[i, 2] = rays[p, 2] * t[i]
    return X


@_jit
def _unshadowed(sel, tsh, dist, lit):
    """lit[j] for the candidates j in sel: the shadow-ray hit is not nearer than the point (less a margin)."""
    for j in sel:
        d = dist[j]
        lit[j] = tsh[j] >= d - (0.01 + 1e-5 * d)


@_jit
def _restore(pix, coef_img, amb_img, maps, st_coef, st_amb, st_map):
    for j in range(pix.shape[0]):
        p = pix[j]
        for k in range(3):
            coef_img[p, k] = st_coef[p, k]
            amb_img[p, k] = st_amb[p, k]
        maps[p, 0] = st_map[p, 0]
        maps[p, 1] = st_map[p, 1]


@_jit
def _darken(pix, coef_img, maps):
    for j in range(pix.shape[0]):
        p = pix[j]
        coef_img[p, 0] = 0.0
        coef_img[p, 1] = 0.0
        coef_img[p, 2] = 0.0
        maps[p, 0] = -1
        maps[p, 1] = -1


def _cat(parts: list[np.ndarray]) -> np.ndarray:
    return np.concatenate(parts) if parts else np.zeros(0, np.int64)


class StaticLayer:
    """The static shapes' per-pixel products (the full computation over them alone)."""

    def __init__(self, surface: dict, npx: int, w: int, h: int) -> None:
        self.t = surface["t"]  # (npx,) nearest static hit, inf = none
        self.sid = surface["sid"]  # (npx,) its index in the scene's shape list, -1 = none
        self.coef, self.amb, self.map = surface["coef_img"], surface["amb_img"], surface["maps"]
        self.gt = surface["gt"]  # (depth, column, row, lit, points), flat
        lit_idx = surface["lit_idx"]
        self.dist = np.zeros(npx)
        self.neg_lvec = np.zeros((npx, 3))
        self.xn = np.full((npx, 2), np.nan)
        self.dist[lit_idx] = surface["lit_dist"]
        self.neg_lvec[lit_idx] = surface["lit_neg_lvec"]
        self.xn[lit_idx] = surface["lit_xn"]
        self.tiles = cast.tile_bounds(self.xn, w, h, cast.TILE)


class Frame:
    """What one frame changed over the static layer (for its ground truth, made when asked for)."""

    def __init__(self) -> None:
        empty = np.zeros(0, np.int64)
        self.shadowed = empty  # static pixels in a moving shape's projector shadow
        self.pix = empty  # pixels showing a moving surface, and at each:
        self.points = np.zeros((0, 3))  # the surface point (camera mm)
        self.uvp = np.zeros((0, 2))  # its projector coordinates (NaN where not in front)
        self.lit = np.zeros(0, bool)  # whether the projector lights it


class Buffers:
    """One set of frame buffers (what the rig's frame kernels read) and what last changed in it."""

    def __init__(self, npx: int) -> None:
        self.coef = np.zeros((npx, 3), np.float32)
        self.amb = np.zeros((npx, 3), np.float32)
        self.map = np.full((npx, 2), -1, np.int16)
        self.dirty = np.zeros(0, np.int64)  # pixels the frame held here changed over the static layer
        self.frame = Frame()
        self.gt: tuple | None = None  # that frame's ground truth, once asked for

    def reset(self, static: StaticLayer) -> None:
        self.coef[:] = static.coef
        self.amb[:] = static.amb
        self.map[:] = static.map
        self.dirty = np.zeros(0, np.int64)
        self.frame = Frame()
        self.gt = None


class MovingLayer:
    """Per-frame composition for a VirtualRig whose scene has moving shapes (`slots` sets of buffers)."""

    def __init__(self, rig: object, slots: int = 1) -> None:
        self.rig = rig
        w, h = rig.geometry.camera_size
        self.w, self.h, self.npx = w, h, w * h
        rays = rig._rays
        self.cam_xy = np.ascontiguousarray(rays[:, :2] / rays[:, 2:3])
        self.cam_tiles = cast.tile_bounds(self.cam_xy, w, h, cast.TILE)
        self.sets = [Buffers(self.npx) for _ in range(slots)]
        self.static: StaticLayer | None = None
        o = rig.options
        self._amb3 = np.ascontiguousarray(o.ambient * np.asarray(o.ambient_color), np.float64)
        self._RT = np.ascontiguousarray(np.asarray(rig._R, np.float64).T)
        self._T = np.ascontiguousarray(rig._T, np.float64)
        self._Kp = np.ascontiguousarray(rig._Kp, np.float64)
        self._distp = np.ascontiguousarray(np.asarray(rig._distp, np.float64).ravel())
        self._Cp = np.ascontiguousarray(rig._Cp, np.float64)
        self._mark = np.zeros(self.npx, bool)  # per-pixel scratch flags, left cleared
        self._in_frame = np.zeros(self.npx, bool)  # pixels showing a moving surface this frame
        self._t = np.full(self.npx, np.inf)  # per-pixel scratch: nearest moving hit, left at none
        self._sid = np.full(self.npx, -1, np.int32)
        self._face = np.zeros(self.npx, np.int8)
        self._tsh = np.full(self.npx, np.inf)  # per-pixel scratch: shadow-ray hit, left at none
        self._junk_sid = np.zeros(self.npx, np.int32)  # what a shadow ray met: not needed
        self._junk_face = np.zeros(self.npx, np.int8)
        self._static_boxes: dict[int, np.ndarray] = {}  # projector view boxes of the static shapes
        cast.warm_up()

    # ------------------------------------------------------------------ static part
    def build_static(self, shapes: list[Shape]) -> None:
        """The static shapes' layer (once per scene and board pose); the buffers start from it."""
        ids = [i for i, s in enumerate(shapes) if not s.moves]
        surface = self.rig._surface([shapes[i] for i in ids], shadows=True)
        sid = surface["sid"]
        surface["sid"] = np.where(sid >= 0, np.asarray([*ids, -1], np.int32)[sid], -1).astype(np.int32)
        self.static = StaticLayer(surface, self.npx, self.w, self.h)
        self._static_boxes = {i: cast.view_box(shapes[i], self.rig._R, self.rig._T) for i in ids}
        for buf in self.sets:
            buf.reset(self.static)

    # ------------------------------------------------------------------ one frame
    def compose(self, shapes: list[Shape], slot: int = 0) -> None:
        """Bring buffer set `slot` to these shapes (the static ones as at build_static). One at a time."""
        buf = self.sets[slot]
        st = self.static
        rig = self.rig
        moving = [(i, s) for i, s in enumerate(shapes) if s.moves]
        R, T = rig._R, rig._T
        none = np.zeros(0, np.bool_)
        # camera rays that can meet a moving shape, shape by shape (its bounds seen from the camera)
        touched = []
        zero = np.zeros(3)
        for i, s in moving:
            box = cast.view_box(s, np.eye(3), np.zeros(3))
            sel = cast.select(self.cam_tiles, self.cam_xy, self.w, self.h, cast.TILE, box, none)
            cast.cast(s, i, zero, rig._rays, sel, self.cam_xy, box, self._t, self._sid, self._face, by_ray=True)
            touched.append(sel)
        pix, t, sid, face = _collect_nearer(_cat(touched), self._t, self._sid, self._face, st.t, st.sid, self._mark)
        frame = Frame()
        # static pixels (not hidden by a moving surface) in the projector shadow of a moving shape
        _flag(pix, self._in_frame, True)
        touched = []
        junk = (self._junk_sid, self._junk_face)
        for i, s in moving:
            box = cast.view_box(s, R, T)
            sel = cast.select(st.tiles, st.xn, self.w, self.h, cast.TILE, box, self._in_frame)
            cast.cast(s, i, self._Cp, st.neg_lvec, sel, st.xn, box, self._tsh, *junk, by_ray=True)
            touched.append(sel)
        frame.shadowed = _collect_shadowed(_cat(touched), self._tsh, st.dist, self._mark)
        # the buffers: back to the static layer where the last frame changed them and this one will
        # not rewrite them, then this frame
        restore = buf.dirty[~self._in_frame[buf.dirty]]
        _flag(pix, self._in_frame, False)
        _restore(restore, buf.coef, buf.amb, buf.map, st.coef, st.amb, st.map)
        _darken(frame.shadowed, buf.coef, buf.map)
        if len(pix):
            self._shade(shapes, pix, t, sid, face, frame, buf)
        buf.dirty = np.concatenate([frame.shadowed, frame.pix])
        buf.frame = frame
        buf.gt = None

    def _shade(
        self,
        shapes: list[Shape],
        pix: np.ndarray,
        t: np.ndarray,
        sid: np.ndarray,
        face: np.ndarray,
        frame: Frame,
        buf: Buffers,
    ) -> None:
        rig = self.rig
        o = rig.options
        wp, hp = rig.geometry.projector_size
        m = len(pix)
        order, starts, ends = _group(sid, len(shapes))  # one run of pixels per shape: slices, not masks
        pix, t, sid, face = pix[order], t[order], sid[order], face[order]
        runs = [(i, int(a), int(b)) for i, (a, b) in enumerate(zip(starts, ends, strict=True)) if b > a]
        X = _points(rig._rays, pix, t)
        n = np.empty((m, 3))
        rho = np.empty((m, 3))
        ks = np.empty(m)
        shin = np.empty(m)
        for i, a, b in runs:
            s = shapes[i]
            Xs, fs = X[a:b], face[a:b]
            n[a:b] = s.normal(Xs, fs)
            rho[a:b] = rig._albedo(s, pix[a:b], Xs, n[a:b], fs)
            ks[a:b] = s.material.specular
            shin[a:b] = s.material.shininess
        n = np.ascontiguousarray(n, np.float64)
        rho = np.ascontiguousarray(rho, np.float64)
        dist = np.empty(m)
        lvec = np.empty((m, 3))
        neg_lvec = np.empty((m, 3))
        cos_i = np.empty(m)
        xn = np.empty((m, 2))
        uvp = np.empty((m, 2))
        cand = np.empty(m, bool)
        _shade_geometry(
            X,
            n,
            rig._rays,
            pix,
            self._Cp,
            self._RT,
            self._T,
            self._Kp,
            self._distp,
            rig._lim,
            wp,
            hp,
            dist,
            lvec,
            neg_lvec,
            cos_i,
            xn,
            uvp,
            cand,
        )
        # shadow rays toward the projector, against every shape that can be in the way
        own = {i: (a, b) for i, a, b in runs}
        sel = np.nonzero(cand)[0]
        tsh = np.full(m, np.inf)
        junk = (self._junk_sid, self._junk_face)  # (m <= npx)
        reach = float(dist[sel].max()) if len(sel) else 0.0
        for i, s in enumerate(shapes):
            if cast.distance_bound(s, self._Cp) > reach:
                continue  # farther from the projector than every point here
            parts = [sel]
            if i in own and s.convex and cast.outside(s, self._Cp) and cast.outside(s, np.zeros(3)):
                # its own points facing the projector: nothing of it is in the way
                lo, hi = np.searchsorted(sel, own[i])
                parts = [sel[:lo], sel[hi:]]
            box = self._static_boxes[i] if i in self._static_boxes else cast.view_box(s, rig._R, rig._T)
            for rays in parts:
                cast.cast(s, i, self._Cp, neg_lvec, rays, xn, box, tsh, *junk, by_ray=True)
        lit = np.zeros(m, bool)
        _unshadowed(sel, tsh, dist, lit)
        frame.pix, frame.points, frame.uvp, frame.lit = pix, X, uvp, lit
        _shade_finish(
            n, rig._rays, pix, rho, ks, shin, lvec, dist, cos_i, uvp, lit, rig._d_ref, bool(o.shading),
            bool(o.specular), float(o.exposure), self._amb3, buf.coef, buf.amb, buf.map,
        )  # fmt: skip

    # ------------------------------------------------------------------ ground truth
    def ground_truth(self, slot: int = 0) -> tuple[np.ndarray, ...]:
        """(depth, column, row, lit, points), flat, of the frame held in buffer set `slot`."""
        buf = self.sets[slot]
        if buf.gt is None:
            depth, col, row, lit, pts = (a.copy() for a in self.static.gt)
            f = buf.frame
            lit[f.shadowed] = False
            col[f.shadowed] = np.nan
            row[f.shadowed] = np.nan
            # as the full computation stores them: float32 of the float64 values, NaN where not lit
            depth[f.pix] = f.points[:, 2]
            pts[f.pix] = f.points
            col[f.pix] = np.where(f.lit, f.uvp[:, 0], np.nan)
            row[f.pix] = np.where(f.lit, f.uvp[:, 1], np.nan)
            lit[f.pix] = f.lit
            buf.gt = (depth, col, row, lit, pts)
        return buf.gt

    def visible_and_lit(self, slot: int = 0) -> tuple[bool, bool]:
        st = self.static
        f = self.sets[slot].frame
        visible = bool(np.isfinite(st.t).any() or len(f.pix))
        lit = st.gt[3].copy()
        lit[f.shadowed] = False
        lit[f.pix] = f.lit
        return visible, bool(lit.any())
