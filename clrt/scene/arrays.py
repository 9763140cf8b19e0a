"""From a Scene to the typed arrays the device needs (stage 1's output).

One triangle list for all objects, each triangle tagged with its material;
per-object vertex normals; material and light records; and, for scenes with
textures or colours, per-triangle corner detail, the texture table and the
texels.  The dtypes are the device layouts of clrt/layouts.py.  The reference
tracer (clrt/reference.py) reads scenes its own way and does not use this module.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from clrt.config import MATERIAL_DOUBLE_SIDED, MATERIAL_SMOOTH, TEXTURE_WRAPS
from clrt.errors import TooLargeError
from clrt.layouts import LIGHT, MATERIAL, TEXEL, TEXTURE, TRIANGLE_DETAIL, TRIANGLE_INFO, TRIANGLE_VERTS
from clrt.scene.blocks import map_blocks
from clrt.scene.instances import Instances
from clrt.scene.mesh import Mesh
from clrt.scene.placed import scene_instances
from clrt.scene.scene import MATERIAL_TEXTURES, Scene
from clrt.scene.texture import srgb_decode


class Later:
    """What a SceneArrays field holds in place of an array that a device made a
    copy of itself (:class:`ShadingSource`): ``make()`` makes it on the host,
    where it is first asked for; ``length``: its length, where known."""

    def __init__(self, make, length: int | None = None):
        self.make, self.length = make, length


class _MadeOnUse:
    """A SceneArrays field that may hold a :class:`Later`: the array is made
    on first use and kept."""

    def __set_name__(self, owner, name: str):
        self.name, self.key = name, f"_{name}"

    def __get__(self, arrays, owner=None):
        if arrays is None:                 # (a dataclass field without a default)
            raise AttributeError(self.name)
        value = arrays.__dict__[self.key]
        if isinstance(value, Later):
            value = arrays.__dict__[self.key] = value.make()
        return value

    def __set__(self, arrays, value) -> None:
        arrays.__dict__[self.key] = value


@dataclass(frozen=True)
class ShadingSource:
    """What a device needs to make a scene's per-triangle and per-vertex
    shading arrays itself (clrt.device.crease), where the scene is one object
    of one mesh without authored normals, textures or colours, not placed:
    ``mesh``, the object's mesh before any crease split (its triangles are
    the split's, bit for bit); ``crease``, the split's angle for a smooth
    material (Mesh.split_at_creases), None for a flat one (the mesh's own
    vertices); ``material_base``, the row of the object's material (a
    triangle's row is it, or ``material_base + 1 + face_material``)."""

    mesh: Mesh
    crease: float | None
    material_base: int = 0

    def triangle_materials(self) -> np.ndarray:
        """(F,) int32 material row of each triangle, as flatten_scene gives it."""
        ids = self.mesh.face_material
        if ids is None:
            return np.full(len(self.mesh.faces), self.material_base, np.int32)
        return (self.material_base + 1 + ids).astype(np.int32)


@dataclass
class SceneArrays:
    """The scene as the kernels see it, triangles in input order, positions in
    the device's frame: the scene's own, moved by ``-origin``
    (:func:`device_origin`; zeros for a scene near the origin).

    Where ``shading`` is set, a device makes ``tri_info`` and
    ``vertex_normals`` itself (and the corners, gathered from the uploaded
    vertices): those three hold :class:`Later` and are made on the host only
    if asked for."""

    corners: np.ndarray = _MadeOnUse()          # (F, 3, 3) float32 triangle corners, device frame
    tri_info: np.ndarray = _MadeOnUse()         # (F,) TRIANGLE_INFO
    vertex_normals: np.ndarray = _MadeOnUse()   # (V, 4) float32
    materials: np.ndarray        # (M,) MATERIAL
    lights: np.ndarray           # (L,) LIGHT, at least one record (OpenCL buffers cannot be empty), device frame
    bounds: np.ndarray           # (2, 3) float64, the scene's own frame
    detail: "SurfaceDetail | None" = None   # None: no textures or colours (a plain program)
    origin: np.ndarray = field(default_factory=lambda: np.zeros(3))   # (3,) float64: the device frame's
    #                                                                    origin, in the scene's frame
    instances: "Instances | None" = None     # an instanced scene's placements (placed_arrays), else None
    material_base: np.ndarray | None = None  # (I,) int32: each instance's first material row
    shading: ShadingSource | None = None     # the device makes the shading arrays (flatten_scene)

    @property
    def num_triangles(self) -> int:
        corners = self.__dict__["_corners"]      # (not made for a count)
        return corners.length if isinstance(corners, Later) else len(corners)

    @property
    def triangle_materials(self) -> np.ndarray:
        """(F,) int32: ``tri_info["material"]`` (without the crease split where
        the device made ``tri_info``)."""
        if self.shading is not None and isinstance(self.__dict__["_tri_info"], Later):
            return self.shading.triangle_materials()
        return self.tri_info["material"]


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


