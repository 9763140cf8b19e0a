"""Scene files: several objects, materials, lights and a camera described in TOML.

``load_scene(path)`` reads a file with :mod:`tomllib` (data only, nothing is
executed) and returns a :class:`~clrt.scene.scene.Scene`.  The schema is
documented key by key in ``docs/scene-files.md``; the tables below are its
single source of truth in code.

Every problem raises :class:`~clrt.errors.InputError` with one line naming the
file, the key path and what was expected, e.g.::

    scene.toml: objects[2].material: unknown material 'glas' (did you mean 'glass'?)

Unknown keys are errors everywhere, so that a typo never silently falls back
to a default.
"""

from __future__ import annotations

import json
import math
import os
import re
import tomllib
from dataclasses import replace

import numpy as np

from clrt import checks, config
from clrt.errors import InputError, MeshLoadError
from clrt.scene import primitives
from clrt.scene.environment import Environment
from clrt.scene.load import load_asset
from clrt.scene.mesh import Mesh, vertex_text
from clrt.scene.scene import (MATERIAL_TEXTURES, Camera, Light, Material, Scene, SceneObject, default_light,
                              unknown_name)
from clrt.scene.texture import Texture

__all__ = ["load_scene", "transform_matrix", "OBJECT_TYPES"]


# ---------------------------------------------------------------------------
# Value checks: clrt.checks, the rules the CLI and the Python API use too.  Each
# takes (key path, raw TOML value) and returns the converted value or raises
# InputError("<key path> must be <rule>, got <value>"); _Doc adds the file.


_REQUIRED = object()


def _show(value) -> str:
    """A short rendering of a TOML value for messages."""
    return checks.show(value)


def number(**limits):
    """A finite number, as float, within ``limits`` (gt, ge, lt, le: e.g. ``number(gt=0, lt=180)``)."""
    return lambda name, value: checks.number(name, value, **limits)


def integer(lo, hi=None):
    """An integer in lo..hi (TOML floats such as 2.0 are refused: counts are whole)."""
    return lambda name, value: checks.integer(name, value, lo, hi)


def material_number(field: str):
    """A scalar material field within its range (clrt.config.MATERIAL_RANGES)."""
    return lambda name, value: checks.material_number(name, value, field)


def vector(n: int, **limits):
    """A list of ``n`` numbers, each checked like :func:`number`; a tuple of floats."""
    return lambda name, value: checks.vector(name, value, n, **limits)


def scale_value(name, value):
    """A uniform scale (one number > 0) or a per-axis one (3 numbers > 0)."""
    if checks.is_number(value):
        return (checks.number(name, value, gt=0),) * 3
    if isinstance(value, list):
        return checks.vector(name, value, 3, gt=0)
    raise checks.fail(name, "a number > 0 or 3 numbers > 0", value)


def placement_scale(name, value):
    """An instance's scale: one number or 3, none 0 (negative: a mirror)."""
    values = [value] if checks.is_number(value) else value
    if not isinstance(values, list) or len(values) not in (1, 3) or not all(checks.is_number(v) for v in values):
        raise checks.fail(name, "a number or 3 numbers, not 0 (negative mirrors)", value)
    values = [checks.number(name, v) for v in values]
    if not all(values):
        raise checks.fail(name, "a number or 3 numbers, not 0 (negative mirrors)", value)
    return tuple(values * 3 if len(values) == 1 else values)


def matrix_value(name, value):
    """A 4x4 matrix: 4 rows of 4 finite numbers (checked as a transform later)."""
    if not (isinstance(value, list) and len(value) == 4 and all(isinstance(r, list) and len(r) == 4 for r in value)):
        raise checks.fail(name, "4 rows of 4 numbers", value)
    return np.array([checks.vector(name, row, 4) for row in value], np.float64)


def boolean(name, value):
    return checks.boolean(name, value)


def string(name, value):
    if not isinstance(value, str):
        raise checks.fail(name, "a string", value)
    return value


