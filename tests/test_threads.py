"""Threads sharing clrt's objects (clrt/device/sharing.py): every call answers
as it would alone, bit for bit, whatever runs beside it.

Without the per-object locks two threads on one Accel set the same kernel's
arguments and fill the same chunk buffers: most answers came back wrong (88
of 160 calls in the first try), and two threads on one Renderer crashed
PoCL (a tile buffer released under the other thread's launch).  Threads
interleave differently from run to run, so each test repeats its calls.
"""

import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

import clrt
from clrt.scene import primitives
from clrt.scene.scene import Camera, Light, scene_from_mesh

ROUNDS = 6


def _rays(seed: int, n: int):
    rng = np.random.default_rng(seed)
    origins = rng.normal(size=(n, 3)) * 2.5
    directions = -origins + rng.normal(size=(n, 3)) * 0.6   # hits and misses
    return origins.astype(np.float32), directions.astype(np.float32)


def _answers(accel, origins, directions, device_rays=False) -> list:
    """Every query of ``accel`` on the rays, as host arrays."""
    if device_rays:
        import pyopencl.array as cla
        o, d = cla.to_device(accel.queue, origins), cla.to_device(accel.queue, directions)
        hits = accel.trace(o, d)
        return [np.asarray(a.get()) for a in hits] + [accel.any_hit(o, d).get(), accel.count(o, d).get()]
    hits = accel.trace(origins, directions)
    return ([np.array(a) for a in hits] + [accel.any_hit(origins, directions).copy(),
                                           accel.count(origins, directions).copy(),
                                           *accel.all_hits(origins, directions)])


def _same(got: list, want: list) -> bool:
    return len(got) == len(want) and all(np.array_equal(a, b) for a, b in zip(got, want))


def _in_threads(work, count: int) -> list:
    with ThreadPoolExecutor(count) as pool:
        return list(pool.map(work, range(count)))


def test_threads_share_one_accel(device):
    """Four threads query one Accel, each with its own rays (several chunks a
    call, host and device arrays): each gets the serial answers."""
    accel = clrt.Accel(primitives.torus(1.0, 0.35, 24, 12), device=device, chunk_rays=512)
    rays = [_rays(k, 1500 + 97 * k) for k in range(4)]
    on_device = [False, True, False, True]
    want = [_answers(accel, *r, d) for r, d in zip(rays, on_device)]
    assert (want[0][1] >= 0).any() and (want[0][1] < 0).any()     # prim: hits and misses

    def work(k):
        return [_same(_answers(accel, *rays[k], on_device[k]), want[k]) for _ in range(ROUNDS)]

    assert _in_threads(work, 4) == [[True] * ROUNDS] * 4


def test_threads_with_their_own_accels(device):
    """Threads that build and query an Accel each (host SAH builds side by
    side, on the process's one context) get what one thread gets."""
    meshes = [primitives.torus(1.0, 0.35, 20 + 2 * k, 10) for k in range(3)]
    rays = [_rays(10 + k, 1200) for k in range(3)]
    want = [_answers(clrt.Accel(m, device=device, builder="sah"), *r) for m, r in zip(meshes, rays)]

    def work(k):
        accel = clrt.Accel(meshes[k], device=device, builder="sah", chunk_rays=400)
        return [_same(_answers(accel, *rays[k]), want[k]) for _ in range(ROUNDS)]

    assert _in_threads(work, 3) == [[True] * ROUNDS] * 3


def _cameras(count: int) -> list:
    return [Camera(eye=(3 * np.cos(a), 1.0, 3 * np.sin(a)), target=(0, 0, 0), width=40, height=30)
            for a in np.linspace(0.0, 2.5, count)]


def test_threads_share_one_renderer(device):
    """Three threads render other views with one Renderer: each frame (image
    and hits) is the one rendered alone."""
    renderer = clrt.Renderer(scene_from_mesh(primitives.torus(1.0, 0.35, 24, 12)), device=device)
    cameras = _cameras(3)
    want = [renderer.render(c, hits=True) for c in cameras]
    want = [(f.image.copy(), f.prim.copy()) for f in want]

    def work(k):
        frames = [renderer.render(cameras[k], hits=True) for _ in range(ROUNDS)]
        return [np.array_equal(f.image, want[k][0]) and np.array_equal(f.prim, want[k][1]) for f in frames]

    assert _in_threads(work, 3) == [[True] * ROUNDS] * 3


