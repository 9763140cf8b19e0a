"""The host's stages of making an Accel or a Renderer: ``python -m benchmarks.host_stages``.

    python -m benchmarks.host_stages --device gpu --triangles 1M,10M,50M
    python -m benchmarks.host_stages --device cpu --triangles 1M --no-split

On a torus of about each count of triangles (vertices float32, faces int32,
as a caller's arrays arrive), the median wall ms of ``--repeat`` runs of each
host stage -- the mesh's checks, its bounds (the vertices its faces use), the
corner gather into the device's frame, ``scene_from_mesh`` (which leaves the
crease split for smooth shading to its first use), the crease split and the
split's vertex normals made on the host, ``flatten_scene`` (the host's
arrays) -- and their device twins where the device has float64 (the
vertices and faces uploaded, then split and normals made there:
clrt.device.crease, which a Renderer on a GPU uses); then the whole calls,
``clrt.Accel(V, F)``, ``clrt.Renderer(scene)`` of one scene made before
(warm: one untimed call of each first) and ``clrt.Renderer((V, F))`` (new
arrays every call, as a user's first call: its checks, bounds, scene and any
crease split included; with ``--no-split``, of ``scene_from_mesh((V, F),
flat)``), beside the build they contain (``Acceleration.build_ms``: the
device build, its upload included), ``Renderer.timings`` and what the whole
call spent beyond those stages.  Last, issue 38's yardstick: the device build from
corners (warm, as ``benchmarks.build`` times it) and the corners' upload
alone, and each whole call over their sum (the issue asks for at most 1.5).
What a whole call spends beyond its build and the stages above is the rest
of the host's set-up (context, programs, uploads).  ``--no-split`` leaves
the crease split out (a flat-shaded scene), which takes the host seconds
from a few million triangles on; ``--no-host-shading`` leaves out only the
host's split, normals and flatten_scene, which a GPU's calls do not run
(minutes at 50M); ``--no-calls`` times the stages alone.
Timing is done here, never in tests.
"""

from __future__ import annotations

import sys

if not __package__:   # run as a script, python benchmarks/NAME.py: import from the repository, not this folder
    import os.path
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import argparse
import gc
import math
import statistics
import time

import numpy as np

from benchmarks.common import POSITIVE, exit_code, parse_count


