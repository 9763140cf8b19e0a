"""Instances: meshes placed in a scene by affine transforms (docs/instances.md).

    >>> instances = as_instances([bunny, (bunny, lifted), (teapot, turned)])
    >>> instances.meshes         # the distinct meshes: [bunny, teapot]
    >>> instances.mesh_of        # (3,) int64: [0, 0, 1]
    >>> instances.transforms     # (3, 4, 4) float64, object -> world

What the entry points take as several meshes: a list of meshes (each as
:func:`clrt.scene.load.as_mesh` takes one: a Mesh, a file path, a trimesh
object) or of ``(mesh, transform)`` pairs, an :class:`Instances` made from
arrays, or a glTF file (.gltf, .glb), whose mesh nodes are its instances.
One mesh object listed twice is one mesh placed twice (instanced, not
copied); instance ``k`` is the ``k``-th entry, the index queries report.
Every transform is checked here (4x4, finite, affine, invertible), so a bad
one is one line naming its instance.
"""

from __future__ import annotations

import itertools
import os
from dataclasses import replace

import numpy as np

from clrt import checks, config
from clrt.errors import InputError
from clrt.scene.formats.part import Part, build, fill_normals
from clrt.scene.formats.trimesh_objects import is_trimesh_scene
from clrt.scene.mesh import Mesh


def _is_mesh_source(value) -> bool:
    """Something that names or is one mesh (not a (vertices, faces) pair: that
    is given as a clrt.Mesh inside a list of instances)."""
    return (isinstance(value, (Mesh, str, os.PathLike))
            or hasattr(value, "vertices") and hasattr(value, "faces") or is_trimesh_scene(value))


def _is_pair(value) -> bool:
    return isinstance(value, (tuple, list)) and len(value) == 2 and _is_mesh_source(value[0])


def is_instance_list(source) -> bool:
    """Does ``source`` list several placed meshes (rather than being one mesh,
    such as ``(vertices, faces)``)?"""
    return isinstance(source, Instances) or (
        isinstance(source, (list, tuple)) and any(_is_mesh_source(x) or _is_pair(x) for x in source))


def is_gltf_file(source) -> bool:
    """Is ``source`` the path of a glTF file, whose mesh nodes are instances?"""
    return isinstance(source, (str, os.PathLike)) and os.fspath(source).lower().endswith((".gltf", ".glb"))


