"""Reference scenes of the path tracer, written as glTF 2.0: ``python -m benchmarks.scenes``.

    python -m benchmarks.scenes               # the Cornell box, and the bunny scene if its mesh is there
    python -m benchmarks.scenes --mesh-dir ../shared/meshes --out out/scenes

The scenes of issue #35's Mitsuba 3 anchor, built from numbers (no download):

- ``cornell-box`` (committed as assets/scenes/cornell-box.gltf): the Cornell box as Mitsuba 3's
  ``mi.cornell_box()`` builds it, a simplified version of the Cornell University measured box: five
  walls, 2 units square around the origin (floor y = -1, ceiling y = 1, back z = -1, red x = -1,
  green x = 1), two boxes turned about y, a 0.46 x 0.38 light 0.01 below the ceiling facing down,
  RGB reflectances and radiance taken from the measured spectra, a camera at z = 3.9 looking down -z
  with a vertical field of view of 39.3077 degrees.
- ``bunny00`` (only where ``bunny00.off`` is, written to ``--out``, never committed): the 75k-triangle
  scan resting on a diffuse ground under a square area light, 1920x1080.

Every surface is a glTF metallic-roughness material made pure Lambert (metallic 0, roughness 1 and
``KHR_materials_specular`` specularFactor 0, which removes the dielectric lobe), as Mitsuba's
``diffuse`` BSDF is.  Emission is linear radiance, ``emissiveFactor x KHR_materials_emissive_strength``
(the factor is at most 1 by the specification, the strength carries the rest), leaving the front
face only (``doubleSided`` false): the counter-clockwise side, as Mitsuba's area emitters do.

Only numpy and the standard library: benchmarks.mitsuba_reference imports this module in Mitsuba's
own environment, and the GPU machine as it is.  The output is deterministic: the committed file is
byte for byte what this writes (tests/test_reference_scenes.py checks it).
"""

from __future__ import annotations

import sys

if not __package__:   # run as a script, python benchmarks/NAME.py: import from the repository, not this folder
    import os.path
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import base64
import json
import math
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CORNELL_BOX_FILE = ROOT / "assets" / "scenes" / "cornell-box.gltf"
SHARED_MESHES = ROOT.parent / "shared" / "meshes"
BUNNY_FILE_NAME = "bunny00-area-light.glb"


