"""Command line: ``clrt render`` and ``clrt info`` (also ``python -m clrt``).

Every error a user can cause ends as one line on stderr, ``clrt: <what went
wrong>``, and a non-zero exit: 2 for bad input, 3 for OpenCL trouble.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
from pathlib import Path

from clrt import checks, config
from clrt.errors import ClrtError, DeviceError, InputError, OutputError

DEFAULT_OUTPUT = "clrt-default.png"
_ACCEL_WORDS = {"box": "boxes", "sphere": "spheres", "ellipse": "ellipsoids"}


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line and exit code 2."""

    def error(self, message):
        raise InputError(f"{message} (see {self.prog} --help)")


# Option types.  Each parses the text and checks the value with clrt.checks under
# the option's name, so the CLI says what the Python API and scene files say:
# "--width must be an integer in 1..65536, got 0".

def _number_text(text: str):
    """'3' -> 3, '2.5' -> 2.5, anything else stays text (the check then names it)."""
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def _vector_text(text: str):
    values = [_number_text(x.strip()) for x in text.split(",")]
    return tuple(values) if all(checks.is_number(v) for v in values) else text


def _typed(check, parse=_number_text):
    """argparse type: ``check(parse(text))``; the check raises InputError itself."""
    def convert(text: str):
        return check(parse(text))
    return convert


def _integer(name: str, lo: int, hi: int | None = None):
    return _typed(lambda v: checks.integer(name, v, lo, hi))


def _number(name: str, **limits):
    return _typed(lambda v: checks.number(name, v, **limits))


def _vector(name: str, check=checks.position):
    return _typed(lambda v: check(name, v), _vector_text)


def _device(text: str) -> str:
    return checks.device(text, "--device")


_MATERIAL_OPTIONS = ("color", "ambient", "diffuse", "specular", "shininess", "crease")


