"""The path tracer's own incoherent rays beside the random set: ``python -m benchmarks.path_rays MESH``.

    python -m benchmarks.path_rays .meshes/bunny00.off --device gpu --size 1920x1080 --spp 1 --max-depth 3

The path tracer (path.cl) renders the mesh from the speed benchmark's camera
(benchmarks.raysets.reference_camera) with the default light and records,
instead of only tracing, the rays it traces after the camera's
(clrt.renderer.path.PathTracer.record_rays): its diffuse **bounces** (closest
hit, from each path vertex in the direction the BSDF chose) and its **shadow**
rays (any hit up to the light: next-event estimation).  Those and as many rays
of the ``random`` set of benchmarks.raysets (origins in the box enlarged by
10 %, directions uniform) are then put on the device once and timed through
``clrt.Accel`` of each ``--builder`` (benchmarks.raysets.measure): closest
hit and any hit (the shadow rays up to their own lengths), kernel ms (median
of the launches' profiling times after a warm-up) and Mrays/s of it, the wall
ms of the call, and whether any hit found exactly the rays closest hit did.  This is issue
39's "diffuse bounce rays and shadow rays of the path tracer ... beside the
random set".  ``--embree`` adds Embree's wall ms for the same rays on the host
CPU (embreex: one core, as benchmarks.raysets says).
"""

from __future__ import annotations

import sys

if not __package__:   # run as a script, python benchmarks/NAME.py: import from the repository, not this folder
    import os.path
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import argparse

import numpy as np

from benchmarks.common import NON_NEGATIVE, POSITIVE, exit_code, parse_count, parse_size, rate
from benchmarks.raysets import embree_measure, measure, random_rays, reference_camera
from clrt.config import BUILDER_CHOICES


def recorded_rays(mesh, camera, device, spp: int, max_depth: int, seed: int, capacity: int) -> dict:
    """The path tracer's rays (PathTracer.record_rays) of ``mesh`` seen by ``camera``."""
    import clrt
    from clrt.renderer.path import PathTracer
    from clrt.scene.scene import scene_from_mesh
    scene = scene_from_mesh(mesh)
    scene.integrator = "path"
    renderer = clrt.Renderer(scene, device=device)
    return PathTracer(renderer).record_rays(camera, spp=spp, max_depth=max_depth, seed=seed, capacity=capacity)


def run(mesh_path, device=None, size=(1920, 1080), spp: int = 1, max_depth: int = 3, builders=("auto",),
        count: int = 1_000_000, seed: int = 0, repeat: int = 20, warmup: int = 3, embree: bool = False) -> None:
    import clrt
    from clrt.device.context import create_context, device_label
    mesh = clrt.load_mesh(mesh_path)
    camera = reference_camera(mesh, str(mesh_path), size)
    recorded = recorded_rays(mesh, camera, device, spp, max_depth, seed, count)
    bounce_o, bounce_d = recorded["bounce"]
    shadow_o, shadow_d, shadow_t = recorded["shadow"]
    # float32 rays as the random set's (near the origin, as the benchmark meshes
    # lie, the same points; far from it a ray may meet the surface it leaves)
    bounce_o, shadow_o = bounce_o.astype(np.float32), shadow_o.astype(np.float32)
    random_o, random_d = random_rays(mesh, max(len(bounce_o), 1), seed)
    sets = [("bounce", bounce_o, bounce_d, np.inf), ("shadow", shadow_o, shadow_d, shadow_t),
            ("random", random_o, random_d, np.inf)]
    print(f"{mesh.name}, {len(mesh.faces):,} triangles, on {device_label(create_context(device)[1].device)}; "
          f"path tracer at {size[0]}x{size[1]}, {spp} spp, max_depth {max_depth}: "
          f"{recorded['traced']['bounce']:,} bounces and {recorded['traced']['shadow']:,} shadow rays traced "
          f"(up to {count:,} of each timed); random: as many as the bounces, seed {seed}")
    print()
    print("| builder | rays | count | closest kernel ms | Mrays/s | closest wall ms | any-hit kernel ms | Mrays/s "
          "| any-hit wall ms | hits | any hit where closest |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for builder in builders:
        accel = clrt.Accel(mesh, builder=builder, device=device)
        for name, o, d, tmax in sets:
            if not len(o):
                print(f"| {builder} | {name} | 0 | | | | | | | | |")
                continue
            m = measure(accel, o, d, tmax, repeat, warmup)
            print(f"| {builder} | {name} | {len(o):,} | {m['closest_kernel_ms']:.3f} | "
                  f"{rate(len(o) / m['closest_kernel_ms'] / 1e3)} | {m['closest_wall_ms']:.3f} | "
                  f"{m['any_kernel_ms']:.3f} | {rate(len(o) / m['any_kernel_ms'] / 1e3)} | {m['any_wall_ms']:.3f} | "
                  f"{m['hits']:,} | {'yes' if m['any_agrees'] else 'NO'} |")
    if embree:
        for name, o, d, tmax in sets:
            if len(o):
                e = embree_measure(mesh, o, d, tmax, repeat, warmup)
                print(f"| Embree (embreex, 1 core) | {name} | {len(o):,} | | | {e['closest_wall_ms']:.3f} | | | "
                      f"{e['any_wall_ms']:.3f} | {e['hits']:,} | |")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.path_rays", description=__doc__.split("\n")[0])
    p.add_argument("mesh", help="a mesh file")
    p.add_argument("--device", default=None, help="'cpu', 'gpu' or an index (default: clrt's choice)")
    p.add_argument("--size", type=parse_size, default=(1920, 1080), help="the path-traced image, WxH")
    p.add_argument("--spp", type=POSITIVE, default=1, help="samples a pixel (default 1)")
    p.add_argument("--max-depth", type=POSITIVE, default=3,
                   help="Mitsuba's count (default 3: shadow rays from the first two vertices, bounces from both, "
                        "the second's only to find emitters)")
    p.add_argument("--builder", default="auto", help="comma-separated builders (default: auto)")
    p.add_argument("--rays", type=parse_count, default=1_000_000, help="most rays of each kind timed (default 1M)")
    p.add_argument("--seed", type=NON_NEGATIVE, default=0, help="of the path tracer's samples and the random set")
    p.add_argument("--repeat", type=POSITIVE, default=20, help="timed queries of each set (the median is printed)")
    p.add_argument("--warmup", type=NON_NEGATIVE, default=3, help="untimed queries before them")
    p.add_argument("--embree", action="store_true", help="Embree's times for the same rays (needs embreex)")
    args = p.parse_args(argv)
    builders = tuple(b.strip() for b in args.builder.split(",") if b.strip())
    bad = [b for b in builders if b not in BUILDER_CHOICES]
    if bad or not builders:
        p.error(f"--builder: {', '.join(bad) or 'none given'} (use {', '.join(BUILDER_CHOICES)})")
    if args.rays < 1:
        p.error("--rays must be at least 1")
    return exit_code(run, args.mesh, args.device, args.size, args.spp, args.max_depth, builders, args.rays,
                     args.seed, args.repeat, args.warmup, args.embree)


if __name__ == "__main__":
    sys.exit(main())