@dataclass(frozen=True)
class Surface:
    """A pure Lambert surface: ``base_color`` is its linear RGB reflectance,
    ``emission`` the linear RGB radiance leaving its front face."""

    name: str
    base_color: tuple
    emission: tuple = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Shape:
    """Triangles in world space: ``vertices`` (V, 3) float32, ``faces`` (F, 3)
    uint32, counter-clockwise seen from the front (glTF's and Mitsuba's front
    face), ``normals`` (V, 3) float32 flat per face."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    surface: Surface


@dataclass(frozen=True)
class View:
    """A pinhole camera: clrt's :class:`clrt.scene.scene.Camera` fields
    (``fov``: vertical, degrees)."""

    eye: tuple
    target: tuple
    up: tuple
    fov: float
    width: int
    height: int

    def camera_to_world(self) -> np.ndarray:
        """4x4: columns right, up, backward (glTF cameras look down -z) and the eye."""
        eye, target, up = (np.asarray(v, dtype=np.float64) for v in (self.eye, self.target, self.up))
        forward = (target - eye) / np.linalg.norm(target - eye)
        right = np.cross(forward, up)
        right /= np.linalg.norm(right)
        m = np.eye(4)
        m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = right, np.cross(right, forward), -forward, eye
        return m


@dataclass(frozen=True)
class ReferenceScene:
    """Shapes (a tuple of :class:`Shape`, in the file's order), the camera, and
    the max depth issue #35 measures the scene at (Mitsuba's counting)."""

    name: str
    shapes: tuple
    view: View
    max_depth: int


# ---------------------------------------------------------------------------
# Geometry


def quad(name: str, surface: Surface, centre, u, v) -> Shape:
    """The parallelogram centre +- u +- v, two triangles, its front facing u x v."""
    c, u, v = (np.asarray(a, dtype=np.float64) for a in (centre, u, v))
    vertices = np.stack([c - u - v, c + u - v, c + u + v, c - u + v])
    n = np.cross(u, v)
    normals = np.repeat((n / np.linalg.norm(n))[None], 4, axis=0)
    return Shape(name, vertices.astype(np.float32), np.array([[0, 1, 2], [0, 2, 3]], np.uint32),
                 normals.astype(np.float32), surface)


def turned_box(name: str, surface: Surface, centre, half_size, degrees_about_y: float) -> Shape:
    """A box of half extents ``half_size``, turned by ``degrees_about_y``
    (right-handed: +x toward -z) and moved to ``centre``; its six faces face
    outwards, four vertices each (flat normals)."""
    a = math.radians(degrees_about_y)
    turn = np.array([[math.cos(a), 0.0, math.sin(a)], [0.0, 1.0, 0.0], [-math.sin(a), 0.0, math.cos(a)]])
    axes = turn * np.asarray(half_size, dtype=np.float64)[None, :]   # columns: the box's half axes
    faces = []
    for k in range(3):   # the faces on +axis k and -axis k
        i, j = (k + 1) % 3, (k + 2) % 3   # (i, j, k) cyclic: axis_i x axis_j along +axis_k
        for sign in (1.0, -1.0):
            faces.append(quad(name, surface, np.asarray(centre) + sign * axes[:, k], sign * axes[:, i], axes[:, j]))
    return merge(name, surface, faces)


def merge(name: str, surface: Surface, parts) -> Shape:
    """One shape of several (their faces renumbered in order)."""
    offsets = np.cumsum([0] + [len(p.vertices) for p in parts])[:-1]
    return Shape(name, np.concatenate([p.vertices for p in parts]),
                 np.concatenate([p.faces + np.uint32(o) for p, o in zip(parts, offsets)]),
                 np.concatenate([p.normals for p in parts]), surface)


def flat_shape(name: str, surface: Surface, vertices, faces) -> Shape:
    """A mesh given by shared vertices, made flat: three vertices a triangle
    with its face normal (triangles of zero area get +y)."""
    vertices, faces = np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64)
    corners = vertices[faces]
    n = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.where(length > 0, n / np.where(length > 0, length, 1.0), [0.0, 1.0, 0.0])
    return Shape(name, corners.reshape(-1, 3).astype(np.float32),
                 np.arange(3 * len(faces), dtype=np.uint32).reshape(-1, 3),
                 np.repeat(n, 3, axis=0).astype(np.float32), surface)


# ---------------------------------------------------------------------------
# The scenes

# Mitsuba 3's cornell_box(): RGB (linear) of the Cornell measured reflectance and emission spectra.
CORNELL_WHITE = Surface("white", (0.885809, 0.698859, 0.666422))
CORNELL_RED = Surface("red", (0.570068, 0.0430135, 0.0443706))
CORNELL_GREEN = Surface("green", (0.105421, 0.37798, 0.076425))
CORNELL_LIGHT = Surface("light", CORNELL_WHITE.base_color, (18.387, 13.9873, 6.75357))


def cornell_box(width: int = 256, height: int = 256) -> ReferenceScene:
    """The Cornell box of ``mi.cornell_box()`` (the module docstring), its camera
    at ``width`` x ``height``."""
    white, red, green = CORNELL_WHITE, CORNELL_RED, CORNELL_GREEN
    x, y, z = np.eye(3)
    shapes = (
        quad("floor", white, -y, x, -z),            # front +y
        quad("ceiling", white, y, x, z),            # front -y
        quad("back", white, -z, x, y),              # front +z
        quad("green wall", green, x, z, y),         # front -x
        quad("red wall", red, -x, -z, y),          # front +x
        quad("light", CORNELL_LIGHT, (0.0, 0.99, 0.01), 0.23 * x, 0.19 * z),   # front -y, 0.01 below the ceiling
        turned_box("tall box", white, (-0.33, -0.4, -0.28), (0.3, 0.61, 0.3), 18.25),
        turned_box("short box", white, (0.335, -0.7, 0.38), (0.3, 0.3, 0.3), -17.0),
    )
    return ReferenceScene("cornell-box", shapes, View((0.0, 0.0, 3.9), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0),
                                                      39.3077, width, height), 8)


