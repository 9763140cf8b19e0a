"""Command line: ``clrt render`` and ``clrt info`` (also ``python -m clrt``).

Every error a user can cause ends as one line on stderr, ``clrt: <what went
wrong>``, and a non-zero exit: 2 for bad input, 3 for OpenCL trouble.  What
clrt went on without (:class:`clrt.errors.ClrtWarning`, e.g. an OBJ's missing
texture) is one line too: ``clrt: warning: <what>``.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
import time
import warnings
from pathlib import Path

from clrt import config, options, output
from clrt.errors import ClrtError, ClrtWarning, DeviceError, InputError, OutputError

DEFAULT_OUTPUT = options.DEFAULT_OUTPUT


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line and exit code 2."""

    def error(self, message):
        raise InputError(f"{message} (see {self.prog} --help)")


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
    options.add_options(r, options.RENDER)   # the table of clrt/options.py, which clrt.render takes too

    i = sub.add_parser("info", help="list OpenCL devices; with MESH, build statistics of its BVH",
                       description="Without MESH: OpenCL platforms and devices, '*' marking the one "
                                   "clrt would use. With MESH: statistics of the acceleration build "
                                   "for the device clrt would use (or --device).")
    i.add_argument("mesh", nargs="?", help="mesh file to build a BVH for")
    options.add_options(i, options.INFO)

    sub.add_parser("batch", help="render many sources and views on a Dask cluster (docs/distributed.md)",
                   add_help=False)   # its options: clrt/batch/cli.py

    if bench:
        from clrt.bench.paper import add_bench_parser
        add_bench_parser(sub)
    else:
        sub.add_parser("bench", help="rerun the paper's timing and detail-loss experiments on this machine",
                       add_help=False)
    return p


def _output_path(args) -> tuple[Path, output.Writer, str]:
    """The image to write, its writer and depth (clrt.output.render_writer),
    checked before any work: a writable file of a format that holds the image
    asked for (--bit-depth), its optional package installed."""
    if args.output is not None:
        if not args.output.strip():
            raise OutputError(f"-o must name an image file, got {args.output!r}")
        out = Path(args.output)
        if out.is_dir():
            raise OutputError(f"cannot write {args.output}: it is a folder (give a file name, e.g. "
                              f"{out / 'image'}{output.WRITERS['png'].suffix})")
        if args.output.endswith(("/", os.sep)):
            raise OutputError(f"cannot write {args.output}: names a folder (ends with '/'), and there is "
                              "no such folder")
    elif args.mesh:
        out = Path(Path(args.mesh).stem + output.WRITERS["png"].suffix)
    else:
        out = Path(DEFAULT_OUTPUT)
    writer, depth = output.render_writer(out, args.bit_depth)   # an optional package missing: said before any work
    if not out.parent.is_dir():
        raise OutputError(f"cannot write {out}: folder {out.parent} does not exist")
    if not os.access(out.parent, os.W_OK):
        raise OutputError(f"cannot write {out}: no permission to create files in {out.parent}")
    return out, writer, depth


#: Host bytes a pixel that writing an image of each depth needs at once: the
#: 8-bit image, its sRGB staging and PIL's copy; for 16-bit the float32 image,
#: the uint16 one and the PNG rows; for float (.exr) the float32 image, its
#: channels and OpenEXR's copy of them (12 bytes a pixel each).
_HOST_BYTES = {"8-bit": 10, "16-bit": 40, "float": 36}


