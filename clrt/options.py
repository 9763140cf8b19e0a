"""The render options, declared once: :data:`OPTIONS`.

Each :class:`Option` has its Python name and its command-line flag, how the
flag's text is read, the check of its value (clrt.checks, under the name the
user wrote), its default, its help and who takes it (its ``stage``).  From
this one table come

- the argparse options of ``clrt render`` and ``clrt info`` (:func:`add_options`;
  ``clrt batch render`` adds its share with :func:`add_render_options` and
  :func:`add_accel_options`, or ``add_options(parser, "batch")``),
- the keywords of the Python API: ``clrt.render(source, **options)`` takes every
  option whose stage is not ``output`` (:func:`check_api`), ``Renderer`` the
  ``renderer`` ones, ``Renderer.render`` ``samples`` and ``max_depth``,

so a bad value gets the same rule either way, only the name differs::

    --width must be an integer in 1..65536, got 0        (clrt render --width 0)
    width must be an integer in 1..65536, got 0          (clrt.render(mesh, width=0))
    --light must be 3 finite numbers, got (0, nan, 0)    (clrt render --light 0,nan,0)
    lights[0] must be 3 finite numbers, got (0, nan, 0)  (clrt.render(mesh, lights=[(0, nan, 0)]))

Building a parser from the table stays cheap (``clrt --help`` imports no numpy).
"""

from __future__ import annotations

import argparse
import difflib
import sys
from dataclasses import dataclass
from typing import Callable

from clrt import checks, config, output
from clrt.errors import InputError

# Stages: who takes an option's value.
SCENE = "scene"          # clrt.scene.render_setup.render_scene: materials, background, samples, max_depth
CAMERA = "camera"        # render_setup.render_camera
LIGHTS = "lights"        # render_setup.render_lights
RENDERER = "renderer"    # clrt.Renderer: the device and the acceleration structure
OUTPUT = "output"        # the command line only: the file written and what is printed

RENDER, INFO, BATCH = "render", "info", "batch"   # commands
DEFAULT_OUTPUT = "clrt-default.png"   # clrt render's image of the built-in scene


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


def _as_is(text: str) -> str:
    return text


@dataclass(frozen=True)
class Option:
    """One render option.

    ``name``: the Python keyword (``max_depth``); ``flag``: the command line's
    (``--max-depth``).  ``check(label, value)`` returns the value converted or
    raises InputError naming ``label`` -- the flag on the command line, the name
    in Python.  ``parse``: the flag's text to a value (None: a switch, which
    takes no text).  ``many``: given once per item on the command line
    (``--light`` again for each light), as a list in Python (``lights``).
    ``default``: what argparse and the API take when the option is not given
    (None: the scene's value, else clrt.config's).  ``api``: why ``clrt.render``
    does not take it (output options), or None.
    """

    name: str
    flag: str
    check: Callable
    help: str
    stage: str
    parse: Callable | None = number_text
    default: object = None
    metavar: str | None = None
    short: str | None = None
    many: bool = False
    commands: tuple = (RENDER, BATCH)
    api: str | None = None

    @property
    def dest(self) -> str:
        """argparse's attribute: the flag's words joined by '_' (``--light``: ``light``)."""
        return self.flag.lstrip("-").replace("-", "_")

    def from_text(self, text: str):
        """The command line's value of ``text``, checked under the flag."""
        return self.check(self.flag, self.parse(text))

    def value(self, value):
        """A Python value checked under the name (None: not given, stays None)."""
        if value is None:
            return None
        if not self.many:
            return self.check(self.name, value)
        if isinstance(value, (tuple, list)) and len(value) == 3 and all(checks.is_number(v) for v in value):
            # one position where a list of them is meant: say how to write it
            raise InputError(f"{self.name} must be a list of positions (x, y, z) or clrt.Light, got "
                             f"{checks.show(value)}: for one light there, write [{checks.show(value)}]")
        if isinstance(value, (str, bytes, dict)) or not hasattr(value, "__iter__"):
            raise checks.fail(self.name, "a list of positions (x, y, z) or clrt.Light", value)
        return [self.check(f"{self.name}[{i}]", item) for i, item in enumerate(value)]


