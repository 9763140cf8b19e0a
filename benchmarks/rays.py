"""Batch ray queries, clrt against trimesh: ``python -m benchmarks.rays [MESH]``.

The same rays go to clrt (``clrt.Accel`` on the chosen OpenCL device), to
trimesh's numpy intersector (``trimesh.ray.ray_triangle``, needs ``rtree``) and,
when ``embreex`` is installed, to trimesh's Embree intersector
(``pip install -e '.[raybench]'`` installs both).  Three queries: the first
hit of each ray, whether it hits anything, and every hit along it.

Rays: origins spread over a sphere of twice the mesh's bounding radius, aimed
at uniform random points of its bounding box (a fixed seed), so most hit and
some graze.  Times are wall-clock medians of ``--repeat`` calls after one
warm-up call (which builds the BVH program, trimesh's r-tree, Embree's scene),
host<->device copies included; the one-off set-up is printed apart.  The numpy
intersector is slow (about a hundred rays a second on a 30,000-triangle mesh),
so it gets the first ``--reference-rays`` rays only, timed once after a warm-up
on ten rays.

Agreement with clrt on the same rays: first hit -- the same triangle, or the
same distance within 1e-5 of the mesh's size (a ray through an edge may name
either triangle); any hit -- the same answer; all hits -- the same set of
triangles along the ray.  The table is markdown, for docs/benchmarks.md.
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

from clrt.config import ACCELS, BUILDERS
from benchmarks.common import NON_NEGATIVE, POSITIVE, exit_code, median_wall_ms, parse_count, rate, ray_memory

QUERIES = ("first", "any", "all")


def make_rays(mesh, count: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(count, 3) float64 origins and directions (not unit) around ``mesh``."""
    rng = np.random.default_rng(seed)
    lo, hi = mesh.bounds
    centre, radius = (lo + hi) / 2, 0.5 * float(np.linalg.norm(hi - lo))
    o = rng.normal(size=(count, 3))
    o = centre + 2.0 * radius * o / np.linalg.norm(o, axis=1, keepdims=True)
    targets = lo + rng.random((count, 3)) * (hi - lo)
    return o, targets - o


def _median_time(call, repeat: int, warmup=None):
    (warmup or call)()   # program build, r-tree, Embree scene
    times, result = [], None
    for _ in range(repeat):
        start = time.perf_counter()
        result = call()
        times.append(time.perf_counter() - start)
    return statistics.median(times), result


def _plane_t(vertices, faces, o, d, tri):
    """Distance along unit d to the plane of each triangle (inf where tri < 0)."""
    t = np.full(len(o), np.inf)
    hit = tri >= 0
    v = vertices[faces[tri[hit]]]
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        t[hit] = np.einsum("ij,ij->i", v[:, 0] - o[hit], n) / np.einsum("ij,ij->i", d[hit], n)
    return t


def _agree_first(ref_tri, tri, ref_t, t, tol):
    same_hit = (ref_tri >= 0) == (tri >= 0)
    close = np.abs(np.where(np.isfinite(ref_t), ref_t, 0) - np.where(np.isfinite(t), t, 0)) <= tol
    return float(np.mean(same_hit & ((ref_tri == tri) | close)))


