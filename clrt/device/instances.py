"""A scene of instances built for the device: each distinct mesh's BVH through
the one build front end (any builder, the device's included), then joined
with the instance table and a top level (clrt.accel.instances;
docs/instances.md) -- built on the device (clrt.device.top_level) when the
meshes' builder is the device's, else on the host.

    >>> scene = instanced_scene(instances, accel="box", builder="auto", leaf_size=4, device=None)
    >>> scene.acceleration.instances       # (I,) INSTANCE rows, uploaded with the rest
    >>> moved, changed = move_instances(scene, instances, transforms)
    >>> changed = refit_meshes(scene, refitted, [k])   # mesh k's vertices moved
"""

from __future__ import annotations

import time

import numpy as np

from clrt import checks
from clrt.accel.instances import (TwoLevel, assemble, instance_table, lbvh_depth_bound, mesh_places, move,
                                  to_recheck, top_level)
from clrt.config import MAX_COORDINATE
from clrt.device.acceleration import build_acceleration
from clrt.device.context import create_context
from clrt.device.scene import DeviceScene, stage
from clrt.device.top_level import DeviceTopLevel
from clrt.errors import InputError
from clrt.layouts import INSTANCE
from clrt.scene.arrays import device_origin, mesh_frames
from clrt.scene.instances import Instances, checked_transforms, mapped_boxes


def build_two_level(instances: Instances, accel: str, builder: str, leaf_size: int, device: str | None,
                    material_base=None) -> tuple[TwoLevel, np.ndarray, np.ndarray, np.ndarray]:
    """The two-level structure of ``instances`` with the meshes' corners (each
    mesh in its own device frame, mesh after mesh: what its slots index), the
    instances' world box (caller's frame) and the world's device origin.
    ``material_base``: (I,) each instance's first material row (the renderer's;
    Instance.material), else 0.  The top level is the device's (a linear BVH)
    where the meshes' builder is, else the host's (binned SAH)."""
    start = time.perf_counter()
    mesh_origins, corners = mesh_frames(instances.meshes)
    bottoms = [build_acceleration(c, accel, builder, leaf_size, device) for c in corners]
    for b in bottoms:   # the rows are read back and joined: the builder's device buffers go
        b.device_buffers = None
    mesh_bounds = np.stack([m.bounds for m in instances.meshes]).astype(np.float64)
    places = np.zeros(len(instances), INSTANCE)
    places["mesh"] = instances.mesh_of
    if material_base is not None:
        places["material"] = material_base
    mesh_places(bottoms, places, accel)
    if accel != "none" and bottoms[0].builder == "device":
        found = {}

        def checked(recheck, far, bounds, origin):   # (the instances' transforms are checked: Instances)
            found.update(bounds=bounds, origin=origin)

        top_build = DeviceTopLevel(create_context(device)[0], places, mesh_bounds, mesh_origins, accel)
        top_build.place(instances.transforms, checked)
        table, top = top_build.read()
        two = assemble(bottoms, table, top, accel, top_build.depth_bound, start)
        two.device_top = top_build
        return two, np.concatenate(corners), found["bounds"], found["origin"]
    bounds = instances.bounds
    origin = device_origin(bounds)
    table, _ = instance_table(instances.transforms, instances.mesh_of, mesh_bounds, mesh_origins, origin)
    for name in ("root", "first", "count", "material"):
        table[name] = places[name]
    top = top_level(table, accel) if accel != "none" else None
    two = assemble(bottoms, table, top, accel, top.depth if top is not None else 0, start)
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


def transform_array(transforms, count: int, copy: bool = True) -> np.ndarray:
    """``transforms`` as a (count, 4, 4) float64 array (``copy``: a new one),
    its values not yet checked (one line for what is not a stack of count
    4x4 matrices, as checked_transforms says it)."""
    try:
        with np.errstate(over="ignore", invalid="ignore"):
            m = np.array(transforms, dtype=np.float64, copy=copy or None)
    except (TypeError, ValueError):
        raise checks.fail("transforms", f"({count}, 4, 4) affine matrices", transforms) from None
    if m.shape != (count, 4, 4):
        raise InputError(f"transforms must have shape ({count}, 4, 4), got {m.shape}")
    return m


def _checked(transforms: np.ndarray, instances: Instances, recheck, far) -> None:
    """The verdict on moved instances whose fast checks named ``recheck`` (a
    transform the host checks exactly: all are, then -- checked_transforms
    decides, as when Instances are made) and ``far`` (placed past
    MAX_COORDINATE); InputError, one line, for the first bad one."""
    if recheck is not None:
        checked_transforms(transforms, len(instances))
    if far is not None:
        mesh = instances.meshes[instances.mesh_of[far]]
        box = mapped_boxes(transforms[far:far + 1], np.asarray(mesh.bounds, np.float64)[None])
        raise InputError(f"instance {far}'s transform takes its mesh to {float(np.abs(box).max()):.3g}, past "
                         f"+-{MAX_COORDINATE:.0e} (the device computes in float32)")