def _light(label: str, value):
    """A light: its position (3 numbers), or in Python a clrt.Light (with its colour)."""
    scene = sys.modules.get("clrt.scene.scene")   # loaded wherever a Light was made
    if scene is not None and isinstance(value, scene.Light):
        return value
    return checks.position(label, value)


def _integer(lo: int, hi: int):
    return lambda label, value: checks.integer(label, value, lo, hi)


def _material(field: str):
    return lambda label, value: checks.material_number(label, value, field)


def _range(field: str) -> str:
    lo, hi = config.MATERIAL_RANGES[field]
    return f"{lo}..{hi}"


def _aovs(label: str, value):
    return checks.aov_names(label, value)


def _path(label: str, value):
    return checks.text(label, value)   # checked as a file to write by the command (cli._output_path)


def _environment(label: str, value):
    """An environment map: a file name (.exr or .hdr, read when the scene is
    made), or in Python also a clrt.Environment, an (H, W, 3) array or a dict of
    an Environment's fields."""
    if isinstance(value, (str, bytes)) or hasattr(value, "__fspath__"):
        text = str(value if not isinstance(value, bytes) else value.decode(errors="replace"))
        if not text.lower().endswith((".exr", ".hdr")):
            raise checks.fail(label, "an equirectangular .exr or .hdr image", value)
        return str(value)
    return value   # an Environment, an array or a dict: clrt.Environment checks it


def _switch(label: str, value):
    return checks.boolean(label, value)


_SIDE = f"1..{config.MAX_IMAGE_SIDE}"
_FORMATS = ", ".join(output.IMAGE_SUFFIXES)

