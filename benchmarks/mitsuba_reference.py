"""Mitsuba 3 renders of the reference scenes (benchmarks/scenes.py): ``python -m benchmarks.mitsuba_reference``.

    python -m benchmarks.mitsuba_reference check                  # the glTF Cornell box is Mitsuba's own
    python -m benchmarks.mitsuba_reference reference              # tests/data/cornell-box-mitsuba.npz
    python -m benchmarks.mitsuba_reference render --scene bunny00 --spp 64 --runs 3 --out out/mitsuba

Mitsuba is a peer for comparison, never a dependency of clrt or of its tests: run this in an
environment of its own (docs/path-tracing.md, "Reference images"), from the repository root, e.g.
``python3 -m venv /work/mitsuba-venv && /work/mitsuba-venv/bin/pip install mitsuba trimesh`` and
``/work/mitsuba-venv/bin/python -m benchmarks.mitsuba_reference check``.  The scenes are read from
the glTF files benchmarks.scenes writes (geometry through trimesh, materials and camera from the
JSON) and handed to Mitsuba as meshes: pure Lambert ``diffuse`` BSDFs, ``area`` emitters, a
``perspective`` sensor with the glTF camera's vertical field of view, a box pixel filter (each
pixel the mean over its square, as clrt's jittered samples are), the ``independent`` sampler, the
``path`` integrator.

check: (1) Mitsuba's camera rays at pixel centres are clrt's (clrt.reference.camera_rays), for a
square and a 16:9 image; (2) an emitting triangle in one corner of an off-axis, non-square view
covers the same pixels in Mitsuba's render as clrt's camera model says (orientation, no flip, the
half-pixel convention); (3) the glTF box's triangles are those of ``mi.cornell_box()``, faces
turned the same way; (4) the two Cornell boxes render alike within noise (tests/path_reference.py).
Exit 1 if any check fails.

reference: the converged Cornell box for the tests, as independent batches whose spread gives each
pixel's noise.  render: time Mitsuba on a scene (wall time per render after a warm-up; Msamples/s
= pixels x spp / s) and write the image as EXR and .npy.  ``--variant cuda_ad_rgb`` on a GPU.
"""

from __future__ import annotations

import sys

if not __package__:   # run as a script, python benchmarks/NAME.py: import from the repository, not this folder
    import os.path
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import glob
import hashlib
import json
import math
import os
import re
import time
from pathlib import Path

import numpy as np

from benchmarks import scenes

REFERENCE_FILE = scenes.ROOT / "tests" / "data" / "cornell-box-mitsuba.npz"
SCENE_FILES = {"cornell-box": scenes.CORNELL_BOX_FILE,
               "bunny00": scenes.ROOT / "out" / "scenes" / scenes.BUNNY_FILE_NAME}
DEFAULT_SIZES = {"cornell-box": (1024, 1024), "mitsuba-cornell-box": (1024, 1024), "bunny00": (1920, 1080)}
IMAGE_LAYOUT = ("(H, W, 3) linear RGB; row 0 = top of the image, column 0 = left; pixel (px, py) = mean radiance over "
                "[px, px+1) x [py, py+1) of clrt's camera model (camera.cl; box filter). Mitsuba's film pixel (x, y) "
                "is clrt's pixel (px, py) = (x, y): no flip (checked by `check`).")


