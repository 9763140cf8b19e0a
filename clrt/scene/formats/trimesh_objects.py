"""trimesh objects handed to clrt -- a ``trimesh.Trimesh`` or a ``trimesh.Scene``
(what ``trimesh.load`` gives) -- and the meshes of a file that trimesh reads (STL).

A trimesh object looks as its file does when clrt reads the file by path,
because what trimesh keeps of it goes through the same mappings as clrt's own
readers (the table in docs/scene-files.md):

* geometry: vertices and faces in their order.  A Scene's every Trimesh
  (points and paths are skipped) is placed by its node's world transform as
  the glTF reader places nodes (:func:`~clrt.scene.formats.part.placed`: a
  mirroring transform reverses the winding), in the order of
  ``scene.graph.nodes_geometry``.  trimesh's glTF loader (5.2.0) lists sibling
  nodes there in reverse file order, so the triangle ids of
  ``trimesh.load("x.glb")`` follow the file's nodes backwards where the file
  has several; each node's own triangles keep their order, and the image is
  the same.
* normals that came from the file (trimesh keeps loaded normals in its cache;
  it computes them only when asked).
* ``TextureVisuals``: texture coordinates and the material.  A
  ``PBRMaterial`` is mapped as the glTF reader maps a glTF material
  (:func:`~clrt.scene.formats.gltf.whitted_from_pbr` and
  :func:`~clrt.scene.formats.gltf.pbr_from_gltf`: its factors, emissiveFactor
  and doubleSided), with its base colour, metallicRoughness, normal and
  emissive textures; a ``SimpleMaterial`` as the OBJ reader
  maps an MTL material (:func:`~clrt.scene.formats.obj.mtl_material`:
  diffuse as Kd, specular as Ks, glossiness as Ns; ambient, like Ka, is not
  used), its ``image`` the texture; a ``MultiMaterial`` with
  ``face_materials`` gives each face its own.  The placeholder material
  trimesh makes for UVs without one (``empty_material()``) is no material:
  the faces get the object's own, as a file without materials does.
* ``ColorVisuals``: vertex or face colours, scaled to 0..1 by their integer
  type; sRGB, as PLY's and OFF's are -- except on a mesh trimesh read from a
  glTF file (its metadata has ``from_gltf_primitive``), whose colours are
  glTF's linear COLOR_0.
* images (PIL, any mode) become textures as file textures do
  (:meth:`~clrt.scene.texture.Texture.from_image`).

What trimesh (5.2.0) does not keep cannot be used: glTF samplers (textures
repeat, glTF's default wrap), the KHR_materials extensions (emissive
strength, specular, transmission, ior), normalTexture's scale, a texture set
other than TEXCOORD_0, MTL's ``-clamp``.  trimesh holds baseColorFactor
and MTL colours in 8 bits: a glTF factor that is no multiple of 1/255 comes
out up to 1/510 off (an MTL's own numbers, which trimesh keeps aside in
``kwargs``, are used where they agree with those 8 bits).  alphaMode and the
occlusion texture are not used, as the glTF reader does not use them.  trimesh's own
joining of a scene (``force="mesh"``) packs differing materials into one
atlas image, or drops them: clrt renders what it is handed.

trimesh itself is imported only when a file needs it (it takes seconds on
some machines); its objects are recognised by their attributes.
"""

from __future__ import annotations

import io
import os

import numpy as np

from clrt.errors import ClrtError, InputError, MeshLoadError
from clrt.scene.formats import tds
from clrt.scene.formats.gltf import GLTF_TEXTURES, pbr_from_gltf, whitted_from_pbr
from clrt.scene.formats.obj import mtl_material
from clrt.scene.formats.part import Part, build, fail, fill_normals, placed, short
from clrt.scene.mesh import Mesh
from clrt.scene.texture import Texture


def is_trimesh_scene(source) -> bool:
    """Whether ``source`` is a trimesh.Scene (a scene graph and its geometry)."""
    return hasattr(source, "geometry") and hasattr(getattr(source, "graph", None), "nodes_geometry")


def mesh_of(source) -> Mesh:
    """The Mesh of a trimesh.Trimesh, a trimesh.Scene or anything with
    ``vertices`` and ``faces`` (:func:`asset_of` without the materials)."""
    return asset_of(source)[0]