class Instances:
    """Meshes and their placements.

    ``meshes``: the distinct meshes (anything :func:`clrt.scene.load.as_mesh`
    takes, each); ``mesh_of``: (I,) the mesh of each instance, an index into
    ``meshes``; ``transforms``: (I, 4, 4) affine maps from each mesh's space
    to the world (None: the identity for all).  Checked when made: one line,
    :class:`clrt.InputError`, naming the first bad instance.

    Attributes: ``meshes`` (list of Mesh), ``mesh_of`` ((I,) int64),
    ``transforms`` ((I, 4, 4) float64).
    """

    def __init__(self, meshes, mesh_of, transforms=None):
        from clrt.scene.load import as_mesh
        self.meshes = [as_mesh(m) for m in meshes]
        if not self.meshes:
            raise InputError("instances need at least one mesh")
        try:
            index = np.asarray(mesh_of)
        except (TypeError, ValueError):
            index = np.asarray(None)
        if index.ndim != 1 or len(index) == 0 or not np.issubdtype(index.dtype, np.integer):
            raise checks.fail("mesh_of", "a non-empty list of mesh indices", mesh_of)
        if len(index) > config.MAX_INSTANCES:
            raise InputError(f"a scene holds at most {config.MAX_INSTANCES:,} instances (results name them by "
                             f"int32), got {len(index):,}")
        missing = np.nonzero((index < 0) | (index >= len(self.meshes)))[0]
        if len(missing):
            k = int(missing[0])
            raise InputError(f"instance {k} names mesh {int(index[k])}, but there "
                             f"{'is 1 mesh' if len(self.meshes) == 1 else f'are {len(self.meshes)} meshes'} "
                             f"(0..{len(self.meshes) - 1})")
        self.mesh_of = index.astype(np.int64)
        if transforms is None:
            transforms = np.broadcast_to(np.eye(4), (len(index), 4, 4))
        self.transforms = checked_transforms(transforms, len(index))

    def __len__(self) -> int:
        return len(self.mesh_of)

    def __repr__(self) -> str:
        return f"<clrt.Instances: {len(self):,} of {len(self.meshes):,} meshes>"

    def boxes(self) -> np.ndarray:
        """(I, 2, 3) float64: each instance's box in the world -- its mesh's box,
        the eight corners mapped by the transform (it holds every point of the
        placed mesh)."""
        mesh_boxes = np.stack([m.bounds for m in self.meshes]).astype(np.float64)[self.mesh_of]   # (I, 2, 3)
        return mapped_boxes(self.transforms, mesh_boxes)

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) float64: the box of every instance's box."""
        known = self.__dict__.get("_bounds")
        if known is not None:
            return known.copy()
        boxes = self.boxes()
        return np.stack([boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)])

    def with_transforms(self, transforms: np.ndarray, bounds: np.ndarray) -> "Instances":
        """These meshes placed by ``transforms`` instead: a new Instances that
        takes (does not copy) the (I, 4, 4) float64 array, checked already
        (clrt.device.instances.move_instances checks a move as
        :func:`checked_transforms` does, without its singular values for
        10,000 instances), and ``bounds``, their world box as :attr:`bounds`
        gives it (a move computes it)."""
        moved = object.__new__(Instances)
        moved.meshes, moved.mesh_of, moved.transforms = self.meshes, self.mesh_of, transforms
        moved._bounds = np.array(bounds, np.float64)
        return moved

    def flattened(self) -> Mesh:
        """All instances as one Mesh: each instance's mesh moved by its transform
        (in float64, then rounded to float32), instances in order -- the scene
        a two-level BVH must answer as (its triangle ``k`` of instance ``i``
        is row ``sum(F of instances before i) + k``)."""
        vertices, faces, base = [], [], 0
        for mesh, m in zip((self.meshes[k] for k in self.mesh_of), self.transforms):
            vertices.append(mesh.vertices.astype(np.float64) @ m[:3, :3].T + m[:3, 3])
            faces.append(mesh.faces.astype(np.int64) + base)
            base += len(mesh.vertices)
        return Mesh(np.concatenate(vertices).astype(np.float32), np.concatenate(faces).astype(np.int32))