def torus_arrays(count: int) -> tuple[np.ndarray, np.ndarray]:
    """(V, 3) float32 and (F, 3) int32 of a torus of about ``count`` triangles."""
    from clrt.scene.primitives import torus
    ring = max(3, int(math.sqrt(count / 2) * 1.4))
    mesh = torus(n_major=ring, n_minor=max(3, count // 2 // ring))
    return np.ascontiguousarray(mesh.vertices, np.float32), np.ascontiguousarray(mesh.faces, np.int32)


def _median_ms(make, repeat: int, before=None) -> tuple[float, object]:
    """Median wall ms of ``make(before())`` (``before`` untimed), and the last result."""
    walls, result = [], None
    for _ in range(repeat):
        gc.collect()
        arg = before() if before is not None else None
        start = time.perf_counter()
        result = make(arg) if before is not None else make()
        walls.append(1e3 * (time.perf_counter() - start))
    return statistics.median(walls), result


def stages(vertices, faces, device, repeat: int, split: bool, calls: bool = True, host_shading: bool = True) -> dict:
    """Stage name -> median ms for one mesh (see the module docstring);
    without ``host_shading`` the host's crease split, vertex normals and
    flatten_scene left out."""
    import clrt
    from clrt.config import DEFAULT_CREASE_ANGLE
    from clrt.device.context import create_context
    from clrt.scene.arrays import device_origin, flatten_scene, triangle_corners
    from clrt.scene.mesh import Mesh
    from clrt.scene.scene import scene_from_mesh
    out = {}
    out["Mesh(V, F): the checks"], mesh = _median_ms(lambda: Mesh(vertices, faces), repeat)
    out["Mesh.bounds (used vertices)"], bounds = _median_ms(lambda m: m.bounds, repeat,
                                                            lambda: Mesh(vertices, faces))
    origin = device_origin(bounds)
    out["triangle_corners (gather, frame)"], corners = _median_ms(lambda: triangle_corners(mesh, origin), repeat)
    material = None if split else {"smooth": False}
    name = "scene_from_mesh (the split left for later)" if split else "scene_from_mesh (flat: no split)"
    out[name], scene = _median_ms(lambda m: scene_from_mesh(m, material), repeat, lambda: Mesh(vertices, faces))
    shaded = Mesh(vertices, faces)
    if split and host_shading:
        out["crease split on the host (area normals included)"], shaded = _median_ms(
            lambda m: _made(m.split_at_creases(DEFAULT_CREASE_ANGLE)), repeat, lambda: Mesh(vertices, faces))
    if host_shading:
        out["vertex normals on the host"], _ = _median_ms(lambda: shaded.vertex_normals(), repeat)
        out["flatten_scene"], _ = _median_ms(lambda: flatten_scene(scene), repeat)   # (its split made by the first)
    context, queue = create_context(device)
    if "cl_khr_fp64" in queue.device.extensions:
        from clrt.device.crease import shade_on_device, upload_mesh
        out["upload_mesh (vertices, faces)"], uploaded = _median_ms(lambda: upload_mesh(context, queue, mesh),
                                                                   repeat)
        crease = DEFAULT_CREASE_ANGLE if split else None
        shade_on_device(context, queue, uploaded, crease)   # the program built
        out["shade_on_device (split, normals)"], _ = _median_ms(
            lambda: shade_on_device(context, queue, uploaded, crease), repeat)
    if not calls:
        return out
    fresh = (lambda: (vertices.copy(), faces.copy()))     # (a new Mesh each call: nothing cached)
    for call, make, before in (
            ("Accel(V, F)", lambda: clrt.Accel((vertices, faces), device=device), None),
            ("Renderer(scene)", lambda: clrt.Renderer(scene, device=device), None),
            ("Renderer(V, F)", lambda arrays: clrt.Renderer(arrays if split else scene_from_mesh(arrays, material),
                                                            device=device), fresh)):
        made = make(before()) if before else make()   # programs built, driver warm
        del made
        out[f"{call}: whole call"], made = _median_ms(
            (lambda arrays: _finished(make(arrays))) if before else (lambda: _finished(make())), repeat, before)
        out[f"{call}: of it the build"] = made.acceleration.build_ms
        if call.startswith("Renderer"):
            out.update({f"{call}: {stage}": ms for stage, ms in made.timings.items()})
            out[f"{call}: beyond its stages"] = out[f"{call}: whole call"] - sum(made.timings.values())
        del made
    if "cl_khr_fp64" in queue.device.extensions:   # issue 38's yardstick: build + upload of the corners
        build = out["device build from corners (warm)"] = _build_ms(context, queue, corners, repeat)
        upload = out["upload of the corners"] = _upload_ms(context, queue, corners, repeat)
        for call in ("Accel(V, F)", "Renderer(scene)", "Renderer(V, F)"):
            out[f"{call} / (build + upload) (ratio)"] = out[f"{call}: whole call"] / (build + upload)
    return out


def _made(mesh):
    """A crease split made (its faces asked for)."""
    mesh.faces   # noqa: B018
    return mesh


def _build_ms(context, queue, corners, repeat: int) -> float:
    """Warm median wall ms of a device build from the corners in host memory."""
    from clrt.device.build import build_on_device
    build_on_device(context, queue, corners).release()
    walls = []
    for _ in range(repeat):
        start = time.perf_counter()
        built = build_on_device(context, queue, corners)
        queue.finish()
        walls.append(1e3 * (time.perf_counter() - start))
        built.release()
    return statistics.median(walls)


def _upload_ms(context, queue, corners, repeat: int) -> float:
    """Warm median wall ms of the corners alone copied to the device, as the
    device build copies them (clrt.device.pinned.upload: staged on GPUs)."""
    import pyopencl as cl
    from clrt.device import pinned
    buffer = cl.Buffer(context, cl.mem_flags.READ_WRITE, corners.nbytes)
    walls = []
    for _ in range(1 + repeat):
        start = time.perf_counter()
        pinned.upload(context, queue, buffer, corners)
        queue.finish()
        walls.append(1e3 * (time.perf_counter() - start))
    buffer.release()
    return statistics.median(walls[1:])


def _finished(made):
    made.queue.finish()
    return made


def run(counts, device=None, repeat=3, split=True, out=None, calls=True, host_shading=True):
    from clrt.device.context import create_context, device_label
    out = out or sys.stdout
    _, queue = create_context(device)
    columns = {}
    for count in counts:
        vertices, faces = torus_arrays(count)
        columns[len(faces)] = stages(vertices, faces, device, repeat, split, calls, host_shading)
    print(f"device: {device_label(queue.device)}; medians of {repeat}, ms\n", file=out)
    print("| stage | " + " | ".join(f"{n:,} triangles" for n in columns) + " |", file=out)
    print("|---|" + "---|" * len(columns), file=out)
    for stage in next(iter(columns.values())):
        digits = 2 if stage.endswith("(ratio)") else 1
        print(f"| {stage} | " + " | ".join(f"{c[stage]:,.{digits}f}" for c in columns.values()) + " |", file=out)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.host_stages", description=__doc__.split("\n")[0])
    p.add_argument("--triangles", type=lambda s: [parse_count(x) for x in s.split(",")], default=[1_000_000],
                   help="comma-separated counts, e.g. 1M,10M (default 1M)")
    p.add_argument("--device", help="'gpu', 'cpu' or P:D (default: clrt's choice)")
    p.add_argument("--repeat", type=POSITIVE, default=3, help="runs of each stage, median reported (default 3)")
    p.add_argument("--no-split", action="store_true", help="a flat-shaded scene: no crease split")
    p.add_argument("--no-calls", action="store_true", help="the stages alone, not the whole calls")
    p.add_argument("--no-host-shading", action="store_true",
                   help="leave out the host's crease split, vertex normals and flatten_scene (minutes at 50M)")
    args = p.parse_args(argv)
    return exit_code(run, args.triangles, args.device, args.repeat, not args.no_split, calls=not args.no_calls,
                     host_shading=not args.no_host_shading)


if __name__ == "__main__":
    sys.exit(main())
