"""What a first call compiles on a CPU device (docs/benchmarks.md, "The first
call with empty caches"): the device builder's program holds only the
kernels its build launches, and the host sorts for it -- in the order of the
device's radix sort."""

import numpy as np
import pyopencl as cl
import pytest

from clrt.device import build, host_sort, program
from clrt.device.build_kernels import launched_kernels
from clrt.device.context import create_context
from clrt.device.wide_build import collapse_on_device
from clrt.errors import KernelBuildError


@pytest.fixture(scope="module")
def cpu_queue():
    return create_context("cpu")


@pytest.mark.parametrize("keep_keys", [True, False])
@pytest.mark.parametrize("n", [1, 2, 5000, 70_001])
def test_the_host_sort_is_the_device_sort(n, keep_keys, cpu_queue):
    """The host's order is the device radix sort's (build_sort.cl): stable by
    the whole 32-bit key, equal keys in input order -- pairs read back from the
    buffers sorted in place (the ids, as morton_codes leaves them, the places
    0 .. n - 1; the keys sorted where asked for, else as they were), against
    numpy's stable sort of the keys."""
    context, queue = cpu_queue
    rng = np.random.default_rng(n)
    keys = rng.integers(0, 1 << 32, n, dtype=np.uint64).astype(np.uint32)
    keys[rng.random(n) < 0.6] = keys[0]           # a long run of one key
    keys[::7] &= np.uint32(0xFFFF0000)            # keys alike in their high half only
    keys[1::7] &= np.uint32(0x0000FFFF)           # and in their low half only
    ids = np.arange(n, dtype=np.uint32)
    flags = cl.mem_flags.READ_WRITE | cl.mem_flags.COPY_HOST_PTR
    key_buffer, id_buffer = cl.Buffer(context, flags, hostbuf=keys), cl.Buffer(context, flags, hostbuf=ids)
    assert host_sort.sort_on_host(queue, n, key_buffer, id_buffer, keep_keys=keep_keys) is id_buffer
    got_keys, got_ids = np.empty_like(keys), np.empty_like(ids)
    cl.enqueue_copy(queue, got_keys, key_buffer)
    cl.enqueue_copy(queue, got_ids, id_buffer, is_blocking=True)
    want = np.argsort(keys, kind="stable")
    assert np.array_equal(got_ids, want)
    assert np.array_equal(got_keys, keys[want] if keep_keys else keys)


@pytest.mark.parametrize("options", [{}, {"treelet_leaves": 7}, {"partition": True, "top_clusters": 16},
                                     {"tail_threshold": 1}, {"reinsert_iterations": 2}])
def test_a_build_compiles_the_kernels_it_launches_and_no_other(options, cpu_queue, monkeypatch):
    """On either kind of device the builder's program keeps exactly the
    kernels the build launches (the treelets', the SAH partition's, the
    reinsertion's and the tail's only when asked for) -- on a CPU device also
    the two that collapse the built tree into the wide BVH
    (clrt.device.wide_build, launched by the geometry) --, and the CPU's tree
    is the one the GPU driver's launches build (with ploc_tail from 2048
    clusters on, and the CPU's PLOC radius: a GPU's own is smaller), run here
    -- PLOC by iterations: with the partition a GPU climbs the linear BVH
    instead (build_hierarchy.cl), another tree."""
    context, queue = cpu_queue
    options = {"treelet_leaves": 0, "tail_group": 256, "top_clusters": 128, "partition": False,
               "reinsert_iterations": 0, **options}
    rng = np.random.default_rng(4)
    n = 12_000          # more than the serial tail takes (TAIL_THRESHOLD): the passes run first
    corners = (rng.random((n, 1, 3)) + 0.02 * rng.standard_normal((n, 3, 3))).astype(np.float32)
    built = build.build_on_device(context, queue, corners, leaf_size=4, profile=True, **options)
    launched = {name for name, _, _ in built.launches}
    segmented = bool(options.get("partition"))
    tail = options.get("tail_threshold", build.TAIL_THRESHOLD["cpu"]) > options["top_clusters"]
    kept = launched_kernels("cpu", segmented, options["treelet_leaves"] > 0, tail, wide=True,
                            reinsertion=options["reinsert_iterations"] > 0)
    assert launched | {"wide_plan", "wide_write"} == set(kept), launched ^ set(kept)
    defines = build.build_defines("box", "cpu", options["treelet_leaves"], 256, options["top_clusters"], segmented)
    assert set(program.build_program(context, "build_bvh.cl", defines, kernels=kept).kernel_names.split(";")) \
        == set(kept)
    wide = collapse_on_device(context, queue, built.rows, built.num_rows, built.tri_verts, built.kernels)
    assert wide.num_packets >= len(corners) / 4        # (tests/test_wide_build.py: its every byte)
    monkeypatch.setattr(build, "device_kind", lambda device: "gpu")
    monkeypatch.setattr(build, "PLOC_RADIUS", dict.fromkeys(build.PLOC_RADIUS, build.PLOC_RADIUS["cpu"]))
    gpu = build.build_on_device(context, queue, corners, leaf_size=4, profile=True,
                                **{**options, "tail_threshold": 2048, "hierarchy": False})
    launched = {name for name, _, _ in gpu.launches}
    assert launched == set(launched_kernels("gpu", segmented, options["treelet_leaves"] > 0, True,
                                            reinsertion=options["reinsert_iterations"] > 0)), launched
    for a, b in zip(built.read_back(), gpu.read_back()):
        assert np.array_equal(a.view(np.uint8), b.view(np.uint8))
    if segmented:      # a GPU's default with the partition: PLOC up the linear BVH, no ploc_merge, no tail
        hierarchical = build.build_on_device(context, queue, corners, leaf_size=4, profile=True, **options)
        launched = {name for name, _, _ in hierarchical.launches}
        assert launched == set(launched_kernels("gpu", segmented, options["treelet_leaves"] > 0, True,
                                                reinsertion=options["reinsert_iterations"] > 0,
                                                hierarchical=True)), launched


