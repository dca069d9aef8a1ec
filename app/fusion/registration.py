"""Registration of each scan to the model: point-to-plane ICP from a predicted pose, with a failure test.

Poses map a scan's camera coordinates into the model's frame (the camera's at the first scan), X_model = M X_cam.
The model the scans are registered to is a point map in that frame: one point (with its normal) per `map_voxel_mm`
cell, taken from the first registered scan that reached the cell and never moved after (so the map stays anchored
to the early scans and a full turn closes on them rather than on its own recent past). A scan is tried from the
pose predicted by constant motion (the last pose times the last step per frame), point-to-plane coarse then fine,
with projective correspondences by default (app/fusion/projective.py; Open3D's k-d tree search with
`association="nearest"`; the fine stage coloured ICP with `colour`, off by default: docs/performance.md, "Whole
models"); it is accepted when
enough of its points found the map (fitness), they fit well (inlier RMSE) and the step from the prediction is
plausible. A scan that fails from the prediction is tried again from constant motion over every frame since the
last accepted scan, then from that scan's pose (the object stopped): a live thread that falls behind, or a run of
failed scans, leaves the object far from where the prediction stops coasting. When those fail too, the scan is
dropped, the model is left as it was, and the prediction goes on from the last good pose.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from app.fusion.open3d_import import open3d

MAX_COAST = 3  # scans the prediction goes on at the last step after the last accepted one
MAX_WIDEN = 3.0  # the most the jump gates widen for a prediction over many frames (9 and more)
# The gates below were tuned on the virtual rig's 640x480 camera, a pixel covering 0.355 mm at mid range (780 mm);
# a coarser camera's depth is noisier in proportion (a scan's inlier RMSE at 320x240: 0.4-0.9 mm, not 0.33-0.42)
REFERENCE_FOOTPRINT_MM = 0.355


@dataclass
class TrackSettings:
    stride: int = 3  # back-project every stride-th pixel (each way) of a scan
    map_voxel_mm: float = 1.0
    coarse_mm: float = 4.0  # correspondence distances of the two ICP stages
    fine_mm: float = 2.0
    coarse_iterations: int = 3  # from the constant-motion prediction the fine stage does the rest (docs)
    fine_iterations: int = 20
    fine_tolerance: float = 1e-7  # relative change of fitness and RMSE that ends the fine stage (Open3D's ICP)
    step_tolerance: float = 1e-7  # the projective ICP's: the norm of a step's twist (rad and mm) that ends a stage
    min_fitness: float = 0.5  # share of the scan's points with a map point within fine_mm
    max_rmse_mm: float = 0.65  # the scans of the bench scenes fit at 0.50-0.63 mm (docs/performance.md)
    max_step_deg: float = 8.0  # from the prediction one frame on (x sqrt(frames) over more: Tracker._test)
    max_step_mm: float = 15.0
    max_incidence_deg: float = 70.0  # steeper points are not added to the map (their depth is the least sure)
    # correspondences: "projective" (the map drawn into the predicted camera, app/fusion/projective.py) or "nearest"
    # (Open3D's legacy ICP, a k-d tree search); the coloured ICP is Open3D's, nearest always
    association: str = "projective"
    colour: bool = False  # the fine stage is coloured ICP (Park et al. 2017): texture holds what geometry lets slide
    colour_weight: float = 0.9  # 1 - lambda_geometric


def for_footprint(settings: TrackSettings, footprint_mm: float) -> TrackSettings:
    """The RMSE gate widened for a camera whose pixel covers more than the reference's (never narrowed)."""
    scale = max(1.0, footprint_mm / REFERENCE_FOOTPRINT_MM)
    return replace(settings, max_rmse_mm=settings.max_rmse_mm * scale)


@dataclass
class TrackResult:
    ok: bool
    pose: np.ndarray  # (4, 4) the estimate, or the prediction it was tried from when not ok
    fitness: float
    rmse_mm: float
    reason: str = ""


def rotation_deg(R: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))))


