"""BVH build time and tree quality per builder: ``python -m benchmarks.build``.

    python -m benchmarks.build --device gpu
    python -m benchmarks.build --device gpu --triangles 1M,10M --builders sah,device
    python -m benchmarks.build --device cpu --meshes camel --repeat 3

For each scene and builder (``paper``, ``sah``: on the host; ``device``: PLOC
on the OpenCL device, clrt.device.build), one table row:

* build ms, ``first`` (the first build in this process: for the device
  builder it includes compiling the program) and ``warm`` (median of
  ``--repeat`` after that): wall time from the triangles in a host numpy array
  to the rows, slot-ordered triangles and ids in device buffers -- for the
  host builders the build, the pair rows, the triangle gather and the upload;
* ``device ms``: the device builder's kernels and copies (profiling events),
  and its phases;
* the tree: SAH cost (Acceleration.stats' formula), depth, bytes on the device;
* ``refit ms``: warm wall time of ``Accel.refit`` to the vertices moved by 1 %
  (the triangles uploaded, the volumes refitted on the device);
* ``trace ms``: median kernel time of one closest-hit primary ray per pixel
  at 1920x1080 (``trace_camera``), the scene's trees launched in turn for
  TRACE_ROUNDS rounds, on the fixed cameras of benchmarks.speed for its
  meshes, and a framing camera for the generated scenes: ``--triangles N``
  makes a grid of copies of the bunny (benchmarks.scale.instanced);
* ``random ms``: median kernel time of closest hits of ``--random`` rays
  (1M by default; benchmarks.raysets' random set, seed 0: origins in the
  mesh's box, directions uniform), rays and results on the device, in the
  same rounds as the primary rays; ``hits`` of those rays (every tree must
  give the same).

Then a second table, the whole calls a user waits for beside the build
(``--calls``; for the host builders and ``device``): ``upload ms``, the
triangles alone copied to the device as the device build copies them (warm
median); ``Accel() ms``, the warm median wall of ``clrt.Accel(mesh)`` (checks,
bounds, corners, build, upload, programs: all of it); ``scene ms``, one
``scene_from_mesh(mesh)`` (its crease split for smooth shading happens
there); ``Renderer() ms``, the warm median wall of ``clrt.Renderer(scene)``
of that scene; and each call over ``build warm + upload`` (issue 38 asks for
at most 1.5).

Prints markdown tables; timing is done here, never in tests.  ``--profile``
adds, for each device variant, one warm build launch by launch: device ms per
kernel and where the device sat idle between launches (waiting for the host).
"""

from __future__ import annotations

import sys

if not __package__:   # run as a script, python benchmarks/NAME.py: import from the repository, not this folder
    import os.path
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import argparse
import contextlib
import statistics
import time
from pathlib import Path

import numpy as np
import pyopencl as cl

from benchmarks.common import NON_NEGATIVE, SHARED_MESHES, exit_code, int_at_least, parse_count, rate
from benchmarks.scale import instanced
from benchmarks.speed import CASES
from clrt.config import HOST_BUILDERS, MAX_LEAF_SIZE
from clrt.scene.arrays import triangle_corners

SIZE = (1920, 1080)


def _host_build(context, queue, corners, volume, builder, leaf_size) -> tuple[dict, list]:
    """A host build up to device buffers; returns (stats, buffers)."""
    from clrt.accel import build
    from clrt.scene.arrays import triangle_verts
    built = build(corners, volume, builder, leaf_size)
    tris = triangle_verts(corners[built.prim_ids])
    mf = cl.mem_flags
    buffers = [cl.Buffer(context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=a)
               for a in (built.rows, tris, built.prim_ids)]
    queue.finish()
    return built.stats(), buffers


# Variants of the device builder, side by side with it (``--builders``):
# without ploc_tail (every PLOC iteration three launches, as before it), and
# with the triangles uploaded from pageable memory (no page-locked staging);
# and the tree a GPU builds, on any device (``device/as-gpu``: the GPU's
# choices of clrt.device.build -- treelets, ploc_tail's work-group, the SAH
# partition from PART_MIN_TRIANGLES -- e.g. a GPU's tree on PoCL).
DEVICE_VARIANTS = {"device": {}, "device/no-tail": {"tail_threshold": 1},
                   "device/plain-upload": {"staged_upload": False}, "device/as-gpu": {}}


