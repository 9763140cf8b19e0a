"""glTF 2.0, as JSON (``.gltf``) or binary (``.glb``): geometry, materials,
images and the first perspective camera, read from the JSON document and its
buffers.

Read: every node of the scene with its world transform (an instanced mesh
appears once per node); triangles, strips and fans (points and lines are
skipped); POSITION, NORMAL, TEXCOORD_n (the base colour texture's set) and
COLOR_0 (linear); sparse and normalised-integer accessors; buffers and images
as data URIs, the GLB's binary chunk or regular files in the file's folder;
materials' metallic-roughness model: base colour, metallicRoughness, normal
and emissive textures (with their samplers' wrap modes), their factors,
normalTexture's scale, doubleSided, KHR_materials_emissive_strength,
KHR_materials_specular (its factors), KHR_materials_transmission and
KHR_materials_ior -- mapped onto the Whitted model too (the table in
docs/scene-files.md).  Draco- and meshopt-compressed primitives are refused.

Faces come in a depth-first walk of the scene's nodes in file order (the
scene's ``nodes`` in order, each node followed by its ``children`` in order,
each child's own children before the next child), within a node its mesh's
primitives in order, within a primitive its triangles in index order, strips
and fans triangulated as the glTF specification numbers them.

Read here rather than by trimesh, whose reader (5.2.0) drops sparse
accessors and TRIANGLE_FAN primitives, takes normalised-integer texture
coordinates as they are, quantises COLOR_0 to 8 bits, ignores a mirroring
node's winding and orders nodes by its graph, not by the file.
"""

from __future__ import annotations

import io
import math
import os
import struct

from dataclasses import replace

import numpy as np

from clrt.config import DEFAULT_DIFFUSE, MATERIAL_RANGES, MAX_COORDINATE, MAX_SPECULAR_COLOR
from clrt.errors import InputError, MeshLoadError
from clrt.scene.formats.part import Part, build, fail, fill_normals, first_cycle, placed, read_bytes, short
from clrt.scene.mesh import Mesh
from clrt.scene.texture import Texture


def read_gltf(data: bytes, path: str, name: str) -> "tuple[Mesh, list]":
    """The mesh of a .gltf file's bytes and its materials."""
    return build(_gltf_parts(data, "gltf", path), path, name)


def read_glb(data: bytes, path: str, name: str) -> "tuple[Mesh, list]":
    """The mesh of a .glb file's bytes and its materials."""
    return build(_gltf_parts(data, "glb", path), path, name)


def gltf_camera(path: str) -> dict | None:
    """:func:`_file_camera` of a .gltf file."""
    return _file_camera(path, ".gltf")


def glb_camera(path: str) -> dict | None:
    """:func:`_file_camera` of a .glb file."""
    return _file_camera(path, ".glb")


_GLTF_COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32,
                    5126: np.float32}
_GLTF_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_GLTF_COMPRESSION = ("KHR_draco_mesh_compression", "EXT_meshopt_compression")
_GLTF_WRAPS = {10497: "repeat", 33071: "clamp", 33648: "mirror"}
_GLTF_MAX_ACCESSOR = 1 << 28   # bytes of an accessor without a bufferView (all zeros, or sparse)


class _GltfError(ValueError):
    """What is wrong with a glTF file's content, in words."""


def _gltf_int(value, what: str, low: int = 0) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise _GltfError(f"{what} is {value!r}, not an integer >= {low}")
    return value