# ----------------------------------------------------------------------- the device's frame
#
# The device computes in float32, and some of its precision goes with the
# coordinates' magnitude rather than the scene's size: the box test widens
# every box plane by about 1e-6 of |coordinate| (volume_ray in
# kernels/volumes.cl), so far from the origin the BVH stops culling, and hit
# points and shading steps carry float32 rounding of that magnitude.  So the
# triangles go to the device (and to every BVH builder) in a frame of their
# own: moved by -c, c the device origin below, with every ray origin moved
# by -c too (camera eyes and lights on the host, in float64; batch origins
# on the device, load_ray in kernels/rays.cl).  Answers are not changed:
#
# * v - c is exact in float32 for every vertex coordinate v of the axis
#   (Sterbenz: c and v float32 of one sign, c/2 <= v <= 2c), so the device
#   holds the user's float32 mesh, moved, with no rounding;
# * the triangle test starts from A = v - o, and (v - c) - (o - c) rounds to
#   exactly what v - o does whenever o - c is exact too -- for every origin
#   within a factor two of c on each moved axis (Sterbenz again), and for
#   every float32 origin beyond c whose step is at most c's grain (c is a
#   multiple of it).  From there the test only sees differences and the
#   direction: t, u, v, prim, the normal and the face flag come out bit for
#   bit, whichever frame the BVH was built in (every walk finds the hits of
#   brute force, ties going to the lower index).  An origin that is not
#   exact rounds once, by half a float32 step of its distance from c: the
#   test's own first rounding, of v - o, is of that size anyway.
#
# Only axes on which the scene lies far from the origin move, so scenes near
# it keep their frame, bit for bit.  "Far": at least RECENTRE_DISTANCE
# diagonals of the scene's box.  Below that the widening is at most about
# 4 * 2^-20 * 16 = 6e-5 of the diagonal, which stops no culling above a few
# million triangles (a torus of 40k triangles lost nothing at 370 diagonals,
# docs/limits.md), and exactness (Sterbenz, above) needs only 1.25.
RECENTRE_DISTANCE = 16.0


