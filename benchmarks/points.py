"""Point queries, clrt beside its peers on the same points:
``python -m benchmarks.points [MESH ...]``.

Points: ``--points`` of them uniform in the mesh's bounding box enlarged by
10 % about its centre (numpy ``default_rng(seed).random((N, 3))``, float64,
then stored as float32), one set per mesh that every library answers.

Queries, where each library has them:

==================  ==================================  ===========================================
query               clrt (Accel)                        Open3D ``RaycastingScene`` / Warp
==================  ==================================  ===========================================
closest points      ``closest_points``                  ``compute_closest_points`` / ``mesh_query_point_no_sign``
distance            ``distance``                        ``compute_distance`` / (the same query)
signed distance     ``signed_distance`` (each ``sign``) ``compute_signed_distance`` / ``mesh_query_point*``
inside              ``contains``                        ``compute_occupancy``
winding number      ``winding_number``                  -- / ``mesh_query_point_sign_winding_number``
==================  ==================================  ===========================================

With ``--grid N``, also ``sdf_grid(N)`` (each ``sign``; the mesh's box grown by
5 % of its longest side) beside Open3D's ``compute_signed_distance`` of the
same N^3 samples, made in numpy.

Open3D (Embree inside, ``pip install open3d-cpu``) runs on the CPU and Warp
(``pip install warp-lang``) on an NVIDIA GPU through CUDA; both are optional
imports, measured when installed.  Times are medians of ``--repeat`` calls
after ``--warmup`` untimed ones, from numpy points to numpy answers (wall),
with clrt's kernel time (profiling events) beside its wall time.  The last
columns say whether the answers agree: the mean distance, and the share of
points inside.

``--turns`` instead runs clrt and Open3D taking turns, query by query, on
closest points, distances and signed distances (clrt's by the normal rule):
wall and process CPU times, and the paired ratio -- the median over the
repetitions of Open3D's time over clrt's in the same one, the figure that
holds still on a shared machine whose speed drifts (issue 36's 10x on PoCL).
"""

from __future__ import annotations

import sys

if not __package__:   # run as a script, python benchmarks/NAME.py: import from the repository, not this folder
    import os.path
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import argparse
import statistics
import time

import numpy as np

from benchmarks.common import NON_NEGATIVE, POSITIVE, SHARED_MESHES, exit_code, parse_count
from clrt.errors import InputError

#: The signed-distance rules of clrt's signed_distance, each measured.
SIGNS = ("winding", "normal", "parity")


def make_points(mesh, count: int, seed: int = 0) -> np.ndarray:
    """(count, 3) float32 points uniform in the mesh's box enlarged by 10 % about its centre."""
    lo, hi = np.asarray(mesh.bounds, np.float64)
    centre, half = (lo + hi) / 2, 1.1 * (hi - lo) / 2
    return (centre - half + np.random.default_rng(seed).random((count, 3)) * 2 * half).astype(np.float32)


def _median(call, repeat: int, warmup: int, kernel_ms=None):
    for _ in range(warmup):
        call()
    if kernel_ms:
        kernel_ms()
    walls, kernels, result = [], [], None
    for _ in range(repeat):
        start = time.perf_counter()
        result = call()
        walls.append(1e3 * (time.perf_counter() - start))
        if kernel_ms:
            kernels.append(kernel_ms())
    return statistics.median(walls), (statistics.median(kernels) if kernels else None), result


def _summary(result, kind: str) -> tuple:
    """(mean distance, share inside) of an answer of ``kind``: "distance",
    "signed" (negative inside; Open3D's convention), "inside" (bool) or
    "winding" (winding numbers: inside where >= 0.5)."""
    a = np.asarray(result)
    if kind == "inside":
        return None, float(a.mean())
    if kind == "winding":
        return None, float((a >= 0.5).mean())
    if kind == "signed":
        return float(np.abs(a).mean()), float((a < 0).mean())
    return float(a.mean()), None


def _kind(name: str) -> str:
    return ("signed" if name.startswith(("signed", "sdf_grid")) else "inside" if name == "inside"
            else "winding" if name == "winding number" else "distance")