class PointMap:
    """The model's points and normals, one per occupied cell; cells, once filled, are never overwritten."""

    def __init__(self, voxel_mm: float) -> None:
        self.voxel = float(voxel_mm)
        self.keys = np.zeros(0, np.int64)  # sorted
        self.points = np.zeros((0, 3))
        self.normals = np.zeros((0, 3))
        self.colours = np.zeros((0, 3))

    def _key(self, p: np.ndarray) -> np.ndarray:
        q = np.floor(p / self.voxel).astype(np.int64) + (1 << 20)
        return (q[:, 0] << 42) | (q[:, 1] << 21) | q[:, 2]

    def add(self, points: np.ndarray, normals: np.ndarray, colours: np.ndarray) -> int:
        """Points in cells not yet filled (the first point of a cell when several fall in it); how many."""
        if len(points) == 0:
            return 0
        k = self._key(points)
        k, first = np.unique(k, return_index=True)
        pos = np.searchsorted(self.keys, k)
        pos_c = np.minimum(pos, max(len(self.keys) - 1, 0))
        new = (pos >= len(self.keys)) | (self.keys[pos_c] != k) if len(self.keys) else np.ones(len(k), bool)
        k, idx = k[new], first[new]
        if not len(k):
            return 0
        keys = np.concatenate([self.keys, k])
        order = np.argsort(keys, kind="stable")
        self.keys = keys[order]
        self.points = np.concatenate([self.points, points[idx]])[order]
        self.normals = np.concatenate([self.normals, normals[idx]])[order]
        self.colours = np.concatenate([self.colours, colours[idx]])[order]
        return len(k)

    def __len__(self) -> int:
        return len(self.keys)