def anything(name, value):
    """Passed through; checked later by code that needs more context (material references)."""
    return value


# ---------------------------------------------------------------------------
# The schema: key -> (check, default).  _REQUIRED marks keys without a default.
# Ranges and defaults come from clrt.config, as for the CLI and the Python API.

_MATERIAL_DEFAULTS = Material()
MATERIAL_KEYS = {
    "color": (checks.color, _MATERIAL_DEFAULTS.color),
    "ambient": (material_number("ambient"), _MATERIAL_DEFAULTS.ambient),
    "diffuse": (material_number("diffuse"), _MATERIAL_DEFAULTS.diffuse),
    "specular": (material_number("specular"), _MATERIAL_DEFAULTS.specular),
    "shininess": (material_number("shininess"), _MATERIAL_DEFAULTS.shininess),
    "smooth": (boolean, _MATERIAL_DEFAULTS.smooth),
    "crease": (lambda name, value: checks.crease(value, name), _MATERIAL_DEFAULTS.crease),
    "reflectivity": (material_number("reflectivity"), _MATERIAL_DEFAULTS.reflectivity),
    "transparency": (material_number("transparency"), _MATERIAL_DEFAULTS.transparency),
    "ior": (material_number("ior"), _MATERIAL_DEFAULTS.ior),
    # the path tracer's (clrt.Material says how each is read); None: from the Phong keys above
    "emission": (checks.intensity, _MATERIAL_DEFAULTS.emission),
    "double_sided": (boolean, _MATERIAL_DEFAULTS.double_sided),
    "metallic": (material_number("metallic"), None),
    "roughness": (material_number("roughness"), None),
    "specular_weight": (material_number("specular_weight"), None),
    "specular_color": (vector(3, ge=0, le=config.MAX_SPECULAR_COLOR), _MATERIAL_DEFAULTS.specular_color),
    "transmission": (material_number("transmission"), None),
    "normal_scale": (material_number("normal_scale"), _MATERIAL_DEFAULTS.normal_scale),
    # image files, relative to the scene file (read by _Loader.texture)
    **{name: (string, None) for name in MATERIAL_TEXTURES},
}

# checkerboard's second material when the file gives none: dark tiles.
DEFAULT_MATERIAL2 = Material(color=(0.1, 0.1, 0.1))

CAMERA_KEYS = {
    # eye and target are optional together: without them the scene is framed.
    "eye": (checks.position, None),
    "target": (checks.position, None),
    "up": (checks.position, config.DEFAULT_UP),
    "fov": (lambda name, value: checks.fov(value, name), config.DEFAULT_FOV),
    "width": (integer(1, config.MAX_IMAGE_SIDE), config.DEFAULT_WIDTH),
    "height": (integer(1, config.MAX_IMAGE_SIDE), config.DEFAULT_HEIGHT),
}

RENDER_KEYS = {
    # max_depth is checked for the integrator of the same table (load); None: the integrator's default
    "max_depth": (lambda name, value: checks.max_depth(value, name), None),
    "samples": (lambda name, value: checks.samples(value, name), config.DEFAULT_SAMPLES),
    "background": (checks.intensity, config.DEFAULT_BACKGROUND),
    "ambient_light": (checks.intensity, config.DEFAULT_AMBIENT_LIGHT),
    "integrator": (lambda name, value: checks.choice(name, value, config.INTEGRATORS), config.DEFAULT_INTEGRATOR),
    "spp": (lambda name, value: checks.spp(value, name), None),
    "seed": (lambda name, value: checks.seed(value, name), 0),
    "exposure": (lambda name, value: checks.exposure(value, name), 0.0),
    "environment": (anything, None),   # a file name (relative to the scene file) or {image, rotation, strength}
}