# Variants' settings that are constants of clrt.device.build rather than
# arguments of build_on_device: builder -> {constant: value} (device_choices).
DEVICE_CONSTANTS: dict[str, dict] = {}


@contextlib.contextmanager
def device_choices(builder: str):
    """While in it, the device builder makes ``builder``'s choices of device
    type: a GPU's for ``device/as-gpu``, the device's own otherwise; and
    takes the variant's DEVICE_CONSTANTS."""
    from clrt.device import build
    saved = build.device_kind
    constants = DEVICE_CONSTANTS.get(builder, {})
    saved_constants = {name: getattr(build, name) for name in constants}
    if builder == "device/as-gpu":
        build.device_kind = lambda device: "gpu"
    for name, value in constants.items():
        setattr(build, name, value)
    try:
        yield
    finally:
        build.device_kind = saved
        for name, value in saved_constants.items():
            setattr(build, name, value)


def time_builds(context, queue, corners, volume, builder, leaf_size, repeat):
    """(first ms, warm median ms, stats, device timings or None).  Device
    builds are timed as a user's (no exact boxes kept, no profiling); one
    more build keeps the boxes for the statistics and times the phases on
    the device."""
    from clrt.device.build import build_on_device
    walls, last = [], None
    for _ in range(1 + repeat):
        if last is not None and builder in DEVICE_VARIANTS:
            last.release()
        start = time.perf_counter()
        if builder in DEVICE_VARIANTS:
            last = build_on_device(context, queue, corners, volume=volume, leaf_size=leaf_size,
                                   **DEVICE_VARIANTS[builder])
            queue.finish()
        else:
            last = _host_build(context, queue, corners, volume, builder, leaf_size)
        walls.append(1e3 * (time.perf_counter() - start))
    if builder in DEVICE_VARIANTS:
        last.release()
        last = build_on_device(context, queue, corners, volume=volume, leaf_size=leaf_size, keep_boxes=True,
                               device_times=True, **DEVICE_VARIANTS[builder])
        timings = last.timings
        stats = last.stats()
        last.release()
    else:
        stats, buffers = last
        for b in buffers:
            b.release()
        timings = None
    return walls[0], statistics.median(walls[1:]) if repeat else walls[0], stats, timings


def _traced_accel(mesh, volume, builder, leaf_size, device):
    """clrt.Accel over ``mesh`` from ``builder`` (a device variant's settings
    applied to its one build)."""
    from clrt.device import build, reinsert as reinsertion
    from clrt.query import Accel
    leaves = DEVICE_VARIANTS.get(builder, {}).get("treelet_leaves")
    minimum = DEVICE_VARIANTS.get(builder, {}).get("treelet_min")
    top = DEVICE_VARIANTS.get(builder, {}).get("top_clusters")
    partition = DEVICE_VARIANTS.get(builder, {}).get("partition")
    reinsert = DEVICE_VARIANTS.get(builder, {}).get("reinsert_iterations")
    saved_reinsert = dict(reinsertion.REINSERT_ITERATIONS)
    if reinsert is not None:                 # at any size
        reinsertion.REINSERT_ITERATIONS.update({kind: ((1 << 62, reinsert),) for kind in saved_reinsert})
    saved, saved_min = dict(build.TREELET_LEAVES), build.TREELET_MIN_TRIANGLES
    saved_top, saved_partition = dict(build.SAH_TOP_CLUSTERS), dict(build.SAH_PARTITION)
    if leaves is not None:                   # the variant's treelets for this one build
        build.TREELET_LEAVES.update({kind: leaves for kind in saved})
    if minimum is not None:
        build.TREELET_MIN_TRIANGLES = ((0, minimum),)
    if top is not None:
        build.SAH_TOP_CLUSTERS.update({kind: top for kind in saved_top})
    saved_minimum = build.PART_MIN_TRIANGLES
    if partition is not None:
        build.SAH_PARTITION.update({kind: bool(partition) for kind in saved_partition})
        build.PART_MIN_TRIANGLES = 0
    try:
        return Accel(mesh, accel=volume, builder="device" if builder in DEVICE_VARIANTS else builder,
                     leaf_size=leaf_size, device=device)
    finally:
        build.TREELET_LEAVES.update(saved)
        build.TREELET_MIN_TRIANGLES = saved_min
        build.SAH_TOP_CLUSTERS.update(saved_top)
        build.SAH_PARTITION.update(saved_partition)
        build.PART_MIN_TRIANGLES = saved_minimum
        reinsertion.REINSERT_ITERATIONS.update(saved_reinsert)


