"""Wavefront OBJ, with its MTL material libraries and their texture images.

Read: ``v``, ``vt``, ``vn``, ``f`` (polygons of any size, triangulated in
place; negative indices count back), ``usemtl`` and ``mtllib``; lines,
points, groups and smoothing groups are ignored, a trailing backslash
continues a statement.  Texture coordinates and normals are used when every
face corner names one.  MTL files (``mtllib``, beside the OBJ) give each
material's Kd, Ks, Ns, d/Tr, Ni, illum and map_Kd image (the table in
docs/scene-files.md); a missing MTL file or image is left out, with a
:class:`~clrt.errors.MeshLoadWarning` naming it and the OBJ.

Parsed here rather than by trimesh (5.2.0 checked), whose OBJ reader emits
``usemtl`` sections in reverse order, moves the second triangle of every quad
to the end of the mesh, and opens the ``mtllib`` and texture files named
inside the OBJ.
"""

from __future__ import annotations

import math
import os
import re
import warnings

import numpy as np

from clrt.errors import InputError, MeshLoadWarning
from clrt.scene.formats.part import Part, build, fail, read_side_file, short, texture
from clrt.scene.formats.text import decode, nonblank_lines, polygons, xyz
from clrt.scene.formats.triangulate import triangulate
from clrt.scene.mesh import Mesh


def read(data: bytes, path: str, name: str) -> "tuple[Mesh, list]":
    """The mesh of an OBJ file's bytes and the materials of its MTL files."""
    return build([_parse_obj(data, path, os.path.dirname(os.path.abspath(path)))], path, name)


def _parse_obj(data: bytes, label: str, folder: str | None = None) -> Part:
    """Geometry and surface detail of a Wavefront OBJ file.

    ``v``, ``vt``, ``vn``, ``f``, ``usemtl`` and ``mtllib`` are read; lines and
    points are ignored.  Texture coordinates and normals are used when every
    face corner names one.  Material libraries (``mtllib``, :func:`_parse_mtl`)
    are read from ``folder`` (the OBJ's own), when they are there.
    """
    text = decode(data)
    # A trailing backslash continues a statement on the next line.
    text = text.replace("\\\r\n", " ").replace("\\\n", " ").replace("\t", " ")
    if "#" in text:
        text = re.sub(r"#[^\r\n]*", "", text)
    if re.search(r"^ ", text, flags=re.MULTILINE):
        text = re.sub(r"^ +", "", text, flags=re.MULTILINE)
    lines = text.splitlines()
    vertex_lines = [line[2:] for line in lines if line.startswith("v ")]
    face_lines = [line[2:] for line in lines if line.startswith("f ")]
    if not face_lines:
        what = f"only {len(vertex_lines)} vertices" if vertex_lines else "no geometry"
        raise fail(label, f"contains no triangles ({what})")
    vertices = xyz(vertex_lines, label)
    # A corner is "v", "v/vt", "v//vn" or "v/vt/vn": field 0 is the vertex index.
    face_text = "\n".join(face_lines)
    counts, flat = polygons(_obj_field(face_text, 0).split("\n"), label, counted=False)
    if (flat == 0).any():
        raise fail(label, "face index 0 (OBJ indices start at 1)")
    # The statements whose order matters: relative indices count back over them,
    # and a face has the material of the last usemtl before it.  Listed only
    # when needed: most files have neither.
    ordered = statements = None
    if (flat < 0).any() or "/" in face_text or any(line.startswith("usemtl ") for line in lines):
        ordered = [line for line in lines if line[:2] in ("v ", "f ", "vt", "vn", "us")]
        statements = [line.split(" ", 1)[0] for line in ordered]
    written = flat
    flat = _obj_absolute(flat, counts, statements, "v", label) - 1
    bad = np.flatnonzero((flat < 0) | (flat >= len(vertices)))
    if bad.size:   # said here, in the file's 1-based numbering (Mesh would say 0-based)
        face = int(np.searchsorted(np.cumsum(counts), bad[0], side="right")) + 1
        raise fail(label, f"face {face} names vertex {int(written[bad[0]])}, but the file defines "
                          f"{len(vertices)} vertices (OBJ indices 1..{len(vertices)}, or negative counting back)")
    # Triangle corners as positions in the flat corner list, so that every
    # per-corner field triangulates exactly as the vertex indices do.
    corners = triangulate(counts, flat, vertices, names=np.arange(len(flat)))
    part = Part(vertices, flat[corners])
    if "/" in face_text:
        for field, keyword in ((1, "vt"), (2, "vn")):
            rows = [line.split()[1:] for line in lines if line.startswith(keyword + " ")]
            indices = _obj_field(face_text, field, missing="0").split()
            if not rows or len(indices) != len(flat) or "0" in indices:
                continue   # some corner lacks one: ignore them all
            try:
                table = np.array([row[:3] + ["0"] * (3 - len(row[:3])) for row in rows], dtype=np.float64)
                index = _obj_absolute(np.array(indices, dtype=np.int64), counts, statements, keyword, label)
            except ValueError as exc:
                raise fail(label, f"malformed {keyword} data ({short(exc)})") from None
            if index.max() > len(table):
                raise fail(label, f"{keyword} index {index.max()} out of range ({len(table)} defined)")
            if keyword == "vt":
                part.uv = table[index - 1][corners][..., :2]
            else:   # a vertex with several normals becomes one vertex per normal
                pairs, inverse = np.unique(np.stack([flat, index - 1], axis=1), axis=0, return_inverse=True)
                part.vertices, part.normals = vertices[pairs[:, 0]], table[pairs[:, 1]]
                part.faces = inverse.reshape(-1)[corners]
    used = [line.split(None, 1)[1].strip() for line in lines if line.startswith("usemtl ") and " " in line]
    libraries = [line.split(None, 1)[1].strip() for line in lines
                 if line.startswith("mtllib ") and len(line.split()) > 1]
    if used and folder is not None:
        materials, textures = {}, {}
        for name in _mtl_libraries(libraries, folder):
            materials.update(_parse_mtl(os.path.join(folder, name), label, textures))
        if materials:
            names = list(materials)
            current, polygon_material = -1, []
            for statement, line in zip(statements, ordered):
                if statement == "usemtl":
                    name = line.split(None, 1)[1].strip() if " " in line else ""
                    current = names.index(name) if name in materials else -1
                elif statement == "f":
                    polygon_material.append(current)
            part.face_material = np.repeat(np.asarray(polygon_material, np.int64), counts - 2)
            part.materials = [materials[n] for n in names]
    return part