def start_mitsuba(variant: str):
    """Import Mitsuba with ``variant`` set.  For an LLVM variant without
    DRJIT_LIBLLVM_PATH, the newest libLLVM of the system is named: Dr.Jit's
    own search takes Debian 12's LLVM 15, whose x86 back end cannot select the
    fminimum its kernels use (the process aborts) -- apt-get install libllvm19."""
    if variant.startswith("llvm") and "DRJIT_LIBLLVM_PATH" not in os.environ:
        found = []
        for path in glob.glob("/usr/lib/*/libLLVM*.so*") + glob.glob("/usr/lib/llvm-*/lib/libLLVM*.so*"):
            m = re.search(r"libLLVM[-.]?(?:so\.)?(\d+)", os.path.basename(path))
            if m and os.path.isfile(path):
                found.append((int(m.group(1)), path))
        if found:
            major, path = max(found)
            if major < 16:
                print(f"warning: the newest libLLVM here is {major}; Dr.Jit may abort in LLVM's instruction "
                      f"selection (install libllvm19, or set DRJIT_LIBLLVM_PATH)", file=sys.stderr)
            os.environ["DRJIT_LIBLLVM_PATH"] = path
    try:
        import mitsuba as mi
    except ImportError:
        sys.exit("mitsuba is not installed in this Python: run this in Mitsuba's own environment "
                 "(pip install mitsuba trimesh), from the repository root")
    mi.set_variant(variant)
    return mi


# ---------------------------------------------------------------------------
# The glTF scene in Mitsuba


def read_scene(path, size=None) -> scenes.ReferenceScene:
    """A glTF file of benchmarks.scenes, read back: triangles through trimesh
    (node transforms applied), materials and camera from the JSON (trimesh
    quantises base colours to 8 bits).  ``size``: (width, height), else the
    camera's aspect ratio at 1080 pixels high."""
    import trimesh
    path = Path(path)
    loaded = trimesh.load(str(path), force="scene", process=False)
    doc = gltf_json(path)
    surfaces = {m["name"]: surface_of(m) for m in doc["materials"]}
    shapes = []
    for node in loaded.graph.nodes_geometry:
        transform, geometry = loaded.graph[node]
        mesh = loaded.geometry[geometry]
        v = trimesh.transformations.transform_points(mesh.vertices, transform).astype(np.float32)
        f = np.asarray(mesh.faces, dtype=np.uint32)
        shapes.append(scenes.Shape(node, v, f, np.zeros_like(v), surfaces[mesh.visual.material.name]))
    camera_node = next(n for n in doc["nodes"] if "camera" in n)
    m = np.asarray(camera_node["matrix"], dtype=np.float64).reshape(4, 4).T
    perspective = doc["cameras"][camera_node["camera"]]["perspective"]
    if size is None:
        size = (round(1080 * perspective.get("aspectRatio", 1.0)), 1080)
    view = scenes.View(tuple(m[:3, 3]), tuple(m[:3, 3] - m[:3, 2]), tuple(m[:3, 1]),
                       math.degrees(perspective["yfov"]), *size)
    return scenes.ReferenceScene(doc["scenes"][0]["name"], tuple(shapes), view, 8)


def gltf_json(path: Path) -> dict:
    data = path.read_bytes()
    if data[:4] == b"glTF":   # GLB: the JSON chunk first
        length = int.from_bytes(data[12:16], "little")
        data = data[20:20 + length]
    return json.loads(data)


def surface_of(material: dict) -> scenes.Surface:
    """The Lambert surface a material of benchmarks.scenes stands for (others are refused)."""
    pbr = material.get("pbrMetallicRoughness", {})
    ext = material.get("extensions", {})
    if (pbr.get("metallicFactor", 1.0), pbr.get("roughnessFactor", 1.0),
            ext.get("KHR_materials_specular", {}).get("specularFactor", 1.0)) != (0.0, 1.0, 0.0):
        raise ValueError(f"material {material.get('name')!r} is not pure Lambert: Mitsuba's diffuse would differ")
    strength = ext.get("KHR_materials_emissive_strength", {}).get("emissiveStrength", 1.0)
    emission = tuple(float(e) * strength for e in material.get("emissiveFactor", (0.0, 0.0, 0.0)))
    return scenes.Surface(material["name"], tuple(pbr["baseColorFactor"][:3]), emission)