LIGHT_KEYS = {
    "position": (checks.position, _REQUIRED),
    "color": (checks.intensity, config.DEFAULT_LIGHT_COLOR),
    "intensity": (number(ge=0), 1.0),
    "direction": (checks.position, None),   # a spot light's axis
    "cutoff": (number(gt=0, le=90), config.DEFAULT_SPOT_CUTOFF),
    "beam": (number(ge=0, le=90), None),
}

TOP_KEYS = {"camera", "render", "materials", "objects", "instances", "lights"}

# Keys every object accepts, then the keys of each type.
OBJECT_KEYS = {
    "type": (string, _REQUIRED),
    "name": (string, ""),
    "material": (anything, None),
    "translate": (checks.position, (0.0, 0.0, 0.0)),
    "rotate": (checks.position, (0.0, 0.0, 0.0)),
    "scale": (scale_value, (1.0, 1.0, 1.0)),
    "show": (boolean, True),   # false: drawn only where [[instances]] place it
}
OBJECT_TYPES = {
    "mesh": {"path": (string, _REQUIRED)},
    "sphere": {"radius": (number(gt=0), 1.0), "subdivisions": (integer(0, 7), 4),
               "centre": (checks.position, (0.0, 0.0, 0.0))},
    "box": {"size": (vector(3, gt=0), (1.0, 1.0, 1.0))},
    "plane": {"size": (vector(2, gt=0), (1.0, 1.0))},
    "checkerboard": {"tiles": (integer(1, 1024), 8), "size": (number(gt=0), 8.0),
                     "material2": (anything, None)},
    "torus": {"major": (number(gt=0), 1.0), "minor": (number(gt=0), 0.35)},
}
# [[instances]]: an object placed once more (docs/scene-files.md, "Instances").
INSTANCE_KEYS = {
    "object": (string, _REQUIRED),
    "translate": (checks.position, None),
    "rotate": (checks.position, None),
    "scale": (placement_scale, None),
    "matrix": (matrix_value, None),
    "material": (anything, None),
}
TORUS_SEGMENTS = (48, 24)   # finer than primitives.torus's default: it is seen close up


# ---------------------------------------------------------------------------

def _join(path: str, key) -> str:
    """``objects[2]`` + ``material`` -> ``objects[2].material``; odd keys are quoted as in TOML."""
    if isinstance(key, int):
        return f"{path}[{key}]"
    key = key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else json.dumps(key)
    return f"{path}.{key}" if path else key


_unknown = unknown_name


class _Doc:
    """Reads one scene file's tables; every error names the file and the key path."""

    def __init__(self, label: str):
        self.label = label

    def error(self, path: str, message: str, cls=InputError) -> InputError:
        where = f"{self.label}: {path}: " if path else f"{self.label}: "
        return cls(where + " ".join(str(message).split()))

    def check(self, value, path: str, check):
        """``check(path, value)``; its InputError ("<path> must be ...") gains the file's name."""
        try:
            return check(path, value)
        except InputError as exc:
            raise InputError(f"{self.label}: {exc}") from None

    def table(self, value, path: str, schema: dict) -> dict:
        """Validate a TOML table against ``schema``: no unknown keys, required keys
        present, every value checked; returns key -> converted value (or default)."""
        if not isinstance(value, dict):
            raise self.error(path, f"expected a table, got {_show(value)}")
        for key in value:
            if key not in schema:
                raise self.error(_join(path, key), _unknown("key", key, schema))
        out = {}
        for key, (check, default) in schema.items():
            if key in value:
                out[key] = self.check(value[key], _join(path, key), check)
            elif default is _REQUIRED:
                raise self.error(_join(path, key), "missing (this key is required)")
            else:
                out[key] = default
        return out

    def array_of_tables(self, value, path: str) -> list:
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise self.error(path, f"expected an array of tables ([[{path}]]), got {_show(value)}")
        return value