#: Every render option, in the order ``clrt render --help`` lists them.
OPTIONS = {o.name: o for o in [
    Option("output", "--output", _path, short="-o", stage=OUTPUT, parse=_as_is, commands=(RENDER,),
           api="it returns the image: write it with clrt.output.write_image",
           help=f"image to write ({_FORMATS}; default: MESH name {output.WRITERS['png'].suffix}, or "
                f"{DEFAULT_OUTPUT}); .exr holds the linear, unclamped image as float32 OpenEXR (needs "
                f"{output.EXR_INSTALL_HINT}); an existing file is replaced only once the render succeeded, and "
                "only if clrt wrote it (see --force)"),
    Option("force", "--force", _switch, short="-f", stage=OUTPUT, parse=None, default=False, commands=(RENDER,),
           api="it writes no file",
           help="replace the output even if clrt did not write it (by default an existing file is replaced only "
                "if clrt wrote it, such as the previous render)"),
    Option("width", "--width", _integer(1, config.MAX_IMAGE_SIDE), stage=CAMERA,
           help=f"image width in pixels, {_SIDE} (default: the scene's, else {config.DEFAULT_WIDTH})"),
    Option("height", "--height", _integer(1, config.MAX_IMAGE_SIDE), stage=CAMERA,
           help=f"image height in pixels, {_SIDE} (default: the scene's, else {config.DEFAULT_HEIGHT})"),
    Option("eye", "--eye", checks.position, stage=CAMERA, parse=vector_text,
           help="camera position x,y,z (default: the file's camera, else framed from the bounds)"),
    Option("target", "--target", checks.position, stage=CAMERA, parse=vector_text,
           help="point looked at (default: centre of the bounds)"),
    Option("up", "--up", checks.position, stage=CAMERA, parse=vector_text, help="up vector (default 0,1,0)"),
    Option("fov", "--fov", lambda label, v: checks.fov(v, label), stage=CAMERA,
           help=f"vertical field of view in degrees, > 0 and < 180 (default {config.DEFAULT_FOV:g})"),
    Option("lights", "--light", _light, stage=LIGHTS, parse=vector_text, many=True, metavar="X,Y,Z",
           help="point light position; repeat for more lights (default: the scene's, else one above the eye)"),
    Option("color", "--color", checks.color, stage=SCENE, parse=vector_text,
           help="material colour r,g,b, linear 0..1 (default .8,.8,.8); like every material option it replaces "
                "that field of every object's material"),
    Option("ambient", "--ambient", _material("ambient"), stage=SCENE,
           help=f"ambient coefficient, {_range('ambient')} (default {config.DEFAULT_AMBIENT:g})"),
    Option("diffuse", "--diffuse", _material("diffuse"), stage=SCENE,
           help=f"diffuse coefficient, {_range('diffuse')} (default {config.DEFAULT_DIFFUSE:g})"),
    Option("specular", "--specular", _material("specular"), stage=SCENE,
           help=f"specular coefficient, {_range('specular')} (default {config.DEFAULT_SPECULAR:g})"),
    Option("shininess", "--shininess", _material("shininess"), stage=SCENE,
           help=f"Phong exponent, {_range('shininess')} (default {config.DEFAULT_SHININESS:g})"),
    Option("flat", "--flat", _switch, stage=SCENE, parse=None, default=False,
           help="flat shading (no vertex-normal interpolation)"),
    Option("crease", "--crease", lambda label, v: checks.crease(v, label), stage=SCENE, metavar="DEG",
           help="smooth shading keeps edges whose faces meet at more than DEG degrees sharp (0..180; default "
                f"{config.DEFAULT_CREASE_ANGLE:g}; 180 smooths every edge)"),
    Option("background", "--background", checks.intensity, stage=SCENE, parse=vector_text,
           help="background colour r,g,b, linear, >= 0 (default: the scene's, else black)"),
    Option("samples", "--samples", lambda label, v: checks.samples(v, label), stage=SCENE,
           help=f"anti-aliasing: N x N rays per pixel, 1..{config.MAX_SAMPLES} (default: the scene's; 1 for a "
                "mesh, 2 for the built-in scene)"),
    Option("max_depth", "--max-depth", lambda label, v: checks.max_depth(v, label), stage=SCENE,
           help=f"whitted: reflection/refraction bounces, 0..{config.MAX_BOUNCES} (default: the scene's, else "
                f"{config.DEFAULT_MAX_DEPTH}); path: the longest path as Mitsuba counts max_depth, 1 = emitters "
                f"seen directly, 2 = direct light, ..., up to {config.MAX_PATH_DEPTH}, or -1 = unbounded (default: "
                f"the scene's, else {config.DEFAULT_PATH_MAX_DEPTH}; Russian roulette from depth "
                f"{config.PATH_RR_DEPTH})"),
    Option("integrator", "--integrator", lambda label, v: checks.choice(label, v, config.INTEGRATORS),
           stage=SCENE, parse=_as_is, metavar="|".join(config.INTEGRATORS),
           help=f"whitted (the paper's Phong and Whitted optics; default: the scene's, else "
                f"{config.DEFAULT_INTEGRATOR}) or path (path tracing: soft shadows, indirect light, emissive "
                "surfaces, environment maps; see docs/path-tracing.md)"),
    Option("spp", "--spp", lambda label, v: checks.spp(v, label), stage=SCENE,
           help=f"path: samples per pixel, 1..{config.MAX_SPP} (default: the scene's, else {config.DEFAULT_SPP}), "
                "added in passes (Ctrl-C after the first keeps the passes done)"),
    Option("seed", "--seed", lambda label, v: checks.seed(v, label), stage=SCENE,
           help="seed of the random numbers (path) and the sample jitter (whitted), 0..2^32-1 (default: the "
                "scene's, else 0): one seed gives the same image on one device"),
    Option("exposure", "--exposure", lambda label, v: checks.exposure(v, label), stage=SCENE, metavar="STOPS",
           help="8- and 16-bit images show the linear image x 2^STOPS, clamped to 0..1, sRGB-encoded (default: "
                "the scene's, else 0; .exr files hold the linear image as it is)"),
    Option("environment", "--environment", _environment, stage=SCENE, parse=_as_is, metavar="FILE",
           help="path: an equirectangular HDR environment map (.exr, needs the 'exr' extra, or .hdr) lighting "
                "the scene and seen behind it, importance-sampled (default: the scene's, else the background "
                "colour)"),
    Option("bit_depth", "--bit-depth", lambda label, v: output.check_bit_depth(v, label), stage=OUTPUT,
           metavar="|".join(map(str, output.BIT_DEPTHS)),
           api="it returns uint8 sRGB, or float32 linear RGB with linear=True (write_image(..., bit_depth=16) "
               "writes 16 bits)",
           help="bits a colour sample of the image: 8 (default) or 16, for formats that hold it (.png): 16 is "
                "rendered as linear light and encoded to sRGB on the host; .exr holds linear float32 instead"),
    Option("device", "--device", lambda label, v: checks.device(v, label), stage=RENDERER, parse=_as_is,
           commands=(RENDER, INFO),
           help="'gpu', 'cpu' or P:D platform/device indices (default: PYOPENCL_CTX, else the first GPU, else "
                "the first CPU)"),
    Option("accel", "--accel", lambda label, v: checks.choice(label, v, config.ACCELS), stage=RENDERER,
           parse=_as_is, default=config.DEFAULT_ACCEL, commands=(RENDER, INFO, BATCH),
           help=f"BVH bounding-volume shape ({', '.join(config.VOLUMES)}), or none for brute force "
                f"(default {config.DEFAULT_ACCEL})"),
    Option("builder", "--builder", lambda label, v: checks.choice(label, v, config.BUILDER_CHOICES),
           stage=RENDERER, parse=_as_is, default=config.DEFAULT_BUILDER, commands=(RENDER, INFO, BATCH),
           help="BVH builder: paper (the paper's median split) or sah (binned SAH) on the host, device (PLOC on "
                "the OpenCL device), or auto (default: device where the device computes in float64, else sah)"),
    Option("leaf_size", "--leaf-size", _integer(1, config.MAX_LEAF_SIZE), stage=RENDERER,
           default=config.DEFAULT_LEAF_SIZE, commands=(RENDER, INFO, BATCH),
           help=f"most triangles per BVH leaf, 1..{config.MAX_LEAF_SIZE} (default {config.DEFAULT_LEAF_SIZE})"),
    Option("aov", "--aov", _aovs, stage=OUTPUT, parse=_as_is, metavar="NAMES", commands=(RENDER,),
           api="per-pixel images come from clrt.camera_images (or Accel.camera_images)",
           help="also write per-pixel images, comma-separated: depth (along the view axis), distance (along the "
                "ray), normal, prim (triangle index), instance (placement of a mesh), hit, front; each as "
                "OUT.NAME.npy (the values; inf / -1 / 0 where nothing is hit) and OUT.NAME.png (a picture of them); "
                "with an .exr output, as channels of that file instead (Z, distance, N.X N.Y N.Z, prim, instance, "
                "hit, front); see docs/ray-queries.md"),
    Option("quiet", "--quiet", _switch, short="-q", stage=OUTPUT, parse=None, default=False, commands=(RENDER,),
           api="it prints nothing", help="print only the output path"),
]}

