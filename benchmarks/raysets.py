"""Incoherent ray sets, seeded and shareable: ``python -m benchmarks.raysets [MESH]``.

Four sets of rays, each made reproducibly from a seed:

* ``random`` -- the peers' incoherent benchmark: origins uniform in the mesh's
  bounding box enlarged by 10 % (5 % each side), directions uniform on the sphere;
* ``camera`` -- the pixel-centre rays of the reference camera (the speed cases'
  camera for their meshes, else one framing the mesh), 1920x1080 by default;
* ``diffuse`` -- cosine-weighted bounces from primary hits of that camera: hit
  pixels drawn at random, kept in pixel order (as a wavefront renderer holds
  them), leaving on the side the camera saw;
* ``ao`` -- ambient-occlusion rays: 16 cosine-weighted rays per drawn hit point,
  each at most ``AO_REACH`` (10 %) of the mesh's bounding-box diagonal long.

Secondary rays start at the hit point (from the barycentrics, in float64) moved
1e-5 of the diagonal off the surface, so they do not meet their own triangle.

``--write DIR`` saves each set as ``<set>.f32``: plain little-endian float32,
N rows of 6 (origin, unit direction), no header -- what other tracers can read
to run exactly the same rays; ``--read FILE`` runs such files (``--tmax`` caps
their rays, as the AO set's reach does).

Per set and variant (``--accel`` x ``--builder``), the rays are put on the device
once, then closest-hit and any-hit queries run from device arrays: ``kernel`` is
the median of the launches' profiling times after a warm-up, ``wall`` the host
clock around the call and its finish.  Hits and the sum of hit distances identify
the result: the same file gives the same figures on every device and variant.
``--embree`` adds Embree's figures for the same rays on the host CPU (wall
clock, rays on the host): the yardstick for clrt on PoCL.  embreex holds the
GIL while it traces, so that is Embree on one core; ``--embree-processes N``
adds Embree on N cores (N processes, each tracing its share of the rays),
taking turns with clrt's first variant query by query, and prints the speed
ratio of each turn's pair: on a shared machine whose speed drifts, the
paired ratio is the figure that holds still.  ``--open3d`` adds Open3D's
RaycastingScene (Embree 4, all cores) to those turns, and both peers' builds
from the arrays beside clrt's Accel (benchmarks.peer_turns).
"""

from __future__ import annotations

import sys

if not __package__:   # run as a script, python benchmarks/NAME.py: import from the repository, not this folder
    import os.path
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

from benchmarks.common import (NON_NEGATIVE, POSITIVE, builder_label, rate, exit_code, median_wall_ms, parse_count,
                               parse_groups, parse_size, parse_walks, ray_memory, walk)
from clrt.config import ACCELS, BUILDER_CHOICES
from clrt.errors import InputError

RAY_SETS = ("random", "camera", "diffuse", "ao")
AO_RAYS_PER_POINT = 16
AO_REACH = 0.1          # of the bounding-box diagonal
OFFSET = 1e-5           # of the diagonal: how far secondary rays start off the surface
ROW = 6                 # float32 per ray in a ray file: ox oy oz dx dy dz


def _diagonal(mesh) -> float:
    lo, hi = np.asarray(mesh.bounds, np.float64)
    return float(np.linalg.norm(hi - lo))


def reference_camera(mesh, name: str | None = None, size=(1920, 1080)):
    """The speed benchmark's camera for its meshes (matched by file stem), else a
    camera framing the mesh; vertical fov 45 degrees, up +y."""
    from benchmarks.speed import CASES
    from clrt.scene.scene import Camera
    w, h = size
    for file, eye, target in CASES.values():
        if name is not None and Path(name).stem == Path(file).stem:
            return Camera(eye, target, (0.0, 1.0, 0.0), 45.0, w, h)
    return Camera.framing(mesh.bounds, w, h, 45.0, up=(0.0, 1.0, 0.0))