def _mtl_libraries(arguments: "list[str]", folder: str) -> "list[str]":
    """The file names of ``mtllib`` statements (their arguments): one statement
    may name several libraries, separated by spaces (the OBJ specification);
    a whole argument naming a file in ``folder`` is one name with spaces."""
    names = []
    for text in arguments:
        names.extend([text] if os.path.isfile(os.path.join(folder, text)) else text.split())
    return names


def _obj_field(face_text: str, field: int, missing: str = "") -> str:
    """The face lines with each corner "v/vt/vn" replaced by one of its fields
    (``missing`` where the corner has none)."""
    if "/" not in face_text:
        return face_text if field == 0 else re.sub(r"\S+", missing, face_text)
    if field == 0:
        return re.sub(r"/\S*", "", face_text)
    return re.sub(r"\S+", lambda m: (m.group(0).split("/") + [""] * 2)[field] or missing, face_text)


def _obj_absolute(index: np.ndarray, counts: np.ndarray, statements: list, keyword: str, label: str) -> np.ndarray:
    """1-based indices of ``keyword`` rows, negative ones (counting back from
    the rows defined so far) made absolute."""
    if not (index < 0).any():
        return index
    defined, base = 0, []
    for statement in statements:
        if statement == keyword:
            defined += 1
        elif statement == "f":
            base.append(defined)
    return np.where(index > 0, index, np.repeat(np.asarray(base, dtype=np.int64), counts) + index + 1)