class _GltfFile:
    """A glTF document and its buffers (read when first needed): accessors,
    primitives and images."""

    def __init__(self, doc: dict, data: bytes, file_type: str, path: str):
        self.doc, self.path = doc, path
        self.folder = os.path.dirname(os.path.abspath(path))
        self.buffers: dict = {}
        self.glb_bin = None
        if file_type == "glb":
            offset = 20 + struct.unpack_from("<I", data, 12)[0]
            if len(data) >= offset + 8:
                length, kind = struct.unpack_from("<II", data, offset)
                if kind == 0x004E4942:   # "BIN\0"
                    if len(data) < offset + 8 + length:
                        raise _GltfError(f"truncated GLB file (its binary chunk is {length} bytes, the file "
                                         f"holds {len(data) - offset - 8})")
                    self.glb_bin = memoryview(data)[offset + 8:offset + 8 + length]

    def item(self, kind: str, index, what: str) -> dict:
        items = self.doc.get(kind)
        n = len(items) if isinstance(items, list) else 0
        if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < n:
            raise _GltfError(f"{what} {index!r} does not exist (the file has {n})")
        if not isinstance(items[index], dict):
            raise _GltfError(f"{what} {index} is not an object")
        return items[index]

    def uri(self, uri, what: str) -> "bytes | None":
        """The bytes a URI names: a data URI, or a regular file in the file's
        folder (None if there is no such file)."""
        import base64
        import urllib.parse
        if not isinstance(uri, str):
            raise _GltfError(f"{what}: uri is not a string")
        if uri.startswith("data:"):
            head, sep, body = uri.partition(",")
            if not sep:
                raise _GltfError(f"{what}: malformed data URI")
            try:
                return base64.b64decode(body) if head.endswith(";base64") else urllib.parse.unquote_to_bytes(body)
            except ValueError:
                raise _GltfError(f"{what}: bad base64 in its data URI") from None
        name = urllib.parse.unquote(uri)
        folder = os.path.realpath(self.folder)
        full = os.path.realpath(os.path.join(folder, name))
        if os.path.isabs(name) or os.path.commonpath([full, folder]) != folder:
            raise _GltfError(f"{what}: '{uri}' escapes the folder of the file")
        if not os.path.exists(full):
            return None
        if not os.path.isfile(full):   # a FIFO or device could block forever
            raise _GltfError(f"{what}: '{uri}' is not a regular file")
        with open(full, "rb") as fh:
            return fh.read()

    def buffer(self, index) -> memoryview:
        if index not in self.buffers:
            b = self.item("buffers", index, "buffer")
            if "uri" not in b:
                if self.glb_bin is None or index != 0:
                    raise _GltfError(f"buffer {index} has no uri and the file no binary chunk")
                data = self.glb_bin
            else:
                data = self.uri(b["uri"], f"buffer {index}")
                if data is None:
                    raise _GltfError(f"buffer {index}: no such file '{b['uri']}'")
            length = _gltf_int(b.get("byteLength", len(data)), f"buffer {index} byteLength")
            if len(data) < length:
                raise _GltfError(f"buffer {index} holds {len(data)} bytes, its byteLength says {length}")
            self.buffers[index] = memoryview(data)[:length]
        return self.buffers[index]

    def _view_array(self, view_index, offset, dtype, width: int, count: int, what: str) -> np.ndarray:
        """(count, width) elements of ``dtype`` (little-endian) from a bufferView."""
        view = self.item("bufferViews", view_index, "bufferView")
        buf = self.buffer(view.get("buffer"))
        start = _gltf_int(view.get("byteOffset", 0), f"bufferView {view_index} byteOffset")
        length = _gltf_int(view.get("byteLength"), f"bufferView {view_index} byteLength")
        offset = _gltf_int(offset, f"{what} byteOffset")
        if start + length > len(buf):
            raise _GltfError(f"bufferView {view_index} ends past the end of its buffer")
        dtype = np.dtype(dtype).newbyteorder("<")
        size = dtype.itemsize * width
        stride = _gltf_int(view.get("byteStride", 0), f"bufferView {view_index} byteStride") or size
        if stride < size:
            raise _GltfError(f"{what}: bufferView {view_index} byteStride {stride} is less than an element")
        if count == 0:
            return np.zeros((0, width), dtype.newbyteorder("="))
        total = stride * (count - 1) + size
        if offset + total > length:
            raise _GltfError(f"{what} reads past the end of bufferView {view_index}")
        raw = np.frombuffer(buf, np.uint8, count=total, offset=start + offset)
        if stride != size:
            padded = np.zeros(stride * count, np.uint8)
            padded[:total] = raw
            raw = np.ascontiguousarray(padded.reshape(count, stride)[:, :size]).reshape(-1)
        return raw.view(dtype).reshape(count, width).astype(dtype.newbyteorder("="))

    def accessor(self, index, what: str, widths=None) -> "tuple[np.ndarray, bool]":
        """An accessor's elements (count, width), sparse values applied, in
        their stored type; and whether they are normalised integers."""
        a = self.item("accessors", index, "accessor")
        where = f"{what} (accessor {index})"
        dtype = _GLTF_COMPONENTS.get(a.get("componentType"))
        width = _GLTF_WIDTHS.get(a.get("type"))
        if dtype is None or width is None:
            raise _GltfError(f"{where}: unknown componentType {a.get('componentType')!r} or type {a.get('type')!r}")
        if widths is not None and width not in widths:
            raise _GltfError(f"{where} has type {a.get('type')}")
        count = _gltf_int(a.get("count"), f"{where} count")
        if "bufferView" in a:
            out = self._view_array(a["bufferView"], a.get("byteOffset", 0), dtype, width, count, where)
        else:
            if count * width * np.dtype(dtype).itemsize > _GLTF_MAX_ACCESSOR:
                raise _GltfError(f"{where}: count {count} without a bufferView is too large")
            out = np.zeros((count, width), dtype)
        sparse = a.get("sparse")
        if sparse is not None:
            if not isinstance(sparse, dict) or not isinstance(sparse.get("indices"), dict) \
                    or not isinstance(sparse.get("values"), dict):
                raise _GltfError(f"{where}: malformed sparse")
            n = _gltf_int(sparse.get("count"), f"{where} sparse count", 1)
            ind, val = sparse["indices"], sparse["values"]
            index_type = {5121: np.uint8, 5123: np.uint16, 5125: np.uint32}.get(ind.get("componentType"))
            if index_type is None:
                raise _GltfError(f"{where}: sparse indices of componentType {ind.get('componentType')!r}")
            rows = self._view_array(ind.get("bufferView"), ind.get("byteOffset", 0), index_type, 1, n,
                                    f"{where} sparse indices")[:, 0].astype(np.int64)
            values = self._view_array(val.get("bufferView"), val.get("byteOffset", 0), dtype, width, n,
                                      f"{where} sparse values")
            if rows.max() >= count:
                raise _GltfError(f"{where}: sparse index {rows.max()} past its {count} elements")
            out = out.copy()
            out[rows] = values
        return out, bool(a.get("normalized", False))

    def floats(self, index, what: str, widths) -> np.ndarray:
        """An accessor's elements as float64, normalised integers mapped to 0..1 (-1..1 signed)."""
        values, normalized = self.accessor(index, what, widths)
        if normalized and np.issubdtype(values.dtype, np.integer):
            top = float(np.iinfo(values.dtype).max)
            return np.maximum(values / top, -1.0)
        return values.astype(np.float64)

    def primitive(self, mesh: int, k: int, prim) -> Part | None:
        """One primitive's triangles in the mesh's own space (None: points,
        lines, or no POSITION); faces in index order, strips and fans
        triangulated as the glTF specification numbers them."""
        where = f"meshes[{mesh}].primitives[{k}]"
        if not isinstance(prim, dict):
            raise _GltfError(f"{where} is not an object")
        compressed = [e for e in _GLTF_COMPRESSION if e in (prim.get("extensions") or {})]
        if compressed:
            raise _GltfError(f"{where} is compressed with {compressed[0]}, which clrt does not read")
        mode = prim.get("mode", 4)
        if mode in (0, 1, 2, 3):
            return None
        if mode not in (4, 5, 6):
            raise _GltfError(f"{where}: unknown mode {mode!r}")
        attributes = prim.get("attributes")
        if not isinstance(attributes, dict) or "POSITION" not in attributes:
            return None
        vertices = self.floats(attributes["POSITION"], f"{where}.attributes.POSITION", (3,))
        n = len(vertices)
        if "indices" in prim:
            values, _ = self.accessor(prim["indices"], f"{where}.indices", (1,))
            if not np.issubdtype(values.dtype, np.unsignedinteger):
                raise _GltfError(f"{where}.indices are not unsigned integers")
            index = values[:, 0].astype(np.int64)
        else:
            index = np.arange(n, dtype=np.int64)
        if index.size and index.max() >= n:
            raise _GltfError(f"{where}: vertex index {index.max()} past its {n} vertices")
        if mode == 4:
            if len(index) % 3:
                raise _GltfError(f"{where}: {len(index)} triangle indices, not a multiple of 3")
            faces = index.reshape(-1, 3)
        else:
            i = np.arange(max(len(index) - 2, 0))
            if mode == 5:   # strip: (i, i + 1, i + 2), the odd ones as (i, i + 2, i + 1)
                faces = np.stack([index[i], index[i + 1 + i % 2], index[i + 2 - i % 2]], axis=1)
            else:           # fan: (0, i + 1, i + 2)
                faces = np.stack([index[np.zeros_like(i)], index[i + 1], index[i + 2]], axis=1)
        part = Part(vertices, faces.reshape(-1, 3), srgb_colors=False)   # COLOR_0 is linear
        if "NORMAL" in attributes:
            part.normals = self.floats(attributes["NORMAL"], f"{where}.attributes.NORMAL", (3,))
        texcoord = 0
        if "material" in prim:
            material = self.item("materials", prim["material"], f"{where}.material")
            infos = list(gltf_texture_infos(material).values())   # the base colour's first
            if infos:
                texcoord = infos[0].get("texCoord", 0)
            part.face_material = np.full(len(part.faces), prim["material"], dtype=np.int64)
        key = f"TEXCOORD_{texcoord}"
        if key in attributes:
            uv = self.floats(attributes[key], f"{where}.attributes.{key}", (2,))
            uv[:, 1] = 1.0 - uv[:, 1]   # glTF's v runs down the image; clrt's (OBJ's) up
            part.uv = uv[part.faces] if len(uv) == n else None
        if "COLOR_0" in attributes:
            colors = self.floats(attributes["COLOR_0"], f"{where}.attributes.COLOR_0", (3, 4))
            part.vertex_colors = np.clip(colors[:, :3], 0.0, 1.0) if len(colors) == n else None
        for name, array in (("NORMAL", part.normals),):
            if array is not None and len(array) != n:
                raise _GltfError(f"{where}.attributes.{name} has {len(array)} elements, POSITION {n}")
        return part

    def image(self, texture_index):
        """The PIL image of a texture; None for one in an extension's format
        only, or an image file that is not there."""
        texture = self.item("textures", texture_index, "texture")
        source = texture.get("source")
        if source is None:
            return None
        image = self.item("images", source, "image")
        if "bufferView" in image:
            view = self.item("bufferViews", image["bufferView"], "bufferView")
            data = self._view_array(image["bufferView"], 0, np.uint8, 1, _gltf_int(
                view.get("byteLength"), "bufferView byteLength"), f"image {source}").tobytes()
        elif "uri" in image:
            data = self.uri(image["uri"], f"image {source}")
        else:
            data = None
        if data is None:
            return None
        from PIL import Image
        try:
            with Image.open(io.BytesIO(data)) as opened:
                opened.load()
                return opened.copy()
        except (OSError, ValueError, Image.DecompressionBombError) as exc:
            raise _GltfError(f"image {source}: cannot read the texture image ({type(exc).__name__})") from None