class Tracker:
    def __init__(
        self,
        settings: TrackSettings | None = None,
        camera_matrix: np.ndarray | None = None,
        size: tuple[int, int] | None = None,
    ) -> None:
        """camera_matrix, size: the scans' pinhole camera, which projective correspondences need (without them
        the nearest-neighbour ICP is used)."""
        self.o3d = open3d()
        self.settings = settings or TrackSettings()
        self.projective = None
        if self.settings.association == "projective" and not self.settings.colour and camera_matrix is not None:
            from app.fusion.projective import ProjectiveICP

            self.projective = ProjectiveICP(camera_matrix, size, self.settings.stride)
        self.map = PointMap(self.settings.map_voxel_mm)
        self.pose: np.ndarray | None = None  # the last accepted pose
        self.step = np.eye(4)  # the last accepted step, per frame
        self.since_ok = 1  # scans since the last accepted one
        self.frame: int | None = None  # the frame id of the last accepted scan
        self.gap = 1  # frames between the last two accepted scans
        self.frames_since = 1  # frames from the last accepted scan to the one being tracked
        self.accepted = 0  # scans accepted (the first one included)
        self._frame_id: int | None = None  # the frame id of the scan being tracked

    def prediction(self) -> np.ndarray:
        """The last accepted pose moved on by the last step per frame for each frame since, for at most MAX_COAST
        scans' worth of frames (at the last gap between accepted scans): beyond them constant motion is a guess that
        runs away from the object rather than toward it. Per frame, not per scan: a live fusion thread takes the
        newest scan, so the frames between the scans it tracks vary (offline every frame is a scan: the same)."""
        if self.pose is None:
            return np.eye(4)
        P = self.pose
        for _ in range(min(self.frames_since, MAX_COAST * self.gap)):
            P = P @ self.step
        return P

    def _cloud(self, pts: np.ndarray, nrm: np.ndarray, rgb: np.ndarray) -> object:
        o3d = self.o3d
        pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
        pc.normals = o3d.utility.Vector3dVector(nrm)
        if self.settings.colour:  # (only the coloured ICP reads them)
            pc.colors = o3d.utility.Vector3dVector(rgb)
        return pc

    def _map_near(self, pts: np.ndarray, init: np.ndarray) -> np.ndarray:
        """Which map points are near the scan placed at `init` (its box, padded by twice the coarse distance): Open3D
        builds its search tree from the target on every call, and the far side of the model is never matched."""
        st = self.settings
        P = pts @ init[:3, :3].T + init[:3, 3]
        pad = 2.0 * st.coarse_mm * min(self.since_ok, MAX_COAST)  # wider while scans fail
        lo, hi = P.min(axis=0) - pad, P.max(axis=0) + pad
        return np.all((self.map.points >= lo) & (self.map.points <= hi), axis=1)

    def _map_cloud(self, pts: np.ndarray, init: np.ndarray) -> object:
        near = self._map_near(pts, init)
        return self._cloud(self.map.points[near], self.map.normals[near], self.map.colours[near])

    def _register_projective(self, pts: np.ndarray, init: np.ndarray) -> tuple[np.ndarray, float, float] | str:
        """(pose, fitness, inlier RMSE), or why not: no scan point near the map, or a singular step."""
        st = self.settings
        near = self._map_near(pts, init)
        # the coarse stage takes the pixel's point; the fine one the nearest of 3 x 3 (as a nearest-neighbour search:
        # one pixel's alone left the turntable's mean error at 0.307 mm, against 0.271 with Open3D's search)
        stages = [
            (st.coarse_mm, st.coarse_iterations, st.step_tolerance, 0),
            (st.fine_mm, st.fine_iterations, st.step_tolerance, 1),
        ]
        m = self.map
        try:
            found = self.projective.register(pts, m.points[near], m.normals[near], init, stages, st.fine_mm)
        except np.linalg.LinAlgError:  # the correspondences leave a motion unconstrained (e.g. all on one plane)
            return "a singular registration step (the matched points do not fix the pose)"
        return "no point of the scan near the model" if found is None else found

    def track(self, pts: np.ndarray, nrm: np.ndarray, rgb: np.ndarray, frame_id: int | None = None) -> TrackResult:
        """Register a scan's camera-frame points (with normals toward the camera, colours 0..1); on success, extend
        the map. frame_id: the scan's frame (None: one frame after the scan before)."""
        st = self.settings
        if frame_id is not None and self.frame is not None and frame_id > self.frame:
            self.frames_since = frame_id - self.frame
        else:  # no frame ids: every scan one frame on
            self.frames_since = self.since_ok
        self._frame_id = frame_id
        if self.pose is None:  # the first scan defines the model's frame
            self._accept(np.eye(4), pts, nrm, rgb)
            return TrackResult(True, np.eye(4), 1.0, 0.0)
        ray = pts / np.linalg.norm(pts, axis=1, keepdims=True)
        facing = -np.einsum("ij,ij->i", nrm, ray) >= np.cos(np.radians(st.max_incidence_deg))
        pts, nrm, rgb = pts[facing], nrm[facing], rgb[facing]
        if len(pts) < 50:
            self.since_ok += 1
            return TrackResult(False, self.prediction(), 0.0, 0.0, f"too few points ({len(pts)})")
        init = self.prediction()
        res = self._register(pts, nrm, rgb, init)
        if not res.ok and "singular" not in res.reason:
            # lost: the object went on while the scans failed (or the thread fell behind it), or stopped
            for other in self.recovery_starts(init):
                again = self._register(pts, nrm, rgb, other)
                if again.ok:
                    res = again
                    break
        if not res.ok:
            self.since_ok += 1
            return res
        self._accept(res.pose, pts, nrm, rgb)
        return res

    def recovery_starts(self, tried: np.ndarray) -> list[np.ndarray]:
        """Where a scan that failed from the prediction is tried again: constant motion over every frame since the
        last accepted scan (the prediction stops coasting after MAX_COAST scans), then no motion since it."""
        P = self.pose
        full = P @ np.linalg.matrix_power(self.step, self.frames_since)
        starts = [full] if not np.allclose(full, tried) else []
        return [*starts, P] if not np.allclose(P, tried) else starts

    def _register(self, pts: np.ndarray, nrm: np.ndarray, rgb: np.ndarray, init: np.ndarray) -> TrackResult:
        """The registration from `init` and its failure test (pose = init when it failed)."""
        st = self.settings
        if self.projective is not None:
            found = self._register_projective(pts, init)
            if isinstance(found, str):
                return TrackResult(False, init, 0.0, 0.0, found)
            M, fitness, rmse = found
            return self._test(M, init, fitness, rmse, pts)
        reg = self.o3d.pipelines.registration
        src = self._cloud(pts, nrm, rgb)
        tgt = self._map_cloud(pts, init)
        try:  # (Open3D raises when no point of the scan finds the map)
            est = reg.TransformationEstimationPointToPlane(reg.TukeyLoss(k=st.coarse_mm))
            r = reg.registration_icp(
                src, tgt, st.coarse_mm, init, est, reg.ICPConvergenceCriteria(max_iteration=st.coarse_iterations)
            )
            fine = reg.ICPConvergenceCriteria(
                relative_fitness=st.fine_tolerance, relative_rmse=st.fine_tolerance, max_iteration=st.fine_iterations
            )
            if st.colour:
                est = reg.TransformationEstimationForColoredICP(1.0 - st.colour_weight, reg.TukeyLoss(k=st.fine_mm))
                r = reg.registration_colored_icp(src, tgt, st.fine_mm, r.transformation, est, fine)
            else:
                est = reg.TransformationEstimationPointToPlane(reg.TukeyLoss(k=st.fine_mm))
                r = reg.registration_icp(src, tgt, st.fine_mm, r.transformation, est, fine)
        except RuntimeError:
            return TrackResult(False, init, 0.0, 0.0, "no point of the scan near the model")
        M = np.asarray(r.transformation).copy()
        return self._test(M, init, float(r.fitness), float(r.inlier_rmse), pts)

    def _test(self, M: np.ndarray, init: np.ndarray, fitness: float, rmse: float, pts: np.ndarray) -> TrackResult:
        """The failure test of a registration result."""
        st = self.settings
        D = np.linalg.inv(init) @ M
        # the jump as the scan's centre sees it (a turn about a far axis shifts the camera's origin a lot)
        centre = pts.mean(axis=0)
        # the prediction is less sure the more frames it spans (a change of motion grows with them): the jump it
        # allows grows as their square root, one frame's as set, up to MAX_WIDEN (a far jump on this nearly
        # symmetric bust can fit a wrong side as well as the right one)
        widen = min(float(np.sqrt(max(1, self.frames_since))), MAX_WIDEN)
        jump_mm = float(np.linalg.norm(D[:3, :3] @ centre + D[:3, 3] - centre))
        reason = ""
        if fitness < st.min_fitness:
            reason = f"fitness {fitness:.2f} < {st.min_fitness:g}"
        elif rmse > st.max_rmse_mm:
            reason = f"inlier RMSE {rmse:.2f} mm > {st.max_rmse_mm:g}"
        elif rotation_deg(D[:3, :3]) > st.max_step_deg * widen or jump_mm > st.max_step_mm * widen:
            reason = f"a jump from the prediction ({rotation_deg(D[:3, :3]):.1f} deg, {jump_mm:.1f} mm)"
        if reason:
            return TrackResult(False, init, fitness, rmse, reason)
        return TrackResult(True, M, fitness, rmse)

    def _accept(self, M: np.ndarray, pts: np.ndarray, nrm: np.ndarray, rgb: np.ndarray) -> None:
        if self.pose is not None:
            # the step per frame, averaged over the frames since the last accepted scan (rotation by its angle)
            step = np.linalg.inv(self.pose) @ M
            self.step = _root(step, self.frames_since)
            self.gap = max(1, round(self.frames_since / self.since_ok))  # frames per scan tried since
        self.frame = self._frame_id
        self.pose = M
        self.since_ok = 1
        self.accepted += 1
        ray = pts / np.linalg.norm(pts, axis=1, keepdims=True)
        steep = -np.einsum("ij,ij->i", nrm, ray) < np.cos(np.radians(self.settings.max_incidence_deg))
        keep = ~steep
        P = pts[keep] @ M[:3, :3].T + M[:3, 3]
        N = nrm[keep] @ M[:3, :3].T
        self.map.add(P, N, rgb[keep])


