"""One scan ready for fusion: depth and colour on the undistorted pinhole grid, cut to the working volume.

Open3D's TSDF integration and the registration's back-projection assume a pinhole camera; the decoder's depth is on
the camera's distorted pixel grid. `ScanMaker` resamples it once per scan through cv2.remap tables made once per
calibration: bilinear where the four source pixels have depth and agree within `max_step_mm` (so no mixed pixel
bridges a depth edge), none elsewhere. Depth Z is unchanged by the resampling; only where it is looked up moves.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from core.calibration import Calibration


@dataclass
class Scan:
    depth: np.ndarray  # (H, W) float32 Z mm on the pinhole grid, 0 = none
    colour: np.ndarray  # (H, W, 3) uint8 RGB on the same grid
    frame_id: int  # the newest frame's id: the geometry is that frame's
    # what registration reads: the depth without the pixels near a silhouette or depth edge (None: depth itself)
    track_depth: np.ndarray | None = None


class ScanMaker:
    def __init__(
        self,
        calibration: Calibration,
        volume_mm: tuple[float, ...] | None = None,
        max_step_mm: float = 2.0,
        edge_px: int = 3,
        smooth_px: float = 2.0,
    ) -> None:
        w, h = calibration.camera_size
        self.size = (w, h)
        self.K = calibration.camera_matrix.copy()
        self.K[0, 1] = 0.0  # the pinhole grid has no skew (Open3D's intrinsics cannot hold one)
        self._mx, self._my = cv2.initUndistortRectifyMap(
            calibration.camera_matrix, calibration.camera_distortion, None, self.K, (w, h), cv2.CV_32FC1
        )
        # integer maps to the top-left tap of each bilinear read (exact under nearest lookup)
        self._fx, self._fy = np.floor(self._mx), np.floor(self._my)
        ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
        self.ray_x = (xs - self.K[0, 2]) / self.K[0, 0]  # X / Z per pinhole pixel
        self.ray_y = (ys - self.K[1, 2]) / self.K[1, 1]
        self.volume = None if volume_mm is None else np.asarray(volume_mm, np.float32)
        self.max_step = float(max_step_mm)
        self.smooth_px = float(smooth_px)
        self._kernel = np.ones((2, 2), np.uint8)
        self._edge_kernel = np.ones((2 * edge_px + 1, 2 * edge_px + 1), np.uint8)

    def make(self, depth: np.ndarray, colour: np.ndarray, frame_id: int) -> Scan:
        d = np.ascontiguousarray(depth, np.float32)
        lin = cv2.remap(d, self._mx, self._my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        valid = (d > 0).astype(np.float32)
        cover = cv2.remap(valid, self._mx, self._my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        big = np.where(d > 0, d, 0).astype(np.float32)
        small = np.where(d > 0, d, np.float32(1e9)).astype(np.float32)
        # a bilinear tap reads the 2x2 block whose top-left is floor(x, y): max and min over it
        hi = cv2.dilate(big, self._kernel, anchor=(0, 0), borderType=cv2.BORDER_CONSTANT, borderValue=0)
        lo = cv2.erode(small, self._kernel, anchor=(0, 0), borderType=cv2.BORDER_CONSTANT, borderValue=1e9)
        hi_u = cv2.remap(hi, self._fx, self._fy, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        lo_u = cv2.remap(lo, self._fx, self._fy, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        ok = (cover > 0.999) & (hi_u - lo_u <= self.max_step)
        out = np.where(ok, lin, 0).astype(np.float32)
        if self.volume is not None:
            out = self.crop(out)
        # silhouettes and depth edges: the decoder's least sure pixels, and fixed in the camera's frame, so they
        # would pull a registration toward no motion; the pixels within edge_px of one are left out of it. The
        # volume takes them: over the views the TSDF averages their error, and without them the surface a path
        # shows only near the silhouette is missing (docs/performance.md, "Whole models")
        good = cv2.erode((out > 0).astype(np.uint8), self._edge_kernel)
        inner = np.where(good > 0, out, 0).astype(np.float32)
        col = cv2.remap(colour, self._mx, self._my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        return Scan(out, col, frame_id, inner)

    def crop(self, depth: np.ndarray) -> np.ndarray:
        """Depth outside the working volume (camera mm) set to none."""
        x0, x1, y0, y1, z0, z1 = self.volume
        X = self.ray_x * depth
        Y = self.ray_y * depth
        keep = (depth >= z0) & (depth <= z1) & (X >= x0) & (X <= x1) & (Y >= y0) & (Y <= y1)
        return np.where(keep, depth, 0).astype(np.float32)

    def points_and_normals(
        self, depth: np.ndarray, stride: int, colour: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Camera-frame points (N, 3) on every stride-th pixel with depth, unit normals toward the camera from the
        depth grid's central differences (pixels whose four neighbours have depth within max_step_mm), and their
        colours (N, 3) in 0..1 (grey without `colour`)."""
        # smoothed first: the decoder's small depth ripple follows the projector's stripes, which stay put in the
        # camera's frame, and on a smooth surface it would hold a registration at no motion
        Z = smooth_depth(depth, self.smooth_px)
        # only the strided grid is ever read (each stride-th pixel and its four neighbours stride away): the points
        # of pixels 0, stride, 2 stride, ...; c is each inner one, its neighbours right, left, below and above
        Zs = Z[::stride, ::stride]
        P = np.stack([self.ray_x[::stride, ::stride] * Zs, self.ray_y[::stride, ::stride] * Zs, Zs], axis=2)
        c = P[1:-1, 1:-1]
        right, left, below, above = P[1:-1, 2:], P[1:-1, :-2], P[2:, 1:-1], P[:-2, 1:-1]
        dx = right - left
        dy = below - above
        zc = c[..., 2]
        ok = zc > 0
        for z in (right[..., 2], left[..., 2], below[..., 2], above[..., 2]):
            ok &= (z > 0) & (np.abs(z - zc) <= self.max_step * stride)
        n = np.cross(dx[ok], dy[ok])
        norm = np.linalg.norm(n, axis=1, keepdims=True)
        good = norm[:, 0] > 0
        pts = c[ok][good].astype(np.float64)
        n = (n[good] / norm[good]).astype(np.float64)
        flip = np.einsum("ij,ij->i", n, pts) > 0  # toward the camera (at the origin)
        n[flip] *= -1
        if colour is None:
            rgb = np.full((len(pts), 3), 0.5)
        else:
            # smoothed as the depth: what is left of the stripes in a frame set's colour stays put in the camera
            soft = cv2.GaussianBlur(colour, (0, 0), self.smooth_px)
            rgb = soft[::stride, ::stride][1:-1, 1:-1][ok][good].astype(np.float64) / 255.0
        return pts, n, rgb