def _parser(bench: bool = False) -> argparse.ArgumentParser:
    """The CLI's parser; ``bench`` adds the real ``clrt bench`` options (the
    benchmark package is imported only for that command)."""
    from clrt import __version__
    p = _Parser(prog="clrt", description="Ray trace triangle meshes with OpenCL.")
    p.add_argument("--version", action="version", version=f"clrt {__version__}")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    r = sub.add_parser("render", help="render a mesh (or the built-in scene) to an image",
                       description="Render MESH (OBJ, PLY, OFF, STL, GLB/GLTF, 3DS), a TOML scene file "
                                   "(docs/scene-files.md) or, with no argument, the built-in scene. "
                                   "Options override the scene: camera and render options replace the "
                                   "scene's, material options replace that field of every object's "
                                   "material. Prints the output path (absolute).")
    r.add_argument("mesh", nargs="?", help="mesh file or TOML scene file; omit for the built-in scene")
    formats = ", ".join(config.IMAGE_FORMATS)
    r.add_argument("-o", "--output", help=f"image to write ({formats}; default: MESH name .png, or "
                                          f"{DEFAULT_OUTPUT}); an existing file is replaced only once the "
                                          "render succeeded, and only if clrt wrote it (see --force)")
    r.add_argument("-f", "--force", action="store_true",
                   help="replace the output even if clrt did not write it (by default an existing "
                        "file is replaced only if clrt wrote it, such as the previous render)")
    side = f"1..{config.MAX_IMAGE_SIDE}"
    r.add_argument("--width", type=_integer("--width", 1, config.MAX_IMAGE_SIDE),
                   help=f"image width in pixels, {side} (default: the scene's, else {config.DEFAULT_WIDTH})")
    r.add_argument("--height", type=_integer("--height", 1, config.MAX_IMAGE_SIDE),
                   help=f"image height in pixels, {side} (default: the scene's, else {config.DEFAULT_HEIGHT})")
    r.add_argument("--eye", type=_vector("--eye"), help="camera position x,y,z (default: the file's camera, "
                                                       "else framed from the bounds)")
    r.add_argument("--target", type=_vector("--target"), help="point looked at (default: centre of the bounds)")
    r.add_argument("--up", type=_vector("--up"), help="up vector (default 0,1,0)")
    r.add_argument("--fov", type=_typed(lambda v: checks.fov(v, "--fov")),
                   help=f"vertical field of view in degrees, > 0 and < 180 (default {config.DEFAULT_FOV:g})")
    r.add_argument("--light", type=_vector("--light"), action="append", metavar="X,Y,Z",
                   help="point light position; repeat for more lights (default: the scene's, else one "
                        "above the eye)")
    r.add_argument("--color", type=_vector("--color", checks.color),
                   help="material colour r,g,b, linear 0..1 (default .8,.8,.8); like every material "
                        "option it replaces that field of every object's material")
    r.add_argument("--ambient", type=_number("--ambient", ge=0),
                   help=f"ambient coefficient (default {config.DEFAULT_AMBIENT:g})")
    r.add_argument("--diffuse", type=_number("--diffuse", ge=0),
                   help=f"diffuse coefficient (default {config.DEFAULT_DIFFUSE:g})")
    r.add_argument("--specular", type=_number("--specular", ge=0),
                   help=f"specular coefficient (default {config.DEFAULT_SPECULAR:g})")
    r.add_argument("--shininess", type=_number("--shininess", ge=0),
                   help=f"Phong exponent (default {config.DEFAULT_SHININESS:g})")
    r.add_argument("--flat", action="store_true", help="flat shading (no vertex-normal interpolation)")
    r.add_argument("--crease", type=_typed(lambda v: checks.crease(v, "--crease")), metavar="DEG",
                   help="smooth shading keeps edges whose faces meet at more than DEG degrees sharp "
                        f"(0..180; default {config.DEFAULT_CREASE_ANGLE:g}; 180 smooths every edge)")
    r.add_argument("--background", type=_vector("--background", checks.intensity),
                   help="background colour r,g,b, linear, >= 0 (default: the scene's, else black)")
    r.add_argument("--samples", type=_typed(lambda v: checks.samples(v, "--samples")),
                   help=f"anti-aliasing: N x N rays per pixel, 1..{config.MAX_SAMPLES} (default: the "
                        "scene's; 1 for a mesh, 2 for the built-in scene)")
    r.add_argument("--max-depth", type=_typed(lambda v: checks.max_depth(v, "--max-depth")),
                   help=f"reflection/refraction bounces, 0..{config.MAX_BOUNCES} (default: the scene's, "
                        f"{config.DEFAULT_MAX_DEPTH})")
    r.add_argument("--device", type=_device, help="'gpu', 'cpu' or P:D platform/device indices (default: "
                                                  "PYOPENCL_CTX, else the first GPU, else the first CPU)")
    _accel_options(r)
    r.add_argument("--aov", type=_aov_list, metavar="NAMES",
                   help="also write per-pixel images, comma-separated: depth (along the view axis), "
                        "distance (along the ray), normal, prim (triangle index), hit, front; each as "
                        "OUT.NAME.npy (the values; inf / -1 / 0 where nothing is hit) and OUT.NAME.png "
                        "(a picture of them); see docs/ray-queries.md")
    r.add_argument("-q", "--quiet", action="store_true", help="print only the output path")

    i = sub.add_parser("info", help="list OpenCL devices; with MESH, build statistics of its BVH",
                       description="Without MESH: OpenCL platforms and devices, '*' marking the one "
                                   "clrt would use. With MESH: statistics of the acceleration build "
                                   "for the device clrt would use (or --device).")
    i.add_argument("mesh", nargs="?", help="mesh file to build a BVH for")
    i.add_argument("--device", type=_device, help="device to use (same forms as render --device)")
    _accel_options(i)

    if bench:
        from clrt.bench.paper import add_bench_parser
        add_bench_parser(sub)
    else:
        sub.add_parser("bench", help="rerun the paper's timing and detail-loss experiments on this machine",
                       add_help=False)
    return p


def _aov_list(text: str) -> tuple:
    from clrt.query.aov import parse_aovs
    return parse_aovs(text)


def _accel_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--accel", default=config.DEFAULT_ACCEL, type=_typed(
        lambda v: checks.choice("--accel", v, config.ACCELS), str),
        help=f"BVH bounding-volume shape ({', '.join(config.VOLUMES)}), or none for brute force "
             f"(default {config.DEFAULT_ACCEL})")
    p.add_argument("--builder", default=config.DEFAULT_BUILDER, type=_typed(
        lambda v: checks.choice("--builder", v, config.BUILDERS), str),
        help=f"BVH builder: paper (the paper's median split), sah (binned SAH; default "
             f"{config.DEFAULT_BUILDER}) or device (PLOC on the OpenCL device)")
    p.add_argument("--leaf-size", default=config.DEFAULT_LEAF_SIZE,
                   type=_integer("--leaf-size", 1, config.MAX_LEAF_SIZE),
                   help=f"most triangles per BVH leaf, 1..{config.MAX_LEAF_SIZE} (default {config.DEFAULT_LEAF_SIZE})")