def _gltf_walk(doc: dict):
    """``(node index, node, world matrix)`` of each node of the file's scene
    (``scene``, else the first; without scenes, every node that is no node's
    child, in file order), depth first in file order: a root node, then its
    children in their ``children`` order, each with its own children before
    the next; a node reached twice (two parents) is visited once (_gltf_parts
    refuses a cycle)."""
    nodes = doc.get("nodes", [])
    scenes = doc.get("scenes", [])
    if scenes:
        roots = scenes[doc.get("scene", 0)].get("nodes", [])
    else:
        children = {c for node in nodes for c in node.get("children", [])}
        roots = [i for i in range(len(nodes)) if i not in children]
    stack = [(int(i), np.eye(4)) for i in reversed(list(roots))]
    seen = set()
    while stack:
        index, parent = stack.pop()
        if index in seen:
            continue
        seen.add(index)
        node = nodes[index]
        world = parent @ _node_matrix(node)
        yield index, node, world
        stack += [(int(c), world) for c in reversed(node.get("children", []))]


def _gltf_parts(data: bytes, file_type: str, path: str, nodes: list | None = None) -> list[Part]:
    """Every triangle of a glTF file's scene, with its normals, texture
    coordinates, vertex colours and materials.

    Face order: nodes as :func:`_gltf_walk` visits them, in each node's mesh
    its primitives in order, in each primitive its triangles in index order
    (an instanced mesh appears once per node).  Each node's world transform is
    applied; a node whose transform mirrors (negative determinant) has its
    triangles' corners 1 and 2 swapped (and their texture coordinates), so
    that faces still face out, as the glTF specification says.  A primitive
    without NORMAL gets its smooth (area-weighted) normals when another
    primitive of the file has authored ones, which are kept.  With ``nodes``
    (gltf_nodes), each primitive goes there unplaced instead, with its node."""
    kind = file_type.upper()
    try:
        doc = _gltf_json(data, "." + file_type)
        if file_type == "glb" and len(data) < struct.unpack_from("<I", data, 8)[0]:
            raise ValueError(f"truncated GLB file (header says {struct.unpack_from('<I', data, 8)[0]} "
                             f"bytes, the file has {len(data)})")
    except Exception as exc:  # noqa: BLE001 -- named in words
        raise fail(path, f"corrupt or unsupported {kind} file: {_gltf_json_problem(exc)}") from None
    problem = _gltf_reference_problem(doc)
    if problem:
        raise fail(path, f"corrupt {kind} file: {problem}")
    cycle = first_cycle([node.get("children", []) for node in doc.get("nodes", [])])
    if cycle is not None:
        raise fail(path, f"corrupt {kind} file: node {cycle} is its own ancestor (the nodes make a cycle)")
    try:
        gltf = _GltfFile(doc, data, file_type, path)
        with np.errstate(all="ignore"):  # bad numbers are reported by Mesh.from_arrays
            materials = _gltf_materials(gltf)
            cache, parts = {}, []
            for index, node, world in _gltf_walk(doc):
                if "mesh" not in node:
                    continue
                primitives = gltf.item("meshes", node["mesh"], "mesh").get("primitives", [])
                for k, primitive in enumerate(primitives):
                    key = (node["mesh"], k)
                    if key not in cache:
                        cache[key] = gltf.primitive(node["mesh"], k, primitive)
                    if cache[key] is not None and len(cache[key].faces) and nodes is not None:
                        nodes.append((index, node["mesh"], world, replace(cache[key], materials=materials)))
                    elif cache[key] is not None and len(cache[key].faces):
                        parts.append(replace(placed(cache[key], world), materials=materials))
            fill_normals(parts)
    except MeshLoadError:
        raise
    except _GltfError as exc:
        raise fail(path, f"corrupt or unsupported {kind} file: {exc}") from None
    except Exception as exc:  # noqa: BLE001 -- a malformed document (a string where an object belongs, ...)
        raise fail(path, f"corrupt or unsupported {kind} file ({short(exc)})") from exc
    if not parts and not nodes:
        raise fail(path, "contains no triangles")
    return parts


