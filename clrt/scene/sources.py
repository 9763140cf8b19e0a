"""What the entry points accept as a scene or a mesh, turned into one.

The renderer, the ray queries and the CLI take a Scene, a Mesh, a mesh or scene
file path, a trimesh object or (vertices, faces); this module is where each of
those becomes a Scene or a Mesh.  File readers are imported only when a file
is read (they bring trimesh).
"""

from __future__ import annotations

import os

from clrt.scene.mesh import Mesh
from clrt.scene.scene import Scene, scene_from_mesh


def as_mesh(source) -> Mesh:
    """A Mesh from a Scene (all objects, in order) or from anything
    :func:`clrt.scene.load.as_mesh` takes (a Mesh, a path, a trimesh object,
    (vertices, faces))."""
    if isinstance(source, Scene):
        return Mesh.concatenate([o.mesh for o in source.objects])
    from clrt.scene.load import as_mesh as mesh_of
    return mesh_of(source)


def as_scene(source) -> Scene:
    """A Scene from a Scene, a TOML scene file (``.toml``), or anything
    :func:`~clrt.scene.scene.scene_from_mesh` takes (a Mesh, a mesh file path --
    a glTF camera node becomes the scene's camera --, a trimesh Trimesh or
    Scene -- with its materials and textures, as its file by path --,
    (vertices, faces)) with the default framing and light; InputError otherwise."""
    if isinstance(source, Scene):
        return source
    from clrt.scene.load import SCENE_EXTENSION
    if isinstance(source, (str, os.PathLike)) and os.fspath(source).lower().endswith(SCENE_EXTENSION):
        from clrt.scene.scene_file import load_scene
        return load_scene(source)
    return scene_from_mesh(source)