# Trace times of trees a few per cent apart are compared in one loop: every
# round launches each tree's camera rays once, so that a change of the GPU's
# clock falls on all of them alike (timed one tree after the other, the same
# tree's figure moved by 2-3 % between runs).
TRACE_ROUNDS = 15
RANDOM_RAYS = 1_000_000


def trace_and_refit_ms(mesh, camera, volume, builders, leaf_size, device, random_rays: int = 0) -> dict:
    """builder -> (median primary-ray kernel ms over TRACE_ROUNDS interleaved
    rounds after two, warm wall ms of Accel.refit to vertices moved by 1 %,
    median kernel ms of ``random_rays`` random rays' closest hits in the same
    rounds (nan for none), their hits)."""
    from benchmarks.raysets import _queries, random_rays as make_random_rays
    from clrt import layouts
    accels = {}
    for b in builders:
        with device_choices(b):
            accels[b] = _traced_accel(mesh, volume, b, leaf_size, device)
    hits = {b: cl.Buffer(a.context, cl.mem_flags.READ_WRITE, camera.width * camera.height * layouts.HIT.itemsize)
            for b, a in accels.items()}
    queries = {}
    if random_rays:
        origins, directions = make_random_rays(mesh, random_rays)
        queries = {b: _queries(a, origins, directions, np.inf)["closest"] for b, a in accels.items()}
    kernel = {b: [] for b in accels}
    random_kernel = {b: [] for b in accels}
    random_hits = {b: -1 for b in accels}
    for round_ in range(2 + TRACE_ROUNDS):
        for b, accel in accels.items():
            event = accel.launch_camera(camera, hits[b])
            accel.queue.finish()
            if round_ >= 2:
                kernel[b].append(1e-6 * (event.profile.end - event.profile.start))
            if b in queries:
                accel.kernel_ms()
                result = queries[b]()
                accel.queue.finish()
                if round_ >= 2:
                    random_kernel[b].append(accel.kernel_ms())
                if round_ == 0:
                    prim = result.prim.get() if hasattr(result.prim, "get") else result.prim
                    random_hits[b] = int((np.asarray(prim) >= 0).sum())
    for buffer in hits.values():
        buffer.release()
    moved = mesh.vertices * np.float32(1.01)
    out = {}
    for b, accel in accels.items():
        walls = []
        for _ in range(6):
            start = time.perf_counter()
            accel.refit(moved)
            accel.queue.finish()
            walls.append(1e3 * (time.perf_counter() - start))
        out[b] = (statistics.median(kernel[b]), statistics.median(walls[1:]),
                  statistics.median(random_kernel[b]) if random_kernel[b] else float("nan"), random_hits[b])
    return out


# A generated scene of the issue's size for the CPU comparison ("a 50k-triangle
# scan"; the held-out scan is not shipped): a torus knot of 2 x 782 x 32 triangles.
GENERATED = {"knot50k": dict(segments=782, sides=32)}


def embree_build_ms(mesh, repeat: int) -> tuple[float, float]:
    """(first, warm median) wall ms of an Embree build (embreex, all host
    cores): the scene made, the mesh added, committed by its first ray."""
    from embreex import mesh_construction, rtcore_scene
    vertices, faces = np.asarray(mesh.vertices, np.float32), np.asarray(mesh.faces, np.int32)
    origin, direction = np.zeros((1, 3), np.float32), np.array([[0.0, 0.0, 1.0]], np.float32)
    walls = []
    for _ in range(1 + repeat):
        start = time.perf_counter()
        scene = rtcore_scene.EmbreeScene()
        mesh_construction.TriangleMesh(scene, vertices, faces)
        scene.run(origin, direction)
        walls.append(1e3 * (time.perf_counter() - start))
    return walls[0], statistics.median(walls[1:]) if repeat else walls[0]