def test_keep_kernels_cuts_the_others_out_and_names_a_missing_one(cpu_queue):
    context, _ = cpu_queue
    defines = build.build_defines("box", "cpu")
    source = program.expand_source("build_bvh.cl")
    kept = program.keep_kernels(source, ["emit_tree", "ploc_top"])
    assert "void emit_tree(" in kept and "void ploc_top(" in kept and "void ploc_tail(" not in kept
    assert "inline void clear_build_state" in kept            # helpers stay: the compiler drops the unused
    built = program.build_program(context, "build_bvh.cl", defines, kernels=("emit_tree", "ploc_top"))
    assert sorted(built.kernel_names.split(";")) == ["emit_tree", "ploc_top"]
    with pytest.raises(KernelBuildError, match="no kernel ploc_nowhere"):
        program.keep_kernels(source, ["emit_tree", "ploc_nowhere"])


@pytest.mark.parametrize("kind", ["cpu", "gpu"])
def test_a_top_level_compiles_the_kernels_it_launches_and_no_other(kind, monkeypatch):
    """The top level of a scene of instances keeps exactly the kernels its
    place() launches on either kind of device (the GPU driver's launches run
    here), and both kinds' trees answer as the host-built top level."""
    import clrt
    from clrt.device import top_level
    from clrt.device.build_kernels import top_level_kernels
    from clrt.scene.instances import Instances
    from conftest import TEST_MESHES

    monkeypatch.setattr(top_level, "device_kind", lambda device: kind)
    rng = np.random.default_rng(5)
    transforms = np.tile(np.eye(4), (40, 1, 1))
    transforms[:, :3, 3] = rng.uniform(-5.0, 5.0, (40, 3))
    instances = Instances([TEST_MESHES["torus"](), TEST_MESHES["box"]()], rng.integers(0, 2, 40), transforms)
    on_device = clrt.Accel(instances, builder="device", device="cpu")
    on_host = clrt.Accel(instances, builder="sah", device="cpu")
    top = on_device.acceleration.device_top
    assert {kernel.site_name for kernel in top.sites.kernels} == set(top_level_kernels(kind))
    assert set(top.program.kernel_names.split(";")) == set(top_level_kernels(kind))
    origins = rng.uniform(-8.0, 8.0, (500, 3))
    directions = rng.normal(size=(500, 3))
    want, got = on_host.trace(origins, directions), on_device.trace(origins, directions)
    assert want.hit.sum() > 50
    for field in want._fields:
        assert np.array_equal(getattr(got, field), getattr(want, field)), field