def transform_matrix(translate=(0.0, 0.0, 0.0), rotate=(0.0, 0.0, 0.0), scale=(1.0, 1.0, 1.0)) -> np.ndarray:
    """4x4 affine matrix T @ Rz @ Ry @ Rx @ S: scale, then rotate about X, Y, Z
    (degrees, right-handed: 90 about y takes +x to -z), then translate."""
    def rotation(axis: int, degrees: float) -> np.ndarray:
        c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
        i, j = [(1, 2), (2, 0), (0, 1)][axis]   # the plane the axis turns
        m = np.eye(4)
        m[i, i], m[i, j], m[j, i], m[j, j] = c, -s, s, c
        return m

    m = np.diag([*map(float, scale), 1.0])
    for axis in range(3):
        m = rotation(axis, rotate[axis]) @ m
    m[:3, 3] += np.asarray(translate, dtype=np.float64)
    return m


def _plane(size) -> Mesh:
    """A size[0] x size[1] quad in y = 0 centred on the origin, facing +y."""
    x, z = 0.5 * size[0], 0.5 * size[1]
    v = [[-x, 0, -z], [-x, 0, z], [x, 0, z], [x, 0, -z]]
    return Mesh.from_arrays(v, [[0, 1, 2], [0, 2, 3]], "plane")


def _unlabelled(exc: MeshLoadError, *names: str) -> str:
    """A Mesh's message without the mesh's own name in front ("torus: vertex ..."),
    for a message that names the scene file's object instead."""
    text = str(exc)
    for name in (*names, "icosphere", "box", "plane", "floor0", "floor1", "torus"):
        if name and text.startswith(f"{name}: "):
            return text[len(name) + 2:]
    return text


