"""What the entry points accept as a scene or a mesh, turned into one.

The renderer, the ray queries and the CLI take a Scene, a Mesh, a mesh or scene
file path, a trimesh object or (vertices, faces); this module is where each of
those becomes a Scene or a Mesh.  File readers are imported only when a file
is read (they bring trimesh).
"""

from __future__ import annotations

import os

from clrt.scene.instances import as_instances, is_gltf_file, is_instance_list
from clrt.scene.mesh import Mesh
from clrt.scene.placed import gltf_scene, placed_scene
from clrt.scene.scene import Scene, scene_from_mesh


def as_mesh(source) -> Mesh:
    """A Mesh from a Scene (all objects, in order, as placed) or from anything
    :func:`clrt.scene.load.as_mesh` takes (a Mesh, a path, a trimesh object,
    (vertices, faces))."""
    if isinstance(source, Scene):
        return Mesh.concatenate([o.mesh for o in (source.flattened() if source.instanced else source).objects])
    from clrt.scene.load import as_mesh as mesh_of
    return mesh_of(source)


def as_scene(source) -> Scene:
    """A Scene from a Scene, a TOML scene file (``.toml``), or anything
    :func:`~clrt.scene.scene.scene_from_mesh` takes (a Mesh, a mesh file path --
    a glTF camera node becomes the scene's camera --, a trimesh Trimesh or
    Scene -- with its materials and textures, as its file by path --,
    (vertices, faces)) with the default framing and light; InputError otherwise.
    Several meshes -- a list of meshes or of ``(mesh, 4x4 transform)`` pairs,
    a clrt.Instances, a glTF file whose nodes place a mesh more than once --
    make a Scene of placed meshes (clrt.scene.placed; docs/instances.md)."""
    if isinstance(source, Scene):
        return source
    if is_instance_list(source):
        return placed_scene(as_instances(source))
    if is_gltf_file(source):
        from clrt.scene.formats.gltf import gltf_shares_meshes
        if gltf_shares_meshes(os.fspath(source)):
            return gltf_scene(source)
    from clrt.scene.load import SCENE_EXTENSION
    if isinstance(source, (str, os.PathLike)) and os.fspath(source).lower().endswith(SCENE_EXTENSION):
        from clrt.scene.scene_file import load_scene
        return load_scene(source)
    return scene_from_mesh(source)