def device_origin(bounds) -> np.ndarray:
    """(3,) float64 c, the origin of the device's frame for a scene whose box is
    ``bounds`` ((2, 3), float32 values): on each axis where the box lies
    RECENTRE_DISTANCE diagonals or more from 0, a float32 near the box's centre,
    a multiple of its grain: the largest power of two at most a quarter of the
    diagonal (so c lies within 1/8 diagonal of the centre and has few
    significant bits), or the float32 step at the box's far side where that is
    larger (so c is a float32) -- such that v - c is exact for every float32 v
    in the box; 0 on the other axes (the comment above says why)."""
    # Each step an IEEE operation in double, as the device's twin
    # (build_instances.cl's instance_frame, which chooses a moved scene's
    # frame) takes them: the same origin bit for bit.
    lo, hi = ([float(x) for x in np.asarray(b, np.float64)] for b in bounds)
    origin = np.zeros(3)
    dx, dy, dz = hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]
    diagonal = math.sqrt((dx * dx + dy * dy) + dz * dz)    # (Python's floats overflow to inf; NaN stays)
    if not math.isfinite(diagonal):
        return origin
    for k in range(3):
        near = min(abs(lo[k]), abs(hi[k]))            # the box's distance from 0 on this axis
        # (not >=: a box of one point with recentring off, RECENTRE_DISTANCE
        # infinite, compares with inf * 0 = NaN, and stays where it is)
        if lo[k] * hi[k] <= 0.0 or not near >= RECENTRE_DISTANCE * diagonal:
            continue
        far = max(abs(lo[k]), abs(hi[k]))
        # The largest power of two at most diagonal / 4: frexp's exponent is exact where log2 may round up.
        grain = max(float(np.spacing(np.float32(far))),
                    math.ldexp(1.0, math.frexp(diagonal / 4.0)[1] - 1) if diagonal > 0.0 else 0.0)
        c = round(0.5 * (lo[k] + hi[k]) / grain) * grain
        # Sterbenz for every v in [lo, hi]: c a float32 of their sign, c/2 <= |v| <= 2c.
        if float(np.float32(c)) == c and c * lo[k] > 0.0 and abs(c) <= 2.0 * near and far <= 2.0 * abs(c):
            origin[k] = c
    return origin


def triangle_corners(mesh: Mesh, origin=None) -> np.ndarray:
    """(F, 3, 3) float32 corners of a mesh's triangles (row = face index), moved
    by ``-origin`` (:func:`device_origin`: the subtraction is exact) when given."""
    # np.take: the same gather as mesh.vertices[mesh.faces], several times faster
    # (numpy 2.4); "clip" writes straight into ``out`` ("raise" fills a
    # temporary first), the faces being checked already; blocks of faces side
    # by side on a few threads (clrt.scene.blocks).
    vertices, faces = np.ascontiguousarray(mesh.vertices, np.float32), mesh.faces
    corners = np.empty((len(faces), 3, 3), np.float32)
    shift = np.asarray(origin, np.float32) if origin is not None and np.any(origin) else None

    def gather(start: int, stop: int) -> None:
        np.take(vertices, faces[start:stop], axis=0, out=corners[start:stop], mode="clip")
        if shift is not None:
            corners[start:stop] -= shift

    map_blocks(gather, len(faces))
    return corners


def triangle_verts(corners: np.ndarray) -> np.ndarray:
    """(F, 3, 3) corners -> (F,) TRIANGLE_VERTS records (the w lanes 0)."""
    records = np.zeros(len(corners), TRIANGLE_VERTS)
    for k, name in enumerate(("v0", "v1", "v2")):
        records[name][:, :3] = corners[:, k]
    return records


def flatten_scene(scene: Scene, pbr_textures: bool = False, device_shading: bool = False) -> SceneArrays:
    """One triangle list for all objects, each triangle tagged with its material:
    each object's ``material`` then its ``materials``, object after object.
    (An instanced scene, ``Scene.instanced``, is not flattened: it gives
    :func:`placed_arrays`.)

    ``pbr_textures``: upload the path tracer's textures too (emission,
    metallic-roughness, normal maps); without it only base colour textures
    get rows (the others' rows are -1), as the Whitted renderer reads no
    other -- a scene whose only textures are those then builds the plain
    program, and renders bit for bit as it did before they were read.

    ``device_shading``: the caller's device can make the shading arrays
    (clrt.device.crease): for a scene :func:`shading_source` finds one for,
    the arrays come back with ``shading`` set and the corners, tri_info and
    vertex normals left for the host to make only if asked for -- no crease
    split, no normals, no gather on the host."""
    if scene.instanced:
        return placed_arrays(scene, pbr_textures)
    source = shading_source(scene) if device_shading else None
    if source is not None:
        return _shaded_on_device(scene, source, pbr_textures)
    meshes = [o.mesh for o in scene.objects]
    mesh = meshes[0] if len(meshes) == 1 else Mesh.concatenate(meshes)   # (one object: no copy)
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

    textures = {}   # (id(Texture), linear) -> (row, Texture, linear), in order of first use
    flat_materials = []
    for o, mats in zip(scene.objects, object_materials):
        flat_materials += _texture_rows(mats, o.mesh.uv is not None, pbr_textures, textures)
    materials = material_rows(flat_materials)

    detail = None
    if textures or mesh.colors is not None:
        detail = surface_detail(mesh, [(tex, linear) for _, tex, linear in textures.values()])
    bounds = scene.bounds
    origin = device_origin(bounds)
    return SceneArrays(triangle_corners(mesh, origin), tri_info, normals, materials,
                       light_records(scene.lights, origin), bounds, detail, origin)