def gltf_nodes(path: str) -> list:
    """A glTF file's scene as its nodes place it, nothing moved:
    ``(node index, mesh index, the node's world matrix, a primitive of the
    mesh as a Part in the mesh's own space)`` for each primitive of each mesh
    node, in read_gltf's order (clrt.scene.instances makes instances of them)."""
    nodes: list = []
    _gltf_parts(read_bytes(path), os.path.splitext(path)[1].lower()[1:], path, nodes)
    return nodes


def gltf_shares_meshes(path: str) -> bool:
    """Does a glTF/GLB file's scene place a mesh in several nodes (the renderer
    keeps those as instances)?  From the JSON; False where that fails."""
    ext = os.path.splitext(path)[1].lower()
    try:
        doc = _gltf_json(_glb_json_bytes(path) if ext == ".glb" else read_bytes(path), ext)
        cycle = first_cycle([n.get("children", []) for n in doc.get("nodes", [])])
        if _gltf_reference_problem(doc) or cycle is not None:
            return False
        meshes = [node["mesh"] for _, node, _ in _gltf_walk(doc) if "mesh" in node]
    except Exception:  # noqa: BLE001 -- any problem is the reader's to report
        return False
    return len(set(meshes)) < len(meshes)


def whitted_from_pbr(pbr: dict, extensions: dict | None = None) -> dict:
    """Material fields (clrt.Material) of a glTF material's
    ``pbrMetallicRoughness`` values and ``extensions`` (the table in
    docs/scene-files.md), its texture aside: base colour (``baseColorFactor``,
    its alpha unused), metallic/roughness to diffuse, specular, shininess and
    reflectivity, KHR_materials_transmission and KHR_materials_ior to
    transparency and ior.  A key left out has glTF's default.  Also how a
    trimesh PBRMaterial is mapped (:mod:`clrt.scene.formats.trimesh_objects`)."""
    extensions = extensions or {}
    base = [float(c) for c in pbr.get("baseColorFactor", [1.0] * 4)][:3]
    metallic = min(max(float(pbr.get("metallicFactor", 1.0)), 0.0), 1.0)
    roughness = min(max(float(pbr.get("roughnessFactor", 1.0)), 0.0), 1.0)
    reflectivity = metallic * (1.0 - roughness)
    fields = {"color": tuple(min(max(c, 0.0), 1.0) for c in base),
              "diffuse": DEFAULT_DIFFUSE * (1.0 - reflectivity),
              "specular": 1.0 - roughness,
              # the highlight's width: Blinn-Phong's exponent 2 / alpha^2 - 2 (alpha = roughness^2),
              # divided by 4 for the Phong (R.V)^n lobe the shader uses, whose angle to the
              # mirror direction is about twice the half-vector's angle to the normal
              "shininess": min(max((2.0 / max(roughness ** 4, 1e-6) - 2.0) / 4.0, 1.0), 1000.0),
              "reflectivity": reflectivity}
    transmission = extensions.get("KHR_materials_transmission", {}).get("transmissionFactor", 0.0)
    if transmission:
        fields["transparency"] = min(max(float(transmission), 0.0), 1.0)
    if "KHR_materials_ior" in extensions:
        fields["ior"] = min(max(float(extensions["KHR_materials_ior"].get("ior", 1.5)), 1.0),
                            MATERIAL_RANGES["ior"][1])
    return fields


