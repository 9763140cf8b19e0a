"""What an Accel is made from: one mesh, or several meshes placed as
instances (a list of meshes or of ``(mesh, transform)`` pairs, a
clrt.Instances, or a glTF file whose nodes place meshes more than once) --
a two-level scene on the device (docs/instances.md).

    >>> mesh, instances, scene = query_scene([bunny, (bunny, lifted)], accel="box", ...)
"""

from __future__ import annotations

import numpy as np

from clrt.device.instances import instanced_scene
from clrt.device.scene import DeviceScene
from clrt.scene.arrays import device_origin, triangle_corners
from clrt.scene.instances import Instances, is_gltf_file, is_instance_list, placed_meshes
from clrt.scene.mesh import Mesh
from clrt.scene.sources import as_mesh


def query_scene(source, *, accel: str, builder: str, leaf_size: int, device: str | None,
                **upload) -> tuple[Mesh | None, Instances | None, DeviceScene]:
    """(the mesh, None, its DeviceScene) for one mesh -- anything
    clrt.scene.sources.as_mesh takes, a glTF file with one mesh node among
    them --, (None, the Instances, their two-level DeviceScene) for several;
    options checked already, as Accel takes them (``upload``:
    max_buffer_bytes, max_buffer_label)."""
    options = dict(accel=accel, builder=builder, leaf_size=leaf_size, device=device, **upload)
    mesh = placed_meshes(source) if is_instance_list(source) or is_gltf_file(source) else as_mesh(source)
    if isinstance(mesh, Instances):
        return None, mesh, instanced_scene(mesh, **options)
    origin = device_origin(mesh.bounds)   # the device's frame (clrt.scene.arrays)
    return mesh, None, DeviceScene(triangle_corners(mesh, origin), bounds=mesh.bounds, origin=origin, **options)


def source_of(mesh: Mesh | None, instances: Instances | None):
    """What an Accel of ``mesh`` or ``instances`` is made again from (a copy, a
    pickle): the instances, or the mesh's vertices and faces (its surface
    detail plays no part in queries)."""
    if instances is not None:
        return instances
    return Mesh(np.asarray(mesh.vertices), np.asarray(mesh.faces), mesh.name)