#: Each option's name as the command line writes it (render_setup's labels).
FLAGS = {name: o.flag for name, o in OPTIONS.items()}
#: The options ``clrt.render`` takes: every one but the output options.
API_OPTIONS = {name: o for name, o in OPTIONS.items() if o.api is None}
VECTOR_FLAGS = {o.flag for o in OPTIONS.values() if o.parse is vector_text}


def _argparse_type(option: Option):
    def convert(text: str):
        return option.from_text(text)
    convert.__name__ = option.dest   # argparse names a type in its own errors
    return convert


def add_option(parser: argparse.ArgumentParser, option: Option) -> None:
    """``option`` as an argparse argument of ``parser``."""
    flags = [option.short, option.flag] if option.short else [option.flag]
    if option.parse is None:
        parser.add_argument(*flags, action="store_true", help=option.help)
        return
    parser.add_argument(*flags, type=_argparse_type(option), default=option.default, metavar=option.metavar,
                        action="append" if option.many else "store", help=option.help)


def add_options(parser: argparse.ArgumentParser, command: str, stages=None) -> None:
    """The options of ``command`` (render, info or batch), in the table's order;
    only those of ``stages`` when given."""
    for option in OPTIONS.values():
        if command in option.commands and (stages is None or option.stage in stages):
            add_option(parser, option)