#: The textures of a glTF material: Material field -> (where the textureInfo
#: is: in pbrMetallicRoughness or at the material's top level, its key).
GLTF_TEXTURES = {"texture": ("pbr", "baseColorTexture"),
                 "metallic_roughness_texture": ("pbr", "metallicRoughnessTexture"),
                 "normal_texture": ("top", "normalTexture"),
                 "emission_texture": ("top", "emissiveTexture")}


def gltf_texture_infos(material: dict) -> dict:
    """``{Material field: textureInfo}`` of the textures a glTF material names
    (GLTF_TEXTURES), the base colour's first.  A primitive's texture
    coordinates are the set (``texCoord``) of the first: one set per material."""
    pbr = material.get("pbrMetallicRoughness") or {}
    infos = {field: (pbr if place == "pbr" else material).get(key) for field, (place, key) in GLTF_TEXTURES.items()}
    return {field: info for field, info in infos.items() if isinstance(info, dict)}


def pbr_from_gltf(material: dict, where: str) -> dict:
    """The path tracer's Material fields of a glTF material (its JSON object),
    its textures aside (the table in docs/scene-files.md): metallicFactor,
    roughnessFactor; emission = emissiveFactor x
    KHR_materials_emissive_strength's emissiveStrength (linear radiance, as
    Mitsuba and Blender read it); KHR_materials_specular's specularFactor and
    specularColorFactor; KHR_materials_transmission's transmissionFactor;
    doubleSided; normalTexture's scale.  A key left out has glTF's default.
    InputError ``'<where> <key> must be ..., got ...'`` for a value that is not
    finite or out of its range (a negative emission, a metallicFactor of 2);
    ``where`` names the material.  Also how a trimesh PBRMaterial is mapped."""
    from clrt import checks
    pbr = material.get("pbrMetallicRoughness") or {}
    extensions = material.get("extensions") or {}

    def factor(table, key, default, hi=1.0):
        return checks.number(f"{where} {key}", table.get(key, default), ge=0, le=hi)

    strength_table = extensions.get("KHR_materials_emissive_strength") or {}
    # (glTF caps emissiveFactor at 1, leaving brighter to the strength; a factor
    # above 1 is taken as the radiance it says all the same)
    emissive = checks.intensity(f"{where} emissiveFactor", material.get("emissiveFactor", [0.0, 0.0, 0.0]))
    strength = factor(strength_table, "emissiveStrength", 1.0, MAX_COORDINATE)
    specular = extensions.get("KHR_materials_specular") or {}
    transmission = extensions.get("KHR_materials_transmission") or {}
    fields = {"metallic": factor(pbr, "metallicFactor", 1.0), "roughness": factor(pbr, "roughnessFactor", 1.0),
              "emission": checks.intensity(f"{where} emissiveFactor x emissiveStrength",
                                           [e * strength for e in emissive]),
              "specular_weight": factor(specular, "specularFactor", 1.0),
              "specular_color": checks.vector(f"{where} specularColorFactor",
                                              specular.get("specularColorFactor", [1.0, 1.0, 1.0]),
                                              ge=0, le=MAX_SPECULAR_COLOR),
              "transmission": factor(transmission, "transmissionFactor", 0.0),
              "double_sided": checks.boolean(f"{where} doubleSided", material.get("doubleSided", False))}
    normal = material.get("normalTexture")
    if isinstance(normal, dict):
        lo, hi = MATERIAL_RANGES["normal_scale"]
        fields["normal_scale"] = checks.number(f"{where} normalTexture.scale", normal.get("scale", 1.0),
                                               ge=lo, le=hi)
    return fields


