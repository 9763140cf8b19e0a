"""Two checkouts of clrt side by side on one device: their answers and times.

Made to show the same answers, and kernel times within noise, before and
after a change to the code's interfaces.

    python -m benchmarks.versions --base ../old-checkout --mesh-dir .meshes --device gpu

Each round runs one process per checkout (this one and ``--base``, in
alternating order), and each process measures, on every mesh: 1M random rays
(``--rays``; origins uniform in the mesh's box grown by 10 % about its
centre, directions uniform on the sphere; numpy default_rng(0)) closest and
any hit, kernel and whole-call ms; primary rays of a 1080p camera (``--size``)
made and traced in one launch (``Accel.launch_camera``); a frame's kernels and
wall (``Renderer.render``); ``Accel()``'s wall; ``build_on_device``'s wall and
device ms -- for the default and the host SAH builders, medians of
``--repeat`` calls after a warm-up.  It prints the medians over rounds per checkout, their ratio, and
whether the hits (prims and t) and the frame's pixels were the same bit for
bit.  A checkout must have clrt's public API (Accel, Renderer, Camera,
scene_from_mesh, clrt.scene.load.load_mesh); run on the device's checkout as
the working tree, with ``--base`` a copy of the older package's root.
"""

from __future__ import annotations

import sys

if not __package__:   # run as a script, python benchmarks/NAME.py: import from the repository, not this folder
    import os.path
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import argparse
import hashlib
import json
import os
import statistics
import subprocess
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
MESHES = ("bunny00", "camel")


def _digest(*arrays) -> str:
    import numpy as np
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