def _agree_sets(n, faces, ref, other):
    """Fraction of rays whose sets of (ray, triangle) hits are equal."""
    key = lambda pairs: np.unique(pairs[0].astype(np.int64) * faces + pairs[1].astype(np.int64))  # noqa: E731
    differ = np.setxor1d(key(ref), key(other))
    return 1.0 - len(np.unique(differ // faces)) / max(n, 1)


def run(mesh_path, rays: int = 1_000_000, reference_rays: int = 2_000, device=None, accel="box",
        builder="sah", repeat: int = 3, seed: int = 0, systems=("clrt", "trimesh", "embree"), out=sys.stdout):
    import trimesh
    from clrt.scene import primitives
    from clrt.scene.load import load_mesh
    from clrt.query import Accel

    ray_memory(rays, 160)   # float64 rays and unit directions, float32 copies, results
    mesh = load_mesh(mesh_path) if mesh_path else primitives.torus_knot(segments=512, sides=32)
    name = Path(mesh_path).name if mesh_path else "torus knot (generated)"
    o, d = make_rays(mesh, rays, seed)
    unit = d / np.linalg.norm(d, axis=1, keepdims=True)
    tm = trimesh.Trimesh(mesh.vertices.astype(np.float64), mesh.faces, process=False)
    vertices, faces = tm.vertices.view(np.ndarray), tm.faces.view(np.ndarray)
    tol = 1e-5 * float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))

    start = time.perf_counter()
    acc = Accel(mesh, accel=accel, builder=builder, device=device)
    setup = time.perf_counter() - start
    print(f"mesh: {name}, {len(mesh.faces):,} triangles; {rays:,} rays (seed {seed}); "
          f"clrt: {accel}/{builder} on {acc.device}, set-up {setup:.2f} s; median of {repeat}", file=out)
    print("\n| system | query | rays | seconds | rays/s | agrees with clrt |", file=out)
    print("|---|---|---|---|---|---|", file=out)

    def row(system, query, n, seconds, agree):
        text = "-" if agree is None else f"{100 * agree:.3f} %"
        print(f"| {system} | {query} | {n:,} | {seconds:.4f} | {n / seconds:,.0f} | {text} |", file=out, flush=True)

    # clrt, on every ray; kept to compare the others with
    ours = {}
    sec, hits = _median_time(lambda: acc.trace(o, d), repeat)
    ours["first"] = hits
    row("clrt", "first", rays, sec, None)
    sec, ours["any"] = _median_time(lambda: acc.any_hit(o, d), repeat)
    row("clrt", "any", rays, sec, None)
    sec, ours["all"] = _median_time(lambda: acc.all_hits(o, d), repeat)
    row("clrt", "all", rays, sec, None)

    others = []
    if "trimesh" in systems:
        try:
            import rtree  # noqa: F401 -- trimesh's numpy intersector needs it
            from trimesh.ray.ray_triangle import RayMeshIntersector
            others.append(("trimesh numpy", RayMeshIntersector(tm), min(reference_rays, rays)))
        except ImportError:
            print("| trimesh numpy | - | - | - | - | not run: `pip install rtree` |", file=out)
    if "embree" in systems:
        try:
            from trimesh.ray.ray_pyembree import RayMeshIntersector as EmbreeIntersector
            others.append(("trimesh embreex", EmbreeIntersector(tm), rays))
        except ImportError:
            print("| trimesh embreex | - | - | - | - | not run: `pip install embreex` |", file=out)

    for system, intersector, n in others:
        oo, dd = o[:n], d[:n]
        # The numpy intersector is timed once, after a warm-up on a few rays.
        reps, warm = (1, lambda: intersector.intersects_first(o[:10], d[:10])) if "numpy" in system \
            else (repeat, None)
        sec, tri = _median_time(lambda: intersector.intersects_first(oo, dd), reps, warm)
        tri = np.asarray(tri, np.int64)
        agree = _agree_first(tri, ours["first"].prim[:n], _plane_t(vertices, faces, oo, unit[:n], tri),
                             ours["first"].t[:n].astype(np.float64), tol)
        row(system, "first", n, sec, agree)
        sec, anyhit = _median_time(lambda: intersector.intersects_any(oo, dd), reps, warm)
        row(system, "any", n, sec, float(np.mean(np.asarray(anyhit, bool) == ours["any"][:n])))
        sec, (tri, ray) = _median_time(lambda: intersector.intersects_id(oo, dd, multiple_hits=True), reps, warm)
        mine = ours["all"]
        keep = mine.ray_id < n
        row(system, "all", n, sec, _agree_sets(n, len(faces), (ray, tri), (mine.ray_id[keep], mine.prim[keep])))