def asset_of(source) -> "tuple[Mesh, list]":
    """The mesh of a trimesh object and its materials, as dicts of clrt.Material
    fields that ``mesh.face_material`` indexes (what :func:`clrt.scene.load.load_asset`
    gives for the file by path; the module's docstring says what is taken).
    MeshLoadError naming the object, on one line, for anything wrong with it."""
    label = _label(source)
    materials = _Materials(label)
    try:
        if is_trimesh_scene(source):
            pieces = []
            for node in source.graph.nodes_geometry:
                transform, name = source.graph[node]
                geometry = source.geometry.get(name)
                if hasattr(geometry, "faces") and hasattr(geometry, "vertices") and len(geometry.faces):
                    pieces.append((geometry, np.asarray(transform, dtype=np.float64)))
            if not pieces:
                raise fail(label, "contains no triangles")
        else:
            pieces = [(source, None)]
        parts = []
        with np.errstate(all="ignore"):   # bad numbers are reported by Mesh.from_arrays
            for geometry, world in pieces:
                part = trimesh_part(geometry, linear_colors=_gltf_made(geometry), materials=materials)
                parts.append(part if world is None else placed(part, world))
            fill_normals(parts)
    except ClrtError:
        raise
    except Exception as exc:  # noqa: BLE001 -- trimesh objects can be built wrong in many ways
        raise fail(label, f"cannot read the trimesh object ({short(exc)})") from None
    for part in parts:
        part.materials = materials.fields
    return build(parts, label, "")


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
            parts.append(placed(trimesh_part(geometry, linear_colors=False), np.asarray(transform, np.float64)))
    except MeshLoadError:
        raise
    except Exception as exc:  # trimesh raises anything from KeyError to struct.error
        raise fail(path, f"corrupt or unsupported {file_type.upper()} file ({short(exc)})") from exc
    if not parts:
        raise fail(path, "contains no triangles")
    return parts


def trimesh_part(geometry, linear_colors: bool, materials: "_Materials | None" = None) -> Part:
    """Vertices, faces, and what a trimesh.Trimesh's visual holds: texture
    coordinates, vertex or face colours (sRGB unless ``linear_colors``),
    normals when they came from the file (trimesh keeps loaded normals in its
    cache; it only computes them when asked) and, given ``materials``, each
    face's material."""
    part = Part(np.asarray(geometry.vertices, dtype=np.float64), np.asarray(geometry.faces, dtype=np.int64))
    part.srgb_colors = not linear_colors
    cache = getattr(getattr(geometry, "_cache", None), "cache", {})
    if "vertex_normals" in cache:
        part.normals = np.asarray(geometry.vertex_normals, dtype=np.float64)
    visual = getattr(geometry, "visual", None)
    n_vertices = len(part.vertices)
    kind = getattr(visual, "kind", None)
    if kind == "texture":
        uv = getattr(visual, "uv", None)
        if uv is not None and len(uv) == n_vertices:
            part.uv = np.asarray(uv, dtype=np.float64)[part.faces]
        colors = getattr(visual, "vertex_attributes", {}).get("color")
        if colors is not None and len(colors) == n_vertices:
            part.vertex_colors = unit_colors(colors)
        if materials is not None:
            part.face_material = materials.face_ids(visual, len(part.faces))
    elif kind == "vertex":
        part.vertex_colors = unit_colors(visual.vertex_colors)
    elif kind == "face":
        part.face_colors = unit_colors(visual.face_colors)
    return part


def unit_colors(colors) -> np.ndarray:
    """(n, 3) float64 in 0..1 of RGB(A) colours stored as floats or as normalised integers."""
    c = np.atleast_2d(np.asarray(colors))
    scale = np.iinfo(c.dtype).max if np.issubdtype(c.dtype, np.integer) else 1.0
    return c[:, :3].astype(np.float64) / scale


def _label(source) -> str:
    """How messages name a trimesh object: ``trimesh.Trimesh 'cube.obj'``."""
    kind = type(source)
    name = (getattr(source, "metadata", None) or {}).get("name")
    return f"{kind.__module__.split('.')[0]}.{kind.__name__}" + (f" {name!r}" if isinstance(name, str) else "")


