"""Scenes of placed meshes (docs/instances.md): what the renderer takes as
several meshes -- a list of meshes or of ``(mesh, transform)`` pairs, a
:class:`clrt.Instances`, a glTF file whose nodes place a mesh more than once
-- made into a Scene whose objects place their meshes by transforms
(``SceneObject.transforms``), and such a Scene's placements as Instances.

    >>> scene = placed_scene(as_instances([bunny, (bunny, lifted)]))
    >>> scene.objects[0].transforms.shape     # (2, 4, 4): one object, placed twice
    >>> scene_instances(scene).mesh_of         # [0, 0]

Instance ``k`` is the ``k``-th placement: objects in order, each object's
placements in order (an object without transforms once, where it stands) --
for a list, its ``k``-th entry; for a glTF file, its ``k``-th mesh node in
document order, depth first (as clrt.Accel numbers them).
"""

from __future__ import annotations

import os
from dataclasses import replace

import numpy as np

from clrt.errors import InputError
from clrt.scene.instances import Instances, gltf_placements
from clrt.scene.scene import Camera, Material, Scene, SceneObject, default_light, file_view


def placed_scene(instances: Instances, materials: list | None = None, source: str = "", view=None) -> Scene:
    """A Scene of ``instances``: one object for each run of consecutive
    instances of one mesh, placing it by their transforms, with the default
    material (one Material for all, so that they share their rows) and, with
    ``materials`` (one list for each of the distinct meshes), a file's own
    materials for its faces.  Framed and lit as a single mesh is
    (scene_from_mesh): the camera ``view`` of a file (clrt.scene.load.file_camera)
    or a framing of the bounds, and one light above the eye."""
    mesh_of = instances.mesh_of
    starts = np.flatnonzero(np.r_[True, mesh_of[1:] != mesh_of[:-1]])
    ends = np.r_[starts[1:], len(mesh_of)]
    material = Material()
    objects = [SceneObject(instances.meshes[mesh_of[a]], material, materials[mesh_of[a]] if materials else (),
                           instances.transforms[a:b]) for a, b in zip(starts, ends)]
    scene = Scene(objects, [], source=source)
    if view is not None:
        scene.camera, scene.camera_framed = file_view(view, scene.bounds, os.path.basename(source)), False
    else:
        try:
            scene.camera, scene.camera_framed = Camera.framing(scene.bounds), True
        except InputError:   # too large to frame: a camera the caller places still works
            scene.camera, scene.camera_framed = None, True
    scene.default_lights = True
    if scene.camera is not None:
        scene.lights = [default_light(scene.bounds, scene.camera)]
    return scene


def gltf_scene(path) -> Scene:
    """The Scene of a glTF/GLB file whose nodes place its meshes: each mesh
    node an instance (clrt.scene.instances.gltf_placements: each glTF mesh one
    mesh, another for mirroring nodes), the file's materials and camera."""
    from clrt.scene.load import file_camera
    path = os.fspath(path)
    meshes, materials, mesh_of, transforms = gltf_placements(path)
    return placed_scene(Instances(meshes, mesh_of, transforms), materials, os.fsdecode(path), file_camera(path))


def scene_instances(scene: Scene) -> Instances:
    """Every placement of ``scene``'s objects as Instances (the module's
    docstring says in which order), each distinct Mesh object one mesh."""
    meshes, index, mesh_of, transforms = [], {}, [], []
    for o in scene.objects:
        k = index.setdefault(id(o.mesh), len(meshes))
        if k == len(meshes):
            meshes.append(o.mesh)
        mesh_of += [k] * o.placements
        transforms.append(np.eye(4)[None] if o.transforms is None else o.transforms)
    return Instances(meshes, np.array(mesh_of, np.int64), np.concatenate(transforms))


def moved_scene(scene: Scene, transforms: np.ndarray) -> Scene:
    """A copy of ``scene`` whose placements are ``transforms`` ((I, 4, 4), in
    the order of :func:`scene_instances`; checked already): each object keeps
    its mesh -- the same Mesh object, so that it stays the one uploaded --
    and its materials, and takes its run of the transforms."""
    objects, k = [], 0
    for o in scene.objects:
        obj = object.__new__(SceneObject)   # (made again, a smooth mesh would be split once more)
        placed = np.array(transforms[k:k + o.placements], np.float64)
        placed.flags.writeable = False
        for name, value in (("mesh", o.mesh), ("material", o.material), ("materials", o.materials),
                            ("transforms", placed)):
            object.__setattr__(obj, name, value)
        objects.append(obj)
        k += o.placements
    return replace(scene, objects=objects, lights=list(scene.lights))