def _gltf_materials(gltf: "_GltfFile") -> list:
    """Material fields of each glTF material: :func:`whitted_from_pbr` (the
    Whitted model), :func:`pbr_from_gltf` (the path tracer's), and the
    textures (GLTF_TEXTURES) with their samplers' wrap modes, each image and
    sampler one Texture however many materials use it."""
    doc, path = gltf.doc, gltf.path
    textures, out = {}, []
    for i, m in enumerate(doc.get("materials", [])):
        if not isinstance(m, dict):
            raise _GltfError(f"materials[{i}] is not an object")
        name = m.get("name")
        where = f"materials[{i}]" + (f" {name!r}" if isinstance(name, str) and name else "")
        try:
            pbr_fields = pbr_from_gltf(m, where)
        except InputError as exc:
            raise fail(path, str(exc)) from None
        fields = {**whitted_from_pbr(m.get("pbrMetallicRoughness") or {}, m.get("extensions") or {}), **pbr_fields}
        for field, info in gltf_texture_infos(m).items():
            texture = gltf.item("textures", info.get("index"), f"{where} {GLTF_TEXTURES[field][1]}")
            sampler = texture.get("sampler")
            sampler = gltf.item("samplers", sampler, "sampler") if sampler is not None else {}
            wraps = tuple(_GLTF_WRAPS.get(sampler.get(k, 10497), "repeat") for k in ("wrapS", "wrapT"))
            key = (texture.get("source"), wraps)   # one texture (one copy of its texels) per image and sampler
            if key not in textures:
                image = gltf.image(info.get("index"))
                try:
                    textures[key] = None if image is None else Texture.from_image(
                        image, *wraps, name=f"{os.path.basename(path)} image")
                except InputError as exc:
                    raise fail(path, str(exc)) from None
            if textures[key] is not None:
                fields[field] = textures[key]
        out.append(fields)
    return out