def _render(args) -> int:
    from clrt.renderer import Renderer, check_host_memory
    from clrt.renderer.path import file_image, path_channels
    from clrt.renderer.tiles import TileLimits
    from clrt.scene.render_setup import render_frame

    out, writer, depth = _output_path(args)
    # The frame clrt.render draws for the same options (and `clrt batch render` for its first view).
    scene, camera = render_frame(args.mesh, labels=options.FLAGS,
                                 **options.values(args, options.SCENE, options.CAMERA, options.LIGHTS))
    path = scene.integrator == "path"
    # A scene file's or a glTF file's camera, unless an option places the camera.
    from_file = bool(args.mesh) and not scene.camera_framed and args.eye is None and args.target is None

    # Checked before the (possibly long) render; the writers check again.
    output.check_replace(out, args.force)
    # A format that holds named channels (.exr) gets the AOVs as channels rather than files beside it.
    aovs_inside = writer.holds(channels="named")
    if args.aov and not aovs_inside:
        from clrt.query.aov import aov_paths
        for aov_path in aov_paths(out, args.aov):
            output.check_replace(aov_path, args.force)
    check_host_memory(camera.width * camera.height * _HOST_BYTES[depth], f"a {camera.width}x{camera.height} image")
    samples = (scene.spp or config.DEFAULT_SPP) if path else scene.samples ** 2
    progress = None if args.quiet else _progress_bar(camera.width * camera.height * samples)
    # With a progress bar the first tile is small, so that the bar moves from the start.
    limits = TileLimits(first_launch_pixels=config.PROGRESS_FIRST_TILE) if progress else None
    renderer = Renderer(scene, **options.values(args, options.RENDERER), limits=limits)
    try:
        # 8-bit: the kernel's own sRGB encoding; 16-bit and float: made of the linear image.
        with _warnings_as_lines():
            frame = renderer.render(camera, linear=depth != "8-bit", progress=progress and progress.update)
    finally:
        if progress:
            progress.close()
    aov_note = ""
    image = file_image(frame, depth, scene.exposure)
    if aovs_inside:
        channels = path_channels(frame)   # the path tracer's guides for denoisers: first hits' albedo, normal
        if args.aov:
            from clrt.query.aov import camera_images_of, exr_channels
            channels.update(exr_channels(camera_images_of(renderer, camera), args.aov))
        output.write_image(image, out, force=args.force, bit_depth=args.bit_depth, channels=channels)
        aov_note = f"channels {' '.join(channels)} of {out.name}"
    else:
        aov_images = None
        if args.aov:   # traced before any file is written, so that Ctrl-C there leaves nothing
            from clrt.query.aov import camera_images_of, write_aovs
            aov_images = camera_images_of(renderer, camera)
        written = []
        try:
            output.write_image(image, out, force=args.force, bit_depth=args.bit_depth)
            written.append(out)
            if args.aov:
                write_aovs(renderer, camera, args.aov, out, force=args.force, images=aov_images, written=written)
        except BaseException:
            # an interrupted or failed render leaves nothing behind: not the image without its AOVs
            output.remove_written(written)
            raise
        aov_note = " ".join(str(p.resolve()) for p in written[1:])
    if frame.interrupted:   # Ctrl-C after a pass of the path tracer: what was done is written
        print(f"clrt: interrupted after {frame.spp} of {samples} samples per pixel; wrote {out.resolve()}",
              file=sys.stderr)
        return 130
    if not args.quiet:
        builder = renderer.acceleration.builder   # what "auto" chose
        accel = "brute force" if args.accel == "none" else f"{builder} BVH of {config.VOLUME_WORDS[args.accel]}"
        view = f", camera from {args.mesh}" if from_file else ""
        how = f", path tracing {frame.spp} spp" if path else ""
        placed = renderer.instances
        placed = f", {len(placed):,} placements ({scene.num_triangles:,} placed)" if placed is not None else ""
        print(f"{camera.width}x{camera.height} pixels, {frame.triangles:,} triangles{placed}, "
              f"{len(scene.lights)} light(s), {accel}{view}{how}, device: {frame.device}")
        for stage, ms in {**renderer.timings, **frame.timings}.items():   # the set-up, then the frame
            print(f"  {stage:<20} {ms:10.2f} ms")
        if args.aov:
            print(f"  AOVs: {aov_note}")
    print(out.resolve())
    return 0


@contextlib.contextmanager
def _warnings_as_lines():
    """clrt's warnings of a render (a frame with nothing visible, a missing
    texture) shown every time, once the block is done: as one line each on
    stderr, ``clrt: warning: ...`` (main's _warning_line); other warnings as
    Python shows them."""
    caught = []
    try:
        with warnings.catch_warnings(record=True) as recorded:
            warnings.simplefilter("always", ClrtWarning)
            try:
                yield
            finally:
                caught = list(recorded)
    finally:   # shown once the recording is over (shown inside, they would be recorded again)
        for w in caught:
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)