def scenes(mesh_dir: Path, meshes, counts):
    """(name, mesh, camera) of each scene."""
    from clrt.scene import primitives
    from clrt.scene.load import load_mesh
    from clrt.scene.scene import Camera
    for name in meshes:
        if name in GENERATED:
            mesh = primitives.torus_knot(**GENERATED[name], name=name)
            lo, hi = mesh.bounds
            yield name, mesh, Camera.framing(np.array([lo, hi]), *SIZE)
            continue
        if name not in CASES:    # another mesh of the folder, NAME.off: framed by its box
            mesh = load_mesh(mesh_dir / f"{name}.off")
            yield name, mesh, Camera.framing(np.array(mesh.bounds), *SIZE)
            continue
        file, eye, target = CASES[name]
        yield name, load_mesh(mesh_dir / file), Camera(eye, target, (0.0, 1.0, 0.0), 45.0, *SIZE)
    if counts:
        bunny = load_mesh(mesh_dir / CASES["bunny00"][0])
        for count in counts:
            mesh = instanced(bunny, count)
            lo, hi = mesh.bounds
            yield mesh.name, mesh, Camera.framing(np.array([lo, hi]), *SIZE)


CALLS = ("accel", "scene", "renderer")


def upload_ms(context, queue, corners, repeat: int) -> float:
    """Warm median ms of the triangles alone copied to a device buffer, as the
    device build copies them (clrt.device.pinned.upload: staged on GPUs)."""
    from clrt.device import pinned
    buffer = cl.Buffer(context, cl.mem_flags.READ_WRITE, corners.nbytes)
    walls = []
    for _ in range(1 + max(repeat, 1)):
        start = time.perf_counter()
        pinned.upload(context, queue, buffer, corners)
        queue.finish()
        walls.append(1e3 * (time.perf_counter() - start))
    buffer.release()
    return statistics.median(walls[1:])


def whole_calls(mesh, volume, builder, leaf_size, device, repeat: int, calls, scene=None) -> dict:
    """Wall ms of the calls a user makes: ``accel`` (clrt.Accel(mesh), warm
    median of ``repeat`` after one), ``renderer`` (clrt.Renderer(scene), the
    same), of ``scene`` (made by the caller: whole_call_rows times it)."""
    import gc

    from clrt.query import Accel
    from clrt.renderer import Renderer
    out = {}
    makers = {"accel": lambda: Accel(mesh, accel=volume, builder=builder, leaf_size=leaf_size, device=device),
              "renderer": lambda: Renderer(scene, accel=volume, builder=builder, leaf_size=leaf_size, device=device)}
    for call in ("accel", "renderer"):
        if call not in calls or (call == "renderer" and scene is None):
            continue
        walls = []
        for _ in range(1 + max(repeat, 1)):
            gc.collect()    # the last one's device buffers go before this one is timed
            start = time.perf_counter()
            made = makers[call]()
            made.queue.finish()
            walls.append(1e3 * (time.perf_counter() - start))
            del made
        out[call] = statistics.median(walls[1:])
    return out


def whole_call_rows(context, queue, name, mesh, corners, builds: dict, volume, leaf_size, device, repeat,
                    calls) -> list[str]:
    """Rows of the whole-call table for one scene: each builder's warm build
    (``builds``: builder -> warm ms) beside the upload and the whole calls."""
    from clrt.scene.scene import scene_from_mesh
    upload = upload_ms(context, queue, corners, repeat)
    scene, scene_ms = None, float("nan")
    if "scene" in calls or "renderer" in calls:
        start = time.perf_counter()
        scene = scene_from_mesh(mesh)
        scene_ms = 1e3 * (time.perf_counter() - start)
    rows = []
    for builder, warm in builds.items():
        got = whole_calls(mesh, volume, builder, leaf_size, device, repeat, calls, scene)
        base = warm + upload
        accel, renderer = got.get("accel", float("nan")), got.get("renderer", float("nan"))
        rows.append(f"| {name} | {len(corners):,} | {builder} | {warm:,.1f} | {upload:,.1f} | {1.5 * base:,.1f} "
                    f"| {accel:,.1f} | {accel / base:.2f} | {scene_ms:,.1f} | {renderer:,.1f} "
                    f"| {renderer / base:.2f} |")
    return rows


WHOLE_CALL_HEADER = ("| scene | triangles | builder | build warm ms | upload ms | 1.5 x (build + upload) ms "
                     "| Accel() ms | Accel / (build + upload) | scene ms (scene_from_mesh) | Renderer() ms "
                     "| Renderer / (build + upload) |\n|---|---|---|---|---|---|---|---|---|---|---|")


