"""From a Scene to the typed arrays the device needs (stage 1's output).

One triangle list for all objects, each triangle tagged with its material;
per-object vertex normals; material and light records; and, for scenes with
textures or colours, per-triangle corner detail, the texture table and the
texels.  The dtypes are the device layouts of clrt/layouts.py.  The reference
tracer (clrt/reference.py) reads scenes its own way and does not use this module.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from clrt.config import MATERIAL_SMOOTH
from clrt.config import TEXTURE_WRAPS
from clrt.errors import TooLargeError
from clrt.layouts import LIGHT, MATERIAL, TEXEL, TEXTURE, TRIANGLE_DETAIL, TRIANGLE_INFO, TRIANGLE_VERTS
from clrt.scene.mesh import Mesh
from clrt.scene.scene import Scene
from clrt.scene.texture import srgb_decode


@dataclass
class SceneArrays:
    """The scene as the kernels see it, triangles in input order."""

    corners: np.ndarray          # (F, 3, 3) float32 triangle corners
    tri_info: np.ndarray         # (F,) TRIANGLE_INFO
    vertex_normals: np.ndarray   # (V, 4) float32
    materials: np.ndarray        # (M,) MATERIAL
    lights: np.ndarray           # (L,) LIGHT, at least one record (OpenCL buffers cannot be empty)
    bounds: np.ndarray           # (2, 3) float64
    detail: "SurfaceDetail | None" = None   # None: no textures or colours (a plain program)


@dataclass
class SurfaceDetail:
    """What textures and colours add, for -DSURFACE_DETAIL programs."""

    tri_detail: np.ndarray       # (F,) TRIANGLE_DETAIL, triangles in input order
    textures: np.ndarray         # (T,) TEXTURE, at least one record
    texels: np.ndarray           # (N, 4) uint8 (TEXEL), at least one
    srgb_table: np.ndarray       # (256,) float32 (SRGB_TABLE): 8-bit sRGB -> linear


def srgb_table() -> np.ndarray:
    """The 256 linear values of 8-bit sRGB codes, float32."""
    return srgb_decode(np.arange(256) / 255.0).astype(np.float32)


def triangle_corners(mesh: Mesh) -> np.ndarray:
    """(F, 3, 3) float32 corners of a mesh's triangles (row = face index)."""
    # np.take: the same gather as mesh.vertices[mesh.faces], several times faster (numpy 2.4).
    return np.ascontiguousarray(np.take(mesh.vertices, mesh.faces, axis=0), dtype=np.float32)


def triangle_verts(corners: np.ndarray) -> np.ndarray:
    """(F, 3, 3) corners -> (F,) TRIANGLE_VERTS records (the w lanes 0)."""
    records = np.zeros(len(corners), TRIANGLE_VERTS)
    for k, name in enumerate(("v0", "v1", "v2")):
        records[name][:, :3] = corners[:, k]
    return records


def flatten_scene(scene: Scene) -> SceneArrays:
    """One triangle list for all objects, each triangle tagged with its material:
    each object's ``material`` then its ``materials``, object after object."""
    meshes = [o.mesh for o in scene.objects]
    mesh = Mesh.concatenate(meshes)
    object_materials = [(o.material, *o.materials) for o in scene.objects]
    first = np.cumsum([0] + [len(m) for m in object_materials[:-1]])
    material_of_tri = np.concatenate([
        np.full(len(m.faces), base, np.int32) if m.face_material is None else base + 1 + m.face_material
        for m, base in zip(meshes, first)]).astype(np.int32)

    tri_info = np.zeros(len(mesh.faces), TRIANGLE_INFO)
    tri_info["vertex"] = mesh.faces
    tri_info["material"] = material_of_tri

    normals = np.zeros((len(mesh.vertices), 4), np.float32)
    start = 0
    for m in meshes:   # per object, so that normals never blend across objects
        normals[start:start + len(m.vertices), :3] = m.vertex_normals()
        start += len(m.vertices)

    # A texture colours only meshes with texture coordinates.
    textures = {}   # id(Texture) -> (row, Texture), in order of first use
    flat_materials = []
    for o, mats in zip(scene.objects, object_materials):
        for mat in mats:
            tex = mat.texture if o.mesh.uv is not None else None
            if tex is not None:
                textures.setdefault(id(tex), (len(textures), tex))
            flat_materials.append((mat, textures[id(tex)][0] if tex is not None else -1))
    materials = np.zeros(len(flat_materials), MATERIAL)
    for i, (mat, texture) in enumerate(flat_materials):
        materials[i]["color"][:3] = mat.color
        materials[i]["color"][3:] = np.int32(texture).view(np.float32)
        for name in ("ambient", "diffuse", "specular", "shininess", "reflectivity", "transparency", "ior"):
            materials[i][name] = getattr(mat, name)
        materials[i]["flags"] = MATERIAL_SMOOTH if mat.smooth else 0

    detail = None
    if textures or mesh.colors is not None:
        detail = surface_detail(mesh, [tex for _, tex in textures.values()])
    return SceneArrays(triangle_corners(mesh), tri_info, normals, materials, light_records(scene.lights),
                       scene.bounds, detail)


def surface_detail(mesh: Mesh, textures: list) -> SurfaceDetail:
    """Corner colours and texture coordinates of the concatenated ``mesh``, and
    ``textures`` packed into one texel buffer (rows 0.. of the texture table)."""
    tri_detail = np.zeros(len(mesh.faces), TRIANGLE_DETAIL)
    tri_detail["corner"][:, :, :3] = 1.0 if mesh.colors is None else mesh.colors
    if mesh.uv is not None:
        tri_detail["corner"][:, :, 3] = mesh.uv[:, :, 0]
        tri_detail["v"][:, :3] = mesh.uv[:, :, 1]
    table = np.zeros(max(len(textures), 1), TEXTURE)
    sizes = [t.pixels.shape[0] * t.pixels.shape[1] for t in textures]
    starts = np.cumsum([0] + sizes)
    if starts[-1] > np.iinfo(np.uint32).max:
        raise TooLargeError(f"the scene's textures hold {starts[-1]:,} texels, more than 2**32")
    texels = np.zeros((max(int(starts[-1]), 1),) + TEXEL.shape, TEXEL.base)
    for row, (tex, start) in enumerate(zip(textures, starts)):
        h, w = tex.pixels.shape[:2]
        table[row] = (start, w, h, TEXTURE_WRAPS[tex.wrap_s], TEXTURE_WRAPS[tex.wrap_t])
        texels[start:start + w * h, :3] = tex.pixels.reshape(-1, 3)
    return SurfaceDetail(tri_detail, table, texels, srgb_table())


def light_records(lights) -> np.ndarray:
    """(L,) LIGHT records of a list of Lights, at least one (OpenCL buffers cannot be empty)."""
    records = np.zeros(max(len(lights), 1), LIGHT)
    for i, light in enumerate(lights):
        records[i]["position"][:3] = light.position
        records[i]["color"][:3] = light.color
    return records