# ---------------------------------------------------------------------------
# Camera nodes


def _gltf_json(data: bytes, ext: str) -> dict:
    """The JSON document of a .gltf file or of a .glb file's first chunk."""
    import json
    import struct
    if ext == ".glb":
        if len(data) < 20 or data[:4] != b"glTF":
            raise ValueError("not a GLB file")
        length, kind = struct.unpack_from("<II", data, 12)
        if kind != 0x4E4F534A:   # "JSON"
            raise ValueError("GLB file without a JSON chunk first")
        if len(data) < 20 + length:
            raise ValueError(f"truncated GLB file (its JSON chunk is {length} bytes, the file holds "
                             f"{len(data) - 20} after the header)")
        data = data[20:20 + length]
    return json.loads(data.decode("utf-8"))


def _gltf_json_problem(exc: Exception) -> str:
    """What :func:`_gltf_json` found wrong, in words."""
    import json
    if isinstance(exc, json.JSONDecodeError):
        return f"invalid JSON ({exc})"
    if isinstance(exc, UnicodeDecodeError):
        return f"its JSON is not UTF-8 text (byte {exc.start})"
    if isinstance(exc, ValueError):   # ours: "not a GLB file", "truncated GLB file ..."
        return str(exc)
    return short(exc)


# glTF objects that index others: (list, key, the list indexed).  Cameras are
# file_camera's concern: a broken one does not stop the mesh from loading.
_GLTF_REFERENCES = (("accessors", "bufferView", "bufferViews"), ("bufferViews", "buffer", "buffers"),
                    ("nodes", "mesh", "meshes"))


