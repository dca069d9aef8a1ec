"""A tiny independent renderer for decoder unit tests: a tilted plane seen by a pinhole camera,
lit by a pinhole projector showing any pattern (area-sampled, blurred, noisy, with crosstalk).

It does not replace the virtual rig (drivers/sim/); it lets the decoders be tested against exact
geometry with known ground truth and no other moving part.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from calibration.model import Calibration


def make_calibration(
    cam=(320, 240),
    proj=(512, 384),
    fc=600.0,
    fp=380.0,
    baseline=120.0,
    yaw_deg=-6.0,
    cam_dist=None,
    proj_dist=None,
    mixing=None,
    roll_deg=0.0,
) -> Calibration:
    R = cv2.Rodrigues(np.array([0.0, np.radians(yaw_deg), 0.0]))[0]
    T = np.array([-baseline, 0.0, 0.0])
    if roll_deg:  # the projector turned about its own optical axis (180: mounted upside down)
        roll = cv2.Rodrigues(np.array([0.0, 0.0, np.radians(roll_deg)]))[0]
        R, T = roll @ R, roll @ T
    return Calibration(
        camera_size=cam,
        camera_matrix=[[fc, 0, (cam[0] - 1) / 2], [0, fc, (cam[1] - 1) / 2], [0, 0, 1]],
        camera_distortion=np.zeros(5) if cam_dist is None else cam_dist,
        projector_size=proj,
        projector_matrix=[[fp, 0, (proj[0] - 1) / 2], [0, fp, (proj[1] - 1) / 2], [0, 0, 1]],
        projector_distortion=np.zeros(5) if proj_dist is None else proj_dist,
        R=R,
        T=T,
        color_mixing=mixing,
    )


@dataclass
class Truth:
    depth: np.ndarray
    column: np.ndarray
    lit: np.ndarray


def plane_depth(cal: Calibration, z0: float, slope_x: float = 0.0, steps: tuple = ()) -> tuple[np.ndarray, np.ndarray]:
    """Depth of a plane z = z0 + slope_x * X (and optional steps: (x_from_px, dz)) for each pixel; rays."""
    w, h = cal.camera_size
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    pts = np.stack([xs.ravel(), ys.ravel()], 1).reshape(-1, 1, 2)
    ray = cv2.undistortPoints(
        pts,
        cal.camera_matrix,
        cal.camera_distortion,
        None,
        None,
        None,
        (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12),
    ).reshape(h, w, 2)
    z = z0 / (1.0 - slope_x * ray[..., 0])
    for x_from, dz in steps:
        z = np.where(xs >= x_from, z + dz, z)
    return z, ray


def render(
    cal: Calibration,
    pattern: np.ndarray,
    depth: np.ndarray,
    ray: np.ndarray,
    *,
    albedo=(1.0, 1.0, 1.0),
    ambient=0.0,
    gain=200.0,
    blur=0.6,
    noise=1.0,
    seed=0,
    supersample=4,
) -> tuple[np.ndarray, Truth]:
    """Camera image (uint8 RGB) of a surface of given per-pixel depth lit by `pattern`."""
    h, w = depth.shape
    rng = np.random.default_rng(seed)
    rvec = cv2.Rodrigues(cal.R)[0]
    acc = np.zeros((h, w, 3))
    pw, ph = cal.projector_size
    col_true = None
    for s in range(supersample):
        dx = (s + 0.5) / supersample - 0.5
        # depth varies slowly: reuse the pixel depth with the sub-pixel ray shift
        r = ray.copy()
        r[..., 0] += dx / cal.camera_matrix[0, 0]
        X = np.concatenate([r * depth[..., None], depth[..., None]], 2).reshape(-1, 3)
        uv, _ = cv2.projectPoints(X, rvec, cal.T.reshape(3, 1), cal.projector_matrix, cal.projector_distortion)
        uv = uv.reshape(h, w, 2)
        ui = np.rint(uv[..., 0]).astype(int)
        vi = np.rint(uv[..., 1]).astype(int)
        inside = (ui >= 0) & (ui < pw) & (vi >= 0) & (vi < ph)
        val = np.zeros((h, w, 3))
        val[inside] = pattern[vi[inside], ui[inside]] / 255.0
        acc += val
    X = np.concatenate([ray * depth[..., None], depth[..., None]], 2).reshape(-1, 3)
    uv, _ = cv2.projectPoints(X, rvec, cal.T.reshape(3, 1), cal.projector_matrix, cal.projector_distortion)
    uv = uv.reshape(h, w, 2)
    lit = (uv[..., 0] >= 2) & (uv[..., 0] < pw - 3) & (uv[..., 1] >= 0) & (uv[..., 1] < ph)
    col_true = np.where(lit, uv[..., 0], np.nan).astype(np.float32)
    light = acc / supersample
    if blur > 0:
        light = cv2.GaussianBlur(light, (0, 0), blur)
    img = gain * (light + ambient) * np.asarray(albedo)[None, None, :]  # reflected light
    if cal.color_mixing is not None:
        img = img @ np.asarray(cal.color_mixing).T  # the camera's channels leak into each other
    img = img + rng.normal(0, noise, img.shape)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8), Truth(depth.astype(np.float32), col_true, lit)
