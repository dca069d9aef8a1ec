"""The model's surface: a TSDF volume (Open3D's tensor VoxelBlockGrid: 8^3-voxel blocks allocated where scans reach).

Units are mm throughout (depth_scale 1). The truncation is TRUNC_VOXELS voxels. The mesh keeps the surface where
the summed weight reaches `min_weight` (one per scan that saw it): a surface one stray scan saw is left out. (The
legacy ScalableTSDFVolume of open3d 0.20 integrated nothing from mm-scaled depth here, so it is not used.) Before a
volume is made, its memory is estimated from the surface it may have to hold (the working volume's box surface, or
the far plane of the camera's view) and refused when it would not fit in the machine's free memory.
"""

from __future__ import annotations

import os

import numpy as np

from app.fusion.open3d_import import open3d
from core.errors import InputError

BYTES_PER_VOXEL = 20  # tsdf, weight, colour (3 floats)
BLOCK = 8  # voxels per block edge
TRUNC_VOXELS = 4.0
MEMORY_SHARE = 0.5  # of the free memory a model may take


def free_memory_bytes() -> int:
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError):
        return 1 << 34


def estimated_bytes(voxel_mm: float, surface_mm2: float) -> float:
    """Voxels within the truncation band on both sides of a surface of this area, and their bytes."""
    band = 2.0 * TRUNC_VOXELS + 8.0  # the band, rounded up to whole 8-voxel blocks on either side
    return surface_mm2 / voxel_mm**2 * band * BYTES_PER_VOXEL


def check_memory(voxel_mm: float, surface_mm2: float, free: int | None = None) -> None:
    need = estimated_bytes(voxel_mm, surface_mm2)
    free = free_memory_bytes() if free is None else free
    if need > MEMORY_SHARE * free:
        raise InputError(
            f"--voxel-mm {voxel_mm:g}: the model would need about {need / 2**30:.1f} GiB, more than half of the "
            f"{free / 2**30:.1f} GiB free; choose a larger voxel"
        )


def box_surface_mm2(volume_mm: tuple[float, ...]) -> float:
    x0, x1, y0, y1, z0, z1 = volume_mm
    a, b, c = x1 - x0, y1 - y0, z1 - z0
    return 2.0 * (a * b + b * c + a * c)


class Volume:
    def __init__(
        self,
        voxel_mm: float,
        intrinsic: np.ndarray,
        size: tuple[int, int],
        far_mm: float,
        surface_mm2: float,
        min_weight: float = 3.0,
    ) -> None:
        o3d = open3d()
        self.o3d = o3d
        self.voxel = float(voxel_mm)
        self.far = float(far_mm)
        self.min_weight = float(min_weight)
        self.device = o3d.core.Device("CPU:0")
        blocks = int(estimated_bytes(voxel_mm, surface_mm2) / BYTES_PER_VOXEL / BLOCK**3) + 1000
        f32 = o3d.core.float32
        self.grid = o3d.t.geometry.VoxelBlockGrid(
            attr_names=("tsdf", "weight", "color"),
            attr_dtypes=(f32, f32, f32),
            attr_channels=((1), (1), (3)),
            voxel_size=self.voxel,
            block_resolution=BLOCK,
            block_count=blocks,
            device=self.device,
        )
        self.K = o3d.core.Tensor(np.asarray(intrinsic, np.float64))
        self.size = size
        self.scans = 0

    def integrate(self, depth: np.ndarray, colour: np.ndarray, pose: np.ndarray) -> None:
        """A scan's pinhole depth (mm) and colour (uint8 RGB) at pose (camera -> model)."""
        o3d = self.o3d
        ext = o3d.core.Tensor(np.linalg.inv(pose))
        d = o3d.t.geometry.Image(o3d.core.Tensor(np.ascontiguousarray(depth, np.float32)))
        c = o3d.t.geometry.Image(o3d.core.Tensor(np.ascontiguousarray(colour, np.float32) / 255.0))
        blocks = self.grid.compute_unique_block_coordinates(d, self.K, ext, 1.0, self.far, TRUNC_VOXELS)
        self.grid.integrate(blocks, d, c, self.K, self.K, ext, 1.0, self.far, TRUNC_VOXELS)
        self.scans += 1

    def mesh(self) -> object:
        """The zero surface (marching cubes) as a legacy TriangleMesh with vertex colours."""
        # weights count scans (1 each), and Open3D keeps a voxel only above the threshold: half a scan below
        m = self.grid.extract_triangle_mesh(weight_threshold=self.min_weight - 0.5)
        return m.to_legacy()