def _gltf_reference_problem(doc) -> str | None:
    """The first index in a glTF document that points past its list (an accessor
    that does not exist, ...), as ``'meshes[0].primitives[0].attributes.POSITION:
    accessor 7 does not exist (the file has 2)'``; None when all are in range.
    trimesh would fail on one with an internal error (UnboundLocalError, KeyError)."""
    if not isinstance(doc, dict):
        return f"the JSON is {type(doc).__name__}, not an object"

    def check(where: str, index, kind: str):
        items = doc.get(kind, [])
        n = len(items) if isinstance(items, list) else 0
        if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < n:
            what = kind[:-1] if kind != "meshes" else "mesh"
            return f"{where}: {what} {json_text(index)} does not exist (the file has {n})"
        return None

    def json_text(value):
        import json
        text = json.dumps(value)
        return text if len(text) <= 40 else text[:37] + "..."

    def listed(kind: str):
        items = doc.get(kind, [])
        return [(i, v) for i, v in enumerate(items) if isinstance(v, dict)] if isinstance(items, list) else []

    for i, mesh in listed("meshes"):
        primitives = mesh.get("primitives", [])
        for j, primitive in enumerate(primitives if isinstance(primitives, list) else []):
            if not isinstance(primitive, dict):
                continue
            where = f"meshes[{i}].primitives[{j}]"
            attributes = primitive.get("attributes", {})
            refs = [(f"{where}.attributes.{k}", v) for k, v in attributes.items()] if isinstance(attributes, dict) else []
            if "indices" in primitive:
                refs.append((f"{where}.indices", primitive["indices"]))
            for path, index in refs:
                problem = check(path, index, "accessors")
                if problem:
                    return problem
    for kind, key, target in _GLTF_REFERENCES:
        for i, item in listed(kind):
            if key in item:
                problem = check(f"{kind}[{i}].{key}", item[key], target)
                if problem:
                    return problem
    for kind, key in (("nodes", "children"), ("scenes", "nodes")):   # lists of node indices
        for i, item in listed(kind):
            nodes = item.get(key, [])
            for k, node in enumerate(nodes if isinstance(nodes, list) else []):
                problem = check(f"{kind}[{i}].{key}[{k}]", node, "nodes")
                if problem:
                    return problem
    if "scene" in doc:
        return check("scene", doc["scene"], "scenes")
    return None


def _glb_json_bytes(path: str) -> bytes:
    """A GLB file's header and JSON chunk, without its binary chunk: the
    camera is read after the mesh, and the buffers need not be read twice."""
    import struct
    head = read_bytes(path, prefix=20)
    if len(head) < 20 or head[:4] != b"glTF":
        return head                          # _gltf_json says what is wrong
    return read_bytes(path, prefix=20 + struct.unpack_from("<I", head, 12)[0])


def _node_matrix(node: dict) -> np.ndarray:
    """A glTF node's local transform: ``matrix``, else T * R * S."""
    if "matrix" in node:
        return np.asarray(node["matrix"], dtype=np.float64).reshape(4, 4).T   # column-major
    m = np.eye(4)
    if "translation" in node:
        m[:3, 3] = node["translation"]
    if "rotation" in node:
        x, y, z, w = (float(c) for c in node["rotation"])
        m[:3, :3] = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
    if "scale" in node:
        m[:3, :3] = m[:3, :3] @ np.diag(np.asarray(node["scale"], dtype=np.float64))
    return m


def _file_camera(path: str, ext: str) -> dict | None:
    """The first perspective camera node of a glTF/GLB file (``ext`` ".gltf" or
    ".glb"), in world space: ``{"eye", "forward", "up", "fov" (vertical,
    degrees), "aspect" (width / height or None), "name"}``; None for a file
    without one, or a camera clrt cannot use (orthographic, degenerate).  glTF
    cameras look down their node's -z axis with +y up; parent nodes'
    transforms apply."""
    try:
        doc = _gltf_json(_glb_json_bytes(path) if ext == ".glb" else read_bytes(path), ext)
        cameras = doc.get("cameras", [])
        for _, node, world in _gltf_walk(doc):   # depth first, in file order
            if "camera" in node:
                perspective = cameras[node["camera"]].get("perspective")
                if perspective is not None:
                    forward, up = -world[:3, 2], world[:3, 1]
                    if np.linalg.norm(forward) > 0 and np.linalg.norm(np.cross(forward, up)) > 0:
                        aspect = perspective.get("aspectRatio")
                        return {"eye": world[:3, 3].copy(), "forward": forward / np.linalg.norm(forward),
                                "up": up / np.linalg.norm(up), "fov": math.degrees(float(perspective["yfov"])),
                                "aspect": float(aspect) if aspect else None,
                                "name": cameras[node["camera"]].get("name", "")}
    except MeshLoadError:
        raise
    except Exception as exc:  # noqa: BLE001 -- a malformed camera is reported, not a traceback
        raise fail(path, f"cannot read the file's camera ({short(exc)})") from None
    return None