def run(mesh_dir, meshes, counts, builders, volume="box", leaf_size=4, device=None, repeat=5, trace=True,
        out=None, embree=False, profile=False, calls=CALLS, random_rays=RANDOM_RAYS):
    from clrt.device.context import create_context, device_label
    out = out or sys.stdout
    context, queue = create_context(device)
    print(f"device: {device_label(queue.device)}; volume {volume}, leaf size {leaf_size}; build: first, "
          f"then median of {repeat}; trace: {SIZE[0]}x{SIZE[1]} primary rays and {random_rays:,} random rays, "
          "closest hits, kernel ms\n", file=out)
    print("| scene | triangles | builder | build first ms | build warm ms | device ms | phases (device ms) "
          "| SAH cost | SAH / sah | depth | device MiB | trace ms | Mrays/s | random ms | hits | refit ms |", file=out)
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|", file=out)
    profiles, call_rows = [], []
    for name, mesh, camera in scenes(mesh_dir, meshes, counts):
        corners = triangle_corners(mesh)
        results = {}
        for builder in builders:
            with device_choices(builder):
                results[builder] = time_builds(context, queue, corners, volume, builder, leaf_size, repeat)
        # The trees of the host builders and of the device variants that change the tree.
        traced = [b for b in builders if trace and (b not in DEVICE_VARIANTS or b in ("device", "device/as-gpu")
                                                    or set(DEVICE_VARIANTS[b]) & set(TREE_SETTINGS)
                                                    or DEVICE_CONSTANTS.get(b))]
        traces = trace_and_refit_ms(mesh, camera, volume, traced, leaf_size, device, random_rays) if traced else {}
        untraced = (float("nan"), float("nan"), float("nan"), -1)
        results = {b: (*r, *traces.get(b, untraced)) for b, r in results.items()}
        sah_cost = results["sah"][2]["sah_cost"] if "sah" in results else None
        for builder, (first, warm, stats, timings, trace_ms, refit_ms, random_ms, hits) in results.items():
            device_ms = "-" if timings is None else f"{timings['device']:.2f}"
            phases = "-" if timings is None else " / ".join(
                f"{k} {v:.1f}" for k, v in timings.items() if k not in ("device", "wall"))
            ratio = f"{stats['sah_cost'] / sah_cost:.3f}" if sah_cost else "-"
            print(f"| {name} | {len(corners):,} | {builder} | {first:,.1f} | {warm:,.1f} | {device_ms} | {phases} "
                  f"| {stats['sah_cost']:.2f} | {ratio} | {stats['depth']} | {stats['device_bytes'] / 2**20:,.1f} "
                  f"| {trace_ms:.3f} | {rate(SIZE[0] * SIZE[1] / trace_ms / 1e3)} | {random_ms:.3f} "
                  f"| {hits if hits >= 0 else '-'} | {refit_ms:.2f} |", file=out,
                  flush=True)
        if embree:
            first, warm = embree_build_ms(mesh, repeat)
            print(f"| {name} | {len(corners):,} | Embree (embreex, host CPU) | {first:,.1f} | {warm:,.1f} | - | - "
                  "| - | - | - | - | - | - | - | - | - |", file=out, flush=True)
        if profile:
            profiles += [(name, b, launch_profile(context, queue, corners, volume, b, leaf_size))
                         for b in builders if b in DEVICE_VARIANTS]
        called = {b: results[b][1] for b in builders if b in HOST_BUILDERS or b == "device"}
        if calls and called:
            call_rows += whole_call_rows(context, queue, name, mesh, corners, called, volume, leaf_size, device,
                                         repeat, calls)
    if call_rows:
        print("\nwhole calls (warm medians; the build's column from the table above):\n", file=out)
        print(WHOLE_CALL_HEADER, *call_rows, sep="\n", file=out, flush=True)
    for name, builder, lines in profiles:
        print(f"\n{name}, {builder}, one warm build:", *lines, sep="\n", file=out)


# Idle time between launches worth naming in a profile (the device waiting for the host).
PROFILE_GAP_NS = 20_000