def random_rays(mesh, count: int, seed: int = 0, margin: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """Origins uniform in the bounding box enlarged by ``margin`` of its size on
    each side (10 % in all by default), directions uniform on the sphere;
    (count, 3) float32 each."""
    rng = np.random.default_rng(seed)
    lo, hi = np.asarray(mesh.bounds, np.float64)
    margin = margin * (hi - lo)
    o = (lo - margin) + rng.random((count, 3)) * (hi - lo + 2 * margin)
    d = rng.normal(size=(count, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return o.astype(np.float32), d.astype(np.float32)


def _cosine_hemisphere(normals: np.ndarray, rng) -> np.ndarray:
    """One cosine-weighted unit direction about each unit normal (float64)."""
    n = len(normals)
    r, phi = np.sqrt(rng.random(n)), 2 * np.pi * rng.random(n)
    local = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(0.0, 1 - r * r))], axis=1)
    # an orthonormal basis about each normal (Duff et al.'s branchless construction)
    z = normals
    sign = np.where(z[:, 2] >= 0, 1.0, -1.0)
    a = -1.0 / (sign + z[:, 2])
    b = z[:, 0] * z[:, 1] * a
    x = np.stack([1 + sign * z[:, 0] ** 2 * a, sign * b, -sign * z[:, 0]], axis=1)
    y = np.stack([b, sign + z[:, 1] ** 2 * a, -z[:, 1]], axis=1)
    d = local[:, :1] * x + local[:, 1:2] * y + local[:, 2:] * z
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _primary_hits(accel, mesh, camera):
    """Hit points (float64, from barycentrics) and the unit normals facing the
    camera, of the camera's pixel-centre rays that hit; in pixel order."""
    from clrt.reference import camera_rays
    o, d = camera_rays(camera)
    hits = accel.trace(o, d)
    keep = np.nonzero(hits.hit)[0]
    if len(keep) == 0:
        raise InputError("the reference camera sees nothing of the mesh: no secondary rays to make")
    v = np.asarray(mesh.vertices, np.float64)[np.asarray(mesh.faces)[hits.prim[keep]]]
    u_, v_ = hits.u[keep, None].astype(np.float64), hits.v[keep, None].astype(np.float64)
    points = v[:, 0] * (1 - u_ - v_) + v[:, 1] * u_ + v[:, 2] * v_
    normal = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    facing = np.where((np.einsum("ij,ij->i", normal, d[keep]) > 0)[:, None], -normal, normal)
    return points, facing