def test_a_query_compiles_the_group_of_kernels_it_launches(monkeypatch):
    """An Accel builds trace.cl in the groups of QUERY_PROGRAMS, each when a
    call first needs one of its kernels: a trace builds query_closest's
    group and no other, an any-hit query then its own, a point query the
    points' group, the winding group never -- with the same answers as the
    whole program's (no groups given)."""
    import clrt
    from clrt.device import scene as device_scene
    from clrt.query import accel as query_accel
    from clrt.query.kernels import QUERY_KERNELS, QUERY_PROGRAMS
    from clrt.scene import primitives
    names = [n for group in QUERY_PROGRAMS for n in group]
    assert sorted(names) == sorted(QUERY_KERNELS)              # each kernel in one group
    asked = []

    def spy(context, entry, defines=None, extra_options=(), kernels=None):
        group = None if kernels is None else set(kernels)
        if entry == "trace.cl" and group not in asked:      # (each kernel asks: its group's program, once built)
            asked.append(group)
        return program.build_program(context, entry, defines, extra_options, kernels)
    monkeypatch.setattr(device_scene, "build_program", spy)
    mesh = primitives.torus(1.0, 0.3, 24, 12)
    rng = np.random.default_rng(3)
    origins = rng.normal(size=(400, 3)) * 2
    directions = -origins + 0.5 * rng.normal(size=(400, 3))
    points = rng.normal(size=(300, 3))
    accel = clrt.Accel(mesh, device="cpu")
    assert asked == []
    hits = accel.trace(origins, directions)
    accel.any_hit(origins, directions)
    group_of = {name: set(group) for group in QUERY_PROGRAMS for name in group}
    assert asked == [group_of["query_closest"], group_of["query_any"]]
    near = accel.closest_points(points)
    assert asked == [group_of["query_closest"], group_of["query_any"], group_of["query_closest_point"]]
    assert group_of["query_winding_number"] not in asked
    with monkeypatch.context() as m:
        m.setattr(query_accel, "QUERY_PROGRAMS", None)
        whole = clrt.Accel(mesh, device="cpu")
    got = whole.trace(origins, directions)
    assert asked[-1] is None                                   # the whole program
    assert np.array_equal(got.prim, hits.prim) and np.array_equal(got.t, hits.t) and (hits.prim >= 0).sum() > 50
    assert np.array_equal(whole.closest_points(points).distance, near.distance)


def test_a_program_two_threads_ask_for_is_built_once(cpu_queue, monkeypatch, tmp_path):
    """build_program from two threads at once: one compiles, the other waits
    for it and gets the same program; where the first thread's build fails,
    the waiting one builds it itself."""
    import threading
    import time
    import uuid
    context, _ = cpu_queue
    monkeypatch.setenv("CLRT_CACHE_DIR", str(tmp_path))
    compiled, real = [], program._compile

    def slow_compile(*args):
        compiled.append(threading.current_thread().name)
        time.sleep(0.3)                   # (long enough for the other thread to ask meanwhile)
        if len(compiled) == 1 and fail_first:
            raise KernelBuildError("the first build failed")
        return real(*args)

    monkeypatch.setattr(program, "_compile", slow_compile)
    for fail_first in (False, True):
        compiled.clear()
        defines = {"ACCEL_BVH": None, "VOLUME_SPHERE": None, "BVH_STACK_SIZE": 96 + fail_first,
                   "CLRT_TEST_KEY": uuid.uuid4().hex}        # (a key no build of this process had)
        got = {}

        def ask(name):
            try:
                got[name] = program.build_program(context, "render.cl", defines)
            except KernelBuildError as exc:
                got[name] = exc

        threads = [threading.Thread(target=ask, args=(name,), name=name) for name in ("a", "b")]
        threads[0].start()
        time.sleep(0.05)
        threads[1].start()
        for t in threads:
            t.join()
        if fail_first:
            assert compiled == ["a", "b"] and isinstance(got["a"], KernelBuildError)
            assert isinstance(got["b"], cl.Program)
        else:
            assert compiled == ["a"] and got["a"] is got["b"]


@pytest.mark.parametrize("accel", ["box", "sphere", "none"])
def test_a_renderer_builds_its_program_beside_its_tree(device, accel, monkeypatch):
    """A Renderer starts building render.cl in a thread before its tree is
    built, where the program's defines are foreseen (not a CPU's wide walk of
    boxes): the program its kernels come from is that one -- the foreseen
    defines are the scene's own -- and no thread builds it twice."""
    import threading
    import warnings
    import clrt
    from clrt.device import scene as device_scene
    from clrt.scene import primitives
    from clrt.scene.scene import Camera
    asked = []

    def spy(context, entry, defines=None, extra_options=(), kernels=None):
        built = program.build_program(context, entry, defines, extra_options, kernels)
        if entry == "render.cl":
            asked.append((threading.current_thread().name, dict(defines), built))
        return built

    monkeypatch.setattr(device_scene, "build_program", spy)
    filters = list(warnings.filters)
    renderer = clrt.Renderer(primitives.torus(1.0, 0.3, 48, 24), device=device, accel=accel, builder="device")
    assert warnings.filters == filters, "two threads' builds left a warning filter behind"
    foreseen = device_scene.foreseen_defines(accel, device)
    used = renderer.device_scene.defines()
    if foreseen is None:
        assert renderer.device_scene.kind == "cpu" and accel == "box" and used["BVH_WIDE"] is None
        assert [name for name, _, _ in asked] == ["MainThread"]
    else:
        assert foreseen == used
        assert sorted(name for name, _, _ in asked) == ["MainThread", "clrt-build-render.cl"]
        assert asked[0][1] == asked[1][1] and asked[0][2] is asked[1][2]
    assert not [t for t in threading.enumerate() if t.name.startswith("clrt-build")], "waited for at the end"
    assert next(iter(renderer.kernels.values())).program.int_ptr == asked[-1][2].int_ptr
    assert renderer.render(Camera.framing(renderer.scene.bounds, 24, 16)).visible
