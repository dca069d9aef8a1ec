"""Writing a fused mesh: binary PLY and OBJ (vertex colours where the model has them), through Open3D."""

from __future__ import annotations

from pathlib import Path

from app.fusion.open3d_import import open3d
from core.errors import InputError


def mesh_paths(out: str | Path) -> tuple[Path, Path]:
    """(PLY, OBJ) for an --out path: model.ply -> model.ply and model.obj (any other suffix: both added)."""
    p = Path(out)
    base = p.with_suffix("") if p.suffix.lower() in (".ply", ".obj") else p
    return base.with_suffix(".ply"), base.with_suffix(".obj")


def write_mesh(mesh: object, out: str | Path) -> tuple[Path, Path]:
    o3d = open3d()
    ply, obj = mesh_paths(out)
    if len(mesh.triangles) == 0:
        raise InputError(f"{ply}: the model has no surface yet (too few scans saw any part of it): nothing written")
    ply.parent.mkdir(parents=True, exist_ok=True)
    colours = mesh.has_vertex_colors()
    for path, ascii_ in ((ply, False), (obj, True)):
        ok = o3d.io.write_triangle_mesh(
            str(path), mesh, write_ascii=ascii_, write_vertex_normals=False, write_vertex_colors=colours
        )
        if not ok:
            raise InputError(f"{path}: cannot write the mesh")
    return ply, obj