def clrt_rows(mesh, points, device, repeat, warmup, grid=0):
    """Rows (query, library, wall ms, kernel ms, mean distance, share inside,
    points) of clrt's queries (with ``grid``, sdf_grid's too)."""
    import clrt

    start = time.perf_counter()
    accel = clrt.Accel(mesh, device=device)
    build_ms = 1e3 * (time.perf_counter() - start)
    queries = [("closest points", lambda: accel.closest_points(points).distance),
               ("distance", lambda: accel.distance(points))]
    queries += [(f"signed distance ({sign})", lambda sign=sign: accel.signed_distance(points, sign=sign))
                for sign in SIGNS]
    queries += [("inside", lambda: accel.contains(points)),
                ("winding number", lambda: accel.winding_number(points))]
    if grid:
        queries += [(f"sdf_grid {grid}^3 ({sign})", lambda sign=sign: accel.sdf_grid(grid, sign=sign))
                    for sign in SIGNS]
    device_name = str(accel.device)
    label = "clrt (PoCL)" if "Portable Computing Language" in device_name else f"clrt ({device_name.split(' (')[0]})"
    rows = []
    for name, call in queries:
        wall, kernel, result = _median(call, repeat, warmup, accel.kernel_ms)
        rows.append((name, label, wall, kernel, *_summary(result, _kind(name)), np.size(result)))
    return build_ms, rows


def _peer_row(name, library, call, repeat, warmup) -> tuple:
    wall, _, result = _median(call, repeat, warmup)
    return (name, library, wall, None, *_summary(result, _kind(name)), np.size(result))


def grid_samples(mesh, grid: int) -> np.ndarray:
    """(grid^3, 3) float32: sdf_grid's samples (its default bounds), in its order."""
    from clrt.query.inside import grid_axes
    axes = grid_axes(grid, None, mesh.bounds)
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3).astype(np.float32)


def open3d_rows(mesh, points, repeat, warmup, grid=0):
    try:
        import open3d as o3d
    except ImportError:
        return []
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(np.asarray(mesh.vertices, np.float32)),
                        o3d.core.Tensor(np.asarray(mesh.faces, np.uint32)))
    p = o3d.core.Tensor(points)
    queries = [("closest points", lambda: np.linalg.norm(scene.compute_closest_points(p)["points"].numpy() - points,
                                                         axis=1)),
               ("distance", lambda: scene.compute_distance(p).numpy()),
               ("signed distance", lambda: scene.compute_signed_distance(p).numpy()),
               ("inside", lambda: scene.compute_occupancy(p).numpy() > 0.5)]
    if grid:
        samples = o3d.core.Tensor(grid_samples(mesh, grid))
        queries.append((f"sdf_grid {grid}^3", lambda: scene.compute_signed_distance(samples).numpy()))
    return [_peer_row(name, "Open3D (CPU)", call, repeat, warmup) for name, call in queries]