def sensor_dict(mi, view: scenes.View, spp: int) -> dict:
    return {"type": "perspective", "fov": view.fov, "fov_axis": "y", "near_clip": 1e-3,
            "to_world": mi.ScalarTransform4f().look_at(origin=list(view.eye), target=list(view.target),
                                                       up=list(view.up)),
            "film": {"type": "hdrfilm", "width": view.width, "height": view.height, "rfilter": {"type": "box"},
                     "pixel_format": "rgb", "component_format": "float32"},
            "sampler": {"type": "independent", "sample_count": spp}}


def mitsuba_mesh(mi, shape: scenes.Shape):
    """A Mitsuba mesh of ``shape``'s triangles (no normals: flat, as the
    files' normals are), with its diffuse BSDF and, if it emits, an area emitter."""
    props = mi.Properties()
    props["bsdf"] = mi.load_dict({"type": "diffuse",
                                  "reflectance": {"type": "rgb", "value": list(shape.surface.base_color)}})
    if max(shape.surface.emission) > 0:
        props["emitter"] = mi.load_dict({"type": "area",
                                         "radiance": {"type": "rgb", "value": list(shape.surface.emission)}})
    mesh = mi.Mesh(shape.name, len(shape.vertices), len(shape.faces), props=props)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(np.ascontiguousarray(shape.vertices, dtype=np.float32).ravel())
    params["faces"] = mi.UInt32(np.ascontiguousarray(shape.faces, dtype=np.uint32).ravel())
    params.update()
    return mesh


def mitsuba_scene(mi, scene: scenes.ReferenceScene, max_depth: int, spp: int = 1):
    d = {"type": "scene", "integrator": {"type": "path", "max_depth": max_depth},
         "sensor": sensor_dict(mi, scene.view, spp)}
    for i, shape in enumerate(scene.shapes):
        d[f"shape{i}"] = mitsuba_mesh(mi, shape)
    return mi.load_dict(d)


def anchor_scene(mi, width: int, height: int, max_depth: int, spp: int = 1):
    """``mi.cornell_box()`` itself at ``width`` x ``height``, with the box filter."""
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=width, height=height, rfilter={"type": "box"})
    d["sensor"]["sampler"]["sample_count"] = spp
    d["integrator"]["max_depth"] = max_depth
    return mi.load_dict(d)


def render(mi, scene, spp: int, seed: int) -> np.ndarray:
    return np.array(mi.render(scene, spp=spp, seed=seed), dtype=np.float64)[..., :3]


