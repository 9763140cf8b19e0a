"""What clrt keeps in a long-running program: nothing per call, and nothing of
an Accel or a Renderer once the caller lets it go (docs/limits.md, "A
long-running program")."""

import gc
import sys

import numpy as np
import pytest

import clrt
from clrt.query import accel as accel_module
from clrt.scene import primitives
from clrt.scene.scene import Camera, scene_from_mesh


def _rays(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    origins = (rng.normal(size=(n, 3)) * 2.5).astype(np.float32)
    return origins, -origins


def test_queries_keep_a_bounded_number_of_launch_events(device):
    """Every query's launch events were kept for kernel_ms until it was called:
    a program that queries all day (and never asks for kernel times) grew
    without bound, a few kB a query.  Their times are now summed and the
    events let go, and kernel_ms still counts every launch."""
    accel = clrt.Accel(primitives.icosphere(1), device=device)
    origins, directions = _rays(300)
    queries = 3 * accel_module.LAUNCHES_KEPT
    for k in range(queries):
        [accel.trace, accel.any_hit, accel.count][k % 3](origins, directions)
    assert len(accel.launches) <= accel_module.LAUNCHES_KEPT
    assert accel.kernel_ms() > 0
    assert accel.kernel_ms() == 0.0 and not accel.launches    # counted once


def _device_buffers(obj) -> list:
    """The device buffers of an Accel or a Renderer, scene and per-call."""
    found = [b for parts in obj.geometry.buffers.values() for b in parts]
    for name in ("_buffers", "_frame_buffers", "buffers"):
        found += list(getattr(obj, name, {}).values())
    return found


def _distinct(buffers: list) -> list:
    return list({id(b): b for b in buffers}.values())


def _only_here(buffers: list) -> bool:
    """Is every buffer referred to by ``buffers`` alone?  (sys.getrefcount
    counts the list's reference and its own argument's.)"""
    return all(sys.getrefcount(buffers[k]) == 2 for k in range(len(buffers)))


def test_dropped_accels_and_renderers_free_their_device_buffers(device):
    """An Accel, a Renderer and Accel.from_renderer's queries that the caller
    lets go are freed at once (no reference cycle waits for the garbage
    collector), and nothing else holds their device buffers."""
    origins, directions = _rays(500)
    gc.disable()
    try:
        accel = clrt.Accel(primitives.torus(1.0, 0.35, 16, 8), device=device)
        accel.trace(origins, directions)
        accel.all_hits(origins, directions)
        buffers = _distinct(_device_buffers(accel))
        assert len(buffers) > 5
        del accel
        assert _only_here(buffers)

        renderer = clrt.Renderer(scene_from_mesh(primitives.torus(1.0, 0.35, 16, 8)), device=device)
        renderer.render(Camera(eye=(0, 1, 3), target=(0, 0, 0), width=32, height=24))
        queries = clrt.Accel.from_renderer(renderer)
        queries.trace(origins, directions)
        buffers = _distinct(_device_buffers(renderer) + _device_buffers(queries))
        del renderer, queries
        assert _only_here(buffers)
    finally:
        gc.enable()


def test_batches_of_many_sizes_take_one_work_group_size(device, monkeypatch):
    """Queries and frames of many sizes launch each kernel in groups of one
    size.  PoCL compiles and keeps a variant of a kernel for every work-group
    size it runs, and its own choice follows the batch size: count over
    batches of 1 to 1000 rays grew the process by 40 MB, a frame of every
    size up to 64 x 64 by 10 kB."""
    import pyopencl as cl

    from clrt.device.context import device_kind
    accels = [clrt.Accel(primitives.torus(1.0, 0.35, 16, 8), device=device, accel=volume)
              for volume in ("box", "sphere")]     # sphere volumes: single-ray closest hits
    if device_kind(accels[0].queue.device) != "cpu":
        pytest.skip("the driver's choice stays on GPUs (QUERY_GROUP)")
    renderer = clrt.Renderer(scene_from_mesh(primitives.torus(1.0, 0.35, 16, 8)), device=device)
    groups: dict[tuple, set] = {}     # (kernel, its handle): the group sizes it ran
    enqueue = cl.enqueue_nd_range_kernel

    def recording(queue, kernel, global_size, local_size, *args, **kwargs):
        groups.setdefault((kernel.function_name, kernel.int_ptr), set()).add(local_size and tuple(local_size))
        return enqueue(queue, kernel, global_size, local_size, *args, **kwargs)

    monkeypatch.setattr(cl, "enqueue_nd_range_kernel", recording)
    origins, directions = _rays(700)
    for n in (1, 7, 97, 500, 641, 700):
        for accel in accels:
            accel.trace(origins[:n], directions[:n])
            accel.count(origins[:n], directions[:n])
            accel.all_hits(origins[:n], directions[:n])
        accels[0].camera_images(Camera(eye=(0, 1, 3), target=(0, 0, 0), width=n % 50 + 3, height=5))
        renderer.render(Camera(eye=(0, 1, 3), target=(0, 0, 0), width=n % 50 + 3, height=7))
    assert {"query_count", "query_all", "query_closest", "camera_rays", "shade_pixels"} <= {k for k, _ in groups}
    assert all(len(sizes) == 1 and None not in sizes for sizes in groups.values()), groups
