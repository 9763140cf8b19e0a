"""clrt.device.pinned.upload: the staged path (page-locked blocks filled by
threads) writes exactly the array, for sizes around the block size."""

import numpy as np
import pyopencl as cl
import pytest

from clrt.device import pinned
from clrt.device.context import create_context


@pytest.mark.parametrize("staged", (True, False))
def test_upload_writes_the_array(device, staged, monkeypatch):
    context, queue = create_context(device)
    monkeypatch.setattr(pinned, "STAGE_BYTES", 1 << 20)       # several blocks from a few MB
    rng = np.random.default_rng(3)
    for nbytes in (4, (1 << 20) - 4, 1 << 20, 5 * (1 << 20) + 12, 9 * (1 << 20) + 4):
        array = rng.integers(0, 2 ** 31, nbytes // 4, dtype=np.int32)
        buffer = cl.Buffer(context, cl.mem_flags.READ_WRITE, array.nbytes)
        pinned.upload(context, queue, buffer, array, staged=staged)
        back = np.empty_like(array)
        cl.enqueue_copy(queue, back, buffer, is_blocking=True)
        assert np.array_equal(back, array), nbytes
    pinned._stages.pop(context.int_ptr, None)               # blocks of the patched size


def test_parallel_copy_is_a_copy():
    src = np.arange(9_000_001, dtype=np.uint8)
    for threads in (1, 3, 8):
        dst = np.zeros_like(src)
        pinned._parallel_copy(dst, src, threads)
        assert np.array_equal(dst, src), threads


def _stage_every_ray_array(monkeypatch):
    """Ray arrays of any size through the staging blocks, on every device (as
    large ones go on GPUs), in blocks of 4 kB so that uploads take turns."""
    from clrt.query import accel as query_accel
    monkeypatch.setattr(pinned, "STAGE_BYTES", 4096)
    monkeypatch.setattr(query_accel, "RAY_STAGED_MIN_BYTES", 0)
    monkeypatch.setattr(query_accel, "RAY_STAGING", {"gpu": True, "cpu": True})


def test_ray_chunks_through_staging_give_the_same_answers(device, monkeypatch):
    """Ray arrays uploaded through the page-locked blocks (as on GPUs; forced
    here on every device, with blocks and chunks small enough that many
    uploads take turns in the two blocks on both pipeline queues) give the
    hits of the plain copy, every field, and the same any-hit and all-hits."""
    import clrt
    from clrt.scene import primitives
    mesh = primitives.torus(1.0, 0.35, 24, 12)
    rng = np.random.default_rng(11)
    origins = rng.normal(size=(5000, 3)) * 2.0
    directions = rng.normal(size=(5000, 3)) * 0.5 - 0.1 * origins
    plain = clrt.Accel(mesh, device=device, chunk_rays=700)
    want = plain.trace(origins, directions)
    want_any, want_all = plain.any_hit(origins, directions), plain.all_hits(origins, directions)
    monkeypatch.setattr(pinned, "PARALLEL_COPY_MIN_BYTES", 1024)
    _stage_every_ray_array(monkeypatch)
    staged = clrt.Accel(mesh, device=device, chunk_rays=700)
    pinned._stages.pop(staged.context.int_ptr, None)          # blocks of the patched size
    try:
        got = staged.trace(origins, directions)
        assert (got.prim >= 0).sum() > 300 and (got.prim < 0).sum() > 300     # hits and misses
        for field in want._fields:
            assert np.array_equal(getattr(got, field), getattr(want, field)), field
        assert np.array_equal(staged.any_hit(origins, directions), want_any)
        for a, b in zip(staged.all_hits(origins, directions), want_all):
            assert np.array_equal(a, b)
    finally:
        pinned._stages.pop(staged.context.int_ptr, None)


def test_staged_uploads_from_two_threads(device, monkeypatch):
    """Two threads, each with its own Accel on the process's one context,
    upload their rays through the context's staging blocks at the same time:
    each gets the answers it gets alone."""
    from concurrent.futures import ThreadPoolExecutor

    import clrt
    from clrt.scene import primitives
    mesh = primitives.torus(1.0, 0.35, 24, 12)
    rng = np.random.default_rng(12)
    rays = [(rng.normal(size=(4000, 3)) * 2.0, rng.normal(size=(4000, 3))) for _ in range(2)]
    accels = [clrt.Accel(mesh, device=device, chunk_rays=500) for _ in range(2)]
    want = [a.trace(o, d).t.copy() for a, (o, d) in zip(accels, rays)]
    _stage_every_ray_array(monkeypatch)
    pinned._stages.pop(accels[0].context.int_ptr, None)       # blocks of the patched size
    try:
        def run(k):
            return [accels[k].trace(*rays[k]).t.copy() for _ in range(5)]
        with ThreadPoolExecutor(2) as pool:
            results = list(pool.map(run, (0, 1)))
        for k in (0, 1):
            assert all(np.array_equal(t, want[k]) for t in results[k]), k
    finally:
        pinned._stages.pop(accels[0].context.int_ptr, None)


def test_scene_buffers_through_staging_render_the_same_image(device, monkeypatch):
    """A scene's large arrays (the renderer's per-slot shading data and vertex
    normals; the triangles, rows and ids of a host-built tree) go through the
    page-locked blocks as on GPUs -- forced here for every array on every
    device, in blocks of 4 kB -- and the image and the hits are those of the
    buffers made from the arrays."""
    import clrt
    from clrt.scene import primitives
    scene = clrt.scene_from_mesh(primitives.torus(1.0, 0.35, 24, 12))
    camera = clrt.Camera(scene.camera.eye, scene.camera.target, scene.camera.up, scene.camera.fov, 64, 48)
    want = [clrt.Renderer(scene, device=device, builder=b).render(camera, hits=True) for b in ("sah", "auto")]
    monkeypatch.setattr(pinned, "STAGE_BYTES", 4096)
    monkeypatch.setattr(pinned, "STAGED_MIN_BYTES", 0)
    monkeypatch.setattr(pinned, "PARALLEL_COPY_MIN_BYTES", 1024)
    monkeypatch.setattr(pinned, "device_kind", lambda _: "gpu")    # staged, as on a GPU
    renderers = [clrt.Renderer(scene, device=device, builder=b) for b in ("sah", "auto")]
    pinned._stages.pop(renderers[0].context.int_ptr, None)          # blocks of the patched size
    try:
        for renderer, frame in zip(renderers, want):
            got = renderer.render(camera, hits=True)
            assert (frame.prim >= 0).sum() > 100
            assert np.array_equal(got.image, frame.image) and np.array_equal(got.prim, frame.prim)
    finally:
        pinned._stages.pop(renderers[0].context.int_ptr, None)


def test_points_converted_in_the_staging_give_the_same_answers(device, monkeypatch):
    """float64 points converted to float32 on their way through the page-locked
    blocks (forced on every device; blocks of 4 kB, several threads)
    give bit for bit the answers of the same points given as float32 -- also
    a strided view -- and a point beyond float32, or NaN, the same error."""
    import clrt
    from clrt.errors import InputError
    from clrt.scene import primitives
    mesh = primitives.torus(1.0, 0.35, 24, 12)
    points = np.random.default_rng(13).normal(size=(5000, 3)) * 1.2
    wide = np.concatenate([points, np.ones((len(points), 1))], axis=1)   # rows of 4: a strided (N, 3) view
    plain = clrt.Accel(mesh, device=device, chunk_rays=700)
    as_float32 = points.astype(np.float32)
    want = plain.closest_points(as_float32)
    want_sign, want_wn = plain.signed_distance(as_float32, sign="normal"), plain.winding_number(as_float32)
    bad = {}
    for row in ([1e39, 0.0, 0.0], [0.0, np.nan, 1.0]):
        given = points.copy()
        given[1234] = row
        with pytest.raises(InputError) as error:
            plain.distance(given)
        bad[tuple(row)] = (given, str(error.value))
    monkeypatch.setattr(pinned, "PARALLEL_COPY_MIN_BYTES", 1024)
    _stage_every_ray_array(monkeypatch)
    staged = clrt.Accel(mesh, device=device, chunk_rays=700)
    pinned._stages.pop(staged.context.int_ptr, None)          # blocks of the patched size
    try:
        for given in (points, wide[:, :3]):
            got = staged.closest_points(given)
            assert (got.prim >= 0).all()
            for field in want._fields:
                assert np.array_equal(getattr(got, field), getattr(want, field)), field
            assert np.array_equal(staged.signed_distance(given, sign="normal"), want_sign)
            assert np.array_equal(staged.winding_number(given), want_wn)
        for given, message in bad.values():
            with pytest.raises(InputError) as error:
                staged.distance(given)
            assert str(error.value) == message and "point 1234" in message
    finally:
        pinned._stages.pop(staged.context.int_ptr, None)


def test_arrays_uploaded_together_are_staged_by_their_bytes_together(device, monkeypatch):
    """pinned.upload_together: a mesh's vertices and faces, each below
    STAGED_MIN_BYTES, go through the staging together where their sum reaches
    it on a GPU (a GPU emulated on the test device), and arrive whole."""
    context, queue = create_context(device)
    monkeypatch.setattr(pinned, "STAGED_MIN_BYTES", 1 << 20)
    monkeypatch.setattr(pinned, "device_kind", lambda _: "gpu")
    chosen = []
    plain = pinned.upload
    monkeypatch.setattr(pinned, "upload", lambda *a, **k: chosen.append(a[4]) or plain(*a, **k))
    rng = np.random.default_rng(4)
    for nbytes, staged in ((600_000, True), (300_000, False)):
        arrays = [rng.random(nbytes // 4, dtype=np.float32), rng.integers(0, 9, nbytes // 4, dtype=np.int32)]
        buffers = [cl.Buffer(context, cl.mem_flags.READ_WRITE, a.nbytes) for a in arrays]
        chosen.clear()
        for event in pinned.upload_together(context, queue, list(zip(buffers, arrays))):
            event.wait()
        assert chosen == [staged, staged], nbytes
        for buffer, array in zip(buffers, arrays):
            back = np.empty_like(array)
            cl.enqueue_copy(queue, back, buffer, is_blocking=True)
            assert np.array_equal(back, array), nbytes