def _read_toml(label: str, path: str) -> dict:
    import os
    import stat
    try:
        # A FIFO or device would block open() or read() forever: regular files only.
        if os.path.exists(path) and not os.path.isdir(path) and not stat.S_ISREG(os.stat(path).st_mode):
            raise InputError(f"{label}: not a regular file")
        with open(path, "rb") as fh:
            data = fh.read()
    except FileNotFoundError:
        raise InputError(f"{label}: scene file not found") from None
    except IsADirectoryError:
        raise InputError(f"{label}: is a directory, not a scene file") from None
    except OSError as exc:
        raise InputError(f"{label}: cannot read scene file ({exc.strerror or exc})") from None
    if data.startswith(b"\xef\xbb\xbf"):   # a UTF-8 byte-order mark (Windows editors write one)
        data = data[3:]
    try:
        return tomllib.loads(data.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise InputError(f"{label}: not UTF-8 text (byte {exc.start}); scene files are TOML") from None
    except tomllib.TOMLDecodeError as exc:   # its message carries "(at line L, column C)"
        raise InputError(f"{label}: invalid TOML: {exc}") from None


class _Loader:
    def __init__(self, path):
        self.path = os.fspath(path)
        self.folder = os.path.dirname(os.path.abspath(self.path))
        self.doc = _Doc(self.path)
        self.materials: dict[str, Material] = {}
        self.textures: dict[str, Texture] = {}   # full path -> Texture: an image several materials name, once

    def material(self, value, path: str) -> Material:
        """A material from its fields; the Material's own checks are a backstop."""
        fields = self.doc.table(value, path, MATERIAL_KEYS)
        for name in MATERIAL_TEXTURES:
            if fields[name] is not None:
                fields[name] = self.texture(fields[name], _join(path, name))
        try:
            return Material(**fields)
        except InputError as exc:
            raise self.doc.error(path, exc) from None

    def texture(self, name: str, path: str) -> Texture:
        """The Texture of an image file named relative to the scene file (wraps repeat)."""
        full = os.path.normpath(os.path.join(self.folder, os.path.expanduser(name)))
        if full not in self.textures:
            if not name.strip() or os.path.isdir(full):
                raise self.doc.error(path, f"must name an image file, got {_show(name)}")
            try:
                self.textures[full] = Texture.read(full)
            except InputError as exc:
                raise self.doc.error(path, exc) from None
        return self.textures[full]

    def material_ref(self, value, path: str, default: Material) -> Material:
        """``material = "name"`` or an inline ``material = { ... }`` table."""
        if value is None:
            return default
        if isinstance(value, str):
            if value not in self.materials:
                raise self.doc.error(path, _unknown("material", value, self.materials))
            return self.materials[value]
        if isinstance(value, dict):
            return self.material(value, path)
        raise self.doc.error(path, f"expected a material name or an inline table, got {_show(value)}")

    def mesh_file(self, name: str, path: str) -> "list[tuple[Mesh, list, np.ndarray | None]]":
        """The mesh file's meshes: ``(mesh, its file materials, placements)``.
        One mesh, placements None (clrt.scene.load.load_asset) -- but for a
        glTF file whose nodes place a mesh more than once, as the renderer
        reads one (clrt.scene.placed.gltf_scene): each glTF mesh one Mesh
        object in its own space, placed by its nodes' world matrices ((K, 4,
        4), a run of consecutive nodes placing one mesh each entry, nodes in
        document order, depth first: the instances it makes)."""
        # Relative to the scene file, so a scene renders the same from any directory.
        if not name.strip():
            raise self.doc.error(path, f"is empty (give the mesh file's path), got {_show(name)}", MeshLoadError)
        full = os.path.normpath(os.path.join(self.folder, os.path.expanduser(name)))
        if os.path.isdir(full):
            raise self.doc.error(path, f"is a folder, not a mesh file: {full}", MeshLoadError)
        if not os.path.isfile(full):
            raise self.doc.error(path, f"mesh file not found: {full}", MeshLoadError)
        from clrt.scene.formats.gltf import gltf_shares_meshes
        from clrt.scene.instances import gltf_placements, is_gltf_file
        try:
            if not (is_gltf_file(full) and gltf_shares_meshes(full)):
                return [(*load_asset(full), None)]
            meshes, materials, mesh_of, transforms = gltf_placements(full)
        except MeshLoadError as exc:
            raise self.doc.error(path, exc, MeshLoadError) from None
        starts = np.flatnonzero(np.r_[True, mesh_of[1:] != mesh_of[:-1]])
        ends = np.r_[starts[1:], len(mesh_of)]
        return [(meshes[mesh_of[a]], materials[mesh_of[a]], transforms[a:b]) for a, b in zip(starts, ends)]

    def objects(self, raw: list) -> "list[dict]":
        """Each [[objects]] table as a record: its key path, name, whether it
        is shown, its transform and its parts -- (mesh in its own space, named,
        material, a file's materials): one, or a checkerboard's two."""
        out = []
        for index, value in enumerate(raw):
            path = _join("objects", index)
            if not isinstance(value, dict):
                raise self.doc.error(path, f"expected a table, got {_show(value)}")
            types = ", ".join(OBJECT_TYPES)
            if "type" not in value:
                raise self.doc.error(_join(path, "type"), f"missing (this key is required: one of {types})")
            kind = self.doc.check(value["type"], _join(path, "type"), string)
            if kind not in OBJECT_TYPES:
                raise self.doc.error(_join(path, "type"), _unknown("object type", kind, OBJECT_TYPES))
            schema = {**OBJECT_KEYS, **OBJECT_TYPES[kind]}
            for key in value:   # a key of another type: say so rather than guess a spelling
                if key not in schema and any(key in keys for keys in OBJECT_TYPES.values()):
                    raise self.doc.error(_join(path, key), f"key {key!r} does not apply to type {kind!r} "
                                         f"(its own keys: {', '.join(OBJECT_TYPES[kind])})")
            o = self.doc.table(value, path, schema)
            material = self.material_ref(o["material"], _join(path, "material"), Material())
            name = o["name"] or f"{path} ({kind})"
            if kind == "mesh":
                pieces = self.mesh_file(o["path"], _join(path, "path"))
                if o["material"] is not None:   # the scene's material replaces the file's
                    pieces = [(mesh, (), nodes) for mesh, _, nodes in pieces]
                # one Mesh object for each of the file's meshes, however many runs of nodes place it
                named = {id(mesh): replace(mesh, name=name if len(pieces) == 1 else f"{name}: {mesh.name}")
                         for mesh, _, _ in pieces}
                parts = [(named[id(mesh)], material, file_materials, nodes) for mesh, file_materials, nodes in pieces]
            else:
                meshes = self.primitive(kind, o, path)
                materials = [material]
                if kind == "checkerboard":
                    materials.append(self.material_ref(o["material2"], _join(path, "material2"),
                                                       DEFAULT_MATERIAL2))
                parts = [(replace(mesh, name=name + (f" tiles {k}" if len(meshes) > 1 else "")), mat, (), None)
                         for k, (mesh, mat) in enumerate(zip(meshes, materials))]
            out.append({"path": path, "name": o["name"], "show": o["show"], "parts": parts, "kind": kind,
                        "matrix": transform_matrix(o["translate"], o["rotate"], o["scale"])})
        return out

    def placed(self, records: list, raw: list) -> list[SceneObject]:
        """The scene's objects: each shown object where its transform puts it,
        then each [[instances]] table's placement of the object it names (its
        transform after the object's own), in file order.  An object that an
        instance names is placed, not moved: its mesh is shared by all its
        placements (one bottom-level mesh: docs/instances.md); the others'
        vertices are moved as before."""
        by_name: dict = {}
        for rec in records:
            if rec["name"]:
                by_name.setdefault(rec["name"], []).append(rec)
        placements = []   # (record, matrix, material or None, key path)
        for index, value in enumerate(raw):
            path = _join("instances", index)
            i = self.doc.table(value, path, INSTANCE_KEYS)
            named = by_name.get(i["object"], [])
            if not named:
                raise self.doc.error(_join(path, "object"), _unknown("object", i["object"], by_name) if by_name
                                     else f"no object is named {i['object']!r} (an [[objects]] table takes "
                                          f"name = {i['object']!r})")
            if len(named) > 1:
                raise self.doc.error(_join(path, "object"), f"{len(named)} objects are named {i['object']!r}: "
                                     "an instance names one")
            material = (self.material_ref(i["material"], _join(path, "material"), Material())
                        if i["material"] is not None else None)
            placements.append((named[0], self.placement(i, path) @ named[0]["matrix"], material, path))
        referenced = {id(rec) for rec, *_ in placements}
        objects = []
        for rec in records:
            if not rec["show"] and id(rec) not in referenced:
                raise self.doc.error(_join(rec["path"], "show"), "is false, but no [[instances]] table names the "
                                     "object (give it a name and place it, or remove it)")
            for mesh, mat, file_materials, nodes in rec["parts"] if rec["show"] else ():
                if id(rec) in referenced or nodes is not None:
                    objects.append(self.scene_object(rec["path"], mesh, mat, file_materials, rec["matrix"], nodes))
                else:
                    objects.append(SceneObject(self.transformed(mesh, rec["matrix"], rec["path"]), mat,
                                               file_materials))
        for rec, matrix, material, path in placements:
            for k, (mesh, mat, file_materials, nodes) in enumerate(rec["parts"]):
                if material is not None and (k == 0 or rec["kind"] != "checkerboard"):   # (its odd tiles keep
                    mat, file_materials = material, ()                                    # material2)
                objects.append(self.scene_object(path, mesh, mat, file_materials, matrix, nodes))
        return objects

    def placement(self, i: dict, path: str) -> np.ndarray:
        """An [[instances]] table's 4x4 transform: ``matrix``, or translate,
        rotate and scale -- checked as every instance's is."""
        from clrt.scene.instances import checked_transforms
        given = [key for key in ("translate", "rotate", "scale") if i[key] is not None]
        if i["matrix"] is not None and given:
            raise self.doc.error(_join(path, "matrix"), f"give matrix or {', '.join(given)}, not both")
        key = "matrix" if i["matrix"] is not None else "scale"
        m = i["matrix"] if i["matrix"] is not None else transform_matrix(
            i["translate"] or (0.0, 0.0, 0.0), i["rotate"] or (0.0, 0.0, 0.0), i["scale"] or (1.0, 1.0, 1.0))
        try:
            return checked_transforms(m[None], 1)[0]
        except InputError as exc:
            raise self.doc.error("", str(exc).replace("instance 0's transform", _join(path, key))) from None

    def scene_object(self, path: str, mesh: Mesh, material: Material, file_materials, matrix,
                     nodes=None) -> SceneObject:
        """``mesh`` placed by ``matrix`` -- after each of ``nodes`` ((K, 4, 4): a
        glTF file's node matrices; None: once) --: a SceneObject whose errors (a
        placement past the device's range, a singular one) name ``path``."""
        try:
            return SceneObject(mesh, material, file_materials, matrix[None] if nodes is None else matrix @ nodes)
        except InputError as exc:
            raise self.doc.error(path, exc) from None

    def primitive(self, kind: str, o: dict, path: str) -> "list[Mesh]":
        """The meshes of a built-in object type; a size past the device's range is
        an error naming the object (not the mesh the primitive calls itself)."""
        try:
            if kind == "sphere":
                return [primitives.icosphere(o["subdivisions"], o["radius"], o["centre"])]
            if kind == "box":
                return [primitives.box(o["size"])]
            if kind == "plane":
                return [_plane(o["size"])]
            if kind == "checkerboard":
                return list(primitives.checkerboard(o["tiles"], o["size"]))
            return [primitives.torus(o["major"], o["minor"], *TORUS_SEGMENTS)]
        except MeshLoadError as exc:
            raise self.doc.error(path, _unlabelled(exc), MeshLoadError) from None

    def transformed(self, mesh: Mesh, matrix: np.ndarray, path: str) -> Mesh:
        """``mesh.transformed(matrix)``, its vertices checked first against the device's
        range (+-MAX_COORDINATE), in float64, so that a large scale or translate is an
        error naming the object rather than infinities that a camera or light trips over."""
        with np.errstate(all="ignore"):
            v = mesh.vertices.astype(np.float64) @ matrix[:3, :3].T + matrix[:3, 3]
            largest = float(np.abs(v).max(initial=0.0))
        if not np.isfinite(v).all() or largest > config.MAX_COORDINATE:
            # 3 digits, unless they round to the limit (a float32 1e30 is 1.00000002e30).
            shown = f"{largest:.3g}"
            if not float(shown) > config.MAX_COORDINATE:
                shown = f"{largest:.9g}"
            bad = ~(np.abs(v) <= config.MAX_COORDINATE).all(axis=1)   # NaN too
            raise self.doc.error(path, f"vertex coordinates must lie within +-{checks.show(config.MAX_COORDINATE)} "
                                 f"after its transform (the device computes in float32), got up to "
                                 f"{shown} (the first beyond: {vertex_text(v, int(np.argmax(bad)))})".replace(
                                     "e+", "e"), MeshLoadError)
        try:
            return mesh.transformed(matrix)
        except MeshLoadError as exc:
            raise self.doc.error(path, _unlabelled(exc, mesh.name), MeshLoadError) from None

    def load(self) -> Scene:
        doc = self.doc
        data = _read_toml(self.path, self.path)
        for key in data:
            if key not in TOP_KEYS:
                raise doc.error(_join("", key), _unknown("key", key, TOP_KEYS))

        render = doc.table(data.get("render", {}), "render", RENDER_KEYS)
        materials = data.get("materials", {})
        if not isinstance(materials, dict):
            raise doc.error("materials", f"expected a table of [materials.NAME] tables, got {_show(materials)}")
        for name, value in materials.items():
            self.materials[name] = self.material(value, _join("materials", name))

        raw_objects = doc.array_of_tables(data.get("objects", []), "objects")
        if not raw_objects:
            raise doc.error("objects", "no objects: add at least one [[objects]] table")
        objects = self.placed(self.objects(raw_objects),
                              doc.array_of_tables(data.get("instances", []), "instances"))

        lights = []
        for index, value in enumerate(doc.array_of_tables(data.get("lights", []), "lights")):
            light = doc.table(value, _join("lights", index), LIGHT_KEYS)
            color = tuple(c * light["intensity"] for c in light["color"])
            where = _join("lights", index)
            if light["direction"] is not None and not any(light["direction"]):
                raise doc.error(_join(where, "direction"), "must not be 0, 0, 0")
            if light["beam"] is not None and light["beam"] > light["cutoff"]:
                raise doc.error(_join(where, "beam"), f"must be at most cutoff ({light['cutoff']:g}), got "
                                f"{_show(light['beam'])}")
            lights.append(Light(light["position"], color, light["direction"], light["cutoff"], light["beam"]))

        integrator = render["integrator"]
        if render["max_depth"] is not None:
            doc.check(render["max_depth"], "render.max_depth",
                      lambda name, value: checks.max_depth(value, name, integrator))
        for key in ("spp", "environment"):
            if render[key] is not None and integrator != "path":
                raise doc.error(_join("render", key), 'is the path tracer\'s: add integrator = "path"')
        environment = self.environment(render["environment"]) if render["environment"] is not None else None
        scene = Scene(objects, lights, background=render["background"], ambient_light=render["ambient_light"],
                      max_depth=render["max_depth"], samples=render["samples"], source=os.fsdecode(self.path),
                      integrator=integrator, spp=render["spp"], seed=render["seed"], exposure=render["exposure"],
                      environment=environment)
        scene.camera = self.camera(data.get("camera", {}), scene)
        scene.camera_framed = "eye" not in data.get("camera", {})
        if "lights" not in data:   # as for a single mesh: one light above the eye
            scene.lights, scene.default_lights = [default_light(scene.bounds, scene.camera)], True
        return scene

    def environment(self, value) -> Environment:
        """[render] environment: a file name (relative to the scene file) or a
        table {image, rotation, strength}."""
        path = "render.environment"
        fields = {"image": value} if isinstance(value, str) else value
        if not isinstance(fields, dict) or not isinstance(fields.get("image"), str):
            raise self.doc.error(path, "expected a .exr / .hdr file name or a table {image = FILE, rotation = "
                                       f"DEGREES, strength = FACTOR}}, got {_show(value)}")
        fields = dict(fields)
        fields["image"] = os.path.normpath(os.path.join(self.folder, os.path.expanduser(fields["image"])))
        try:
            return Environment.of(fields)
        except InputError as exc:
            raise self.doc.error(path, exc) from None

    def camera(self, value, scene: Scene) -> Camera:
        c = self.doc.table(value, "camera", CAMERA_KEYS)
        if (c["eye"] is None) != (c["target"] is None):
            missing = "eye" if c["eye"] is None else "target"
            raise self.doc.error(_join("camera", missing), "missing (give both eye and target, or neither "
                                 "to frame the scene)")
        try:
            if c["eye"] is None:
                try:
                    return Camera.framing(scene.bounds, c["width"], c["height"], c["fov"], up=c["up"])
                except InputError as exc:   # a scene too large to frame
                    raise InputError(str(exc).replace("place the camera (eye and target)",
                                                      "give camera.eye and camera.target")) from None
            return Camera(c["eye"], c["target"], c["up"], c["fov"], c["width"], c["height"])
        except InputError as exc:   # eye == target, up parallel to the view
            raise self.doc.error("camera", exc) from None


def load_scene(path) -> Scene:
    """Load the TOML scene file at ``path`` (see ``docs/scene-files.md``).

    Mesh paths inside are relative to the file's folder.  Raises
    :class:`~clrt.errors.InputError` (one line: file, key path, what was expected).
    """
    return _Loader(path).load()
