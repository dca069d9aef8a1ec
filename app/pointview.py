"""The operator view's small 3D point view: a point cloud drawn by a software pinhole, in numpy.

Pure functions (arrays in, an RGB image out), so the view is tested without OpenGL:

- `decimate(depth, rays, image, step)`: every `step`-th pixel each way that has a depth, as
  camera-frame points (mm) with their colours (`rays` = `decimated_rays(Triangulator.ray, step)`,
  computed once per calibration).
- `render_points(xyz, rgb, view)`: the points seen by a virtual camera that orbits a pivot (a point
  on the real camera's optical axis, mid working range): a point X (camera frame) goes to
  X_v = R (X - pivot) + pivot and then through the pinhole `view.camera_matrix`. At yaw = pitch = 0
  the picture is the real camera's (scaled to the render size). Nearer points hide farther ones:
  one sort of a packed (pixel, depth, point) key, the first entry of each pixel wins. Black background.

`PointView.orbit(t_s)` swings the yaw slowly (+-30 degrees, 8 s period) for the window's idle
motion; the window's arrow keys turn the view instead (see app/view.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import cv2
import numpy as np

SWING_DEG = 30.0
SWING_PERIOD_S = 8.0


@dataclass(frozen=True)
class PointView:
    """A virtual camera orbiting `pivot` (camera frame, mm): render size (w, h) and its pinhole."""

    size: tuple[int, int]
    camera_matrix: np.ndarray  # 3x3, for the render size
    pivot: tuple[float, float, float]
    yaw_deg: float = 0.0  # about the vertical (camera y) axis through the pivot
    pitch_deg: float = 0.0  # about the horizontal (camera x) axis through the pivot

    @classmethod
    def for_camera(
        cls,
        camera_matrix: np.ndarray,
        camera_size: tuple[int, int],
        render_size: tuple[int, int],
        pivot_z_mm: float,
    ) -> PointView:
        """The real camera's field of view at `render_size`, orbiting the point pivot_z_mm down its axis."""
        sx, sy = render_size[0] / camera_size[0], render_size[1] / camera_size[1]
        K = np.asarray(camera_matrix, np.float64).copy()
        K[0, :2] *= sx
        K[1, :2] *= sy
        # Pixel centres sit at integer coordinates: scale about the image corner (-0.5, -0.5).
        K[0, 2] = (camera_matrix[0, 2] + 0.5) * sx - 0.5
        K[1, 2] = (camera_matrix[1, 2] + 0.5) * sy - 0.5
        return cls((int(render_size[0]), int(render_size[1])), K, (0.0, 0.0, float(pivot_z_mm)))

    def turned(self, d_yaw: float = 0.0, d_pitch: float = 0.0) -> PointView:
        """Yaw and pitch changed by these many degrees (pitch kept within +-80)."""
        pitch = max(-80.0, min(80.0, self.pitch_deg + d_pitch))
        return replace(self, yaw_deg=(self.yaw_deg + d_yaw + 180.0) % 360.0 - 180.0, pitch_deg=pitch)

    def orbit(self, t_s: float) -> PointView:
        """The idle swing at time t_s: yaw = 30 degrees * sin(2 pi t / 8 s), pitch kept."""
        return replace(self, yaw_deg=SWING_DEG * math.sin(2 * math.pi * t_s / SWING_PERIOD_S))

    def rotation(self) -> np.ndarray:
        """R of X_v = R (X - pivot) + pivot: the yaw (about y), then the pitch (about x)."""
        a, b = math.radians(self.yaw_deg), math.radians(self.pitch_deg)
        ry = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
        rx = np.array([[1, 0, 0], [0, math.cos(b), -math.sin(b)], [0, math.sin(b), math.cos(b)]])
        return rx @ ry

    def extrinsics(self) -> tuple[np.ndarray, np.ndarray]:
        """(R, t) with X_v = R X + t, as cv2.projectPoints takes them (rvec = Rodrigues(R), tvec = t)."""
        R = self.rotation()
        c = np.asarray(self.pivot, np.float64)
        return R, c - R @ c


def decimated_rays(ray: np.ndarray, step: int) -> np.ndarray:
    """Every step-th ray each way as two contiguous planes (x/z, y/z): computed once per calibration."""
    return np.ascontiguousarray(np.moveaxis(ray[::step, ::step], -1, 0))