def throughput(mesh_path, sizes, device=None, repeat: int = 5, seed: int = 0, out=sys.stdout):
    """Per query and size: wall ms of the whole call from numpy (or device) arrays
    to results, kernel ms (profiling events), and the host's share."""
    import pyopencl.array as cla
    from benchmarks.raysets import random_rays, time_queries
    from clrt.query import Accel
    from clrt.scene import primitives
    from clrt.scene.load import load_mesh

    ray_memory(max(sizes), 160)   # float32 and float64 copies of the rays, results
    mesh = load_mesh(mesh_path) if mesh_path else primitives.torus_knot(segments=512, sides=32)
    name = Path(mesh_path).name if mesh_path else "torus knot (generated)"
    acc = Accel(mesh, device=device)
    print(f"mesh: {name}, {len(mesh.faces):,} triangles; random rays (origins in the box, directions on the "
          f"sphere); {acc.device}; median of {repeat} after a warm-up", file=out)
    print("\n| rays | call | wall ms | kernel ms | host share | Mrays/s (wall) | hits |", file=out)
    print("|---|---|---|---|---|---|---|", file=out)
    for n in sizes:
        o, d = random_rays(mesh, n, seed, margin=0.0)
        o_dev, d_dev = cla.to_device(acc.queue, o), cla.to_device(acc.queue, d)
        o64, d64 = o.astype(np.float64), d.astype(np.float64)
        calls = {
            "trace, float32 numpy -> Hits (all fields)": lambda: acc.trace(o, d),
            "trace, float64 numpy -> Hits": lambda: acc.trace(o64, d64),
            "trace, fields=(t, prim)": lambda: acc.trace(o, d, fields=("t", "prim")),
            "trace, device arrays in and out": lambda: acc.trace(o_dev, d_dev),
            "any_hit, numpy": lambda: acc.any_hit(o, d),
            "count, numpy": lambda: acc.count(o, d),
        }
        expected = None
        for label, call in calls.items():
            kernel, wall, result = time_queries(acc, call, repeat, 1)
            hits = "-"
            if label.startswith("trace"):
                prim = result.prim.get() if isinstance(result.prim, cla.Array) else result.prim
                expected = prim if expected is None else expected
                hits = f"{int((prim >= 0).sum()):,}" + ("" if np.array_equal(prim, expected) else " DIFFERENT")
            print(f"| {n:,} | {label} | {wall:.2f} | {kernel:.3f} | {100 * (1 - kernel / wall):.0f} % "
                  f"| {rate(n / wall / 1e3)} | {hits} |", file=out, flush=True)
        _embree_row(mesh, o, d, expected, repeat, out)


def _embree_row(mesh, o, d, prim, repeat: int, out) -> None:
    """The same rays through Embree on the CPU (trimesh's embreex intersector),
    first hit and any hit, when embreex is installed; agreement with clrt's hits."""
    try:
        import trimesh
        from trimesh.ray.ray_pyembree import RayMeshIntersector
    except ImportError:
        print("| - | Embree (embreex) | not run: `pip install embreex` | | | | |", file=out)
        return
    tm = trimesh.Trimesh(mesh.vertices.astype(np.float64), mesh.faces, process=False)
    embree = RayMeshIntersector(tm)
    n = len(o)
    for label, call in (("Embree first hit, numpy", lambda: embree.intersects_first(o, d)),
                        ("Embree any hit, numpy", lambda: embree.intersects_any(o, d))):
        wall, result = median_wall_ms(call, repeat)
        hit = np.asarray(result) >= 0 if result.dtype != bool else np.asarray(result)
        same = float(np.mean(hit == (prim >= 0))) if prim is not None else float("nan")
        print(f"| {n:,} | {label} | {wall:.2f} | - | CPU | {rate(n / wall / 1e3)} "
              f"| {int(hit.sum()):,} ({100 * same:.2f} % of rays agree on hit or miss) |", file=out, flush=True)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.rays", description=__doc__.split("\n")[0])
    p.add_argument("mesh", nargs="?", help="mesh file (default: a generated torus knot, 32,768 triangles)")
    p.add_argument("--rays", type=parse_count, default=1_000_000, help="rays given to clrt and Embree (default 1M)")
    p.add_argument("--reference-rays", type=parse_count, default=2_000,
                   help="rays given to trimesh's numpy intersector (default 2,000)")
    p.add_argument("--device", help="OpenCL device for clrt (default: as clrt render)")
    p.add_argument("--accel", default="box", choices=ACCELS, help="clrt's acceleration (default box)")
    p.add_argument("--builder", default="sah", choices=BUILDERS, help="clrt's BVH builder (default sah)")
    p.add_argument("--repeat", type=POSITIVE, default=3, help="timed runs, median reported (default 3)")
    p.add_argument("--seed", type=NON_NEGATIVE, default=0, help="of the random rays (default 0)")
    p.add_argument("--only", action="append", choices=("clrt", "trimesh", "embree"),
                   help="systems to run besides clrt (repeatable; default all)")
    p.add_argument("--throughput", type=lambda t: [parse_count(x) for x in t.split(",")], metavar="1M,10M",
                   help="instead: wall and kernel time of each query from numpy or device arrays, "
                        "random rays of these counts")
    args = p.parse_args(argv)
    if args.throughput:
        return exit_code(throughput, args.mesh, args.throughput, args.device, args.repeat, args.seed)
    return exit_code(run, args.mesh, args.rays, args.reference_rays, args.device, args.accel, args.builder,
                     args.repeat, args.seed, tuple(args.only or ("clrt", "trimesh", "embree")))


if __name__ == "__main__":
    sys.exit(main())
