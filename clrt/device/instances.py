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

from clrt.accel.instances import TwoLevel, assemble, instance_table
from clrt.device.acceleration import build_acceleration
from clrt.device.scene import DeviceScene, stage
from clrt.scene.arrays import device_origin, triangle_corners
from clrt.scene.instances import Instances


def build_two_level(instances: Instances, accel: str, builder: str, leaf_size: int,
                    device: str | None) -> tuple[TwoLevel, np.ndarray, np.ndarray, np.ndarray]:
    """The two-level structure of ``instances`` with the meshes' corners (each
    mesh in its own device frame, mesh after mesh: what its slots index), the
    instances' world box (caller's frame) and the world's device origin."""
    start = time.perf_counter()
    mesh_origins = np.stack([device_origin(m.bounds) for m in instances.meshes])
    corners = [triangle_corners(m, c) for m, c in zip(instances.meshes, mesh_origins)]
    bottoms = [build_acceleration(c, accel, builder, leaf_size, device) for c in corners]
    for b in bottoms:   # the rows are read back and joined: the builder's device buffers go
        b.device_buffers = None
    bounds = instances.bounds
    origin = device_origin(bounds)
    two = assemble(bottoms, instance_table(instances, mesh_origins, origin), accel, start)
    return two, np.concatenate(corners), bounds, origin


def instanced_scene(instances: Instances, *, accel: str, builder: str, leaf_size: int, device: str | None,
                    timings: dict | None = None, **upload) -> DeviceScene:
    """The DeviceScene of ``instances`` (options as DeviceScene takes them;
    ``upload``: its keywords past the build, max_buffer_bytes and the like)."""
    with stage(timings, "acceleration build"):
        two, corners, bounds, origin = build_two_level(instances, accel, builder, leaf_size, device)
    return DeviceScene(corners, accel=accel, builder=builder, leaf_size=leaf_size, device=device, bounds=bounds,
                       origin=origin, timings=timings, acceleration=two, **upload)