BUNNY_WHITE = Surface("bunny", (0.8, 0.8, 0.8))
BUNNY_GROUND = Surface("ground", (0.5, 0.5, 0.5))
BUNNY_LIGHT = Surface("light", (0.0, 0.0, 0.0), (8.0, 8.0, 8.0))


def bunny_scene(mesh_path, width: int = 1920, height: int = 1080) -> ReferenceScene:
    """bunny00 (an OFF file of triangles, y up, about a unit across) resting on
    an 8 x 8 ground at y = 0 under a 1 x 1 light at y = 2 facing down; the
    camera in front, a little above."""
    vertices, faces = read_off(mesh_path)
    vertices = vertices - [0.0, vertices[:, 1].min(), 0.0]   # resting on the ground
    x, y, z = np.eye(3)
    shapes = (
        flat_shape("bunny", BUNNY_WHITE, vertices, faces),
        quad("ground", BUNNY_GROUND, (0.0, 0.0, 0.0), 4.0 * x, -4.0 * z),     # front +y
        quad("light", BUNNY_LIGHT, (0.0, 2.0, 0.0), 0.5 * x, 0.5 * z),       # front -y
    )
    return ReferenceScene("bunny00", shapes, View((0.0, 0.9, 3.2), (0.0, 0.42, 0.0), (0.0, 1.0, 0.0),
                                                  30.0, width, height), 8)


def read_off(path) -> tuple[np.ndarray, np.ndarray]:
    """(V, 3) float64 vertices and (F, 3) int64 faces of an OFF file of triangles."""
    tokens = Path(path).read_text().split()
    if not tokens or tokens[0] != "OFF":
        raise ValueError(f"{path}: not an OFF file")
    nv, nf = int(tokens[1]), int(tokens[2])
    vertices = np.array(tokens[4:4 + 3 * nv], dtype=np.float64).reshape(nv, 3)
    faces = np.array(tokens[4 + 3 * nv:4 + 3 * nv + 4 * nf], dtype=np.int64).reshape(nf, 4)
    if not (faces[:, 0] == 3).all():
        raise ValueError(f"{path}: only triangles are read here")
    return vertices, faces[:, 1:]


# ---------------------------------------------------------------------------
# glTF


def gltf_document(scene: ReferenceScene) -> tuple[dict, bytes]:
    """The glTF JSON document of ``scene`` (one mesh node per shape, in order,
    then the camera node) and its binary buffer (the document's buffer 0 has no
    uri yet)."""
    doc = {"asset": {"version": "2.0", "generator": "clrt benchmarks/scenes.py"},
           "extensionsUsed": ["KHR_materials_emissive_strength", "KHR_materials_specular"],
           "scene": 0, "scenes": [{"name": scene.name, "nodes": list(range(len(scene.shapes) + 1))}],
           "nodes": [], "meshes": [], "materials": [], "accessors": [], "bufferViews": [], "buffers": []}
    blob = bytearray()

    def view_of(data: np.ndarray, target: int) -> int:
        blob.extend(b"\0" * (-len(blob) % 4))
        doc["bufferViews"].append({"buffer": 0, "byteOffset": len(blob), "byteLength": data.nbytes, "target": target})
        blob.extend(data.tobytes())
        return len(doc["bufferViews"]) - 1

    def accessor(data: np.ndarray, component: int, kind: str, target: int, bounds: bool = False) -> int:
        item = {"bufferView": view_of(data, target), "componentType": component, "count": len(data), "type": kind}
        if bounds:
            item["min"], item["max"] = data.min(axis=0).tolist(), data.max(axis=0).tolist()
        doc["accessors"].append(item)
        return len(doc["accessors"]) - 1

    materials: dict = {}
    for shape in scene.shapes:
        if shape.surface.name not in materials:
            materials[shape.surface.name] = len(doc["materials"])
            doc["materials"].append(gltf_material(shape.surface))
        attributes = {"POSITION": accessor(shape.vertices.astype("<f4"), 5126, "VEC3", 34962, bounds=True),
                      "NORMAL": accessor(shape.normals.astype("<f4"), 5126, "VEC3", 34962)}
        indices = accessor(shape.faces.astype("<u4").ravel(), 5125, "SCALAR", 34963)
        doc["meshes"].append({"name": shape.name, "primitives": [
            {"attributes": attributes, "indices": indices, "material": materials[shape.surface.name]}]})
        doc["nodes"].append({"name": shape.name, "mesh": len(doc["meshes"]) - 1})
    view = scene.view
    doc["cameras"] = [{"name": "camera", "type": "perspective", "perspective": {
        "yfov": math.radians(view.fov), "aspectRatio": view.width / view.height, "znear": 0.001}}]
    matrix = view.camera_to_world()
    doc["nodes"].append({"name": "camera", "camera": 0, "matrix": [float(a) + 0.0 for a in matrix.T.ravel()]})
    doc["buffers"].append({"byteLength": len(blob)})
    return doc, bytes(blob)


