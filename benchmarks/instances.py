"""Scenes of placed meshes (docs/instances.md): ``python -m benchmarks.instances``.

    python -m benchmarks.instances --device cpu                       # 13^3 tori of 75k triangles
    python -m benchmarks.instances --mesh ../shared/meshes/bunny00.off --grid 13 --size 160x120
    python -m benchmarks.instances --move 1k,10k,100k --device gpu

Two tables.  ``render``: one mesh (a torus of about ``--triangles``
triangles, or ``--mesh``) placed ``--grid``^3 times on a cubic grid, each
placement turned about y, rendered by both integrators: the Renderer's set-up
stages, the scene's device bytes, the process's peak host memory, and per
integrator the wall time of the first frame (programs built or loaded) and
the median of ``--repeat`` after it.  ``move``: ``Accel.move_instances`` of N
placements of a small ball to new random transforms -- the instance table and
the top level built again, on the device or on the host by the meshes'
builder (``--builders``) -- its wall time (the median of ``--repeat`` after a
warm-up) and parts: on the host clock ``convert`` (the transforms as an
array), for the device ``host`` (their copy into page-locked memory, the
launches queued at once, the checks), ``wait`` (for the first pass's
summary: upload, checks, boxes and the frame the device chose), ``finish``
(the copies over the scene's buffers, the wait for the end); for the host ``table``, ``top level``, ``upload``; then the device's
phases from profiling events.  Prints markdown tables; timing is done here,
never in tests.
"""

from __future__ import annotations

import sys

if not __package__:   # run as a script, python benchmarks/NAME.py: import from the repository, not this folder
    import os.path
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import argparse
import math
import resource
import statistics
import time

import numpy as np

from benchmarks.common import POSITIVE, int_at_least, parse_count, parse_size
from clrt.errors import ClrtError


def _peak_rss_gib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20   # kB on Linux


def _short(device: str) -> str:
    """PoCL, or the device's name without its platform."""
    return "PoCL" if "Portable Computing Language" in device else device.split(" (")[0]


def grid_instances(mesh, side: int, turn: bool = True):
    """``side``^3 placements of ``mesh`` on a cubic grid 1.3 of its size apart,
    each turned about y by its own angle (clrt.Instances)."""
    from clrt.scene.instances import Instances
    lo, hi = mesh.bounds
    step = 1.3 * float((hi - lo).max())
    cells = np.stack(np.meshgrid(*[np.arange(side)] * 3, indexing="ij"), -1).reshape(-1, 3)
    transforms = np.tile(np.eye(4), (len(cells), 1, 1))
    angle = 0.7 * np.arange(len(cells)) if turn else np.zeros(len(cells))
    c, s = np.cos(angle), np.sin(angle)
    transforms[:, 0, 0], transforms[:, 0, 2], transforms[:, 2, 0], transforms[:, 2, 2] = c, s, -s, c
    transforms[:, :3, 3] = cells * step - transforms[:, :3, :3] @ ((lo + hi) / 2)
    return Instances([mesh], np.zeros(len(cells), np.int64), transforms)


def render_table(mesh, side: int, size, device, repeat: int, spp: int) -> list[str]:
    from clrt.renderer import Renderer
    from clrt.scene.placed import placed_scene
    from clrt.scene.scene import Camera, Light
    instances = grid_instances(mesh, side)
    scene = placed_scene(instances)
    lo, hi = scene.bounds
    centre, reach = (lo + hi) / 2, float(np.linalg.norm(hi - lo))
    camera = Camera(tuple(centre + reach * np.array([0.55, 0.45, 0.75])), tuple(centre), width=size[0],
                    height=size[1])
    light = centre + reach * np.array([-0.5, 1.0, 0.8])
    scene.lights = [Light(tuple(light), (float(np.sum((light - centre) ** 2)) * math.pi,) * 3)]
    start = time.perf_counter()
    renderer = Renderer(scene, device=device)
    setup = time.perf_counter() - start
    t = renderer.timings
    rows = []
    for integrator in ("whitted", "path"):
        walls = []
        for _ in range(1 + repeat):
            begin = time.perf_counter()
            renderer.render(camera, integrator=integrator, spp=spp)
            walls.append(time.perf_counter() - begin)
        rows.append(f"| {len(instances):,} x {len(mesh.faces):,} = {len(instances) * len(mesh.faces):,} "
                    f"| {_short(renderer.device)} | {setup:.2f} s ({t['acceleration build'] / 1e3:.2f} s build) "
                    f"| {renderer.device_bytes / 2**20:,.1f} | {_peak_rss_gib():.2f} | {size[0]}x{size[1]} "
                    f"| {integrator}{f' {spp} spp' if integrator == 'path' else ''} | {walls[0]:.2f} s "
                    f"| {statistics.median(walls[1:]):.3f} s |")
    return rows


def _median_parts(runs: list[dict]) -> dict:
    return {name: statistics.median(run[name] for run in runs) for name in runs[0]}