def move_instances(scene: DeviceScene, instances: Instances, transforms, profile: bool = False
                   ) -> tuple[Instances, bool]:
    """Move the instances of ``scene`` (a two-level DeviceScene of
    ``instances``) to ``transforms`` ((I, 4, 4), object -> world, checked as
    every instance's are; one line and nothing moves for a bad one): the
    instance table and the top level built again -- on the device
    (clrt.device.top_level) when it built them, else on the host
    (clrt.accel.instances.move) -- over the old ones, the meshes' levels left
    as they are, the world's device frame and reach chosen anew: the scene
    as a fresh build of the moved instances would make it, bit for bit.
    Returns the moved Instances and whether the programs' defines changed
    (clrt.device.geometry.DeviceGeometry.move_instances).  The move is done
    on the device when this returns; ``scene.acceleration.move_ms`` is its
    wall time, ``move_times`` its parts (``profile``: the device's phases
    too, run on the scene's profiling queue)."""
    start = time.perf_counter()
    two = scene.acceleration
    on_device = two.device_top is not None
    m = transform_array(transforms, len(instances), copy=not on_device)
    times = {"convert": 1e3 * (time.perf_counter() - start)}
    if on_device:
        frame = {}

        def checked(recheck, far, bounds, origin):
            _checked(m, instances, recheck, far)
            frame.update(bounds=bounds, origin=origin)

        try:
            last = two.device_top.place(m, checked, scene.queue if profile else None, times)
        except InputError:   # its buffers back to the last placement (the host copies read from them)
            two.device_top.place(instances.transforms, lambda *_: None)
            raise
        placed = time.perf_counter()
        bounds = frame["bounds"]
        # The host copies are read back when asked for, from this move's
        # buffers (the last move's reader would read them too): not here.
        two.pending = None
        with scene.out_of_memory():
            changed, copied = scene.geometry.place_instances(scene.queue, two.device_top, last, bounds,
                                                             frame["origin"])
        m = two.device_top.transforms_copy()    # the moved Instances' own, while the device works
        copied.wait()
        two.pending = two.device_top.read
        times["finish"] = 1e3 * (time.perf_counter() - placed)
    else:
        mesh_bounds = np.stack([mesh.bounds for mesh in instances.meshes]).astype(np.float64)
        with np.errstate(all="ignore"):   # (bad transforms are refused below)
            boxes = mapped_boxes(m, mesh_bounds[instances.mesh_of])
            bounds = np.stack([boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)])
            origin = device_origin(bounds)
            far = np.flatnonzero(~(np.abs(boxes).max(axis=(1, 2)) <= MAX_COORDINATE))
        mesh_origins = np.stack([device_origin(mesh.bounds) for mesh in instances.meshes])
        table, condition = instance_table(m, instances.mesh_of, mesh_bounds, mesh_origins, origin)
        recheck = np.flatnonzero(to_recheck(m, condition))
        _checked(m, instances, recheck[0] if len(recheck) else None, far[0] if len(far) else None)
        checked = time.perf_counter()
        rows = move(two, table)
        built = time.perf_counter()
        with scene.out_of_memory():
            changed = scene.geometry.move_instances(scene.queue, rows, bounds, origin)
        scene.queue.finish()
        times.update({"table": 1e3 * (checked - start) - times["convert"], "top level": 1e3 * (built - checked),
                      "upload": 1e3 * (time.perf_counter() - built)})
    two.move_ms = 1e3 * (time.perf_counter() - start)
    two.move_times = times
    return instances.with_transforms(m, bounds), changed


def refit_meshes(scene: DeviceScene, instances: Instances, meshes: list[int]) -> bool:
    """Show ``instances`` on ``scene``, a two-level DeviceScene of instances
    that differ from them only in the vertices of the distinct meshes
    ``meshes`` (and perhaps the transforms): each of those meshes moved into
    its new device frame, its slots uploaded anew and its rows refitted on the
    device (DeviceGeometry.refit_mesh), then the instance table and the top
    level placed anew as :func:`move_instances` places them (every instance
    of a moved mesh has a new world box) -- on the device, where it built the
    top level, after its copy of the meshes' boxes and origins is rewritten.
    One line and nothing refitted for an instance placed past MAX_COORDINATE.
    Returns whether the programs' defines changed."""
    _check_reach(instances)
    origins, corners = mesh_frames([instances.meshes[k] for k in meshes])
    top = scene.acceleration.device_top
    with scene.out_of_memory():
        for k, origin, c in zip(meshes, origins, corners):
            scene.geometry.refit_mesh(scene.queue, k, c)
            if top is not None:
                top.set_mesh_frame(k, np.asarray(instances.meshes[k].bounds, np.float64), origin)
    _, changed = move_instances(scene, instances, instances.transforms)
    return changed


def _check_reach(instances: Instances) -> None:
    """InputError naming the first instance placed past the device's range."""
    reach = np.abs(instances.boxes()).max(axis=(1, 2))
    if not (reach <= MAX_COORDINATE).all():
        k = int(np.argmax(~(reach <= MAX_COORDINATE)))
        raise InputError(f"instance {k}'s transform takes its mesh to {float(reach[k]):.3g}, past "
                         f"+-{MAX_COORDINATE:.0e} (the device computes in float32)")
