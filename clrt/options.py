"""Command-line options shared by ``clrt render`` and ``clrt batch render``.

Each option type parses the text and checks the value with clrt.checks under
the option's name, so the CLI says what the Python API and scene files say:
"--width must be an integer in 1..65536, got 0".  The render options are
added by :func:`add_render_options` (scene, camera, material, lights, render
settings) and :func:`add_accel_options`, so both commands take the same ones.
"""

from __future__ import annotations

import argparse

from clrt import checks, config, output


def number_text(text: str):
    """'3' -> 3, '2.5' -> 2.5, anything else stays text (the check then names it)."""
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def vector_text(text: str):
    values = [number_text(x.strip()) for x in text.split(",")]
    return tuple(values) if all(checks.is_number(v) for v in values) else text


def typed(check, parse=number_text):
    """argparse type: ``check(parse(text))``; the check raises InputError itself."""
    def convert(text: str):
        return check(parse(text))
    return convert


def integer(name: str, lo: int, hi: int | None = None):
    return typed(lambda v: checks.integer(name, v, lo, hi))


def number(name: str, **limits):
    return typed(lambda v: checks.number(name, v, **limits))


def material(field: str):
    """A scalar material option (--ambient, ...) within its range of config.MATERIAL_RANGES."""
    return typed(lambda v: checks.material_number(f"--{field}", v, field))


def _range(field: str) -> str:
    lo, hi = config.MATERIAL_RANGES[field]
    return f"{lo}..{hi}"


def vector(name: str, check=checks.position):
    return typed(lambda v: check(name, v), vector_text)


def device(text: str) -> str:
    return checks.device(text, "--device")


def add_render_options(r: argparse.ArgumentParser) -> None:
    """The scene, camera, light, material and render options of a render command,
    and the image's bit depth."""
    side = f"1..{config.MAX_IMAGE_SIDE}"
    r.add_argument("--width", type=integer("--width", 1, config.MAX_IMAGE_SIDE),
                   help=f"image width in pixels, {side} (default: the scene's, else {config.DEFAULT_WIDTH})")
    r.add_argument("--height", type=integer("--height", 1, config.MAX_IMAGE_SIDE),
                   help=f"image height in pixels, {side} (default: the scene's, else {config.DEFAULT_HEIGHT})")
    r.add_argument("--eye", type=vector("--eye"), help="camera position x,y,z (default: the file's camera, "
                                                       "else framed from the bounds)")
    r.add_argument("--target", type=vector("--target"), help="point looked at (default: centre of the bounds)")
    r.add_argument("--up", type=vector("--up"), help="up vector (default 0,1,0)")
    r.add_argument("--fov", type=typed(lambda v: checks.fov(v, "--fov")),
                   help=f"vertical field of view in degrees, > 0 and < 180 (default {config.DEFAULT_FOV:g})")
    r.add_argument("--light", type=vector("--light"), action="append", metavar="X,Y,Z",
                   help="point light position; repeat for more lights (default: the scene's, else one "
                        "above the eye)")
    r.add_argument("--color", type=vector("--color", checks.color),
                   help="material colour r,g,b, linear 0..1 (default .8,.8,.8); like every material "
                        "option it replaces that field of every object's material")
    r.add_argument("--ambient", type=material("ambient"),
                   help=f"ambient coefficient, {_range('ambient')} (default {config.DEFAULT_AMBIENT:g})")
    r.add_argument("--diffuse", type=material("diffuse"),
                   help=f"diffuse coefficient, {_range('diffuse')} (default {config.DEFAULT_DIFFUSE:g})")
    r.add_argument("--specular", type=material("specular"),
                   help=f"specular coefficient, {_range('specular')} (default {config.DEFAULT_SPECULAR:g})")
    r.add_argument("--shininess", type=material("shininess"),
                   help=f"Phong exponent, {_range('shininess')} (default {config.DEFAULT_SHININESS:g})")
    r.add_argument("--flat", action="store_true", help="flat shading (no vertex-normal interpolation)")
    r.add_argument("--crease", type=typed(lambda v: checks.crease(v, "--crease")), metavar="DEG",
                   help="smooth shading keeps edges whose faces meet at more than DEG degrees sharp "
                        f"(0..180; default {config.DEFAULT_CREASE_ANGLE:g}; 180 smooths every edge)")
    r.add_argument("--background", type=vector("--background", checks.intensity),
                   help="background colour r,g,b, linear, >= 0 (default: the scene's, else black)")
    r.add_argument("--samples", type=typed(lambda v: checks.samples(v, "--samples")),
                   help=f"anti-aliasing: N x N rays per pixel, 1..{config.MAX_SAMPLES} (default: the "
                        "scene's; 1 for a mesh, 2 for the built-in scene)")
    r.add_argument("--max-depth", type=typed(lambda v: checks.max_depth(v, "--max-depth")),
                   help=f"reflection/refraction bounces, 0..{config.MAX_BOUNCES} (default: the scene's, "
                        f"{config.DEFAULT_MAX_DEPTH})")
    r.add_argument("--bit-depth", type=typed(lambda v: output.check_bit_depth(v, "--bit-depth")),
                   metavar="|".join(map(str, output.BIT_DEPTHS)),
                   help="bits a colour sample of the image: 8 (default) or 16, for formats that hold it (.png): "
                        "16 is rendered as linear light and encoded to sRGB on the host; .exr holds linear "
                        "float32 instead")


def add_accel_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--accel", default=config.DEFAULT_ACCEL, type=typed(
        lambda v: checks.choice("--accel", v, config.ACCELS), str),
        help=f"BVH bounding-volume shape ({', '.join(config.VOLUMES)}), or none for brute force "
             f"(default {config.DEFAULT_ACCEL})")
    p.add_argument("--builder", default=config.DEFAULT_BUILDER, type=typed(
        lambda v: checks.choice("--builder", v, config.BUILDER_CHOICES), str),
        help="BVH builder: paper (the paper's median split) or sah (binned SAH) on the host, device "
             "(PLOC on the OpenCL device), or auto (default: device where the device computes in "
             "float64, else sah)")
    p.add_argument("--leaf-size", default=config.DEFAULT_LEAF_SIZE,
                   type=integer("--leaf-size", 1, config.MAX_LEAF_SIZE),
                   help=f"most triangles per BVH leaf, 1..{config.MAX_LEAF_SIZE} (default {config.DEFAULT_LEAF_SIZE})")


VECTOR_OPTIONS = {"--eye", "--target", "--up", "--light", "--color", "--background"}


def glue_vector_values(argv: list[str]) -> list[str]:
    """``--eye -1,2,3`` -> ``--eye=-1,2,3``: argparse would take ``-1,2,3`` for an option."""
    out, i = [], 0
    while i < len(argv):
        if argv[i] in VECTOR_OPTIONS and i + 1 < len(argv):
            out.append(f"{argv[i]}={argv[i + 1]}")
            i += 2
        else:
            out.append(argv[i])
            i += 1
    return out
