"""From a Scene to the typed arrays the device needs (stage 1's output).

One triangle list for all objects, each triangle tagged with its material;
per-object vertex normals; material and light records.  The dtypes are the
device layouts of clrt/layouts.py.  The reference tracer (clrt/reference.py)
reads scenes its own way and does not use this module.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from clrt.config import MATERIAL_SMOOTH
from clrt.layouts import LIGHT, MATERIAL, TRIANGLE_INFO, TRIANGLE_VERTS
from clrt.scene.mesh import Mesh
from clrt.scene.scene import Scene


@dataclass
class SceneArrays:
    """The scene as the kernels see it, triangles in input order."""

    corners: np.ndarray          # (F, 3, 3) float32 triangle corners
    tri_info: np.ndarray         # (F,) TRIANGLE_INFO
    vertex_normals: np.ndarray   # (V, 4) float32
    materials: np.ndarray        # (M,) MATERIAL
    lights: np.ndarray           # (L,) LIGHT, at least one record (OpenCL buffers cannot be empty)
    bounds: np.ndarray           # (2, 3) float64


def triangle_corners(mesh: Mesh) -> np.ndarray:
    """(F, 3, 3) float32 corners of a mesh's triangles (row = face index)."""
    return np.ascontiguousarray(mesh.vertices[mesh.faces], dtype=np.float32)


def triangle_verts(corners: np.ndarray) -> np.ndarray:
    """(F, 3, 3) corners -> (F,) TRIANGLE_VERTS records (the w lanes 0)."""
    records = np.zeros(len(corners), TRIANGLE_VERTS)
    for k, name in enumerate(("v0", "v1", "v2")):
        records[name][:, :3] = corners[:, k]
    return records


def flatten_scene(scene: Scene) -> SceneArrays:
    """One triangle list for all objects, each triangle tagged with its material."""
    meshes = [o.mesh for o in scene.objects]
    mesh = Mesh.concatenate(meshes)
    material_of_tri = np.repeat(np.arange(len(meshes), dtype=np.int32), [len(m.faces) for m in meshes])

    tri_info = np.zeros(len(mesh.faces), TRIANGLE_INFO)
    tri_info["vertex"] = mesh.faces
    tri_info["material"] = material_of_tri

    normals = np.zeros((len(mesh.vertices), 4), np.float32)
    start = 0
    for m in meshes:   # per object, so that normals never blend across objects
        normals[start:start + len(m.vertices), :3] = m.vertex_normals()
        start += len(m.vertices)

    materials = np.zeros(len(scene.objects), MATERIAL)
    for i, o in enumerate(scene.objects):
        mat = o.material
        materials[i]["color"][:3] = mat.color
        for name in ("ambient", "diffuse", "specular", "shininess", "reflectivity", "transparency", "ior"):
            materials[i][name] = getattr(mat, name)
        materials[i]["flags"] = MATERIAL_SMOOTH if mat.smooth else 0

    return SceneArrays(triangle_corners(mesh), tri_info, normals, materials, light_records(scene.lights),
                       scene.bounds)


def light_records(lights) -> np.ndarray:
    """(L,) LIGHT records of a list of Lights, at least one (OpenCL buffers cannot be empty)."""
    records = np.zeros(max(len(lights), 1), LIGHT)
    for i, light in enumerate(lights):
        records[i]["position"][:3] = light.position
        records[i]["color"][:3] = light.color
    return records