def _gltf_made(geometry) -> bool:
    """Whether trimesh's glTF loader made this mesh (its colours are then COLOR_0's, linear)."""
    metadata = getattr(geometry, "metadata", None)
    return isinstance(metadata, dict) and "from_gltf_primitive" in metadata


# The MTL statements trimesh's OBJ loader keeps in a SimpleMaterial's kwargs
# (lower case, as lists of words; kd, ks and ns as numbers).
_MTL_NUMBERS = {"d": "d", "tr": "Tr", "ni": "Ni", "illum": "illum"}


class _Materials:
    """The materials of a trimesh object's geometries, as dicts of clrt.Material
    fields, each material once (in the order first met), each image once."""

    def __init__(self, label: str):
        self.label = label
        self.fields: list = []
        self._ids: dict = {}        # id(trimesh material) -> (material, index or -1)
        self._textures: dict = {}   # id(image) -> (image, Texture)

    def face_ids(self, visual, n_faces: int) -> "np.ndarray | None":
        """(F,) index into :attr:`fields` of each face of a TextureVisuals; None for none."""
        material = getattr(visual, "material", None)
        if isinstance(getattr(material, "materials", None), list):   # a MultiMaterial
            ids = np.array([self.index(m) for m in material.materials] or [-1], dtype=np.int64)
            chosen = getattr(visual, "face_materials", None)
            chosen = np.zeros(n_faces, np.int64) if chosen is None else np.asarray(chosen).reshape(-1)
            if len(chosen) != n_faces or not np.issubdtype(chosen.dtype, np.integer) or chosen.size and (
                    chosen.min() < 0 or chosen.max() >= len(ids)):
                raise fail(self.label, f"face_materials must be {n_faces} integers indexing its "
                                       f"{len(material.materials)} materials")
            out = ids[chosen]
        else:
            out = np.full(n_faces, self.index(material), dtype=np.int64)
        return out if (out >= 0).any() else None

    def index(self, material) -> int:
        """The index of a trimesh material's fields (mapped when first met); -1 for none."""
        key = id(material)
        if key not in self._ids:
            fields = None if material is None else self._mapped(material)
            self._ids[key] = (material, -1 if fields is None else len(self.fields))
            if fields is not None:
                self.fields.append(fields)
        return self._ids[key][1]

    def _mapped(self, material) -> "dict | None":
        name = getattr(material, "name", None)
        where = f"material {name!r}" if isinstance(name, str) else f"material {len(self._ids)}"
        if hasattr(material, "baseColorFactor") and hasattr(material, "metallicFactor"):   # PBRMaterial
            pbr = {}
            if material.baseColorFactor is not None:
                pbr["baseColorFactor"] = list(unit_colors(material.baseColorFactor)[0])
            for key in ("metallicFactor", "roughnessFactor"):
                value = getattr(material, key)
                if value is not None:
                    pbr[key] = self._number(value, f"{where}: {key}")
            if not np.isfinite(pbr.get("baseColorFactor", [0.0])).all():
                raise fail(self.label, f"{where}: baseColorFactor must be finite")
            gltf = {"pbrMetallicRoughness": pbr, "doubleSided": bool(getattr(material, "doubleSided", False))}
            emissive = getattr(material, "emissiveFactor", None)
            if emissive is not None:
                gltf["emissiveFactor"] = [float(e) for e in np.asarray(emissive, np.float64).reshape(-1)]
            try:
                pbr_fields = pbr_from_gltf(gltf, where)
            except InputError as exc:
                raise fail(self.label, str(exc)) from None
            fields = {**whitted_from_pbr(pbr), **pbr_fields}   # trimesh keeps none of the extensions
            for field, (_, key) in GLTF_TEXTURES.items():
                texture = self._texture(getattr(material, key, None), where)
                if texture is not None:
                    fields[field] = texture
            return fields
        if hasattr(material, "diffuse") and hasattr(material, "glossiness"):      # SimpleMaterial
            if _placeholder(material):
                return None
            return mtl_material(self._mtl(material, where), where, self.label)
        return None   # a kind of material clrt does not know: the object's own applies

    def _mtl(self, material, where: str) -> dict:
        """The MTL statements a SimpleMaterial stands for: those of the MTL file
        trimesh read it from (kept in its kwargs), else those trimesh's OBJ
        export writes (Kd, Ks and Ns from diffuse, specular and glossiness)."""
        kwargs = getattr(material, "kwargs", None) or {}
        image = getattr(material, "image", None)
        from_mtl = bool(kwargs) or "file_path" in (getattr(image, "info", None) or {})
        m = {}
        for key, attribute in (("Kd", "diffuse"), ("Ks", "specular")):
            kept, value = kwargs.get(key.lower()), getattr(material, attribute)
            eight_bits = None if value is None else unit_colors(value)[0]
            if kept is not None:
                numbers = [self._number(x, f"{where}: {key}") for x in np.atleast_1d(kept).tolist()]
                kept = (numbers * 3)[:3]
                if eight_bits is None or np.array_equal(np.rint(np.clip(np.asarray(kept) * 255, 0, 255)),
                                                        np.rint(eight_bits * 255)):
                    m[key] = kept   # the file's own numbers, not trimesh's 8 bits of them
                    continue
            elif from_mtl and value is not None and np.array_equal(eight_bits, _TRIMESH_DEFAULT_COLOR):
                continue            # trimesh's default: the file had no such statement
            if eight_bits is not None:
                m[key] = [float(c) for c in eight_bits]
        glossiness, kept = getattr(material, "glossiness", None), kwargs.get("ns")
        if glossiness is not None and not (from_mtl and kept is None and glossiness == 1.0):
            m["Ns"] = self._number(glossiness, f"{where}: glossiness")
        for key, statement in _MTL_NUMBERS.items():
            if key in kwargs:
                words = np.atleast_1d(kwargs[key]).tolist()
                m[statement] = self._number(words[0] if words else "", f"{where}: {statement}")
        texture = self._texture(image, where)
        if texture is not None:
            m["texture"] = texture
        return m

    def _number(self, value, what: str) -> float:
        try:
            number = float(value)
        except (TypeError, ValueError):
            number = float("nan")
        if not np.isfinite(number):
            raise fail(self.label, f"{what} must be a finite number, got {str(value)[:40]!r}")
        return number

    def _texture(self, image, where: str) -> "Texture | None":
        """The Texture of a material's PIL image (any mode), converted as file
        textures are (:meth:`Texture.from_image`); wraps repeat, glTF's default
        (trimesh keeps no samplers)."""
        if image is None:
            return None
        if id(image) not in self._textures:
            if not (hasattr(image, "mode") and hasattr(image, "convert")):
                raise fail(self.label, f"{where}: its texture image must be a PIL image, got {type(image).__name__}")
            info = getattr(image, "info", None) or {}
            name = os.path.basename(str(info.get("file_path", ""))) or f"{where} image"
            try:
                texture = Texture.from_image(image, "repeat", "repeat", name)
            except InputError as exc:
                raise fail(self.label, f"{where}: {exc}") from None
            except Exception as exc:  # noqa: BLE001 -- PIL: OSError, SyntaxError, ... for a broken image
                raise fail(self.label, f"{where}: cannot read its texture image ({short(exc)})") from None
            self._textures[id(image)] = (image, texture)
        return self._textures[id(image)][1]


# trimesh's colour for a SimpleMaterial colour it was not given (color.DEFAULT_COLOR), in 0..1.
_TRIMESH_DEFAULT_COLOR = np.array([102, 102, 102]) / 255.0


def _placeholder(material) -> bool:
    """Whether a SimpleMaterial is trimesh's stand-in for no material
    (``empty_material()``, which TextureVisuals makes for UVs alone)."""
    if getattr(material, "kwargs", None):   # trimesh's OBJ loader made it, from an MTL file
        return False
    if getattr(getattr(material, "image", None), "size", None) != (2, 2):   # a quick no before hashing an image
        return False
    try:
        from trimesh.visual.material import empty_material
        return hash(material) == hash(empty_material())
    except Exception:  # noqa: BLE001 -- another trimesh, or none: then it is a material
        return False
