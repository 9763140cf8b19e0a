"""trimesh objects: a ``trimesh.Trimesh`` handed to clrt, and the meshes of a
file that trimesh reads (STL).

What is taken of a Trimesh: vertices, faces, texture coordinates, vertex or
face colours (sRGB, scaled to 0..1 by their integer type), and normals that
came from its file.  trimesh itself is imported only when a file needs it (it
takes seconds on some machines).
"""

from __future__ import annotations

import io

import numpy as np

from clrt.errors import MeshLoadError
from clrt.scene.formats import tds
from clrt.scene.formats.part import Part, fail, short
from clrt.scene.mesh import Mesh


def mesh_of(source) -> Mesh:
    """The Mesh of a trimesh.Trimesh (anything with ``vertices`` and ``faces``),
    with a Trimesh's texture coordinates and (sRGB) colours."""
    mesh = Mesh.from_arrays(source.vertices, source.faces)
    if hasattr(source, "visual"):
        part = trimesh_part(source, linear_colors=False)
        mesh = mesh.with_detail(uv=part.uv, colors=part.corner_colors())
    return mesh


def read_with_trimesh(data: bytes, file_type: str, path: str) -> list[Part]:
    """Every triangle mesh of a file that trimesh reads (``file_type``, as
    trimesh names it: "stl"), each placed by its node's transform, in the
    order of trimesh's scene graph.

    trimesh is imported here, when a file needs it, and learns our 3DS reader
    then.
    """
    import trimesh
    tds.register_with_trimesh()
    try:
        with np.errstate(all="ignore"):  # bad numbers are reported by Mesh.from_arrays
            scene = trimesh.load(io.BytesIO(data), file_type=file_type, force="scene", process=False,
                                 validate=False, skip_materials=True)
        parts = []
        for node in scene.graph.nodes_geometry:
            transform, geometry_name = scene.graph[node]
            geometry = scene.geometry.get(geometry_name)
            if not isinstance(geometry, trimesh.Trimesh) or len(geometry.faces) == 0:
                continue
            part = trimesh_part(geometry, linear_colors=False)
            matrix = np.asarray(transform, dtype=np.float64)
            if not np.array_equal(matrix, np.eye(4)):
                part.vertices = part.vertices @ matrix[:3, :3].T + matrix[:3, 3]
            parts.append(part)
    except MeshLoadError:
        raise
    except Exception as exc:  # trimesh raises anything from KeyError to struct.error
        raise fail(path, f"corrupt or unsupported {file_type.upper()} file ({short(exc)})") from exc
    if not parts:
        raise fail(path, "contains no triangles")
    return parts


def trimesh_part(geometry, linear_colors: bool) -> Part:
    """Vertices, faces, and what a trimesh.Trimesh's visual holds: texture
    coordinates, vertex or face colours (sRGB unless ``linear_colors``), and
    normals when they came from the file (trimesh keeps loaded normals in its
    cache; it only computes them when asked)."""
    part = Part(np.asarray(geometry.vertices, dtype=np.float64), np.asarray(geometry.faces, dtype=np.int64))
    part.srgb_colors = not linear_colors
    if "vertex_normals" in geometry._cache.cache:
        part.normals = np.asarray(geometry.vertex_normals, dtype=np.float64)
    visual = geometry.visual
    n_vertices = len(part.vertices)
    kind = getattr(visual, "kind", None)
    if kind == "texture":
        uv = getattr(visual, "uv", None)
        if uv is not None and len(uv) == n_vertices:
            part.uv = np.asarray(uv, dtype=np.float64)[part.faces]
        colors = getattr(visual, "vertex_attributes", {}).get("color")
        if colors is not None and len(colors) == n_vertices:
            part.vertex_colors = unit_colors(colors)
    elif kind == "vertex":
        part.vertex_colors = unit_colors(visual.vertex_colors)
    elif kind == "face":
        part.face_colors = unit_colors(visual.face_colors)
    return part


def unit_colors(colors) -> np.ndarray:
    """(n, 3) float64 in 0..1 of RGB(A) colours stored as floats or as normalised integers."""
    c = np.asarray(colors)
    scale = np.iinfo(c.dtype).max if np.issubdtype(c.dtype, np.integer) else 1.0
    return c[:, :3].astype(np.float64) / scale