def shading_source(scene: Scene) -> ShadingSource | None:
    """The ShadingSource of a scene whose shading arrays a device can make
    itself -- one object, not placed, whose mesh has no authored normals and
    no corner colours, whose materials name no texture it could show --
    else None."""
    if len(scene.objects) != 1 or scene.instanced:
        return None
    o = scene.objects[0]
    mesh = o.mesh
    textured = mesh.uv is not None and any(getattr(m, name) is not None
                                           for m in (o.material, *o.materials) for name in MATERIAL_TEXTURES)
    if mesh.normals is not None or mesh.colors is not None or textured:
        return None
    split_of = mesh.crease_split_of
    if split_of is not None:
        return ShadingSource(split_of[0], split_of[1])
    return ShadingSource(mesh, None)


def _shaded_on_device(scene: Scene, source: ShadingSource, pbr_textures: bool) -> SceneArrays:
    """flatten_scene of a one-object scene whose shading arrays the device
    makes: the host's corners, tri_info and vertex normals are Later."""
    o = scene.objects[0]
    materials = material_rows(_texture_rows((o.material, *o.materials), False, pbr_textures, {}))
    bounds = scene.bounds
    origin = device_origin(bounds)
    mesh, count = o.mesh, source.mesh.num_triangles

    def tri_info() -> np.ndarray:
        info = np.zeros(count, TRIANGLE_INFO)
        info["vertex"] = mesh.faces        # (the crease split, made here)
        info["material"] = source.triangle_materials()
        return info

    def vertex_normals() -> np.ndarray:
        normals = np.zeros((len(mesh.vertices), 4), np.float32)
        normals[:, :3] = mesh.vertex_normals()
        return normals

    return SceneArrays(Later(lambda: triangle_corners(source.mesh, origin), count), Later(tri_info, count),
                       Later(vertex_normals), materials, light_records(scene.lights, origin), bounds, None,
                       origin, shading=source)


def _texture_rows(materials, uv: bool, pbr_textures: bool, textures: dict) -> list:
    """``(Material, {texture field: Texture row or -1})`` of an object's
    materials (``uv``: its mesh has texture coordinates), rows added to
    ``textures`` as first used.  A texture applies only to meshes with texture
    coordinates.  Each Texture gets one row per decoding (sRGB colour or linear
    data), however many materials and fields share it, and its texels are
    uploaded once."""
    out = []
    for mat in materials:
        rows = {}
        for name, linear in MATERIAL_TEXTURES.items():
            tex = getattr(mat, name) if uv and (pbr_textures or name == "texture") else None
            if tex is not None:
                rows[name] = textures.setdefault((id(tex), linear), (len(textures), tex, linear))[0]
            else:
                rows[name] = -1
        out.append((mat, rows))
    return out


