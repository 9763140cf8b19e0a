"""Per-stage times of whole frames: ``python -m clrt.bench.frame MESH --size 200x200 ...``.

Set-up stages (initialisation, acceleration build, copy to device) are timed
once, cold, as a user meets them.  Frame stages are medians over ``--repeat``
frames after ``--warmup`` frames; kernel stages come from OpenCL profiling
events, ``frame wall`` is the host clock around a whole ``Renderer.render``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

from clrt.errors import ClrtError


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(x) for x in text.lower().split("x"))
        return w, h
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WxH, got {text!r}") from None


def run(mesh_path, sizes, device=None, repeat=5, warmup=1, out=sys.stdout) -> list[dict]:
    from clrt.render import Renderer
    from clrt.scene.default import default_scene
    from clrt.scene.load import load_mesh
    from clrt.scene.scene import Camera, default_light, scene_from_mesh

    scene = scene_from_mesh(load_mesh(mesh_path)) if mesh_path else default_scene()
    name = mesh_path or "built-in scene"
    renderer = Renderer(scene, device)
    rows = []
    print(f"mesh: {name}, {scene.num_triangles:,} triangles; device: {renderer.device}", file=out)
    print(f"set-up (cold): " + ", ".join(f"{k} {v:.2f} ms" for k, v in renderer.timings.items()), file=out)
    stages = ("ray generation", "pixel colour", "read back")
    print(f"\n| resolution | {' | '.join(stages)} | frame wall | Mrays/s (primary, wall) |", file=out)
    print("|---|" + "---|" * (len(stages) + 2), file=out)
    for w, h in sizes:
        base = scene.camera or Camera.framing(scene.bounds)
        camera = Camera(base.eye, base.target, base.up, base.fov, w, h)
        if mesh_path:
            camera = Camera.framing(scene.bounds, w, h)
            scene.lights = [default_light(scene.bounds, camera)]
        samples = []
        for i in range(warmup + repeat):
            start = time.perf_counter()
            frame = renderer.render(camera)
            wall = 1e3 * (time.perf_counter() - start)
            if i >= warmup:
                samples.append({**{s: frame.timings[s] for s in stages}, "frame wall": wall})
        med = {k: statistics.median(s[k] for s in samples) for k in samples[0]}
        rows.append({"width": w, "height": h, **med})
        mrays = w * h / med["frame wall"] / 1e3
        print(f"| {w}x{h} | " + " | ".join(f"{med[s]:.3f} ms" for s in stages)
              + f" | {med['frame wall']:.3f} ms | {mrays:.3g} |", file=out, flush=True)
    return rows


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m clrt.bench.frame", description=__doc__.split("\n")[0])
    p.add_argument("mesh", nargs="?", help="mesh file (default: the built-in scene)")
    p.add_argument("--size", type=_size, action="append", help="WxH, repeatable (default 200x200, 1920x1080)")
    p.add_argument("--device", help="'gpu', 'cpu' or P:D")
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--warmup", type=int, default=1)
    args = p.parse_args(argv)
    try:
        run(args.mesh, args.size or [(200, 200), (1920, 1080)], args.device, args.repeat, args.warmup)
    except ClrtError as exc:
        print(f"clrt: {exc}", file=sys.stderr)
        return exc.exit_code
    return 0


if __name__ == "__main__":
    sys.exit(main())