def _root(T: np.ndarray, n: int) -> np.ndarray:
    """The rigid motion S with S^n = T: the same screw (axis, pitch), 1/n of its turn and of its slide along it.

    Dividing the shift by n instead is wrong to second order in the angle: a scan's camera orbits a turntable's axis
    ~780 mm away, so 5 degrees between two tracked scans would put the prediction ~5 mm off, beyond the coarse stage."""
    if n == 1:
        return T
    w, u = _log(T)
    return _exp(w / n, u / n)


def _v(w: np.ndarray) -> np.ndarray:
    """The matrix V(w) of SE(3)'s exponential: t = V(w) u for the twist (w, u)."""
    th = float(np.linalg.norm(w))
    K = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    if th < 1e-9:
        return np.eye(3) + 0.5 * K
    return np.eye(3) + (1.0 - np.cos(th)) / th**2 * K + (th - np.sin(th)) / th**3 * (K @ K)


def _log(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    import cv2

    w = cv2.Rodrigues(np.ascontiguousarray(T[:3, :3]))[0][:, 0]
    return w, np.linalg.solve(_v(w), T[:3, 3])


def _exp(w: np.ndarray, u: np.ndarray) -> np.ndarray:
    import cv2

    S = np.eye(4)
    S[:3, :3] = cv2.Rodrigues(np.ascontiguousarray(w, np.float64))[0]
    S[:3, 3] = _v(w) @ u
    return S