def placed_arrays(scene: Scene, pbr_textures: bool = False) -> SceneArrays:
    """An instanced scene (``Scene.instanced``) as a two-level scene's device
    arrays (docs/instances.md): each placement of an object an instance --
    objects in order, each object's placements in order (an object without
    transforms once, where it stands) -- and each distinct Mesh object once,
    however many objects place it.

    ``corners``, ``tri_info`` and ``vertex_normals`` (and the surface detail)
    are then the distinct meshes', mesh after mesh, in their own frames
    (corners each in its own device frame, :func:`mesh_frames`), a
    triangle's ``material`` counting from its object's first material:
    ``material_base`` gives each instance's (objects with the same materials
    and the same kind of mesh, by identity, share their rows).  ``bounds``,
    ``origin`` and the lights are the world's."""
    instances = scene_instances(scene)
    blocks, material_base, textures, flat_materials = {}, [], {}, []
    for o in scene.objects:
        mats = (o.material, *o.materials)
        key = (o.mesh.uv is not None, *(id(m) for m in mats))
        if key not in blocks:
            blocks[key] = len(flat_materials)
            flat_materials += _texture_rows(mats, o.mesh.uv is not None, pbr_textures, textures)
        material_base += [blocks[key]] * o.placements
    meshes = instances.meshes
    mesh = Mesh.concatenate(meshes)
    tri_info = np.zeros(len(mesh.faces), TRIANGLE_INFO)
    tri_info["vertex"] = mesh.faces
    tri_info["material"] = np.concatenate([np.zeros(len(m.faces), np.int32) if m.face_material is None
                                           else 1 + m.face_material for m in meshes])
    normals = np.zeros((len(mesh.vertices), 4), np.float32)
    normals[:, :3] = np.concatenate([m.vertex_normals() for m in meshes])
    detail = None
    if textures or mesh.colors is not None:
        detail = surface_detail(mesh, [(tex, linear) for _, tex, linear in textures.values()])
    bounds = instances.bounds
    origin = device_origin(bounds)
    arrays = SceneArrays(np.concatenate(mesh_frames(meshes)[1]), tri_info, normals, material_rows(flat_materials),
                         light_records(scene.lights, origin), bounds, detail, origin)
    arrays.instances, arrays.material_base = instances, np.array(material_base, np.int32)
    return arrays


def moved_meshes(old: SceneArrays, new: SceneArrays) -> "list[int] | None":
    """The distinct meshes of a scene of placed meshes ``new`` whose corners
    differ from ``old``'s, where ``new`` is ``old``'s scene with vertices moved
    (and perhaps placements): the same distinct meshes, each with as many
    triangles, placed by the same instances with the same materials -- what
    a refit uploads anew.  None where either scene is not one of placed
    meshes or ``new`` is not such a scene."""
    a, b = old.instances, new.instances
    if a is None or b is None or len(a.meshes) != len(b.meshes) or not np.array_equal(a.mesh_of, b.mesh_of) \
            or not np.array_equal(old.material_base, new.material_base):
        return None
    counts = [len(m.faces) for m in b.meshes]
    if counts != [len(m.faces) for m in a.meshes]:
        return None
    first = np.cumsum([0] + counts)
    return [k for k in range(len(counts))
            if not np.array_equal(old.corners[first[k]:first[k + 1]], new.corners[first[k]:first[k + 1]])]


def mesh_frames(meshes) -> "tuple[np.ndarray, list[np.ndarray]]":
    """Each mesh's device frame (:func:`device_origin` of its own box: a
    two-level scene's meshes each have one) as (M, 3) float64 origins, and
    its corners in it ((F, 3, 3) float32 each)."""
    origins = np.stack([device_origin(m.bounds) for m in meshes])
    return origins, [triangle_corners(m, c) for m, c in zip(meshes, origins)]


def uses_pbr_textures(scene: Scene) -> bool:
    """Whether ``scene`` has a texture that only the path tracer reads
    (emission, metallic-roughness, normal map) on a mesh with texture
    coordinates: what ``flatten_scene(pbr_textures=True)`` adds."""
    return any(getattr(mat, name) is not None
               for o in scene.objects if o.mesh.uv is not None
               for mat in (o.material, *o.materials)
               for name in MATERIAL_TEXTURES if name != "texture")