def launch_profile(context, queue, corners, volume, builder, leaf_size) -> list[str]:
    """Lines describing one warm device build, launch by launch: the device
    time per kernel and the idle gaps between launches (host-bound stretches)."""
    from clrt.device.build import build_on_device
    # (Warm: time_builds has built this variant of the scene already.)
    with device_choices(builder):
        bvh = build_on_device(context, queue, corners, volume=volume, leaf_size=leaf_size, profile=True,
                              **DEVICE_VARIANTS[builder])
    bvh.release()
    launches = bvh.launches
    per_kernel: dict[str, list] = {}
    for kernel, start, end in launches:
        entry = per_kernel.setdefault(kernel, [0, 0.0])
        entry[0] += 1
        entry[1] += 1e-6 * (end - start)
    busy = sum(ms for _, ms in per_kernel.values())
    span = 1e-6 * (max(end for _, _, end in launches) - min(start for _, start, _ in launches))
    lines = [f"{len(launches)} launches, device span {span:.3f} ms, kernels busy {busy:.3f} ms, "
             f"wall {bvh.build_ms:.3f} ms", "", "| kernel | launches | device ms |", "|---|---|---|"]
    lines += [f"| {kernel} | {count} | {ms:.3f} |"
              for kernel, (count, ms) in sorted(per_kernel.items(), key=lambda item: -item[1][1])]
    gaps, finished, previous = [], launches[0][2], launches[0][0]
    for kernel, start, end in launches[1:]:
        if start - finished > PROFILE_GAP_NS:
            gaps.append(f"{previous} -> {kernel} {1e-3 * (start - finished):.0f} us")
        finished, previous = max(finished, end), kernel
    lines.append("idle over 20 us between launches: " + (", ".join(gaps) or "none"))
    return lines


# Device builder settings of a variant, device/NAME=N[/NAME=N...]: NAME ->
# build_on_device's keyword.
TUNING = {"tail": "tail_threshold",            # the hand-over to ploc_tail at another count
          "treelets": "treelet_leaves",        # leaves per restructured treelet (0: none)
          "treelet-min": "treelet_min",        # triangles a node needs for its treelet
          "tail-group": "tail_group",          # work-items of ploc_tail
          "sah-top": "top_clusters",           # clusters the SAH top takes from PLOC (1: none)
          "partition": "partition",            # the SAH partition before PLOC (0: off, 1: on)
          "reinsert": "reinsert_iterations",   # iterations of reinsertion (0: none)
          "part-levels": "PART_LEVELS",        # levels of the SAH partition (a constant of clrt.device.build)
          "ploc-radius": "PLOC_RADIUS",        # clusters PLOC searches on each side (a constant too)
          "hierarchy": "hierarchy"}            # with the partition, PLOC up the linear BVH (1) or by iterations (0)
# The settings that change the tree (its trace is timed).
TREE_SETTINGS = ("treelet_leaves", "treelet_min", "top_clusters", "partition", "reinsert_iterations", "hierarchy")