def _parts_text(parts: dict) -> str:
    return " + ".join(f"{name} {ms:.2f}" for name, ms in parts.items())


def move_table(counts, device, repeat: int, builders) -> list[str]:
    """``Accel.move_instances`` of N placements of a small ball to new random
    transforms (turned, stretched, a third mirrored), per top-level builder:
    the whole call's wall time and its parts on the host clock (move_times),
    then the device's phases from profiling events (a second series of moves
    on the scene's profiling queue: launches cost the host more there, so the
    walls above come from the plain queue), and the top level's SAH cost."""
    from clrt.device.instances import move_instances
    from clrt.query import Accel
    from clrt.scene import primitives
    from clrt.scene.instances import Instances
    rows = []
    rng = np.random.default_rng(0)
    ball = primitives.icosphere(1)

    def place(n):
        transforms = np.tile(np.eye(4), (n, 1, 1))
        q, r = np.linalg.qr(rng.normal(size=(n, 3, 3)))
        transforms[:, :3, :3] = q * rng.uniform(0.5, 2.0, (n, 1, 3))
        transforms[:, :3, 3] = rng.uniform(-50.0, 50.0, (n, 3)) * (n / 1000) ** (1 / 3)
        return transforms

    for n in counts:
        for builder in builders:
            accel = Accel(Instances([ball], np.zeros(n, np.int64), place(n)), builder=builder, device=device)
            two = accel.acceleration
            walls, parts = [], []
            for _ in range(1 + repeat):
                moved = place(n)
                start = time.perf_counter()
                accel.move_instances(moved)
                walls.append(1e3 * (time.perf_counter() - start))
                parts.append(dict(two.move_times))
            wall = statistics.median(walls[1:])
            kernels = "(host)"
            if two.device_top is not None:
                profiled = []
                for _ in range(1 + repeat):
                    accel.instances, _ = move_instances(accel.device_scene, accel.instances, place(n), profile=True)
                    profiled.append({name: two.move_times[name] for name in ("upload", "place", "rows", "sort",
                                                                            "nodes", "fit")})
                device_ms = _median_parts(profiled[1:])
                kernels = f"{_parts_text(device_ms)} = {sum(device_ms.values()):.2f}"
            rows.append(f"| {n:,} | {_short(accel.device)} | {'device' if two.device_top is not None else 'host'} "
                        f"| **{wall:.2f} ms** | {wall / n * 1e4:.2f} ms | {_parts_text(_median_parts(parts[1:]))} "
                        f"| {kernels} | {two.top.stats()['sah_cost']:.1f} |")
    return rows


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.instances", description=__doc__.split("\n\n")[0])
    p.add_argument("--mesh", help="the mesh file placed (default: a torus of --triangles triangles)")
    p.add_argument("--triangles", type=parse_count, default=75_000, help="the torus's triangles (default 75k)")
    p.add_argument("--grid", type=int_at_least(1, 1000), default=13, help="placements a side (default 13: 2,197)")
    p.add_argument("--size", type=parse_size, default=(160, 120), help="image size WxH (default 160x120)")
    p.add_argument("--spp", type=POSITIVE, default=4, help="the path tracer's samples a pixel (default 4)")
    p.add_argument("--move", type=lambda s: [parse_count(x) for x in s.split(",")],
                   help="instead: time move_instances of these counts, e.g. 1k,10k,100k")
    p.add_argument("--builders", default="device,sah",
                   help="--move: the meshes' builders, whose choice picks where the top level is built: "
                        "'device' (the device's top level), 'sah' (the host's); default both")
    p.add_argument("--repeat", type=POSITIVE, default=3, help="runs timed after one warm-up (default 3)")
    p.add_argument("--device", help="'gpu', 'cpu' or P:D (default: clrt's choice)")
    args = p.parse_args(argv)
    try:
        if args.move:
            builders = [b for b in args.builders.split(",") if b]
            print("| instances | device | top level | move_instances wall | per 10k | its parts, host clock (ms) "
                  "| device phases, profiled (ms) | top SAH cost |\n|---|---|---|---|---|---|---|---|")
            rows = move_table(args.move, args.device, args.repeat, builders)
        else:
            from clrt.scene import primitives
            from clrt.scene.load import load_mesh
            n = max(3, math.ceil(math.sqrt(args.triangles / 2 / 0.6)))
            mesh = load_mesh(args.mesh) if args.mesh else primitives.torus(1.0, 0.35, n, max(3, round(0.6 * n)))
            print("| triangles | device | set-up | device MiB | host peak GiB | image | integrator | first frame "
                  "| frame |\n|---|---|---|---|---|---|---|---|---|")
            rows = render_table(mesh, args.grid, args.size, args.device, args.repeat, args.spp)
    except ClrtError as exc:
        print(f"clrt: {exc}", file=sys.stderr)
        return exc.exit_code
    print("\n".join(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