def _parse_mtl(path: str, label: str, textures: "dict | None" = None) -> dict:
    """``{name: material fields}`` of an MTL file (docs/scene-files.md has the
    table: Kd, Ks, Ns, d/Tr, Ni, illum, map_Kd).  A missing file, as MTL files
    and images often are beside downloaded OBJ files, is left out with a
    :class:`MeshLoadWarning` naming the OBJ (``label``) and the file: {} for the
    library, no texture for its material.  ``textures``: the Textures read so
    far for the OBJ, by image file and wrap mode, so that an image several
    materials name is read (and uploaded) once."""
    textures = {} if textures is None else textures
    if not os.path.isfile(path):
        warnings.warn(f"{label}: material library {path} not found: its materials are left out",
                      MeshLoadWarning, stacklevel=2)
        return {}
    text = decode(read_side_file(path, label))
    folder = os.path.dirname(path)
    materials, current = {}, None
    for raw in nonblank_lines(text):
        words = raw.split()
        key, args = words[0], words[1:]
        if key == "newmtl":
            name = " ".join(args)
            current = materials.setdefault(name, {})
            continue
        if current is None or not args:
            continue
        try:
            if key in _MTL_MAPS:
                # Options ("-clamp on", "-bm 0.5", "-s 1 1 1", ...) come before the file name.
                clamp = "-clamp" in args and args[args.index("-clamp") + 1:][:1] == ["on"]
                wrap = "clamp" if clamp else "repeat"
                image = os.path.join(folder, args[-1])
                if os.path.isfile(image):
                    cached = (os.path.realpath(image), wrap)
                    if cached not in textures:
                        textures[cached] = texture(image, wrap, wrap, label)
                    current[_MTL_MAPS[key]] = textures[cached]
                    if _MTL_MAPS[key] == "norm" and "-bm" in args:
                        current["bm"] = float(args[args.index("-bm") + 1])
                else:
                    warnings.warn(f"{label}: {os.path.basename(path)}: material {name!r}: texture {image} "
                                  f"not found: the material is untextured", MeshLoadWarning, stacklevel=2)
            elif key in ("Kd", "Ks", "Ke", "Tf"):
                current[key] = [float(x) for x in (args * 3)[:3]]
            elif key in ("Ns", "d", "Tr", "Ni", "illum", "Pr", "Pm"):
                current[key] = float(args[0])
        except (ValueError, IndexError):
            raise fail(label, f"{os.path.basename(path)}: malformed {key} line") from None
    return {name: mtl_material(m, f"{os.path.basename(path)}: material {name!r}", label, textures)
            for name, m in materials.items()}


# The texture statements read: statement -> the key it is kept under.  A
# normal map is named by the PBR extension's `norm`, or by a bump statement
# (Blender writes its normal maps there; a greyscale one is a height map, not used).
_MTL_MAPS = {"map_Kd": "texture", "map_Ke": "map_Ke", "map_Pr": "map_Pr", "map_Pm": "map_Pm",
             "map_RMA": "map_RMA", "norm": "norm", "map_Bump": "norm", "map_bump": "norm", "bump": "norm"}

# The MTL statement behind each material field, for messages.
_MTL_KEYS = {"color": "Kd", "specular": "Ks", "reflectivity": "Ks", "shininess": "Ns", "transparency": "d",
             "ior": "Ni", "texture": "map_Kd"}


def mtl_material(m: dict, where: str, label: str, textures: "dict | None" = None) -> dict:
    """:func:`_whitted_from_mtl`, its values checked: a bad one is an error naming
    the mesh file, the MTL file, the material and the statement, with the values
    as the file has them (not as clamped into range).

    ``m``: an MTL material's statements, ``{"Kd": [r, g, b], "Ks": [...], "Ns":
    float, "d", "Tr", "Ni", "illum": float, "texture": Texture}``, each
    optional; a trimesh SimpleMaterial is mapped through here too
    (:mod:`clrt.scene.formats.trimesh_objects`)."""
    from clrt import checks, config
    for key, value in m.items():
        values = value if isinstance(value, list) else [value] if isinstance(value, float) else []
        if not all(math.isfinite(v) for v in values):
            shown = checks.show(value)
            rule = f"{len(values)} finite numbers" if isinstance(value, list) else "a finite number"
            raise fail(label, f"{where}: {key} must be {rule}, got {shown}")
    fields = {**_whitted_from_mtl(m), **_pbr_from_mtl(m, where, label, {} if textures is None else textures)}
    try:   # the checks clrt.Material makes of these fields (the color is clamped into range already)
        for name in config.MATERIAL_RANGES:
            if name in fields:
                checks.material_number(f"material {name}", fields[name], name)
    except InputError as exc:
        bad = next((f for f in fields if f"material {f} " in str(exc)), "")
        key = _MTL_KEYS.get(bad, "")
        if key == "d" and "d" not in m:
            key = "Tr"
        given = f"{key} {checks.show(m[key])} " if key in m else ""
        raise fail(label, f"{where}: {given}is out of range: {exc}") from None
    return fields


def _whitted_from_mtl(m: dict) -> dict:
    """Material fields (clrt.Material) of an MTL material's statements."""
    fields = {}
    if "Kd" in m:
        fields["color"] = tuple(min(max(c, 0.0), 1.0) for c in m["Kd"])
    if "Ks" in m:
        fields["specular"] = max(sum(m["Ks"]) / 3, 0.0)
        if m.get("illum") in (3.0, 5.0, 7.0):   # "reflection on": mirror by Ks
            fields["reflectivity"] = min(fields["specular"], 1.0)
    if "Ns" in m:
        fields["shininess"] = max(m["Ns"], 0.0)
    opacity = m["d"] if "d" in m else 1.0 - m["Tr"] if "Tr" in m else 1.0
    if opacity < 1.0:
        fields["transparency"] = min(max(1.0 - opacity, 0.0), 1.0)
    if m.get("Ni", 0.0) >= 1.0:
        fields["ior"] = m["Ni"]
    if "texture" in m:
        fields["texture"] = m["texture"]
    return fields


