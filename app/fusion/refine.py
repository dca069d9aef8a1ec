"""The offline refinement of a tracked sequence: every scan registered again against the other views' points.

Why: the decoder's smooth depth errors stay with the camera and projector, so two scans of the object at nearby
poses carry nearly the same error pattern, and registering one to the other pulls it toward no motion. While
tracking, the first scans meet a map made only of the first scan's points and lag the turn (on the turntable by
~3.5 deg after 10 scans); the cells they fill anchor the rest of the model to that lag (docs/performance.md,
"Whole models"). Once the whole sequence is tracked, each scan is registered once more from its tracked pose to
the map of the scans whose pose differs from its own by at least `exclude_deg` (their errors fall elsewhere on the
object), averaged per 1 mm cell; the poses are then re-expressed so that the first scan's stays the model's frame.
A scan whose registration fails the tracker's test keeps its tracked pose (or stays dropped).

The map of "all scans but the near ones" is the sum over all scans' cells minus the near ones': the scans are
grouped into runs of poses within `bin_deg` of the run's first, each run's cells summed once.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.fusion.projective import ProjectiveICP
from app.fusion.registration import TrackSettings, rotation_deg

EXCLUDE_DEG = 15.0
BIN_DEG = 4.0


@dataclass
class Cloud:
    """A scan's registration points in its camera's frame (facing the camera within the incidence limit)."""

    points: np.ndarray  # (N, 3) mm
    normals: np.ndarray  # (N, 3) unit, toward the camera


def _keys(p: np.ndarray, voxel: float) -> np.ndarray:
    q = np.floor(p / voxel).astype(np.int64) + (1 << 20)
    return (q[:, 0] << 42) | (q[:, 1] << 21) | q[:, 2]


class _Cells:
    """Per-cell sums (points, normals, counts) on sorted keys."""

    def __init__(self, keys: np.ndarray, points: np.ndarray, normals: np.ndarray, counts: np.ndarray) -> None:
        u, inv = np.unique(keys, return_inverse=True)
        self.keys = u
        self.sp = np.zeros((len(u), 3))
        self.sn = np.zeros((len(u), 3))
        self.c = np.zeros(len(u))
        np.add.at(self.sp, inv, points)
        np.add.at(self.sn, inv, normals)
        np.add.at(self.c, inv, counts)


def _relative_deg(a: np.ndarray, b: np.ndarray) -> float:
    return rotation_deg((np.linalg.inv(a) @ b)[:3, :3])


def refine_poses(
    clouds: list[Cloud | None],
    poses: list[np.ndarray],
    ok: list[bool],
    settings: TrackSettings,
    icp: ProjectiveICP,
    exclude_deg: float = EXCLUDE_DEG,
    bin_deg: float = BIN_DEG,
) -> tuple[list[np.ndarray], list[bool]]:
    """(poses, registered) after one refinement pass; clouds[i] is None for a scan with too few points. The poses
    are camera -> model with the first registered scan's camera as the model's frame, as the tracker's."""
    st = settings
    voxel = st.map_voxel_mm
    good = [i for i, c in enumerate(clouds) if ok[i] and c is not None]
    if len(good) < 2:
        return [p.copy() for p in poses], list(ok)
    runs: list[list[int]] = []
    for i in good:
        if runs and _relative_deg(poses[runs[-1][0]], poses[i]) < bin_deg:
            runs[-1].append(i)
        else:
            runs.append([i])
    run_cells, centres = [], []
    for r in runs:
        P = np.concatenate([clouds[i].points @ poses[i][:3, :3].T + poses[i][:3, 3] for i in r])
        N = np.concatenate([clouds[i].normals @ poses[i][:3, :3].T for i in r])
        run_cells.append(_Cells(_keys(P, voxel), P, N, np.ones(len(P))))
        centres.append(poses[r[len(r) // 2]])
    total = _Cells(
        np.concatenate([c.keys for c in run_cells]),
        np.concatenate([c.sp for c in run_cells]),
        np.concatenate([c.sn for c in run_cells]),
        np.concatenate([c.c for c in run_cells]),
    )
    at = [np.searchsorted(total.keys, c.keys) for c in run_cells]  # each run's cells among all (keys unique per run)
    stages = [
        (st.coarse_mm, st.coarse_iterations, st.step_tolerance, 0),
        (st.fine_mm, st.fine_iterations, st.step_tolerance, 1),
    ]
    out = [p.copy() for p in poses]
    registered = list(ok)
    cached: tuple[tuple[int, ...], np.ndarray, np.ndarray] | None = None
    for i, cloud in enumerate(clouds):
        if cloud is None:
            continue
        near = tuple(k for k, c in enumerate(centres) if _relative_deg(c, poses[i]) < exclude_deg)
        if cached is None or cached[0] != near:
            sp, sn, c = total.sp.copy(), total.sn.copy(), total.c.copy()
            for k in near:
                sp[at[k]] -= run_cells[k].sp
                sn[at[k]] -= run_cells[k].sn
                c[at[k]] -= run_cells[k].c
            keep = c > 0.5  # (counts are whole: what is left of a cell after the near runs' are taken out)
            norm = np.linalg.norm(sn[keep], axis=1, keepdims=True)
            cached = (near, sp[keep] / c[keep, None], sn[keep] / np.maximum(norm, 1e-12))
        _, mp, mn = cached
        W = cloud.points @ poses[i][:3, :3].T + poses[i][:3, 3]
        pad = 2.0 * st.coarse_mm
        inside = np.all((mp >= W.min(axis=0) - pad) & (mp <= W.max(axis=0) + pad), axis=1)
        if inside.sum() < 6:
            continue
        try:
            found = icp.register(cloud.points, mp[inside], mn[inside], poses[i], stages, st.fine_mm)
        except np.linalg.LinAlgError:  # correspondences that leave a motion free: the tracked pose stays
            continue
        if found is None:
            continue
        M, fitness, rmse = found
        D = np.linalg.inv(poses[i]) @ M
        if fitness >= st.min_fitness and rmse <= st.max_rmse_mm and rotation_deg(D[:3, :3]) <= st.max_step_deg:
            out[i] = M
            registered[i] = True
    first = next(i for i, r in enumerate(registered) if r)
    to_model = np.linalg.inv(out[first])
    return [to_model @ p for p in out], registered