def gltf_material(surface: Surface) -> dict:
    """A pure Lambert glTF material (module docstring), emitting if ``surface`` does."""
    material = {"name": surface.name,
                "pbrMetallicRoughness": {"baseColorFactor": [*map(float, surface.base_color), 1.0],
                                         "metallicFactor": 0.0, "roughnessFactor": 1.0},
                "extensions": {"KHR_materials_specular": {"specularFactor": 0.0}},
                "doubleSided": False}
    strength = max(surface.emission)
    if strength > 0:
        material["emissiveFactor"] = [float(e) / strength for e in surface.emission]
        material["extensions"]["KHR_materials_emissive_strength"] = {"emissiveStrength": float(strength)}
    return material


def gltf_text(doc: dict) -> str:
    """``doc`` as JSON text a person can read: each top-level key on its own
    line, and each item of a top-level list."""
    lines = []
    for key, value in doc.items():
        if isinstance(value, list) and value and isinstance(value[0], dict):
            items = ",\n  ".join(json.dumps(item, separators=(", ", ": ")) for item in value)
            lines.append(f" {json.dumps(key)}: [\n  {items}\n ]")
        else:
            lines.append(f" {json.dumps(key)}: {json.dumps(value, separators=(', ', ': '))}")
    return "{\n" + ",\n".join(lines) + "\n}\n"


def write_gltf(scene: ReferenceScene, path) -> Path:
    """Write ``scene`` as a .gltf file (the buffer as a data URI) or a .glb file,
    by ``path``'s extension."""
    path = Path(path)
    doc, blob = gltf_document(scene)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix.lower() == ".glb":
        blob += b"\0" * (-len(blob) % 4)
        doc["buffers"][0]["byteLength"] = len(blob)
        text = json.dumps(doc, separators=(",", ":")).encode()
        text += b" " * (-len(text) % 4)
        data = (struct.pack("<III", 0x46546C67, 2, 12 + 8 + len(text) + 8 + len(blob))
                + struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(blob), 0x004E4942) + blob)
    else:
        doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(blob).decode()
        data = gltf_text(doc).encode()
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_bytes(data)
    tmp.replace(path)   # no half-written file
    return path


def main(argv=None) -> int:
    import argparse
    p = argparse.ArgumentParser(prog="python -m benchmarks.scenes", description=__doc__.split("\n")[0])
    p.add_argument("--mesh-dir", type=Path, default=SHARED_MESHES,
                   help=f"folder holding bunny00.off (default {SHARED_MESHES}); without it only the Cornell box")
    p.add_argument("--out", type=Path, default=ROOT / "out" / "scenes",
                   help=f"folder for the bunny scene, {BUNNY_FILE_NAME} (default out/scenes, not committed)")
    args = p.parse_args(argv)
    written = [write_gltf(cornell_box(), CORNELL_BOX_FILE)]
    mesh = args.mesh_dir / "bunny00.off"
    if mesh.is_file():
        written.append(write_gltf(bunny_scene(mesh), args.out / BUNNY_FILE_NAME))
    else:
        print(f"{mesh} not found: the bunny scene is not written")
    for path in written:
        print(f"wrote {path} ({path.stat().st_size} bytes)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