def _measure(mesh_dir: str, meshes, device: str, rays: int, size: tuple, repeat: int) -> dict:
    """Everything for one checkout (the clrt first on sys.path), in this process."""
    import numpy as np
    import pyopencl as cl

    import clrt
    from clrt.scene.load import load_mesh
    from clrt.scene.scene import Camera, scene_from_mesh
    med = statistics.median
    out = {"clrt": clrt.__file__}
    for name in meshes:
        mesh = load_mesh(os.path.join(mesh_dir, f"{name}.off"))
        lo, hi = mesh.bounds
        rng = np.random.default_rng(0)
        n = rays
        centre, half = (lo + hi) / 2, 0.55 * (hi - lo)
        o = rng.uniform(centre - half, centre + half, (n, 3)).astype(np.float32)
        z = rng.uniform(-1, 1, n)
        phi = rng.uniform(0, 2 * np.pi, n)
        d = np.stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z], 1).astype(np.float32)
        r = {}
        for builder in ("auto", "sah"):
            walls = []
            for _ in range(5 if builder == "auto" else 2):
                start = time.perf_counter()
                acc = clrt.Accel(mesh, builder=builder, device=device)
                acc.queue.finish()
                walls.append(1e3 * (time.perf_counter() - start))
            r[f"{builder}: Accel() wall ms"] = med(walls)
            for query in ("trace", "any_hit"):
                fn = getattr(acc, query)
                for _ in range(3):
                    fn(o, d)
                acc.kernel_ms()
                kernel, wall = [], []
                for _ in range(repeat):
                    start = time.perf_counter()
                    res = fn(o, d)
                    wall.append(1e3 * (time.perf_counter() - start))
                    kernel.append(acc.kernel_ms())
                r[f"{builder}: random {query} kernel ms"] = med(kernel)
                r[f"{builder}: random {query} wall ms"] = med(wall)
                r[f"{builder}: random {query} answers"] = (_digest(res.prim, res.t) if query == "trace"
                                                              else _digest(res))
            camera = Camera.framing(mesh.bounds, *size)
            hits = cl.Buffer(acc.context, cl.mem_flags.READ_WRITE, size[0] * size[1] * 16)
            for occlusion in (False, True):
                times = []
                for i in range(repeat + 3):
                    event = acc.launch_camera(camera, hits, occlusion=occlusion)
                    event.wait()
                    if i >= 3:
                        times.append(1e-6 * (event.profile.end - event.profile.start))
                r[f"{builder}: primary {'any' if occlusion else 'closest'} kernel ms"] = med(times)
            if builder == "auto" and acc.acceleration.builder == "device":
                from clrt.device.build import build_on_device
                corners = mesh.vertices[mesh.faces].astype(np.float32)
                walls, device_ms = [], []
                for i in range(repeat // 2 + 3):
                    start = time.perf_counter()
                    bvh = build_on_device(acc.context, acc.queue, corners, leaf_size=4, device_times=True)
                    walls.append(1e3 * (time.perf_counter() - start))
                    device_ms.append(bvh.timings["device"])
                    bvh.release()
                r["build_on_device wall ms"] = med(walls[3:])
                r["build_on_device device ms"] = med(device_ms[3:])
        renderer = clrt.Renderer(scene_from_mesh(mesh), device=device)
        camera = Camera.framing(mesh.bounds, *size)
        kernels, walls = [], []
        for i in range(repeat + 6):
            start = time.perf_counter()
            frame = renderer.render(camera)
            if i >= 6:
                walls.append(1e3 * (time.perf_counter() - start))
                kernels.append(frame.timings["ray generation"] + frame.timings["pixel colour"])
        r["frame kernels ms"] = med(kernels)
        r["frame wall ms"] = med(walls)
        r["frame pixels"] = _digest(frame.image)
        out[name] = r
    return out


def _run_round(root: Path, args) -> dict:
    command = [sys.executable, str(Path(__file__).resolve()), "--measure", str(root), "--mesh-dir", args.mesh_dir,
               "--device", args.device, "--rays", str(args.rays), "--size", args.size, "--repeat", str(args.repeat),
               "--meshes", *args.meshes]
    done = subprocess.run(command, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.versions", description=__doc__.split("\n")[0])
    p.add_argument("--base", help="root of the other checkout (the folder holding its clrt/)")
    p.add_argument("--mesh-dir", default=str(REPO.parent / "shared" / "meshes"), help="folder of the .off meshes")
    p.add_argument("--meshes", nargs="+", default=list(MESHES), help="mesh names (default: bunny00 camel)")
    p.add_argument("--device", default="gpu", help="device (default gpu)")
    p.add_argument("--rounds", type=int, default=3, help="processes per checkout (default 3)")
    p.add_argument("--rays", type=int, default=1 << 20, help="random rays (default 1M)")
    p.add_argument("--size", default="1920x1080", help="primary rays' and frames' WxH (default 1920x1080)")
    p.add_argument("--repeat", type=int, default=20, help="timed calls a median is of (default 20)")
    p.add_argument("--measure", metavar="ROOT", help="(internal) measure ROOT's clrt in this process, print JSON")
    args = p.parse_args(argv)
    if args.measure:
        sys.path.insert(0, str(Path(args.measure).resolve()))   # that checkout's clrt, not this one's
        size = tuple(int(x) for x in args.size.split("x"))
        result = _measure(args.mesh_dir, args.meshes, args.device, args.rays, size, args.repeat)
        print(json.dumps(result))
        return 0
    if not args.base or not (Path(args.base) / "clrt").is_dir():
        p.error("--base must name a checkout's root (a folder holding clrt/)")
    if not (Path(args.mesh_dir) / f"{args.meshes[0]}.off").is_file():
        p.error(f"--mesh-dir {args.mesh_dir} has no {args.meshes[0]}.off")
    runs = {"this": [], "base": []}
    for k in range(args.rounds):
        order = [("this", REPO), ("base", Path(args.base).resolve())]
        for label, root in order if k % 2 == 0 else order[::-1]:
            runs[label].append(_run_round(root, args))
    for label in ("base", "this"):
        print(f"{label}: {runs[label][0]['clrt']}")
    print("\n| mesh | measure | base | this | this / base |\n|---|---|---|---|---|")
    for mesh in args.meshes:
        for key, value in runs["this"][0][mesh].items():
            ours = [run[mesh][key] for run in runs["this"]]
            theirs = [run[mesh][key] for run in runs["base"]]
            if isinstance(value, str):
                same = len(set(ours) | set(theirs)) == 1
                print(f"| {mesh} | {key} | | | {'the same' if same else 'DIFFERENT'} |")
            else:
                a, b = statistics.median(theirs), statistics.median(ours)
                print(f"| {mesh} | {key} | {a:.3f} | {b:.3f} | {b / a:.3f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