def smooth_depth(depth: np.ndarray, sigma_px: float) -> np.ndarray:
    """Gaussian smoothing of the pixels with depth (normalised: pixels without depth neither count nor gain one)."""
    if sigma_px <= 0:
        return depth
    rows = np.flatnonzero((depth > 0).any(axis=1))
    if not len(rows):
        return np.zeros_like(depth, np.float32)
    cols = np.flatnonzero((depth > 0).any(axis=0))
    # only the box of the pixels with depth, padded by more than the kernel's reach (OpenCV's float kernel spans
    # 8 sigma + 1): inside the box every tap then reads what the whole image holds (the padding is zeros, so the
    # border rule never shows), and outside it the result is 0 anyway: the same values (to float32 rounding,
    # <= 2.5e-4 mm: OpenCV's vector loops split a shorter row differently) at a fraction of the work
    pad = int(np.ceil(4 * sigma_px)) + 2
    r0, r1 = max(rows[0] - pad, 0), min(rows[-1] + pad + 1, depth.shape[0])
    c0, c1 = max(cols[0] - pad, 0), min(cols[-1] + pad + 1, depth.shape[1])
    d = depth[r0:r1, c0:c1]
    valid = (d > 0).astype(np.float32)
    num = cv2.GaussianBlur(d * valid, (0, 0), sigma_px)
    den = cv2.GaussianBlur(valid, (0, 0), sigma_px)
    out = np.zeros(depth.shape, np.float32)
    with np.errstate(invalid="ignore", divide="ignore"):
        out[r0:r1, c0:c1] = np.where(valid > 0, num / den, 0)
    return out
