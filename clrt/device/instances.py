"""A scene of instances built for the device: each distinct mesh's BVH through
the one build front end (any builder, the device's included), then joined
with the instance table and a top level (clrt.accel.instances;
docs/instances.md).

    >>> scene = instanced_scene(instances, accel="box", builder="auto", leaf_size=4, device=None)
    >>> scene.acceleration.instances       # (I,) INSTANCE rows, uploaded with the rest
"""

from __future__ import annotations

import time

import numpy as np

from clrt.accel.instances import TwoLevel, assemble, instance_table, move
from clrt.config import MAX_COORDINATE
from clrt.device.acceleration import build_acceleration
from clrt.device.scene import DeviceScene, stage
from clrt.errors import InputError
from clrt.scene.arrays import device_origin, mesh_frames
from clrt.scene.instances import Instances, checked_transforms


def build_two_level(instances: Instances, accel: str, builder: str, leaf_size: int, device: str | None,
                    material_base=None) -> tuple[TwoLevel, np.ndarray, np.ndarray, np.ndarray]:
    """The two-level structure of ``instances`` with the meshes' corners (each
    mesh in its own device frame, mesh after mesh: what its slots index), the
    instances' world box (caller's frame) and the world's device origin.
    ``material_base``: (I,) each instance's first material row (the renderer's;
    Instance.material), else 0."""
    start = time.perf_counter()
    mesh_origins, corners = mesh_frames(instances.meshes)
    bottoms = [build_acceleration(c, accel, builder, leaf_size, device) for c in corners]
    for b in bottoms:   # the rows are read back and joined: the builder's device buffers go
        b.device_buffers = None
    bounds = instances.bounds
    origin = device_origin(bounds)
    table = instance_table(instances, mesh_origins, origin)
    if material_base is not None:
        table["material"] = material_base
    two = assemble(bottoms, table, accel, start)
    return two, np.concatenate(corners), bounds, origin


def instanced_scene(instances: Instances, *, accel: str, builder: str, leaf_size: int, device: str | None,
                    timings: dict | None = None, material_base=None, **upload) -> DeviceScene:
    """The DeviceScene of ``instances`` (options as DeviceScene takes them;
    ``upload``: its keywords past the build, max_buffer_bytes and the like;
    ``material_base``: build_two_level's)."""
    with stage(timings, "acceleration build"):
        two, corners, bounds, origin = build_two_level(instances, accel, builder, leaf_size, device, material_base)
    return DeviceScene(corners, accel=accel, builder=builder, leaf_size=leaf_size, device=device, bounds=bounds,
                       origin=origin, timings=timings, acceleration=two, **upload)


def move_instances(scene: DeviceScene, instances: Instances, transforms) -> tuple[Instances, bool]:
    """Move the instances of ``scene`` (a two-level DeviceScene of
    ``instances``) to ``transforms`` ((I, 4, 4), object -> world, checked as
    every instance's are): the instance table and the top level built again
    on the host and uploaded over the old ones (clrt.accel.instances.move),
    the meshes' levels left as they are, the world's device frame and reach
    chosen anew -- the scene as a fresh build of the moved instances would
    make it, bit for bit.  Returns the moved Instances and whether the
    programs' defines changed (clrt.device.geometry.DeviceGeometry.move_instances)."""
    start = time.perf_counter()
    moved = Instances(instances.meshes, instances.mesh_of, checked_transforms(transforms, len(instances)))
    _check_reach(moved)
    return moved, _place(scene, moved, start)


def refit_meshes(scene: DeviceScene, instances: Instances, meshes: list[int]) -> bool:
    """Show ``instances`` on ``scene``, a two-level DeviceScene of instances
    that differ from them only in the vertices of the distinct meshes
    ``meshes`` (and perhaps the transforms): each of those meshes moved into
    its new device frame, its slots uploaded anew and its rows refitted on the
    device (DeviceGeometry.refit_mesh), then the instance table and the top
    level placed anew as :func:`move_instances` places them (every instance
    of a moved mesh has a new world box).  Returns whether the programs'
    defines changed."""
    start = time.perf_counter()
    _check_reach(instances)
    _, corners = mesh_frames([instances.meshes[k] for k in meshes])
    with scene.out_of_memory():
        for k, c in zip(meshes, corners):
            scene.geometry.refit_mesh(scene.queue, k, c)
    return _place(scene, instances, start)


def _check_reach(instances: Instances) -> None:
    """InputError naming the first instance placed past the device's range."""
    reach = np.abs(instances.boxes()).max(axis=(1, 2))
    if not (reach <= MAX_COORDINATE).all():
        k = int(np.argmax(~(reach <= MAX_COORDINATE)))
        raise InputError(f"instance {k}'s transform takes its mesh to {float(reach[k]):.3g}, past "
                         f"+-{MAX_COORDINATE:.0e} (the device computes in float32)")


def _place(scene: DeviceScene, instances: Instances, start: float) -> bool:
    """The instance table of ``instances`` and the top level over their boxes,
    built on the host and uploaded (their meshes' rows as they are on the
    device); whether the programs' defines changed."""
    mesh_origins = np.stack([device_origin(m.bounds) for m in instances.meshes])
    bounds = instances.bounds
    origin = device_origin(bounds)
    rows = move(scene.acceleration, instance_table(instances, mesh_origins, origin))
    with scene.out_of_memory():
        changed = scene.geometry.move_instances(scene.queue, rows, bounds, origin)
    scene.acceleration.move_ms = 1e3 * (time.perf_counter() - start)
    return changed