def warp_rows(mesh, points, repeat, warmup):
    try:
        import warp as wp
    except ImportError:
        return []
    wp.init()
    if not wp.is_cuda_available():
        return []
    wmesh = wp.Mesh(points=wp.array(np.asarray(mesh.vertices, np.float32), dtype=wp.vec3),
                    indices=wp.array(np.asarray(mesh.faces, np.int32).ravel(), dtype=int))

    @wp.kernel
    def unsigned(mesh_id: wp.uint64, pts: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
        i = wp.tid()
        q = wp.mesh_query_point_no_sign(mesh_id, pts[i], 1.0e10)
        out[i] = wp.length(pts[i] - wp.mesh_eval_position(mesh_id, q.face, q.u, q.v))

    @wp.kernel
    def winding(mesh_id: wp.uint64, pts: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
        i = wp.tid()
        q = wp.mesh_query_point_sign_winding_number(mesh_id, pts[i], 1.0e10)
        out[i] = q.sign * wp.length(pts[i] - wp.mesh_eval_position(mesh_id, q.face, q.u, q.v))

    def run(kernel):
        pts = wp.array(points, dtype=wp.vec3)
        out = wp.empty(len(points), dtype=float)
        wp.launch(kernel, dim=len(points), inputs=[wmesh.id, pts, out])
        return out.numpy()

    return [_peer_row(name, "Warp (CUDA)", lambda k=kernel: run(k), repeat, warmup)
            for name, kernel in (("distance", unsigned), ("signed distance", winding))]


#: The queries --turns times, clrt's call and Open3D's, each giving distances.
TURN_QUERIES = ("closest points", "distance", "signed distance (normal)")


def turn_rows(mesh, points, device, repeat: int, warmup: int) -> list[tuple]:
    """clrt and Open3D taking turns on the same points, query by query: each
    repetition runs clrt's call, then Open3D's, so that a slow spell of a
    shared machine falls on both.  Rows (query, clrt wall ms, clrt CPU ms,
    Open3D wall ms, Open3D CPU ms, paired wall ratio, paired CPU ratio, the
    largest difference of their distances): medians; a ratio is the median
    over the repetitions of Open3D's time over clrt's in the same one (above
    1: clrt is faster); CPU time is the process's (every thread's)."""
    import open3d as o3d

    import clrt
    from benchmarks.peer_turns import paired_ratio
    accel = clrt.Accel(mesh, device=device)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(np.asarray(mesh.vertices, np.float32)),
                        o3d.core.Tensor(np.asarray(mesh.faces, np.uint32)))
    p = o3d.core.Tensor(points)
    calls = {"closest points": (lambda: accel.closest_points(points, fields=("point", "distance")).distance,
                                lambda: np.linalg.norm(scene.compute_closest_points(p)["points"].numpy() - points,
                                                       axis=1)),
             "distance": (lambda: accel.distance(points), lambda: scene.compute_distance(p).numpy()),
             "signed distance (normal)": (lambda: np.abs(accel.signed_distance(points, sign="normal")),
                                          lambda: np.abs(scene.compute_signed_distance(p).numpy()))}
    rows = []
    for name in TURN_QUERIES:
        times = []   # per repetition: (clrt wall, clrt CPU, Open3D wall, Open3D CPU)
        answers = [None, None]
        for turn in range(warmup + repeat):
            took = []
            for k, call in enumerate(calls[name]):
                wall, cpu = time.perf_counter(), time.process_time()
                answers[k] = call()
                took += [1e3 * (time.perf_counter() - wall), 1e3 * (time.process_time() - cpu)]
            if turn >= warmup:
                times.append(took)
        t = np.array(times)
        differ = float(np.max(np.abs(np.asarray(answers[0], np.float64) - answers[1])))
        rows.append((name, *np.median(t, axis=0), paired_ratio(t[:, 0], t[:, 2]), paired_ratio(t[:, 1], t[:, 3]),
                     differ))
    return rows


def print_turns(mesh_paths, count, seed, device, repeat, warmup) -> None:
    """--turns: the table of turn_rows for each mesh."""
    from clrt.scene.sources import as_mesh

    print("| mesh | triangles | query | clrt wall (CPU) ms | Open3D wall (CPU) ms | Open3D / clrt: wall (CPU) "
          "| distances differ by |")
    print("|---|---|---|---|---|---|---|")
    for path in mesh_paths:
        mesh = as_mesh(path)
        points = make_points(mesh, count, seed)
        for name, cw, cc, ow, oc, ratio, cpu_ratio, differ in turn_rows(mesh, points, device, repeat, warmup):
            print(f"| {path.name} | {len(mesh.faces):,} | {name} | {cw:.1f} ({cc:.1f}) | {ow:.1f} ({oc:.1f}) "
                  f"| **{ratio:.2f}x** ({cpu_ratio:.2f}x) | {differ:.1e} |")


def subdivided(mesh, times: int):
    """``mesh`` with each triangle split into 4^times (trimesh's midpoint subdivision)."""
    if not times:
        return mesh
    import trimesh
    from clrt.scene.mesh import Mesh
    t = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    for _ in range(times):
        t = t.subdivide()
    return Mesh(np.asarray(t.vertices, np.float32), np.asarray(t.faces, np.int32))


def run(mesh_paths, count, seed, device, repeat, warmup, peers, grid=0, subdivide=0) -> None:
    from clrt.scene import primitives
    from clrt.scene.sources import as_mesh

    print("| mesh | triangles | query | library | wall ms | kernel ms | Mpoints/s (wall) | mean distance | inside |")
    print("|---|---|---|---|---|---|---|---|---|")
    for path in mesh_paths:
        mesh = subdivided(as_mesh(path) if path else primitives.torus(1.0, 0.35, 256, 128), subdivide)
        points = make_points(mesh, count, seed)
        build_ms, rows = clrt_rows(mesh, points, device, repeat, warmup, grid)
        if peers:
            rows += open3d_rows(mesh, points, repeat, warmup, grid) + warp_rows(mesh, points, repeat, warmup)
        label = str(path.name if path else "torus (generated)")
        for name, library, wall, kernel, mean, inside, n in sorted(rows, key=lambda r: r[0]):
            print(f"| {label} | {len(mesh.faces):,} | {name} | {library} | {wall:.2f} | "
                  f"{'' if kernel is None else f'{kernel:.2f}'} | {n / wall / 1e3:.3f} | "
                  f"{'' if mean is None else f'{mean:.6f}'} | {'' if inside is None else f'{100 * inside:.2f} %'} |")
        print(f"\n{label}: clrt.Accel built in {build_ms:.1f} ms; {count:,} points, seed {seed}", file=sys.stderr)


def main(argv=None) -> int:
    from pathlib import Path

    p = argparse.ArgumentParser(prog="python -m benchmarks.points", description=__doc__.split("\n\n")[0])
    p.add_argument("mesh", nargs="*", type=Path,
                   help=f"mesh files (default: a generated torus; scans are in {SHARED_MESHES})")
    p.add_argument("--points", type=parse_count, default=1_000_000, help="points per mesh (default 1M)")
    p.add_argument("--seed", type=NON_NEGATIVE, default=0, help="of the points (default 0)")
    p.add_argument("--device", help="'gpu', 'cpu' or P:D (default: clrt's choice, the first GPU if any)")
    p.add_argument("--repeat", type=POSITIVE, default=5, help="timed calls, median reported (default 5)")
    p.add_argument("--warmup", type=NON_NEGATIVE, default=1, help="untimed calls first (default 1)")
    p.add_argument("--no-peers", action="store_true", help="clrt alone (Open3D and Warp not measured)")
    p.add_argument("--grid", type=NON_NEGATIVE, default=0,
                   help="also sdf_grid of this many samples a side (default 0: none)")
    p.add_argument("--subdivide", type=NON_NEGATIVE, default=0,
                   help="split each triangle into 4^N first (default 0; 2 makes bunny00 1.2M triangles)")
    p.add_argument("--turns", action="store_true",
                   help="instead: clrt and Open3D taking turns on closest points, distances and signed distances "
                        "(paired ratios; needs Open3D and mesh files)")
    args = p.parse_args(argv)
    for path in args.mesh:
        if not path.is_file():
            raise SystemExit(f"benchmarks.points: no mesh file {path}")
    if args.turns:
        try:
            import open3d  # noqa: F401
        except ImportError:
            raise SystemExit("benchmarks.points: --turns needs Open3D: pip install open3d-cpu") from None
        if not args.mesh:
            raise SystemExit("benchmarks.points: --turns needs mesh files")
        return exit_code(print_turns, args.mesh, args.points, args.seed, args.device, args.repeat, args.warmup)
    if args.grid == 1:
        raise SystemExit("benchmarks.points: --grid must be 0 (none) or at least 2")
    return exit_code(run, args.mesh or [None], args.points, args.seed, args.device, args.repeat, args.warmup,
                     not args.no_peers, args.grid, args.subdivide)


if __name__ == "__main__":
    sys.exit(main())