def decimate(
    depth: np.ndarray, rays: np.ndarray, image: np.ndarray | None = None, step: int = 4
) -> tuple[np.ndarray, np.ndarray | None]:
    """Points (N, 3) float32 mm of every step-th pixel with a depth, and their colours (N, 3) uint8 or None.

    rays: `decimated_rays(Triangulator.ray, step)`, the normalised (x/z, y/z) of those pixels.
    """
    d = depth[::step, ::step]
    m = d > 0
    z = d[m]
    xyz = np.empty((z.size, 3), np.float32)
    np.multiply(rays[0][m], z, out=xyz[:, 0])
    np.multiply(rays[1][m], z, out=xyz[:, 1])
    xyz[:, 2] = z
    if image is None:
        return xyz, None
    img = image[::step, ::step][m]
    return xyz, (img if img.dtype == np.uint8 else (img >> 8).astype(np.uint8))


# The depth panel's colour map (app.export.depth_preview: TURBO, near = red) as a 256-entry table.
_TURBO = np.ascontiguousarray(
    cv2.applyColorMap(np.arange(256, dtype=np.uint8).reshape(1, -1), cv2.COLORMAP_TURBO)[0, :, ::-1]
)


def depth_colours(xyz: np.ndarray, depth_range_mm: tuple[float, float] | None) -> np.ndarray:
    """Each point coloured by its camera depth as the depth panel colours it (one table lookup per point)."""
    if xyz.shape[0] == 0:
        return np.zeros((0, 3), np.uint8)
    z = xyz[:, 2]
    lo, hi = depth_range_mm if depth_range_mm is not None else (float(z.min()), float(z.max()))
    t = (z - np.float32(lo)) * np.float32(255.0 / max(hi - lo, 1e-6))
    np.clip(t, 0, 255, out=t)
    return _TURBO[(255 - t).astype(np.uint8)]


def render_points(xyz: np.ndarray, rgb: np.ndarray, view: PointView, near_mm: float = 1.0) -> np.ndarray:
    """RGB (h, w, 3) uint8: each point on the pixel nearest its projection, the nearest point winning."""
    w, h = view.size
    out = np.zeros((h, w, 3), np.uint8)
    if xyz.shape[0] == 0:
        return out
    R, t = view.extrinsics()
    K = view.camera_matrix
    # One 3x3 product: (K R) X + K t = (u z, v z, z) in the view camera (K's last row is 0 0 1).
    q = np.asarray(xyz, np.float32) @ (K @ R).astype(np.float32).T
    q += (K @ t).astype(np.float32)
    z = q[:, 2]
    ok = z > near_mm
    inv = np.float32(1.0) / np.where(ok, z, np.float32(1.0))
    u = np.rint(q[:, 0] * inv)
    v = np.rint(q[:, 1] * inv)
    ok &= (u >= 0) & (u < w) & (v >= 0) & (v < h)
    idx = np.flatnonzero(ok)
    if idx.size == 0:
        return out
    pix = v[idx].astype(np.int64) * w + u[idx].astype(np.int64)
    zs = z[idx]
    # Packed key (pixel | depth | point), sorted once: the first key of each pixel is its nearest point.
    idx_bits = max(1, int(idx.size - 1).bit_length())
    pix_bits = max(1, int(w * h - 1).bit_length())
    z_bits = min(24, 62 - idx_bits - pix_bits)  # 24 bits: 0.1 um steps over a 1 m deep view
    if z_bits < 8:
        raise ValueError(f"render_points: {idx.size} points on {w}x{h} leave no room for depth in the sort key")
    zlo, zhi = float(zs.min()), float(zs.max())
    # float64: a float32 product could round up to 2**z_bits and carry into the pixel bits
    zq = ((zs.astype(np.float64) - zlo) * ((2**z_bits - 1) / max(zhi - zlo, 1e-6))).astype(np.int64)
    np.clip(zq, 0, 2**z_bits - 1, out=zq)
    key = (pix << (z_bits + idx_bits)) | (zq << idx_bits) | np.arange(idx.size, dtype=np.int64)
    key.sort()
    pixel = key >> (z_bits + idx_bits)
    first = np.empty(key.size, bool)
    first[0] = True
    np.not_equal(pixel[1:], pixel[:-1], out=first[1:])
    winner = idx[key[first] & ((1 << idx_bits) - 1)]
    # Whole pixels as one uint32 each (R, G, B, 0): one scattered write per pixel, not three.
    colours = np.zeros((winner.size, 4), np.uint8)
    colours[:, :3] = rgb[winner]
    packed = np.zeros(w * h, np.uint32)
    packed[pixel[first]] = colours.view(np.uint32)[:, 0]
    out[...] = packed.view(np.uint8).reshape(h, w, 4)[:, :, :3]
    return out