def _pbr_from_mtl(m: dict, where: str, label: str, textures: dict) -> dict:
    """The path tracer's Material fields of an MTL material's statements (the
    PBR extension's, as Blender and three.js write them; the table in
    docs/scene-files.md), each checked: Pr -> roughness, Pm -> metallic (each
    0..1); map_Pr and map_Pm (or map_RMA: R roughness, G metallic) -> one
    metallic-roughness texture, its factors 1 where no Pr / Pm is given; Ke
    (>= 0) -> emission and map_Ke -> its texture (an emission of 1 where no Ke
    is given); norm (or a bump map in colour) -> the normal map, -bm its
    scale; Tf -> transmission (the mean of its three, 0..1) in a material
    with PBR statements, where it is the transmission weight -- in a classic
    one it is a filter colour, not read, and the Phong mapping's transmission
    (1 - d) applies.  Fields not given here come from the Phong mapping
    (clrt.Material.pbr_values).  ``textures``: the OBJ's Textures so far, which
    keeps one metallic-roughness Texture for the maps several materials share."""
    from clrt import checks
    fields = {}

    def check(key, **limits):
        try:
            if isinstance(m[key], list):
                return checks.vector(f"{where}: {key}", m[key], **limits)
            return checks.number(f"{where}: {key}", m[key], **limits)
        except InputError as exc:
            raise fail(label, str(exc)) from None

    if "Pr" in m:
        fields["roughness"] = check("Pr", ge=0, le=1)
    if "Pm" in m:
        fields["metallic"] = check("Pm", ge=0, le=1)
    maps = tuple(id(m.get(k)) for k in ("map_Pr", "map_Pm", "map_RMA"))
    if ("metallic-roughness", maps) not in textures:
        textures["metallic-roughness", maps] = _metallic_roughness_texture(m)
    data = textures["metallic-roughness", maps]
    if data is not None:
        fields["metallic_roughness_texture"] = data
        if "map_Pr" in m or "map_RMA" in m:
            fields.setdefault("roughness", 1.0)
        if "map_Pm" in m or "map_RMA" in m:
            fields.setdefault("metallic", 1.0)
    if "Ke" in m:
        fields["emission"] = check("Ke", ge=0)
    if "map_Ke" in m:
        fields["emission_texture"] = m["map_Ke"]
        fields.setdefault("emission", (1.0, 1.0, 1.0))
    normal = m.get("norm")
    if normal is not None and not (normal.pixels == normal.pixels[:, :, :1]).all():   # grey: a height map
        fields["normal_texture"] = normal
        if "bm" in m:
            fields["normal_scale"] = check("bm", ge=-1000, le=1000)
    if "Tf" in m and any(k in m for k in ("Pr", "Pm", "map_Pr", "map_Pm", "map_RMA")):
        fields["transmission"] = sum(check("Tf", ge=0, le=1)) / 3.0
    return fields


def _metallic_roughness_texture(m: dict):
    """One glTF-style metallic-roughness Texture (G roughness, B metallic) of an
    MTL material's map_Pr and map_Pm (their red channels: grey images) or its
    map_RMA (R roughness, G metallic); a missing channel is 255 (the factor
    alone).  A map_Pm of another size than map_Pr is sampled at the nearest
    texel.  None without such maps."""
    from clrt.scene.texture import Texture
    if "map_RMA" in m:
        rma = m["map_RMA"]
        roughness, metallic, like = rma.pixels[:, :, 0], rma.pixels[:, :, 1], rma
    elif "map_Pr" in m or "map_Pm" in m:
        like = m.get("map_Pr", m.get("map_Pm"))
        h, w = like.pixels.shape[:2]
        full = np.full((h, w), 255, np.uint8)

        def channel(key):
            if key not in m:
                return full
            p = m[key].pixels
            rows = np.arange(h) * p.shape[0] // h
            cols = np.arange(w) * p.shape[1] // w
            return p[rows][:, cols, 0]
        roughness, metallic = channel("map_Pr"), channel("map_Pm")
    else:
        return None
    pixels = np.zeros(like.pixels.shape, np.uint8)
    pixels[:, :, 1], pixels[:, :, 2] = roughness, metallic
    return Texture(pixels, like.wrap_s, like.wrap_t, f"{like.name} (metallic-roughness)")