def _output_path(args) -> Path:
    """The image to write, checked before any work: a writable file of a format clrt writes."""
    if args.output is not None:
        if not args.output.strip():
            raise OutputError("-o must name an image file, got ''")
        out = Path(args.output)
        if out.is_dir():
            raise OutputError(f"cannot write {args.output}: it is a folder (give a file name, e.g. "
                              f"{out / 'image.png'})")
        if args.output.endswith(("/", os.sep)):
            raise OutputError(f"cannot write {args.output}: names a folder (ends with '/'), and there is "
                              "no such folder")
    elif args.mesh:
        out = Path(Path(args.mesh).stem + ".png")
    else:
        out = Path(DEFAULT_OUTPUT)
    if out.suffix.lower() not in config.IMAGE_FORMATS:
        kind = f"unknown image type {out.suffix!r}" if out.suffix else "no image type suffix"
        raise OutputError(f"cannot write {out}: {kind} (use one of {', '.join(config.IMAGE_FORMATS)})")
    if not out.parent.is_dir():
        raise OutputError(f"cannot write {out}: folder {out.parent} does not exist")
    if not os.access(out.parent, os.W_OK):
        raise OutputError(f"cannot write {out}: no permission to create files in {out.parent}")
    return out


def _render(args) -> int:
    from clrt.output import check_replace, write_image
    from clrt.renderer import Renderer, check_host_memory
    from clrt.scene.sources import as_scene
    from clrt.scene.default import default_scene
    from clrt.scene.scene import Camera, Light, default_light

    out = _output_path(args)
    scene = as_scene(args.mesh) if args.mesh else default_scene()
    from_file = bool(args.mesh) and not scene.camera_framed   # a scene file's or a glTF camera
    if not (args.mesh or "").lower().endswith(".toml") and args.mesh:
        scene.lights = []   # a mesh: the default light is placed below, from the final camera
    # Material options replace that field of every object's material (documented in README).
    scene.override_materials(smooth=False if args.flat else None,
                             **{k: getattr(args, k) for k in _MATERIAL_OPTIONS})
    if args.background is not None:
        scene.background = args.background
    if args.samples is not None:
        scene.samples = args.samples
    if args.max_depth is not None:
        scene.max_depth = args.max_depth

    # Options override the scene's camera; what neither gives is framed from the bounds.
    bounds, base = scene.bounds, scene.camera
    width = args.width if args.width is not None else (base.width if base else config.DEFAULT_WIDTH)
    height = args.height if args.height is not None else (base.height if base else config.DEFAULT_HEIGHT)
    fov = args.fov if args.fov is not None else (base.fov if base else config.DEFAULT_FOV)
    up = args.up or (base.up if base else config.DEFAULT_UP)
    placed = base if base is not None and not scene.camera_framed else None   # by the user or the file
    if args.eye is None and args.target is None and placed is not None:
        eye, target = placed.eye, placed.target
    else:   # frame for the final size, fov and up
        from_file = False
        framed = Camera.framing(bounds, width, height, fov, up=up)
        target = args.target or (placed.target if placed else framed.target)
        eye = args.eye or (placed.eye if placed else tuple(
            t + e - f for t, e, f in zip(target, framed.eye, framed.target)))
    camera = Camera(eye, target, up, fov, width, height)
    if args.light:
        scene.lights = [Light(p) for p in args.light]
    elif not scene.lights:
        scene.lights = [default_light(bounds, camera)]

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
        accel = "brute force" if args.accel == "none" else f"{args.builder} BVH of {_ACCEL_WORDS[args.accel]}"
        view = f", camera from {args.mesh}" if from_file else ""
        print(f"{camera.width}x{camera.height} pixels, {frame.triangles:,} triangles, "
              f"{len(scene.lights)} light(s), {accel}{view}, device: {frame.device}")
        for stage, ms in frame.timings.items():
            print(f"  {stage:<20} {ms:10.2f} ms")
        if args.aov:
            print("  AOVs: " + " ".join(str(p.resolve()) for p in aov_files))
    print(out.resolve())
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
    from clrt.device.build import build_acceleration
    from clrt.device.context import device_label, select_device
    from clrt.scene.arrays import triangle_corners
    from clrt.scene.load import load_mesh

    mesh = load_mesh(args.mesh)
    device = select_device(args.device)   # as render would: a missing device is exit 3, not ignored
    built = build_acceleration(triangle_corners(mesh), args.accel, args.builder, args.leaf_size, args.device)
    print(f"{args.mesh}: {len(mesh.faces):,} triangles, {len(mesh.vertices):,} vertices; "
          f"device: {device_label(device)}")
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
        # The heavy imports first, still under the start-up handler that
        # clrt/__init__.py installs for the clrt command (Ctrl-C there exits at
        # once: a KeyboardInterrupt inside a C extension's import can abort the
        # interpreter).  Ctrl-C from then on is KeyboardInterrupt, caught below;
        # the handler is set inside the try, so a signal already pending lands here.
        if argv[:1] in (["render"], ["info"]):
            import pyopencl  # noqa: F401
            import clrt.renderer  # noqa: F401
        signal.signal(signal.SIGINT, signal.default_int_handler)
        bench = argv[:1] == ["bench"]
        try:
            args = _parser(bench).parse_args(_glue_vector_values(argv))
        except SystemExit as exc:   # --help, --version: argparse printed them
            return exc.code if isinstance(exc.code, int) else 0
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
