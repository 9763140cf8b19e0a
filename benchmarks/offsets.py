"""Queries on a mesh far from the origin, with and without the device frame:
``python -m benchmarks.offsets``.

    python -m benchmarks.offsets --device cpu
    python -m benchmarks.offsets --offsets 0,1e4,1e5,1e6 --rays 20000 --repeat 3

A torus 2.7 across (40,000 triangles) moved by (s, s, s) for each offset s,
and ``--rays`` random rays at it (origins in its box grown twice, random
directions; moved with it): the median kernel time of the closest hit
(``Accel.trace``) with the scene moved near the origin on the device
(clrt.scene.arrays.device_origin: what clrt does) and without (the scene in
the caller's frame, as before: RECENTRE_DISTANCE made infinite while the
Accel is built).  After timing, the two answers are compared field by field
(``same``: t, prim, u, v equal bit for bit).  Prints a markdown table; timing
is done here, never in tests.
"""

from __future__ import annotations

import sys

if not __package__:   # run as a script, python benchmarks/NAME.py: import from the repository, not this folder
    import os.path
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import argparse
import math
import statistics

import numpy as np

from benchmarks.common import POSITIVE, exit_code

RINGS, SIDES = 200, 100          # 40,000 triangles
SEED = 7


def _accel(mesh, device, recentre: bool):
    """An Accel of ``mesh``, in the device's own frame or (``recentre`` False) the caller's."""
    import clrt
    from clrt.scene import arrays
    saved = arrays.RECENTRE_DISTANCE
    if not recentre:
        arrays.RECENTRE_DISTANCE = math.inf
    try:
        return clrt.Accel(mesh, device=device)
    finally:
        arrays.RECENTRE_DISTANCE = saved


def _time(accel, o, d, repeat: int):
    accel.trace(o, d)   # warm-up: program, buffers
    accel.kernel_ms()
    times, hits = [], None
    for _ in range(repeat):
        hits = accel.trace(o, d)
        times.append(accel.kernel_ms())
    return statistics.median(times), hits


def measure(offsets, rays: int, repeat: int, device=None) -> list[dict]:
    """One row per offset: kernel ms with and without the device frame, hits, agreement."""
    from clrt.scene import primitives
    from clrt.scene.mesh import Mesh
    torus = primitives.torus(1.0, 0.35, RINGS, SIDES)
    rng = np.random.default_rng(SEED)
    lo, hi = torus.bounds
    o0 = (lo + hi) / 2 + rng.uniform(-1, 1, (rays, 3)) * (hi - lo)
    d = rng.normal(size=(rays, 3)).astype(np.float32)
    rows = []
    for s in offsets:
        mesh = Mesh.from_arrays(torus.vertices.astype(np.float64) + s, torus.faces)
        o = o0 + s
        moved, plain = _accel(mesh, device, True), _accel(mesh, device, False)
        moved_ms, a = _time(moved, o, d, repeat)
        plain_ms, b = _time(plain, o, d, repeat)
        same = all(np.array_equal(getattr(a, k), getattr(b, k)) for k in ("t", "prim", "u", "v"))
        rows.append({"offset": s, "origin": moved.geometry.origin, "moved_ms": moved_ms, "plain_ms": plain_ms,
                     "hits": int(a.hit.sum()), "same": same, "device": moved.device})
    return rows


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.offsets", description=__doc__.split("\n\n")[0])
    p.add_argument("--offsets", type=lambda s: [float(x) for x in s.split(",")], default=[0.0, 1e3, 1e4, 1e5, 1e6],
                   help="comma-separated (default 0,1e3,1e4,1e5,1e6)")
    p.add_argument("--rays", type=POSITIVE, default=20000, help="random rays (default 20000)")
    p.add_argument("--repeat", type=POSITIVE, default=3, help="timed runs, median kept (default 3)")
    p.add_argument("--device", help="'gpu', 'cpu' or P:D (default: clrt's choice)")
    args = p.parse_args(argv)
    return exit_code(_report, args)


def _report(args) -> None:
    rows = measure(args.offsets, args.rays, args.repeat, args.device)
    print(f"{args.rays:,} random rays, closest hit, torus of {2 * RINGS * SIDES:,} triangles 2.7 across "
          f"moved by (s, s, s); {rows[0]['device']}; median kernel ms of {args.repeat}\n")
    print("| offset s | device origin | in the device frame | in the caller's frame | speed-up | hits | same |")
    print("|---:|---|---:|---:|---:|---:|---|")
    for r in rows:
        origin = "0" if not r["origin"].any() else ", ".join(f"{x:g}" for x in r["origin"])
        print(f"| {r['offset']:g} | {origin} | {r['moved_ms']:.1f} | {r['plain_ms']:.1f} | "
              f"{r['plain_ms'] / r['moved_ms']:.1f}x | {r['hits']:,} | {'yes' if r['same'] else 'NO'} |")

if __name__ == "__main__":
    sys.exit(main())
