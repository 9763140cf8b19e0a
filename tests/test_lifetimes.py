"""What clrt keeps in a long-running program: nothing per call, and nothing of
an Accel or a Renderer once the caller lets it go (docs/limits.md, "A
long-running program")."""

import gc
import sys

import numpy as np

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

        renderer = clrt.Renderer(scene_from_mesh(primitives.torus(1.0, 0.35, 16, 8)), device)
        renderer.render(Camera(eye=(0, 1, 3), target=(0, 0, 0), width=32, height=24))
        queries = clrt.Accel.from_renderer(renderer)
        queries.trace(origins, directions)
        buffers = _distinct(_device_buffers(renderer) + _device_buffers(queries))
        del renderer, queries
        assert _only_here(buffers)
    finally:
        gc.enable()