def add_render_options(parser: argparse.ArgumentParser) -> None:
    """The scene, camera, light and material options of a render command, and
    the image's bit depth (what ``clrt batch render`` shares with ``clrt render``)."""
    add_options(parser, BATCH, (SCENE, CAMERA, LIGHTS, OUTPUT))


def add_accel_options(parser: argparse.ArgumentParser) -> None:
    """--accel, --builder, --leaf-size."""
    for name in ("accel", "builder", "leaf_size"):
        add_option(parser, OPTIONS[name])


def values(args: argparse.Namespace, *stages: str) -> dict:
    """The options of ``stages`` that ``args`` (parsed from the table) holds, by
    their Python names: ``render_scene(source, **values(args, SCENE))``."""
    return {o.name: getattr(args, o.dest) for o in OPTIONS.values() if o.stage in stages and hasattr(args, o.dest)}


def check_api(options: dict, owner: str = "render") -> dict:
    """The keyword options of a Python call checked by the table: the value
    converted, or InputError with the command line's rule under the Python name.
    An unknown name is an InputError that says which were meant (an output
    option, which ``owner`` does not take, says why)."""
    out = {}
    for name, value in options.items():
        option = API_OPTIONS.get(name)
        if option is None:
            raise InputError(_unknown(name, owner))
        if value is not None:   # None: not given (the default)
            out[name] = option.value(value)
    return out


def check(name: str, value):
    """One option's value checked under its Python name, None included (where the
    caller has no default for it): ``check("leaf_size", 0)`` raises the rule of
    --leaf-size, named leaf_size."""
    return OPTIONS[name].check(name, value)


def by_stage(values: dict, *stages: str) -> dict:
    """The entries of ``values`` whose options are of ``stages``."""
    return {name: value for name, value in values.items() if OPTIONS[name].stage in stages}


def _unknown(name, owner: str) -> str:
    other = OPTIONS.get(name) or next((o for o in OPTIONS.values() if name in (o.flag, o.dest, o.short)), None)
    if other is not None and other.api is not None:   # (the reason is clrt.render's: it returns the image)
        reason = f": {other.api}" if owner == "render" else ""
        return f"{owner} does not take {other.name} ({other.flag}){reason}"
    if other is not None:
        return f"unknown option {name!r} of {owner} (did you mean {other.name!r}?)"
    close = difflib.get_close_matches(str(name), list(API_OPTIONS), n=1)
    hint = f"did you mean {close[0]!r}?" if close else f"expected one of: {', '.join(API_OPTIONS)}"
    return f"unknown option {name!r} of {owner} ({hint})"


def api_doc(indent: str = "    ") -> str:
    """The API options as a docstring lists them: name, then the help."""
    lines = []
    for o in API_OPTIONS.values():
        kind = " (a list: [(x, y, z), ...] or clrt.Light)" if o.many else ""
        lines.append(f"{indent}``{o.name}``{kind}, {o.flag}: {o.help}")
    return "\n".join(lines)


def glue_vector_values(argv: list[str]) -> list[str]:
    """``--eye -1,2,3`` -> ``--eye=-1,2,3``: argparse would take ``-1,2,3`` for an option."""
    out, i = [], 0
    while i < len(argv):
        if argv[i] in VECTOR_FLAGS and i + 1 < len(argv):
            out.append(f"{argv[i]}={argv[i + 1]}")
            i += 2
        else:
            out.append(argv[i])
            i += 1
    return out


# --------------------------------------------------------------------------- for other commands' own options

def typed(check, parse=number_text):
    """argparse type: ``check(parse(text))``; the check raises InputError itself."""
    def convert(text: str):
        return check(parse(text))
    return convert


def integer(name: str, lo: int, hi: int | None = None):
    return typed(lambda v: checks.integer(name, v, lo, hi))


def number(name: str, **limits):
    return typed(lambda v: checks.number(name, v, **limits))


def device(text: str) -> str:
    return checks.device(text, "--device")