def mapped_boxes(transforms: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """(I, 2, 3) float64 boxes of ``boxes`` (I, 2, 3) mapped by ``transforms``
    (I, 4, 4): centre mapped, half extent through |linear part| (the box of
    the mapped corners, in float64; :func:`mapped_columns`)."""
    rows = np.moveaxis(transforms[:, :3], 0, -1)                 # (3, 4, I)
    lo, hi = mapped_columns(rows, *np.moveaxis(boxes, 0, -1))
    return np.stack([lo.T, hi.T], axis=1)


def mapped_columns(rows: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The boxes lo..hi ((3, I) each) mapped by affine maps of rows ``rows``
    ((3, 4, I): linear part, translation): lo, hi (3, I).  Each sum from left
    to right, as the device's top-level build sums (build_instances.cl's
    mapped_box): the same boxes, bit for bit."""
    centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    mid = np.stack([dot3(r[:3], centre) + r[3] for r in rows])
    reach = np.stack([dot3(np.abs(r[:3]), half) for r in rows])
    return mid - reach, mid + reach


def dot3(p, q):
    """The dot products of p and q ((3, ...) each), summed from left to right."""
    return (p[0] * q[0] + p[1] * q[1]) + p[2] * q[2]


def far_placement(scene) -> str:
    """clrt.scene.scene.far_triangle's words for a Scene of placed meshes,
    from the boxes of its placements (their meshes' boxes, mapped):
    "scene.toml: object 'ring', placement 3 reaches (1e+25, 0, 0), 1e+25 from
    the middle of the scene (1 placement that far out)" -- the middle the
    median of the boxes' centres."""
    boxes, names = [], []
    for k, o in enumerate(scene.objects):
        m = np.eye(4)[None] if o.transforms is None else o.transforms
        boxes.append(mapped_boxes(m, np.broadcast_to(o.mesh.bounds, (len(m), 2, 3))))
        names += [(f"object {o.mesh.name!r}" if o.mesh.name else f"object {k}", p) for p in range(len(m))]
    boxes = np.concatenate(boxes)
    middle = np.median(boxes.mean(axis=1), axis=0)
    reach = np.abs(boxes - middle).max(axis=1)                                   # (P, 3) farthest corner
    distance = np.linalg.norm(reach, axis=1)
    farthest = float(distance.max())
    typical = float(np.median(distance))
    far = farthest / 2 if typical == 0.0 else min(1000.0 * typical, farthest / 2)
    count = int((distance >= far).sum())
    k = int(np.argmax(distance))
    corner = np.where(np.abs(boxes[k, 1] - middle) >= np.abs(boxes[k, 0] - middle), boxes[k, 1], boxes[k, 0])
    text = lambda x: f"{x:.3g}".replace("e+", "e")   # noqa: E731
    where = f"{scene.source}: " if scene.source else ""
    return (f"{where}{names[k][0]}, placement {names[k][1]} reaches ({', '.join(map(text, corner))}), "
            f"{text(farthest)} from the middle of the scene ({count:,} placement{'s' if count != 1 else ''} "
            "that far out)")


def checked_transforms(transforms, count: int) -> np.ndarray:
    """(count, 4, 4) float64 affine, invertible transforms; InputError naming the
    first instance whose transform is not one."""
    try:
        with np.errstate(over="ignore", invalid="ignore"):
            m = np.array(transforms, dtype=np.float64)
    except (TypeError, ValueError):
        raise checks.fail("transforms", f"({count}, 4, 4) affine matrices", transforms) from None
    if m.shape != (count, 4, 4):
        raise InputError(f"transforms must have shape ({count}, 4, 4), got {m.shape}")
    bad = ~np.isfinite(m).all(axis=(1, 2))
    if bad.any():
        k = int(np.argmax(bad))
        raise _bad_transform(k, "finite", _entry_text(m[k], ~np.isfinite(m[k])))
    bad = (m[:, 3] != (0.0, 0.0, 0.0, 1.0)).any(axis=1)
    if bad.any():
        k = int(np.argmax(bad))
        raise _bad_transform(k, "affine (last row 0 0 0 1)", f"last row {checks.show(m[k, 3])}")
    singular = np.linalg.svd(m[:, :3, :3], compute_uv=False)   # (I, 3), largest first
    with np.errstate(divide="ignore", invalid="ignore"):
        condition = singular[:, 0] / singular[:, 2]
    bad = ~(condition <= config.MAX_TRANSFORM_CONDITION)
    if bad.any():
        k = int(np.argmax(bad))
        raise _bad_transform(k, f"invertible (a linear part of condition number at most "
                                f"{checks.show(config.MAX_TRANSFORM_CONDITION)})",
                             "a singular one" if not np.isfinite(condition[k]) or singular[k, 2] == 0.0
                             else f"one of condition number {float(condition[k]):.3g}")
    return m


def _bad_transform(k: int, rule: str, got: str) -> InputError:
    """checks.fail's message for instance ``k``'s transform, ``got`` as written."""
    return InputError(f"instance {k}'s transform must be {rule}, got {got}")


def _entry_text(matrix: np.ndarray, where: np.ndarray) -> str:
    r, c = (int(x[0]) for x in np.nonzero(where))
    return f"{checks.show(float(matrix[r, c]))} in row {r}, column {c}"


def as_instances(source) -> Instances:
    """:class:`Instances` from an Instances, from a list of meshes or of
    ``(mesh, transform)`` pairs (``transform``: a 4x4 affine matrix, object ->
    world; one mesh object, or one path, listed twice is one mesh placed
    twice), or from a glTF file: its mesh nodes in document order, depth first,
    each glTF mesh one mesh however many nodes place it (a node's world
    transform composed down its hierarchy).  InputError naming the first bad
    entry (MeshLoadError for a bad file)."""
    if isinstance(source, Instances):
        return source
    if is_gltf_file(source):
        return Instances(*gltf_instances(os.fspath(source)))
    if len(source) > config.MAX_INSTANCES:
        raise InputError(f"a scene holds at most {config.MAX_INSTANCES:,} instances (results name them by "
                         f"int32), got {len(source):,}")
    sources, mesh_of, transforms, seen = [], [], [], {}
    for k, entry in enumerate(source):
        if _is_mesh_source(entry):
            mesh, transform = entry, np.eye(4)
        elif _is_pair(entry):
            mesh, transform = entry
        else:
            raise checks.fail(f"instance {k}", "a mesh or a (mesh, 4x4 transform) pair", entry)
        key = ("path", os.path.abspath(os.fspath(mesh))) if isinstance(mesh, (str, os.PathLike)) else id(mesh)
        if key not in seen:
            seen[key] = len(sources)
            sources.append(mesh)
        mesh_of.append(seen[key])
        transforms.append(_checked_shape(k, transform))
    return Instances(sources, np.array(mesh_of, np.int64), np.stack(transforms))


def _checked_shape(k: int, transform) -> np.ndarray:
    """One instance's transform as a (4, 4) float64 array (its values are checked
    with the others')."""
    try:
        with np.errstate(over="ignore", invalid="ignore"):
            m = np.array(transform, dtype=np.float64)
    except (TypeError, ValueError):
        raise checks.fail(f"instance {k}'s transform", "a 4x4 affine matrix", transform) from None
    if m.shape != (4, 4):
        raise _bad_transform(k, "a 4x4 affine matrix", f"shape {m.shape}")
    return m


def placed_meshes(source) -> "Instances | Mesh":
    """Instances of a list of meshes, an Instances, or a glTF file that places
    meshes more than once (its mesh nodes); a glTF file with one mesh node is
    its one Mesh, placed, as the file reads flattened."""
    if is_gltf_file(source):
        meshes, mesh_of, transforms = gltf_instances(os.fspath(source))
        if len(mesh_of) > 1:
            return Instances(meshes, mesh_of, transforms)
        mesh, m = meshes[mesh_of[0]], transforms[0]
        return Mesh.from_arrays(mesh.vertices.astype(np.float64) @ m[:3, :3].T + m[:3, 3], mesh.faces, mesh.name)
    return as_instances(source)


def gltf_instances(path: str) -> "tuple[list[Mesh], np.ndarray, np.ndarray]":
    """A glTF file's mesh nodes as instances: each glTF mesh once, in its own
    space (its primitives in order, as the flattened file holds a node's
    triangles), and once more with its triangles' corners 1 and 2 swapped if a
    mirroring node places it (the flattened file's faces face out so, as glTF
    says); then, for each mesh node in the flattened file's order (document
    order, depth first), its mesh's index among those and the node's world
    matrix (4x4, float64, composed down the hierarchy)."""
    meshes, _, mesh_of, transforms = gltf_placements(path)
    return meshes, mesh_of, transforms


def gltf_placements(path: str) -> "tuple[list[Mesh], list, np.ndarray, np.ndarray]":
    """:func:`gltf_instances` with the file's materials (a list of clrt
    Materials, the same for every mesh: a mesh's face_material indexes it)
    after the meshes."""
    from clrt.scene.formats.gltf import gltf_nodes
    name = os.path.splitext(os.path.basename(path))[0]
    meshes, materials, found, mesh_of, transforms = [], [], {}, [], []
    for _, primitives in itertools.groupby(gltf_nodes(path), key=lambda entry: entry[0]):
        primitives = list(primitives)
        mesh, world = primitives[0][1:3]
        key = (mesh, bool(np.linalg.det(world[:3, :3]) < 0))
        if key not in found:
            parts = [_rewound(part) if key[1] else replace(part) for *_, part in primitives]
            fill_normals(parts)   # (on copies: the file's primitives are shared by its nodes)
            found[key] = len(meshes)
            built, file_materials = build(parts, path, f"{name} mesh {mesh}")
            meshes.append(built)
            materials.append(file_materials)
        mesh_of.append(found[key])
        transforms.append(world)
    return meshes, materials, np.array(mesh_of, np.int64), np.array(transforms, np.float64)


def _rewound(part: Part) -> Part:
    """A copy of ``part`` with its triangles' corners 1 and 2 swapped (and their
    texture coordinates): a mirroring node's winding, without moving it."""
    return replace(part, faces=part.faces[:, [0, 2, 1]], uv=None if part.uv is None else part.uv[:, [0, 2, 1]])