def make_ray_set(kind: str, mesh, count: int, seed: int = 0, accel=None, camera=None):
    """(origins, unit directions, tmax) of one set; ``accel`` (a clrt.Accel of
    ``mesh``) finds the primary hits of the secondary sets."""
    if kind == "random":
        return (*random_rays(mesh, count, seed), np.inf)
    if kind == "camera":
        from clrt.reference import camera_rays
        return (*camera_rays(camera), np.inf)
    if kind not in ("diffuse", "ao"):
        raise InputError(f"unknown ray set {kind!r} (use one of {', '.join(RAY_SETS)})")
    rng = np.random.default_rng(seed)
    points, facing = _primary_hits(accel, mesh, camera)
    per_point = AO_RAYS_PER_POINT if kind == "ao" else 1
    chosen = np.sort(rng.integers(0, len(points), -(-count // per_point)))
    chosen = np.repeat(chosen, per_point)[:count]
    normals = facing[chosen]
    d = _cosine_hemisphere(normals, rng)
    o = points[chosen] + OFFSET * _diagonal(mesh) * normals
    tmax = AO_REACH * _diagonal(mesh) if kind == "ao" else np.inf
    return o.astype(np.float32), d.astype(np.float32), tmax


def write_rays(path, origins, directions, force: bool = False) -> None:
    """Save rays as plain little-endian float32, N x 6, through a temporary file
    and a rename (never half written), and as clrt writes every file: over an
    existing one only if clrt wrote it, or with ``force`` (clrt.output)."""
    from clrt.output import write_file
    rows = np.concatenate([np.asarray(origins, np.float32), np.asarray(directions, np.float32)], axis=1)
    write_file(rows.astype("<f4").tobytes(), Path(path), force, "--write")


def read_rays(path) -> tuple[np.ndarray, np.ndarray]:
    """Load a ray file (see :func:`write_rays`); (N, 3) float32 origins and unit
    directions.  A file that is not one gets a one-line error."""
    path = Path(path)
    try:
        data = np.fromfile(path, dtype="<f4")
    except OSError as exc:
        raise InputError(f"cannot read ray file {path}: {exc.strerror or exc}") from None
    size = path.stat().st_size
    if size == 0 or size % (4 * ROW):
        raise InputError(f"{path}: not a ray file ({size} bytes; expected N rows of {ROW} float32, "
                         f"a multiple of {4 * ROW} bytes)")
    rows = data.reshape(-1, ROW).astype(np.float32)
    bad = ~np.isfinite(rows).all(axis=1)
    if bad.any():
        raise InputError(f"{path}: ray {int(np.argmax(bad))} has a value that is not finite")
    length = np.linalg.norm(rows[:, 3:].astype(np.float64), axis=1)
    off = np.abs(length - 1) > 1e-3
    if off.any():
        i = int(np.argmax(off))
        raise InputError(f"{path}: ray {i} has a direction of length {length[i]:.6g} (directions must be unit)")
    return np.ascontiguousarray(rows[:, :3]), np.ascontiguousarray(rows[:, 3:])


def time_queries(accel, call, repeat: int, warmup: int):
    """Median kernel ms and wall ms of ``call()`` and its last result."""
    kernel, wall, result = [], [], None
    for i in range(warmup + repeat):
        accel.kernel_ms()
        start = time.perf_counter()
        result = call()
        accel.queue.finish()
        if i >= warmup:
            wall.append(1e3 * (time.perf_counter() - start))
            kernel.append(accel.kernel_ms())
    return statistics.median(kernel), statistics.median(wall), result


def _queries(accel, origins, directions, tmax) -> dict:
    """The two timed queries of a ray set, rays (and a ray's own ``tmax``
    where it is an array) and results on the device: {"closest": call, "any": call}."""
    import pyopencl.array as cla
    o_dev, d_dev = cla.to_device(accel.queue, origins), cla.to_device(accel.queue, directions)
    limit = cla.to_device(accel.queue, np.asarray(tmax, np.float32)) if np.ndim(tmax) else tmax
    return {"closest": lambda: accel.trace(o_dev, d_dev, tmax=limit, fields=("t", "prim")),
            "any": lambda: accel.any_hit(o_dev, d_dev, tmax=limit)}


def measure(accel, origins, directions, tmax=np.inf, repeat: int = 5, warmup: int = 2) -> dict:
    """Closest-hit and any-hit times of one ray set on ``accel``, rays and results
    on the device; hits, the sum of hit distances, and whether the two agree."""
    import pyopencl.array as cla
    calls = _queries(accel, origins, directions, tmax)
    closest = time_queries(accel, calls["closest"], repeat, warmup)
    anyhit = time_queries(accel, calls["any"], repeat, warmup)
    prim, t = (np.asarray(a.get() if isinstance(a, cla.Array) else a) for a in (closest[2].prim, closest[2].t))
    occluded = anyhit[2].get() if isinstance(anyhit[2], cla.Array) else np.asarray(anyhit[2])
    hit = prim >= 0
    return {"closest_kernel_ms": closest[0], "closest_wall_ms": closest[1],
            "any_kernel_ms": anyhit[0], "any_wall_ms": anyhit[1],
            "hits": int(hit.sum()), "sum_t": float(t[hit].astype(np.float64).sum()),
            "any_agrees": bool(np.array_equal(hit, occluded.astype(bool))), "prim": prim, "t": t}


def _embree_scene(vertices, faces):
    """An embreex scene of one triangle mesh (float32 vertices, int32 faces)."""
    from embreex import mesh_construction, rtcore_scene
    scene = rtcore_scene.EmbreeScene()
    mesh_construction.TriangleMesh(scene, vertices, faces)
    return scene


def _embree_limits(count: int, tmax) -> np.ndarray:
    """Embree's per-ray far distances for ``tmax``, one for all or one a ray (its rays take no infinity)."""
    return np.minimum(np.broadcast_to(np.asarray(tmax, np.float64), (count,)), 3e38).astype(np.float32)


def embree_measure(mesh, origins, directions, tmax=np.inf, repeat: int = 5, warmup: int = 2) -> dict:
    """The same rays through Embree on the host CPU (embreex, which holds the
    GIL while it traces: one core): wall ms of closest-hit and occlusion
    queries, hits and the sum of hit distances."""
    scene = _embree_scene(np.asarray(mesh.vertices, np.float32), np.asarray(mesh.faces, np.int32))
    limit = _embree_limits(len(origins), tmax)
    closest_ms, closest = median_wall_ms(lambda: scene.run(origins, directions, dists=limit.copy(), output=1),
                                         repeat, warmup)
    any_ms, occluded = median_wall_ms(lambda: scene.run(origins, directions, dists=limit.copy(),
                                                        query="OCCLUDED"), repeat, warmup)
    prim = np.asarray(closest["primID"])
    hit = prim >= 0
    return {"closest_wall_ms": closest_ms, "any_wall_ms": any_ms, "hits": int(hit.sum()),
            "sum_t": float(np.asarray(closest["tfar"])[hit].astype(np.float64).sum()),
            "any_agrees": bool(np.array_equal(hit, np.asarray(occluded) >= 0)), "prim": prim}


def _embree_worker(vertices, faces, origins, directions, limit, go, done):
    """One process of embree_processes_measure: its share of the rays, one
    query for each "INTERSECT" or "OCCLUDED" it takes from ``go``, its seconds
    and the rays that hit put in ``done`` (None: stop; an error goes there as
    its text)."""
    try:
        scene = _embree_scene(vertices, faces)
        while (query := go.get()) is not None:
            start = time.perf_counter()
            if query == "INTERSECT":
                got = scene.run(origins, directions, dists=limit.copy(), output=1)["primID"]
            else:
                got = scene.run(origins, directions, dists=limit.copy(), query=query)
            seconds = time.perf_counter() - start
            done.put((seconds, int((np.asarray(got) >= 0).sum())))
    except Exception as exc:
        done.put(f"{type(exc).__name__}: {exc}")


def _turn_times(workers, done) -> list[tuple[float, int]]:
    """Each worker's seconds and hits for the query just started; a worker that
    failed or died ends the measurement with a one-line error instead of a wait."""
    import queue
    times = []
    while len(times) < len(workers):
        try:
            got = done.get(timeout=0.5)
        except queue.Empty:
            dead = [w.exitcode for w in workers if not w.is_alive()]
            if dead:
                raise InputError(f"an Embree process died (exit code {dead[0]})") from None
            continue
        if isinstance(got, str):
            raise InputError(f"Embree failed: {got}")
        times.append(got)
    return times


def embree_processes_measure(mesh, origins, directions, tmax=np.inf, processes: int = 2, repeat: int = 5,
                             warmup: int = 2, turn=None) -> dict:
    """Embree on ``processes`` cores: embreex holds the GIL while it traces, so
    one process reaches one core; here each of ``processes`` processes traces
    its share of the rays, all started together.  Median over the
    repetitions of the slowest process's wall ms, closest-hit and occlusion.

    With ``turn``, a callable ``turn(query, counted)`` ("closest" or "any"),
    this process runs it before each of Embree's queries, while Embree's
    processes wait: clrt and Embree take turns on the same cores, so that a
    slow spell of a shared machine falls on both (benchmarks.peer_turns).
    ``times`` holds each repetition's slowest wall ms, (repetition, query);
    ``hits`` the rays that hit, closest and occlusion, in the last one."""
    import multiprocessing
    context = multiprocessing.get_context("spawn")
    vertices, faces = np.asarray(mesh.vertices, np.float32), np.asarray(mesh.faces, np.int32)
    limit = _embree_limits(len(origins), tmax)
    bounds = np.linspace(0, len(origins), processes + 1).astype(int)
    gos, done = [context.Queue() for _ in range(processes)], context.Queue()
    workers = [context.Process(target=_embree_worker, args=(vertices, faces, origins[a:b], directions[a:b],
                                                            limit[a:b], go, done))
               for a, b, go in zip(bounds[:-1], bounds[1:], gos)]
    for w in workers:
        w.start()
    slowest, hits = [], [0, 0]
    try:
        for i in range(warmup + repeat):
            row = []
            for query, embree_query in (("closest", "INTERSECT"), ("any", "OCCLUDED")):
                if turn is not None:
                    turn(query, i >= warmup)
                for go in gos:              # Embree's processes start together ...
                    go.put(embree_query)
                got = _turn_times(workers, done)
                row.append(1e3 * max(seconds for seconds, _ in got))   # ... and the last one to finish counts
                hits[len(row) - 1] = sum(count for _, count in got)
            if i >= warmup:
                slowest.append(row)
    finally:
        for go in gos:
            go.put(None)
        for w in workers:
            w.join(timeout=10)
            if w.is_alive():
                w.terminate()
    slowest = np.array(slowest)
    return {"closest_wall_ms": float(np.median(slowest[:, 0])), "any_wall_ms": float(np.median(slowest[:, 1])),
            "times": slowest, "hits": hits}


def _check_groups(accel, groups) -> None:
    """A work-group size the device cannot launch fails here, in one line."""
    import pyopencl as cl
    device = accel.queue.device
    limit = min(accel.kernels[name].get_work_group_info(cl.kernel_work_group_info.WORK_GROUP_SIZE, device)
                for name in ("query_closest", "query_any"))
    for group in groups:
        if isinstance(group, int) and group > limit:
            raise InputError(f"--group {group}: {accel.device} launches these kernels in work-groups of at most "
                             f"{limit} work-items")


def run(mesh_path=None, sets=RAY_SETS, count: int = 1_000_000, seed: int = 0, variants=(("box", "sah"),),
        device=None, size=(1920, 1080), write_dir=None, read_files=(), tmax=np.inf, repeat: int = 5,
        warmup: int = 2, embree: bool = False, groups=("default",), embree_processes: int = 0,
        out=None, walks=("default",), force: bool = False, open3d: bool = False) -> list[dict]:
    from clrt.query import Accel
    from clrt.scene import primitives
    from clrt.scene.load import load_mesh

    out = out or sys.stdout
    # files first: a bad one fails before the mesh is loaded and the BVH built
    ray_sets = [(Path(path).name, *read_rays(path), tmax) for path in read_files]
    if write_dir is not None:   # every file checked before any work
        from clrt.output import check_replace
        for kind in sets:
            check_replace(Path(write_dir) / f"{kind}.f32", force, "--write")
    if not read_files:   # each set kept in float32, made in float64, and one set's results
        ray_memory(count, 24 * len(sets) + 120)
    mesh = load_mesh(mesh_path) if mesh_path else primitives.torus_knot(segments=512, sides=32)
    name = Path(mesh_path).name if mesh_path else "torus knot (generated)"
    first = Accel(mesh, accel=variants[0][0], builder=variants[0][1], device=device)
    _check_groups(first, groups)
    camera = reference_camera(mesh, mesh_path, size)
    if not read_files:
        for kind in sets:
            o, d, reach = make_ray_set(kind, mesh, count, seed, first, camera)
            ray_sets.append((kind, o, d, reach))
            if write_dir is not None:
                write_rays(Path(write_dir) / f"{kind}.f32", o, d, force)
    print(f"mesh: {name}, {len(mesh.faces):,} triangles; device: {first.device}; seed {seed}; "
          f"ao reach {AO_REACH * _diagonal(mesh):.6g}; median of {repeat} after {warmup} warm-up; "
          f"rays and results on the device", file=out)
    print("\n| rays | count | accel | builder | group | closest: kernel ms | Mrays/s | wall ms | Mrays/s | hits "
          "| sum of t | any-hit: kernel ms | Mrays/s | any agrees |", file=out)
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|", file=out)
    rows = []
    from clrt.query import accel as query_accel
    for (accel_name, builder), walk_name in ((v, w) for v in variants for w in walks):
        if (accel_name, builder) == tuple(variants[0]) and walk_name == "default":
            accel = first
        else:
            with walk(walk_name):
                accel = Accel(mesh, accel=accel_name, builder=builder, device=device)
        shown_builder = builder_label(accel_name, builder, walk_name)
        for (label, o, d, reach), group in ((s, g) for s in ray_sets for g in groups):
            saved = dict(query_accel.QUERY_GROUP), dict(query_accel.PACKET_GROUP)
            if group != "default":
                size = None if group == "driver" else group
                query_accel.QUERY_GROUP.update(gpu=size, cpu=size)
                query_accel.PACKET_GROUP.update(gpu=size, cpu=size)   # work-items of packets too
            try:
                m = measure(accel, o, d, reach, repeat, warmup)
            finally:
                query_accel.QUERY_GROUP.update(saved[0])
                query_accel.PACKET_GROUP.update(saved[1])
            n = len(o)
            mrays = lambda ms: rate(n / ms / 1e3 if ms > 0 else float("inf"))   # noqa: E731
            print(f"| {label} | {n:,} | {accel_name} | {shown_builder} "
                  f"| {group} "
                  f"| {m['closest_kernel_ms']:.3f} | {mrays(m['closest_kernel_ms'])} "
                  f"| {m['closest_wall_ms']:.3f} | {mrays(m['closest_wall_ms'])} | {m['hits']:,} "
                  f"| {m['sum_t']:.6f} | {m['any_kernel_ms']:.3f} | {mrays(m['any_kernel_ms'])} "
                  f"| {'yes' if m['any_agrees'] else 'NO'} |", file=out, flush=True)
            rows.append({"rays": label, "accel": accel_name, "builder": builder, "walk": walk_name, "group": group,
                         **m})
    if embree:
        for label, o, d, reach in ray_sets:
            m = embree_measure(mesh, o, d, reach, repeat, warmup)
            ours = next(r["prim"] for r in rows if r["rays"] == label)
            same = 100 * float(np.mean((m["prim"] >= 0) == (ours >= 0)))
            n = len(o)
            print(f"| {label} | {n:,} | Embree (embreex, host CPU) | - | - | - | - | {m['closest_wall_ms']:.3f} "
                  f"| {rate(n / m['closest_wall_ms'] / 1e3)} | {m['hits']:,} ({same:.3f} % agree on hit or miss) "
                  f"| {m['sum_t']:.6f} | {m['any_wall_ms']:.3f} (wall) | {rate(n / m['any_wall_ms'] / 1e3)} "
                  f"| {'yes' if m['any_agrees'] else 'NO'} |", file=out, flush=True)
            rows.append({"rays": label, "accel": "embree", "builder": "-", **m})
    if embree_processes or open3d:
        # clrt's first variant and the peers take turns, query by query: all rows
        # come from the same stretch of time, and the speed ratios from each turn.
        from benchmarks.peer_turns import print_turns
        accel_name, builder = variants[0]
        chosen = first.device_scene.acceleration.builder
        label = f"{accel_name}, " + (f"auto: {chosen}" if builder == "auto" else builder_label(accel_name, builder,
                                                                                             "default"))
        rows += print_turns(out, first, label, mesh, ray_sets, {"accel": accel_name, "builder": builder}, device,
                            open3d, embree_processes, repeat, warmup)
    return rows


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.raysets", description=__doc__.split("\n")[0])
    p.add_argument("mesh", nargs="?", help="mesh file (default: a generated torus knot, 32,768 triangles)")
    p.add_argument("--set", action="append", choices=RAY_SETS, help="repeatable (default: all)")
    p.add_argument("--rays", type=parse_count, default=1_000_000, help="rays per generated set (default 1M; "
                   "the camera set has one per pixel)")
    p.add_argument("--size", type=parse_size, default=(1920, 1080), help="reference camera image (default 1920x1080)")
    p.add_argument("--seed", type=NON_NEGATIVE, default=0, help="of the generated sets (default 0)")
    p.add_argument("--write", type=Path, metavar="DIR",
                   help="also save each generated set as DIR/<set>.f32 (DIR made if missing)")
    p.add_argument("-f", "--force", action="store_true",
                   help="let --write replace files that clrt did not write")
    p.add_argument("--read", type=Path, action="append", metavar="FILE",
                   help="run the rays of these files instead of generating sets (repeatable)")
    p.add_argument("--tmax", type=float, default=np.inf, help="longest hit distance of --read rays (default inf)")
    p.add_argument("--accel", action="append", choices=ACCELS, help="repeatable (default: box)")
    p.add_argument("--builder", action="append", choices=BUILDER_CHOICES,
                   help="repeatable (default: sah; auto: clrt.Accel's default)")
    p.add_argument("--device", help="'gpu', 'cpu' or P:D (default: clrt's choice, the first GPU if any)")
    p.add_argument("--repeat", type=POSITIVE, default=5, help="timed queries, median reported (default 5)")
    p.add_argument("--warmup", type=NON_NEGATIVE, default=2, help="untimed queries first (default 2)")
    p.add_argument("--group", type=parse_groups, default=["default"],
                   help="work-group sizes of the query kernels to compare, e.g. driver,64,128 (default: "
                        "clrt's, clrt.query.accel.QUERY_GROUP and, for packets of rays, PACKET_GROUP)")
    p.add_argument("--walks", type=parse_walks, default=["default"],
                   help="default,single: also time the single-ray kernels where clrt walks packets of "
                        "coherent rays (CPU devices), side by side")
    p.add_argument("--embree", action="store_true",
                   help="also run the rays through Embree on the host CPU (needs embreex: the raybench extra); "
                        "embreex holds the GIL, so this is Embree on one core")
    p.add_argument("--embree-processes", type=int, default=0, metavar="N",
                   help="also run Embree in N processes at once, each on its share of the rays (Embree on N "
                        "cores), taking turns with clrt's first variant; prints the paired speed ratios")
    p.add_argument("--open3d", action="store_true",
                   help="also run Open3D's RaycastingScene (Embree 4; pip install open3d-cpu) on the same rays, "
                        "all cores, taking turns with clrt's first variant (and Embree's processes); prints the "
                        "paired speed ratios and each one's build from the arrays")
    args = p.parse_args(argv)
    if not args.tmax > 0:
        p.error("--tmax must be positive")
    if args.write is not None and args.write.exists() and not args.write.is_dir():
        p.error(f"--write: {args.write} is not a folder")
    if args.read and (args.set or args.write):
        p.error("--read runs files; it does not go with --set or --write")
    if args.embree_processes < 0:
        p.error("--embree-processes must not be negative")
    if args.embree or args.embree_processes:
        try:
            import embreex  # noqa: F401
        except ImportError:
            p.error("--embree needs embreex: pip install -e '.[raybench]'")
    if args.open3d:
        try:
            import open3d  # noqa: F401
        except ImportError:
            p.error("--open3d needs Open3D: pip install open3d-cpu")
    if args.write is not None:
        try:
            args.write.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            p.error(f"--write: cannot make the folder {args.write}: {exc.strerror}")
    variants = [(a, b) for a in (args.accel or ["box"]) for b in (args.builder or ["sah"])]
    return exit_code(run, args.mesh, tuple(args.set or RAY_SETS), args.rays, args.seed, variants, args.device,
                     args.size, args.write, tuple(args.read or ()), args.tmax, args.repeat, args.warmup,
                     args.embree, tuple(args.group), args.embree_processes, None, tuple(args.walks),
                     args.force, args.open3d)


if __name__ == "__main__":
    sys.exit(main())
