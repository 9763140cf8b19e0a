"""Command line: ``clrt render`` and ``clrt info`` (also ``python -m clrt``).

Every error a user can cause ends as one line on stderr, ``clrt: <what went
wrong>``, and a non-zero exit: 2 for bad input, 3 for OpenCL trouble.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

from clrt.config import ACCELS, BUILDERS, DEFAULT_ACCEL, DEFAULT_BUILDER, DEFAULT_LEAF_SIZE
from clrt.errors import ClrtError, DeviceError, InputError, OutputError
from clrt.output import check_replace, write_image

DEFAULT_OUTPUT = "clrt-default.png"


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line and exit code 2."""

    def error(self, message):
        raise InputError(f"{self.prog}: {message} (see --help)")


def _vector(text: str) -> tuple:
    try:
        values = tuple(float(x) for x in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 3 or not all(np.isfinite(values)):
        raise argparse.ArgumentTypeError(f"expected three numbers x,y,z, got {text!r}")
    return values


def _parser(bench: bool = False) -> argparse.ArgumentParser:
    """The CLI's parser; ``bench`` adds the real ``clrt bench`` options (the
    benchmark package is imported only for that command)."""
    p = _Parser(prog="clrt", description="Ray trace triangle meshes with OpenCL.")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    r = sub.add_parser("render", help="render a mesh (or the built-in scene) to an image",
                       description="Render MESH (OBJ, PLY, OFF, STL, GLB/GLTF, 3DS), a TOML scene file "
                                   "(docs/scene-files.md) or, with no argument, the built-in scene. "
                                   "Options override the scene file. Prints the output path.")
    r.add_argument("mesh", nargs="?", help="mesh file or TOML scene file; omit for the built-in scene")
    r.add_argument("-o", "--output", help=f"image to write (default: MESH name .png, or {DEFAULT_OUTPUT}); "
                                          "an existing file is replaced only once the render succeeded, "
                                          "and only if clrt wrote it (see --force)")
    r.add_argument("-f", "--force", action="store_true",
                   help="replace the output even if clrt did not write it (by default an existing "
                        "file is replaced only if it is an image clrt wrote, such as the previous render)")
    r.add_argument("--width", type=int, help="image width in pixels (default: the scene file's, else 640)")
    r.add_argument("--height", type=int, help="image height in pixels (default: the scene file's, else 480)")
    r.add_argument("--eye", type=_vector, help="camera position x,y,z (default: framed from the bounds)")
    r.add_argument("--target", type=_vector, help="point looked at (default: centre of the bounds)")
    r.add_argument("--up", type=_vector, help="up vector (default 0,1,0)")
    r.add_argument("--fov", type=float, help="vertical field of view in degrees (default 45)")
    r.add_argument("--light", type=_vector, action="append", metavar="X,Y,Z",
                   help="point light position; repeat for more lights (default: one above the eye)")
    r.add_argument("--color", type=_vector, help="material colour r,g,b, linear 0..1 (default .8,.8,.8)")
    r.add_argument("--ambient", type=float, help="ambient coefficient (default 0.1)")
    r.add_argument("--diffuse", type=float, help="diffuse coefficient (default 0.7)")
    r.add_argument("--specular", type=float, help="specular coefficient (default 0.3)")
    r.add_argument("--shininess", type=float, help="Phong exponent (default 32)")
    r.add_argument("--flat", action="store_true", help="flat shading (no vertex-normal interpolation)")
    r.add_argument("--background", type=_vector, help="background colour r,g,b, linear 0..1")
    r.add_argument("--samples", type=int, help="anti-aliasing: N x N rays per pixel (default: the scene's; "
                                               "1 for a mesh, 2 for the built-in scene)")
    r.add_argument("--max-depth", type=int, help="reflection/refraction bounces (default: the scene's, 5)")
    r.add_argument("--device", help="'gpu', 'cpu' or P:D platform/device indices (default: PYOPENCL_CTX, "
                                    "else the first GPU, else the first CPU)")
    _accel_options(r)
    r.add_argument("--aov", type=_aov_list, metavar="NAMES",
                   help="also write per-pixel images, comma-separated: depth (along the view axis), "
                        "distance (along the ray), normal, prim (triangle index), hit, front; each as "
                        "OUT.NAME.npy (the values; inf / -1 / 0 where nothing is hit) and OUT.NAME.png "
                        "(a picture of them); see docs/ray-queries.md")
    r.add_argument("-q", "--quiet", action="store_true", help="print only the output path")

    i = sub.add_parser("info", help="list OpenCL devices; with MESH, build statistics of its BVH",
                       description="Without MESH: OpenCL platforms and devices, '*' marking the one "
                                   "clrt would use. With MESH: statistics of the acceleration build.")
    i.add_argument("mesh", nargs="?", help="mesh file to build a BVH for")
    i.add_argument("--device", help="device to mark as selected (same forms as render --device)")
    _accel_options(i)

    sub.add_parser("batch", help="render many sources and views on a Dask cluster (docs/distributed.md)",
                   add_help=False)   # its options: clrt/batch/cli.py

    if bench:
        from clrt.bench.paper import add_bench_parser
        add_bench_parser(sub)
    else:
        sub.add_parser("bench", help="rerun the paper's timing and detail-loss experiments on this machine",
                       add_help=False)
    return p


def _aov_list(text: str) -> tuple:
    from clrt.query.aov import parse_aovs
    try:
        return parse_aovs(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _accel_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--accel", default=DEFAULT_ACCEL, choices=ACCELS,
                   help=f"BVH bounding-volume shape, or none for brute force (default {DEFAULT_ACCEL})")
    p.add_argument("--builder", default=DEFAULT_BUILDER, choices=BUILDERS,
                   help=f"BVH builder: the paper's median split, or binned SAH (default {DEFAULT_BUILDER})")
    p.add_argument("--leaf-size", type=int, default=DEFAULT_LEAF_SIZE,
                   help=f"most triangles per BVH leaf (default {DEFAULT_LEAF_SIZE})")


def _output_path(args) -> Path:
    if args.output:
        out = Path(args.output)
    elif args.mesh:
        out = Path(Path(args.mesh).stem + ".png")
    else:
        out = Path(DEFAULT_OUTPUT)
    from PIL import Image
    if out.suffix.lower() not in Image.registered_extensions():
        raise OutputError(f"cannot write {out}: unknown image type {out.suffix!r} (use .png)")
    if Image.registered_extensions()[out.suffix.lower()] not in Image.SAVE:
        raise OutputError(f"cannot write {out}: {out.suffix} images can be read but not written (use .png)")
    if not out.parent.is_dir():
        raise OutputError(f"cannot write {out}: folder {out.parent} does not exist")
    if out.is_dir():
        raise OutputError(f"cannot write {out}: it is a folder")
    if not os.access(out.parent, os.W_OK):
        raise OutputError(f"cannot write {out}: no permission to create files in {out.parent}")
    return out


def _render(args) -> int:
    from clrt.renderer import Renderer, check_host_memory
    from clrt.scene.render_setup import (CAMERA_OPTIONS, SCENE_OPTIONS, render_camera, render_lights,
                                         render_scene)

    out = _output_path(args)
    # Shared with `clrt batch render`, so both make the same frame of the same camera.
    scene = render_scene(args.mesh, **{k: getattr(args, k) for k in SCENE_OPTIONS})
    camera = render_camera(scene, **{k: getattr(args, k) for k in CAMERA_OPTIONS})
    scene.lights = render_lights(scene.bounds, camera, scene.lights, args.light)

    # Checked before the (possibly long) render; the writers check again.
    check_replace(out, args.force)
    if args.aov:
        from clrt.query.aov import aov_paths
        for path in aov_paths(out, args.aov):
            check_replace(path, args.force)
    # The image, its sRGB staging and PIL's copy (4 bytes a pixel) live on the host together.
    check_host_memory(camera.width * camera.height * 10, f"a {camera.width}x{camera.height} image")
    renderer = Renderer(scene, args.device, args.accel, args.builder, args.leaf_size)
    frame = renderer.render(camera)
    write_image(frame.image, out, force=args.force)
    if args.aov:
        from clrt.query.aov import write_aovs
        aov_files = write_aovs(renderer, camera, args.aov, out, force=args.force)
    if not args.quiet:
        accel = "brute force" if args.accel == "none" else f"{args.builder} BVH of {args.accel}es"
        print(f"{camera.width}x{camera.height} pixels, {frame.triangles:,} triangles, "
              f"{len(scene.lights)} light(s), {accel}, device: {frame.device}")
        for stage, ms in frame.timings.items():
            print(f"  {stage:<20} {ms:10.2f} ms")
        if args.aov:
            print("  AOVs: " + " ".join(str(p) for p in aov_files))
    print(out.resolve() if not args.quiet else out)
    return 0


def _info(args) -> int:
    from clrt.device.context import describe_devices, list_devices
    if args.mesh:
        return _info_mesh(args)
    print(describe_devices(args.device))
    if not list_devices():
        return DeviceError.exit_code
    return 0


def _info_mesh(args) -> int:
    """Build statistics of the acceleration structure over MESH, and its size on the device."""
    from clrt import accel
    from clrt.scene.arrays import triangle_corners
    from clrt.scene.load import load_mesh

    mesh = load_mesh(args.mesh)
    built = accel.build(triangle_corners(mesh), args.accel, args.builder, args.leaf_size)
    print(f"{args.mesh}: {len(mesh.faces):,} triangles, {len(mesh.vertices):,} vertices")
    if not built.is_bvh:
        print(f"accel none: brute force, {built.device_bytes():,} bytes on the device")
        return 0
    print(f"accel {args.accel}, builder {args.builder}, leaf size {args.leaf_size}:")
    stats = built.stats()
    for key, value in stats.items():
        text = f"{value:,.3f}" if isinstance(value, float) else f"{value:,}"
        print(f"  {key:<22} {text}")
    return 0


_VECTOR_OPTIONS = {"--eye", "--target", "--up", "--light", "--color", "--background"}


def _glue_vector_values(argv: list[str]) -> list[str]:
    """``--eye -1,2,3`` -> ``--eye=-1,2,3``: argparse would take ``-1,2,3`` for an option."""
    out, i = [], 0
    while i < len(argv):
        if argv[i] in _VECTOR_OPTIONS and i + 1 < len(argv):
            out.append(f"{argv[i]}={argv[i + 1]}")
            i += 2
        else:
            out.append(argv[i])
            i += 1
    return out


def main(argv=None) -> int:
    try:
        argv = list(sys.argv[1:] if argv is None else argv)
        if argv[:1] == ["batch"]:
            from clrt.batch.cli import main as batch_main
            return batch_main(argv[1:])
        bench = argv[:1] == ["bench"]
        args = _parser(bench).parse_args(_glue_vector_values(argv))
        if bench:
            from clrt.bench.paper import run_bench
            return run_bench(args)
        return {"render": _render, "info": _info}[args.command](args)
    except ClrtError as exc:
        print(f"clrt: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("clrt: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:   # output piped into e.g. head, which stopped reading
        sys.stderr = open(os.devnull, "w")
        return 1
    except Exception as exc:  # noqa: BLE001 -- driver errors arrive as many types
        import pyopencl as cl
        if isinstance(exc, (cl.Error, MemoryError)):
            print(f"clrt: OpenCL error: {exc}".splitlines()[0], file=sys.stderr)
            return DeviceError.exit_code
        raise


if __name__ == "__main__":
    sys.exit(main())