def material_rows(flat_materials: list) -> np.ndarray:
    """(M,) MATERIAL rows of ``(Material, {texture field: Texture row or -1})``
    pairs: the Phong fields as they are, the path tracer's from
    :meth:`Material.pbr_values` (given, or mapped from Phong)."""
    materials = np.zeros(len(flat_materials), MATERIAL)
    for i, (mat, _) in enumerate(flat_materials):
        row = materials[i]
        row["color"][:3] = mat.color
        for name in ("ambient", "diffuse", "specular", "shininess", "reflectivity", "transparency", "ior"):
            row[name] = getattr(mat, name)
        row["flags"] = (MATERIAL_SMOOTH if mat.smooth else 0) | (MATERIAL_DOUBLE_SIDED if mat.double_sided else 0)
        row["emission"][:3] = mat.emission
        pbr = mat.pbr_values()
        for name in ("metallic", "roughness", "specular_weight", "transmission"):
            row[name] = getattr(pbr, name)
        row["specular_color"][:3] = mat.specular_color
        row["normal_scale"] = mat.normal_scale
    # Texture rows: int32 bits in the w lanes (as_int in the kernels), written as
    # integers so that no float conversion touches the bits of -1 (a NaN).
    rows = {name: np.array([r[name] for _, r in flat_materials], np.int32).reshape(-1)
            for name in MATERIAL_TEXTURES}
    for name, (field, lane) in _TEXTURE_LANES.items():
        materials[field].view(np.int32).reshape(len(materials), -1)[:, lane] = rows[name]
    materials["normal_texture"] = rows["normal_texture"]
    return materials


# Where each texture row of a Material lives in a MATERIAL row: (field, lane).
_TEXTURE_LANES = {"texture": ("color", 3), "emission_texture": ("emission", 3),
                  "metallic_roughness_texture": ("specular_color", 3)}


def surface_detail(mesh: Mesh, textures: list) -> SurfaceDetail:
    """Corner colours and texture coordinates of the concatenated ``mesh``, and
    the texture table of ``textures`` ((Texture, linear) pairs: rows 0.. in
    order), each Texture's texels once in one texel buffer."""
    tri_detail = np.zeros(len(mesh.faces), TRIANGLE_DETAIL)
    tri_detail["corner"][:, :, :3] = 1.0 if mesh.colors is None else mesh.colors
    if mesh.uv is not None:
        tri_detail["corner"][:, :, 3] = mesh.uv[:, :, 0]
        tri_detail["v"][:, :3] = mesh.uv[:, :, 1]
    images = list({id(tex): tex for tex, _ in textures}.values())   # each once, in order of first use
    sizes = [t.pixels.shape[0] * t.pixels.shape[1] for t in images]
    starts = np.cumsum([0] + sizes)
    if starts[-1] > np.iinfo(np.uint32).max:
        raise TooLargeError(f"the scene's textures hold {starts[-1]:,} texels, more than 2**32")
    texels = np.zeros((max(int(starts[-1]), 1),) + TEXEL.shape, TEXEL.base)
    first = {}
    for tex, start in zip(images, starts):
        h, w = tex.pixels.shape[:2]
        texels[start:start + w * h, :3] = tex.pixels.reshape(-1, 3)
        first[id(tex)] = start
    table = np.zeros(max(len(textures), 1), TEXTURE)
    for row, (tex, linear) in enumerate(textures):
        h, w = tex.pixels.shape[:2]
        table[row] = (first[id(tex)], w, h, TEXTURE_WRAPS[tex.wrap_s], TEXTURE_WRAPS[tex.wrap_t], int(linear))
    return SurfaceDetail(tri_detail, table, texels, srgb_table())


def light_records(lights, origin=None) -> np.ndarray:
    """(L,) LIGHT records of a list of Lights, at least one (OpenCL buffers cannot
    be empty); positions moved by ``-origin`` (in float64, then rounded) when given."""
    records = np.zeros(max(len(lights), 1), LIGHT)
    records["cos_outer"] = records["cos_inner"] = -1.0   # point lights: no cone
    shift = np.zeros(3) if origin is None else np.asarray(origin, np.float64)
    for i, light in enumerate(lights):
        records[i]["position"][:3] = np.asarray(light.position, np.float64) - shift
        records[i]["color"][:3] = light.color
        if light.direction is not None:   # a spot light
            records[i]["direction"][:3] = light.direction
            records[i]["cos_outer"] = np.cos(np.radians(light.cutoff))
            records[i]["cos_inner"] = np.cos(np.radians(light.beam))
    return records
