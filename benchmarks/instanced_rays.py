"""Rays against placed meshes beside the same scene flattened (docs/instances.md):
``python -m benchmarks.instanced_rays MESH --grid 5``.

One mesh placed ``--grid``^3 times on a cubic grid, each placement turned
about y (benchmarks.instances' grid), as an Accel of instances and as one
flattened mesh (every placement's corners mapped in float64, then stored as
float32).  Two ray sets, the same for both: a ``--size`` camera looking at the
grid from outside, and ``--rays`` random rays (origins uniform in the scene's
box, directions uniform on the sphere; numpy ``default_rng(--seed)``).  Times
are medians of ``--repeat`` closest-hit queries after one untimed one: the
kernel (profiling events) and the whole call from numpy to numpy.  The last
columns compare the answers: the share of rays whose (instance, triangle) is
the flattened scene's (the others graze an edge or a silhouette, where the
two scenes' float32 corners differ by their rounding), and the largest
difference of t on those rays relative to the scene's size.
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

from benchmarks.common import NON_NEGATIVE, POSITIVE, exit_code, int_at_least, parse_count, parse_size
from benchmarks.instances import grid_instances


def flattened(instances):
    """(vertices float32, faces) of every placement, in instance order."""
    mesh = instances.meshes[0]
    v = np.asarray(mesh.vertices, np.float64)
    f = np.asarray(mesh.faces, np.int64)
    verts = [v @ t[:3, :3].T + t[:3, 3] for t in instances.transforms]
    faces = [f + k * len(v) for k in range(len(verts))]
    return np.concatenate(verts).astype(np.float32), np.concatenate(faces)


def camera_rays(lo, hi, size):
    centre, reach = (lo + hi) / 2, float(np.linalg.norm(hi - lo))
    eye = centre + reach * np.array([0.55, 0.45, 0.75])
    forward = (centre - eye) / np.linalg.norm(centre - eye)
    right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    w, h = size
    half = np.tan(np.radians(22.5))
    x = (np.arange(w) + 0.5) / w * 2 - 1
    y = 1 - (np.arange(h) + 0.5) / h * 2
    xx, yy = np.meshgrid(x * half * w / h, y * half)
    d = forward + xx[..., None] * right + yy[..., None] * up
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    return np.broadcast_to(eye, d.shape).reshape(-1, 3).astype(np.float32), d.reshape(-1, 3).astype(np.float32)


def random_rays(lo, hi, count, seed):
    rng = np.random.default_rng(seed)
    origins = lo + rng.random((count, 3)) * (hi - lo)
    z = rng.uniform(-1, 1, count)
    phi = rng.uniform(0, 2 * np.pi, count)
    r = np.sqrt(1 - z * z)
    return origins.astype(np.float32), np.stack([r * np.cos(phi), r * np.sin(phi), z], 1).astype(np.float32)


def _timed(accel, origins, dirs, repeat):
    hits = accel.trace(origins, dirs)
    walls, kernels = [], []
    for _ in range(repeat):
        accel.launches.clear()
        start = time.perf_counter()
        accel.trace(origins, dirs)
        walls.append(1e3 * (time.perf_counter() - start))
        kernels.append(sum((e.profile.end - e.profile.start) / 1e6 for e in accel.launches))
    return hits, statistics.median(walls), statistics.median(kernels)


def run(path, side, size, count, seed, device, repeat, builder) -> None:
    from clrt.query import Accel
    from clrt.scene.sources import as_mesh
    mesh = as_mesh(path)
    instances = grid_instances(mesh, side)
    vertices, faces = flattened(instances)
    lo, hi = vertices.min(0).astype(np.float64), vertices.max(0).astype(np.float64)
    scene_size = float(np.abs(np.concatenate([lo, hi])).max())
    start = time.perf_counter()
    placed = Accel(instances, device=device, builder=builder)
    placed_s = time.perf_counter() - start
    start = time.perf_counter()
    flat = Accel((vertices, faces), device=device, builder=builder)
    flat_s = time.perf_counter() - start
    triangles = len(mesh.faces)
    print(f"{len(instances):,} placements of {path} ({triangles:,} triangles; {len(faces):,} flattened) on "
          f"{placed.device}; Accel: instances {placed_s:.2f} s, flattened {flat_s:.2f} s; builder {builder}\n")
    print("| rays | scene | kernel ms | wall ms | kernel / flattened | same (instance, triangle) | max t diff / size, same hits |")
    print("|---|---|---|---|---|---|---|")
    sets = {f"camera {size[0]}x{size[1]}": camera_rays(lo, hi, size),
            f"random {count:,}": random_rays(lo, hi, count, seed)}
    for label, (origins, dirs) in sets.items():
        want, flat_wall, flat_kernel = _timed(flat, origins, dirs, repeat)
        got, wall, kernel = _timed(placed, origins, dirs, repeat)
        flat_id = np.where(got.prim >= 0, got.instance.astype(np.int64) * triangles + got.prim, -1)
        same = flat_id == want.prim
        hit = same & (want.prim >= 0)
        dt = np.abs(got.t[hit].astype(np.float64) - want.t[hit]).max() / scene_size if hit.any() else 0.0
        print(f"| {label} | flattened | {flat_kernel:.3f} | {flat_wall:.2f} | 1 | | |")
        print(f"| {label} | instances | {kernel:.3f} | {wall:.2f} | {kernel / flat_kernel:.2f} "
              f"| {100 * same.mean():.4f} % ({np.count_nonzero(~same):,} differ) | {dt:.1e} |")


def main(argv=None) -> int:
    from pathlib import Path
    p = argparse.ArgumentParser(prog="python -m benchmarks.instanced_rays", description=__doc__.split("\n\n")[0])
    p.add_argument("mesh", type=Path, help="the mesh file placed")
    p.add_argument("--grid", type=int_at_least(1, 100), default=5, help="placements a side (default 5: 125)")
    p.add_argument("--size", type=parse_size, default=(1920, 1080), help="camera image WxH (default 1920x1080)")
    p.add_argument("--rays", type=parse_count, default=1_000_000, help="random rays (default 1M)")
    p.add_argument("--seed", type=NON_NEGATIVE, default=0, help="of the random rays (default 0)")
    p.add_argument("--device", help="'gpu', 'cpu' or P:D (default: clrt's choice)")
    p.add_argument("--repeat", type=POSITIVE, default=5, help="timed queries, median reported (default 5)")
    p.add_argument("--builder", default="device", help="of both scenes' BVHs (default: device)")
    args = p.parse_args(argv)
    if not args.mesh.is_file():
        raise SystemExit(f"benchmarks.instanced_rays: no mesh file {args.mesh}")
    return exit_code(run, args.mesh, args.grid, args.size, args.rays, args.seed, args.device, args.repeat,
                     args.builder)


if __name__ == "__main__":
    sys.exit(main())