def test_refit_and_lights_while_other_threads_render_and_query(device):
    """One thread moves the scene back and forth (refit) and swaps the lights
    while another renders with two samples a pixel (a refit could fall between
    them) and a third queries through Accel.from_renderer: every frame and
    every answer is wholly the old scene's or wholly the new one's."""
    meshes = [primitives.torus(1.0, 0.35, 24, 12), primitives.torus(1.0, 0.5, 24, 12)]   # same triangles
    lights = [[Light((0.0, 4.0, 3.0))], [Light((3.0, 4.0, 0.0), (1.0, 0.5, 0.5))]]
    scenes = [scene_from_mesh(m, lights=l) for m, l in zip(meshes, lights)]
    renderer = clrt.Renderer(scenes[0], device=device)
    queries = clrt.Accel.from_renderer(renderer, chunk_rays=512)
    camera, rays = _cameras(1)[0], _rays(3, 1500)
    frames, answers = [], []
    for scene in (scenes[1], scenes[0]):
        renderer.refit(scene)
        frames.insert(0, renderer.render(camera, samples=2).image.copy())
        answers.insert(0, [np.array(a) for a in queries.trace(*rays)])
    assert not np.array_equal(frames[0], frames[1]) and not _same(answers[0], answers[1])
    done = threading.Event()

    def move():
        k = 0
        while not done.is_set():
            k += 1
            renderer.refit(scenes[k % 2])

    def render(_):
        images = [renderer.render(camera, samples=2).image for _ in range(ROUNDS)]
        return [any(np.array_equal(image, f) for f in frames) for image in images]

    def query(_):
        got = [[np.array(a) for a in queries.trace(*rays)] for _ in range(ROUNDS)]
        return [any(_same(g, a) for a in answers) for g in got]

    mover = threading.Thread(target=move)
    mover.start()
    try:
        with ThreadPoolExecutor(2) as pool:
            rendered, queried = pool.submit(render, 0), pool.submit(query, 0)
            assert rendered.result() == [True] * ROUNDS
            assert queried.result() == [True] * ROUNDS
    finally:
        done.set()
        mover.join()


def test_accel_refit_while_another_thread_queries(device):
    """One thread moves an Accel's mesh back and forth (refits in place and
    rebuilds, which replace its buffers and kernels) while another traces
    with it: every answer is wholly the one of the old mesh or of the new."""
    meshes = [primitives.torus(1.0, 0.35, 24, 12), primitives.torus(1.0, 0.5, 24, 12)]
    accel = clrt.Accel(meshes[0], device=device, chunk_rays=512)
    rays = _rays(4, 1500)
    answers = []
    for mesh in meshes:
        accel.refit(mesh.vertices)
        answers.append([np.array(a) for a in accel.trace(*rays)])
    assert not _same(answers[0], answers[1])
    done = threading.Event()

    def move():
        k = 0
        while not done.is_set():
            k += 1
            accel.refit(meshes[k % 2].vertices, rebuild=k % 3 == 0)

    mover = threading.Thread(target=move)
    mover.start()
    try:
        got = [[np.array(a) for a in accel.trace(*rays)] for _ in range(ROUNDS)]
    finally:
        done.set()
        mover.join()
    assert [any(_same(g, a) for a in answers) for g in got] == [True] * ROUNDS


def test_intersector_first_used_by_threads(device, monkeypatch):
    """Threads that use a new RayMeshIntersector at once see its Accel only
    with the host arrays made for it (before: a thread found the Accel while
    another was still making them, and failed with an AttributeError)."""
    trimesh = pytest.importorskip("trimesh")
    import types

    import clrt.query.intersector as intersector
    mesh = trimesh.creation.icosphere(subdivisions=2)
    origins, directions = _rays(5, 300)
    want = clrt.RayMeshIntersector(mesh, device=device).intersects_location(origins, directions)
    fresh = clrt.RayMeshIntersector(mesh, device=device)
    halfway, go_on = threading.Event(), threading.Event()

    def unique(*args, **kwargs):   # the first thread stops halfway through the arrays
        halfway.set()
        go_on.wait(timeout=10.0)
        return np.unique(*args, **kwargs)

    monkeypatch.setattr(intersector, "np", types.SimpleNamespace(**{**vars(np), "unique": unique}))

    class Lock:
        """The intersector's lock; a second thread waiting on it lets the first go on."""

        def __init__(self):
            self.lock = threading.Lock()

        def __enter__(self):
            if not self.lock.acquire(blocking=False):
                go_on.set()
                self.lock.acquire()

        def __exit__(self, *exc):
            self.lock.release()

    fresh._lock = Lock()

    def second():
        halfway.wait(timeout=10.0)
        try:
            return fresh.intersects_location(origins, directions)
        finally:
            go_on.set()

    with ThreadPoolExecutor(2) as pool:
        jobs = [pool.submit(fresh.intersects_location, origins, directions), pool.submit(second)]
        results = [job.result() for job in jobs]
    for got in results:
        assert all(np.array_equal(a, b) for a, b in zip(got, want))


def test_threads_open_one_context(device, monkeypatch):
    """Threads making the first Accel of a device at once share one context
    (a slow driver left two)."""
    import pyopencl as cl

    from clrt.device import context
    monkeypatch.setattr(context, "_CONTEXTS", {})
    made = cl.Context

    def slow_context(*args, **kwargs):
        threading.Event().wait(0.1)     # another thread gets the GIL meanwhile
        return made(*args, **kwargs)

    monkeypatch.setattr(cl, "Context", slow_context)
    monkeypatch.setattr(context.warmup, "take_context", lambda device_ptr: None)   # no context made ahead
    pairs = _in_threads(lambda _: context.create_context(device), 3)
    assert len({id(c) for c, _ in pairs}) == 1