def batches(mi, scene, count: int, spp: int, first_seed: int = 0, label: str = "") -> tuple[np.ndarray, np.ndarray]:
    """Mean of ``count`` renders of ``spp`` each (seeds first_seed...) and the
    variance of one path's estimate per pixel, from their spread."""
    total = total2 = 0.0
    started = time.perf_counter()
    for k in range(count):
        image = render(mi, scene, spp, first_seed + k)
        total, total2 = total + image, total2 + image * image
        if label and (k + 1) % max(1, count // 8) == 0:
            print(f"  {label}: {k + 1}/{count} batches of {spp} spp, {time.perf_counter() - started:.0f} s", flush=True)
    mean = total / count
    return mean, np.maximum(total2 / count - mean * mean, 0.0) * count / (count - 1) * spp


# ---------------------------------------------------------------------------
# check


def clrt_camera(view: scenes.View):
    from clrt.scene.scene import Camera
    return Camera(view.eye, view.target, view.up, view.fov, view.width, view.height)


def check_camera_rays(mi, view: scenes.View) -> float:
    """Largest angle (radians, to first order) between Mitsuba's and clrt's ray through each pixel centre."""
    from clrt.reference import camera_rays
    _, clrt_dirs = camera_rays(clrt_camera(view))
    sensor = mi.load_dict(sensor_dict(mi, view, 1))
    py, px = np.mgrid[0:view.height, 0:view.width]
    position = mi.Point2f(((px.ravel() + 0.5) / view.width).astype(np.float32),
                          ((py.ravel() + 0.5) / view.height).astype(np.float32))
    ray, _ = sensor.sample_ray(0.0, 0.5, position, mi.Point2f(0.5, 0.5))
    dirs = np.array(ray.d)
    dirs = dirs.T if dirs.shape == (3, px.size) else dirs   # Dr.Jit gives (3, N)
    # |difference| of unit vectors, in float64: arccos of a float32 dot product rounds to 3e-4
    return float(np.linalg.norm(dirs.astype(np.float64) - clrt_dirs.astype(np.float64), axis=1).max())


def check_footprint(mi, spp: int = 256) -> float:
    """Largest difference of per-pixel coverage of a corner triangle: Mitsuba's
    render (max depth 1: emitters seen directly, radiance 1) against clrt's
    camera model sampled on a 16 x 16 grid in each pixel."""
    from clrt.reference import camera_rays
    view = scenes.View((0.4, 0.3, 3.0), (0.1, 0.0, 0.0), (0.0, 1.0, 0.0), 35.0, 48, 32)
    tri = np.array([[-1.0, 0.2, 0.0], [-0.2, 0.6, 0.0], [-0.8, 0.9, 0.0]])   # upper left, asymmetric
    shape = scenes.Shape("marker", tri.astype(np.float32), np.array([[0, 1, 2]], np.uint32),
                         np.zeros((3, 3), np.float32),
                         scenes.Surface("marker", (0.0, 0.0, 0.0), (1.0, 1.0, 1.0)))
    if np.cross(tri[1] - tri[0], tri[2] - tri[0])[2] < 0:   # facing the camera (+z)
        raise AssertionError("marker triangle faces away")
    scene = scenes.ReferenceScene("marker", (shape,), view, 1)
    mitsuba = render(mi, mitsuba_scene(mi, scene, 1, spp), spp, 0)[..., 0]
    camera, n = clrt_camera(view), 16
    covered = np.zeros(view.width * view.height)
    for i in range(n):
        for j in range(n):
            o, d = camera_rays(camera, (i + 0.5) / n, (j + 0.5) / n)
            t = (0.0 - o[:, 2]) / d[:, 2]   # the plane z = 0
            p = o + t[:, None] * d
            covered += inside_triangle(p[:, :2], tri[:, :2])
    clrt = (covered / n ** 2).reshape(view.height, view.width)
    if not (clrt[: view.height // 2, : view.width // 2].sum() > 0.9 * clrt.sum() > 0):
        raise AssertionError("the marker is not in the upper left quarter of clrt's image")
    return float(np.abs(mitsuba - clrt).max())


def inside_triangle(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Points (N, 2) inside the 2-D triangle (3, 2), either winding."""
    def cross(a, b):
        return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]

    s = [cross(tri[(k + 1) % 3] - tri[k], p - tri[k]) for k in range(3)]
    return ((s[0] >= 0) & (s[1] >= 0) & (s[2] >= 0)) | ((s[0] <= 0) & (s[1] <= 0) & (s[2] <= 0))


def triangle_planes(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, float]:
    """Sorted unique (unit normal, offset) rows of a mesh's triangles, rounded, and its area."""
    c = vertices.astype(np.float64)[faces]
    n = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
    area = 0.5 * np.linalg.norm(n, axis=1)
    n /= (2 * area)[:, None]
    planes = np.round(np.column_stack([n, np.sum(n * c[:, 0], axis=1)]), 4) + 0.0
    return np.unique(planes, axis=0), float(area.sum())


def check_geometry(mi, scene: scenes.ReferenceScene) -> float:
    """Largest difference between the glTF box and mi.cornell_box(), surface by
    surface (Mitsuba merges the shapes that share a BSDF, so the triangles are
    compared in groups of equal reflectance and emission): sorted vertex
    positions, triangle planes with their facing, area, reflectance, radiance."""
    def group(pairs):
        groups: dict = {}
        for key, v, f in pairs:
            vs, fs = groups.setdefault(tuple(np.round(np.asarray(key, dtype=np.float64), 5).tolist()), ([], []))
            fs.append(np.asarray(f, dtype=np.int64) + sum(len(x) for x in vs))
            vs.append(np.asarray(v, dtype=np.float64))
        return {k: (np.concatenate(vs), np.concatenate(fs)) for k, (vs, fs) in groups.items()}

    ours = group((s.surface.base_color + s.surface.emission, s.vertices, s.faces) for s in scene.shapes)
    theirs = []
    for shape in anchor_scene(mi, 8, 8, 8).shapes():
        key = list(np.array(mi.traverse(shape.bsdf())["reflectance.value"]).ravel())
        emitter = shape.emitter()
        key += list(np.array(mi.traverse(emitter)["radiance.value"]).ravel()) if emitter is not None else [0.0] * 3
        theirs.append((key, np.array(shape.vertex_positions_buffer()).reshape(-1, 3),
                       np.array(shape.faces_buffer()).reshape(-1, 3)))
    theirs = group(theirs)
    if sorted(ours) != sorted(theirs):
        print(f"  surfaces differ: {sorted(ours)} against {sorted(theirs)}")
        return float("inf")
    worst = 0.0
    for key, (v, f) in ours.items():
        tv, tf = theirs[key]
        ours_v, theirs_v = np.unique(np.round(v, 5), axis=0), np.unique(np.round(tv, 5), axis=0)
        (ours_p, ours_a), (theirs_p, theirs_a) = triangle_planes(v, f), triangle_planes(tv, tf)
        if ours_v.shape != theirs_v.shape or ours_p.shape != theirs_p.shape:
            print(f"  surface {key}: {len(ours_v)} vertices, {len(ours_p)} planes against {len(theirs_v)}, "
                  f"{len(theirs_p)}")
            return float("inf")
        worst = max(worst, np.abs(ours_v - theirs_v).max(), np.abs(ours_p - theirs_p).max(), abs(ours_a - theirs_a))
    return worst


def run_check(mi, args) -> int:
    from tests.path_reference import MEAN_Z2_LIMIT, Z_LIMIT, block_z
    box = read_scene(scenes.CORNELL_BOX_FILE, (args.size, args.size))
    wide = scenes.View((0.3, 0.8, 3.2), (0.0, 0.4, 0.0), (0.0, 1.0, 0.0), 30.0, 64, 36)
    results = []

    def report(name, ok, text):
        results.append(ok)
        print(f"{'ok  ' if ok else 'FAIL'} {name}: {text}", flush=True)

    for label, view in (("square", box.view), ("16:9", wide)):
        angle = check_camera_rays(mi, view)
        report(f"camera rays, {label} {view.width}x{view.height}", angle < 1e-5,
               f"largest angle between Mitsuba's and clrt's pixel-centre rays {angle:.2e} rad")
    worst = check_footprint(mi)
    report("orientation and pixel convention", worst < 0.15,
           f"coverage of an upper-left triangle, 48x32 off-axis: largest difference {worst:.3f} (256 spp)")
    worst = check_geometry(mi, box)
    report("surfaces", worst < 1e-4, f"glTF triangles, reflectances and radiance against mi.cornell_box()'s: "
                                      f"largest difference {worst:.1e}")
    ours = mitsuba_scene(mi, box, args.max_depth)
    theirs = anchor_scene(mi, args.size, args.size, args.max_depth)
    a, va = batches(mi, ours, args.batches, args.batch_spp, 0, "glTF box")
    b, vb = batches(mi, theirs, args.batches, args.batch_spp, 10_000, "mi.cornell_box()")
    spp = args.batches * args.batch_spp
    z = block_z(a, va / spp, b, vb / spp)
    bias = a.mean(axis=(0, 1)) / b.mean(axis=(0, 1)) - 1
    report(f"render, max depth {args.max_depth}, {args.size}x{args.size}, {spp} spp each",
           np.abs(z).max() <= Z_LIMIT and np.mean(z ** 2) <= MEAN_Z2_LIMIT,
           f"8x8 blocks: max |z| {np.abs(z).max():.2f}, mean z^2 {np.mean(z ** 2):.3f}; whole-image ratio - 1 RGB "
           + " ".join(f"{100 * x:+.3f}%" for x in bias))
    return 0 if all(results) else 1


# ---------------------------------------------------------------------------
# reference and render


def run_reference(mi, args) -> int:
    scene = read_scene(scenes.CORNELL_BOX_FILE, (args.size, args.size))
    count = args.spp // args.batch_spp
    arrays, started = {}, time.perf_counter()
    for depth in args.depths:
        mean, var = batches(mi, mitsuba_scene(mi, scene, depth), count, args.batch_spp, 0, f"max depth {depth}")
        arrays[f"image_d{depth}"] = mean.astype(np.float16)
        arrays[f"std_d{depth}"] = np.sqrt(var).astype(np.float16)
    meta = {"scene": str(scenes.CORNELL_BOX_FILE.relative_to(scenes.ROOT)),
            "scene_sha256": hashlib.sha256(scenes.CORNELL_BOX_FILE.read_bytes()).hexdigest(),
            "renderer": f"Mitsuba {mi.__version__}", "variant": mi.variant(),
            "integrator": "path (rr_depth 5, Mitsuba's defaults)", "max_depths": list(args.depths),
            "film": "hdrfilm, box filter", "sampler": "independent", "width": args.size, "height": args.size,
            "spp": count * args.batch_spp, "batches": count, "batch_spp": args.batch_spp,
            "seeds": f"0..{count - 1}", "layout": IMAGE_LAYOUT,
            "arrays": "image_dD: mean (float16); std_dD: standard deviation of one path's estimate (float16), "
                      "from the spread of the batches",
            "command": reference_command(args), "drjit": drjit_version(),
            "libllvm": os.environ.get("DRJIT_LIBLLVM_PATH") if mi.variant().startswith("llvm") else None,
            "seconds": round(time.perf_counter() - started), "date": time.strftime("%Y-%m-%d")}
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.stem + ".tmp.npz")
    np.savez_compressed(tmp, meta=np.array(json.dumps(meta)), **arrays)
    tmp.replace(out)
    print(f"wrote {out} ({out.stat().st_size} bytes) in {meta['seconds']} s")
    return 0


def reference_command(args) -> str:
    """The command that makes the reference again, every option spelled out."""
    out = Path(args.out).resolve()
    out = out.relative_to(scenes.ROOT) if out.is_relative_to(scenes.ROOT) else out
    return (f"python -m benchmarks.mitsuba_reference --variant {args.variant} reference --size {args.size} "
            f"--spp {args.spp} --batch-spp {args.batch_spp} --depths {' '.join(map(str, args.depths))} --out {out}")


def drjit_version() -> str:
    import drjit
    return drjit.__version__


def run_render(mi, args) -> int:
    width, height = args.size or DEFAULT_SIZES[args.scene]
    if args.scene == "mitsuba-cornell-box":
        scene = anchor_scene(mi, width, height, args.max_depth, args.spp)
    else:
        path = Path(args.file) if args.file else SCENE_FILES[args.scene]
        if not path.is_file():
            sys.exit(f"{path} not found: write it with python -m benchmarks.scenes")
        scene = mitsuba_scene(mi, read_scene(path, (width, height)), args.max_depth, args.spp)
    image = render(mi, scene, args.spp, 0)   # warm-up: the JIT compiles here
    times = []
    for run in range(args.runs):
        started = time.perf_counter()
        image = render(mi, scene, args.spp, run + 1)
        times.append(time.perf_counter() - started)
    best = min(times)
    print(f"{args.scene} {width}x{height}, {args.spp} spp, max depth {args.max_depth}, {mi.variant()}: "
          f"median {1e3 * float(np.median(times)):.0f} ms, best {1e3 * best:.0f} ms, "
          f"{width * height * args.spp / float(np.median(times)) / 1e6:.1f} Msamples/s (median)")
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        stem = out / f"{args.scene}-{width}x{height}-{args.spp}spp-d{args.max_depth}"
        np.save(stem.with_suffix(".npy"), image.astype(np.float32))
        mi.Bitmap(image.astype(np.float32)).write(str(stem.with_suffix(".exr")))
        print(f"wrote {stem}.exr and .npy")
    return 0


def parse_size(text: str) -> tuple[int, int]:
    """argparse type for 'WxH' (benchmarks.common's needs clrt's OpenCL imports, absent here)."""
    import argparse
    try:
        width, height = (int(x) for x in text.lower().split("x"))
    except ValueError:
        width = height = 0
    if width < 1 or height < 1:
        raise argparse.ArgumentTypeError(f"expected WxH with positive integers, got {text!r}")
    return width, height


def main(argv=None) -> int:
    import argparse

    argv = sys.argv[1:] if argv is None else list(argv)
    p = argparse.ArgumentParser(prog="python -m benchmarks.mitsuba_reference", description=__doc__.split("\n")[0])
    p.add_argument("--variant", default="llvm_ad_rgb",
                   help="Mitsuba variant (default llvm_ad_rgb; cuda_ad_rgb on a GPU)")
    sub = p.add_subparsers(dest="command", required=True)
    c = sub.add_parser("check", help="the glTF Cornell box, camera and pixel convention against Mitsuba's own")
    c.add_argument("--size", type=int, default=64, help="image side of the render check (default 64)")
    c.add_argument("--max-depth", type=int, default=8, help="of the render check (default 8)")
    c.add_argument("--batches", type=int, default=16, help="independent renders of each box (default 16)")
    c.add_argument("--batch-spp", type=int, default=1024, help="spp of each (default 1024)")
    r = sub.add_parser("reference", help="the converged Cornell box of the tests (tests/data)")
    r.add_argument("--size", type=int, default=64, help="image side (default 64)")
    r.add_argument("--spp", type=int, default=65536, help="paths per pixel in all (default 65536)")
    r.add_argument("--batch-spp", type=int, default=1024, help="paths per pixel of one batch (default 1024)")
    r.add_argument("--depths", type=int, nargs="+", default=[2, 3, 8], help="max depths (default 2 3 8)")
    r.add_argument("--out", default=str(REFERENCE_FILE), help="npz file (default tests/data/cornell-box-mitsuba.npz)")
    t = sub.add_parser("render", help="time Mitsuba on a scene and write its image")
    t.add_argument("--scene", choices=sorted(DEFAULT_SIZES), default="cornell-box",
                   help="the glTF Cornell box, mi.cornell_box() itself, or the bunny (default cornell-box)")
    t.add_argument("--file", help="the scene's glTF file (default: where benchmarks.scenes writes it)")
    t.add_argument("--size", type=parse_size, help="WxH (default 1024x1024 for the boxes, 1920x1080 for the bunny)")
    t.add_argument("--spp", type=int, default=64, help="paths per pixel (default 64)")
    t.add_argument("--max-depth", type=int, default=8, help="Mitsuba's max_depth (default 8)")
    t.add_argument("--runs", type=int, default=3, help="timed renders after one warm-up (default 3)")
    t.add_argument("--out", help="folder for the last render's EXR and .npy (default: none written)")
    args = p.parse_args(argv)
    for name in ("batches", "batch_spp", "spp", "runs", "size"):
        value = getattr(args, name, None)
        if isinstance(value, int) and value < 1:
            p.error(f"--{name.replace('_', '-')} must be at least 1")
    if args.command == "reference" and args.spp % args.batch_spp:
        p.error("--spp must be a multiple of --batch-spp")
    mi = start_mitsuba(args.variant)
    return {"check": run_check, "reference": run_reference, "render": run_render}[args.command](mi, args)


if __name__ == "__main__":
    sys.exit(main())