class _LazyProgress:
    """A tqdm bar on stderr that appears only once a render has run
    PROGRESS_DELAY seconds and disappears when it ends.  tqdm itself is
    imported only then: a fast frame (most GPU frames) never pays for the
    import (20-30 ms of a first image)."""

    def __init__(self, total: int):
        self.total, self.done, self.bar = total, 0, None
        self.start = time.perf_counter()

    def update(self, n: int) -> None:
        self.done += n
        if self.bar is None and time.perf_counter() - self.start >= config.PROGRESS_DELAY:
            try:
                from tqdm import tqdm
            except ImportError:          # tqdm comes with the 'distributed' extra
                self.start = float("inf")
                return
            self.bar = tqdm(total=self.total, initial=self.done, unit="px", unit_scale=True, leave=False,
                            desc="rendering", file=sys.stderr)
        elif self.bar is not None:
            self.bar.update(n)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _progress_bar(total: int) -> _LazyProgress:
    return _LazyProgress(total)


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
    from clrt.device.acceleration import build_acceleration
    from clrt.device.context import device_label, select_device
    from clrt.scene.arrays import device_origin, triangle_corners
    from clrt.scene.load import load_mesh

    mesh = load_mesh(args.mesh)
    device = select_device(args.device)   # as render would: a missing device is exit 3, not ignored
    corners = triangle_corners(mesh, device_origin(mesh.bounds))   # the tree render and queries build
    built = build_acceleration(corners, args.accel, args.builder, args.leaf_size, args.device, statistics=True)
    print(f"{args.mesh}: {len(mesh.faces):,} triangles, {len(mesh.vertices):,} vertices; "
          f"device: {device_label(device)}")
    if not built.is_bvh:
        print(f"accel none: brute force, {built.device_bytes():,} bytes on the device")
        return 0
    print(f"accel {args.accel}, builder {built.builder}, leaf size {args.leaf_size}:")
    stats = built.stats()
    for key, value in stats.items():
        text = f"{value:,.3f}" if isinstance(value, float) else f"{value:,}"
        print(f"  {key:<22} {text}")
    return 0


def _device_option(argv: list) -> str | None:
    """The value of --device in a command line, before argparse has run."""
    for k, arg in enumerate(argv):
        if arg == "--device" and k + 1 < len(argv):
            return argv[k + 1]
        if arg.startswith("--device="):
            return arg.split("=", 1)[1]
    return None


def main(argv=None) -> int:
    with warnings.catch_warnings():   # restores the display of warnings for a caller in Python
        warnings.showwarning = _warning_line(warnings.showwarning)
        return _main(argv)


def _warning_line(show_other):
    """A :func:`warnings.showwarning` that prints clrt's warnings as its errors
    are printed, on one line (not Python's two, with a source line), and passes
    any other to ``show_other``."""
    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, ClrtWarning):
            print(f"clrt: warning: {' '.join(str(message).split())}", file=sys.stderr)
        else:
            show_other(message, category, filename, lineno, file, line)
    return show


def _main(argv) -> int:
    try:
        argv = list(sys.argv[1:] if argv is None else argv)
        if argv[:1] == ["batch"]:
            from clrt.batch.cli import main as batch_main
            # Ctrl-C from here on reaches the batch as KeyboardInterrupt, so that it
            # writes its manifest, closes its cluster and says how to resume
            # (clrt/__init__.py's start-up handler would exit at once).
            signal.signal(signal.SIGINT, signal.default_int_handler)
            return batch_main(argv[1:])
        # The heavy imports first, still under the start-up handler that
        # clrt/__init__.py installs for the clrt command (Ctrl-C there exits at
        # once: a KeyboardInterrupt inside a C extension's import can abort the
        # interpreter).  Ctrl-C from then on is KeyboardInterrupt, caught below;
        # the handler is set inside the try, so a signal already pending lands here.
        if argv[:1] == ["render"]:
            from clrt.device import warmup    # the driver starts while numpy and pyopencl load
            warmup.start(_device_option(argv))
        if argv[:1] in (["render"], ["info"]):
            import pyopencl  # noqa: F401
            import clrt.renderer  # noqa: F401
        signal.signal(signal.SIGINT, signal.default_int_handler)
        bench = argv[:1] == ["bench"]
        try:
            args = _parser(bench).parse_args(options.glue_vector_values(argv))
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