def tuned_variant(builder: str) -> dict:
    """build_on_device's keywords of ``device/NAME=N[/NAME=N...]``; KeyError
    for an unknown NAME, ValueError for a value that is not an integer."""
    settings = {}
    for item in builder.split("/")[1:]:
        name, _, value = item.partition("=")
        setting = TUNING[name]
        settings[setting] = parse_count(value) if setting == "tail_threshold" else int(value)
    return settings


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.build", description=__doc__.split("\n")[0])
    mesh_names = sorted(CASES) + sorted(GENERATED)     # what --meshes accepts
    default_dir = SHARED_MESHES
    p.add_argument("--mesh-dir", type=Path, default=default_dir, help=f"folder of the meshes (default {default_dir})")
    p.add_argument("--meshes", type=lambda s: [x for x in s.split(",") if x], default=sorted(CASES),
                   help=f"comma-separated, of {', '.join(mesh_names)} or NAME for NAME.off in --mesh-dir (default {', '.join(sorted(CASES))}; "
                        f"'' for none)")
    p.add_argument("--triangles", type=lambda s: [parse_count(x) for x in s.split(",")], default=[],
                   help="also grids of bunny copies of about these many triangles, e.g. 1M,10M")
    p.add_argument("--builders", type=lambda s: s.split(","), default=list(HOST_BUILDERS) + ["device"],
                   help=f"comma-separated, of {', '.join(list(HOST_BUILDERS) + list(DEVICE_VARIANTS))}, "
                        "device/tail=N, device/tail-group=N, device/treelets=N, device/treelet-min=N, "
                        "device/sah-top=N, device/partition=0|1, device/part-levels=N (with partition=1), "
                        "device/reinsert=N, device/ploc-radius=N (1..24), device/hierarchy=0|1, "
                        "or several settings in one, e.g. device/treelets=0/reinsert=8 "
                        "(default: paper, sah, device)")
    p.add_argument("--volume", default="box", choices=("box", "sphere", "ellipse"),
                   help="bounding-volume shape (default box)")
    p.add_argument("--leaf-size", type=int_at_least(1, MAX_LEAF_SIZE), default=4,
                   help="most triangles per leaf (default 4)")
    p.add_argument("--repeat", type=NON_NEGATIVE, default=5, help="warm builds timed after the first (default 5)")
    p.add_argument("--no-trace", action="store_true", help="skip the primary- and random-ray timing")
    p.add_argument("--random", type=lambda s: 0 if s.strip() == "0" else parse_count(s), default=RANDOM_RAYS,
                   help=f"random rays traced beside the primary rays (default {RANDOM_RAYS:,}; 0: none)")
    p.add_argument("--calls", type=lambda s: [x for x in s.split(",") if x], default=list(CALLS),
                   help=f"whole calls timed beside the build, comma-separated of {', '.join(CALLS)} "
                        "('' for none; default all)")
    p.add_argument("--profile", action="store_true",
                   help="after the table, one warm build of each device variant launch by launch: device ms "
                        "per kernel and the device's idle gaps")
    p.add_argument("--device", help="'gpu', 'cpu' or P:D (default: clrt's choice)")
    p.add_argument("--embree", action="store_true", help="also time Embree's build of each scene on the host CPU "
                                                         "(needs embreex: the raybench extra)")
    args = p.parse_args(argv)
    for b in args.builders:
        if b.startswith("device/") and "=" in b:
            try:
                settings = tuned_variant(b)
                DEVICE_CONSTANTS[b] = {k: v for k, v in settings.items() if k.isupper()}
                DEVICE_VARIANTS[b] = {k: v for k, v in settings.items() if not k.isupper()}
                if not 1 <= DEVICE_CONSTANTS[b].get("PART_LEVELS", 1) < 64:
                    p.error(f"--builders: {b!r}: part-levels must be in 1..63")
                if not 1 <= DEVICE_CONSTANTS[b].get("PLOC_RADIUS", 1) <= 24:   # ploc_merge's local tables
                    p.error(f"--builders: {b!r}: ploc-radius must be in 1..24")
                if "PLOC_RADIUS" in DEVICE_CONSTANTS[b]:   # (a constant per device type: one for every type)
                    from clrt.device.build import PLOC_RADIUS
                    DEVICE_CONSTANTS[b]["PLOC_RADIUS"] = dict.fromkeys(PLOC_RADIUS, DEVICE_CONSTANTS[b]["PLOC_RADIUS"])
            except (ValueError, argparse.ArgumentTypeError):
                p.error(f"--builders: {b!r} needs an integer after '='")
            except KeyError as exc:
                p.error(f"--builders: {b!r}: unknown setting {exc.args[0]!r} (choose from {', '.join(TUNING)})")
        if b in DEVICE_VARIANTS:   # a bad setting fails now, before any mesh is made
            from clrt.device.build import check_tuning
            exit = exit_code(check_tuning, **{key: value for key, value in DEVICE_VARIANTS[b].items()
                                              if key != "staged_upload"})
            if exit:
                return exit
        if b not in HOST_BUILDERS and b not in DEVICE_VARIANTS:
            p.error(f"unknown builder {b!r}")
    for c in args.calls:
        if c not in CALLS:
            p.error(f"unknown call {c!r} (choose from {', '.join(CALLS)})")
    for m in args.meshes:
        if m not in mesh_names and not (args.mesh_dir / f"{m}.off").is_file():
            p.error(f"unknown mesh {m!r} (choose from {', '.join(mesh_names)}, or NAME for NAME.off in --mesh-dir)")
    if args.embree:
        try:
            import embreex  # noqa: F401
        except ImportError:
            p.error("--embree needs embreex: pip install -e '.[raybench]'")
    return exit_code(run, args.mesh_dir, args.meshes, args.triangles, args.builders, args.volume,
                     args.leaf_size, args.device, args.repeat, not args.no_trace, embree=args.embree,
                     profile=args.profile, calls=args.calls, random_rays=args.random)


if __name__ == "__main__":
    sys.exit(main())
