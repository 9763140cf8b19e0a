"""One set of rules for every value a user gives clrt.

The command line, the Python API (``Camera``, ``Material``, ``Light``,
``Scene``, ``render``, ``trace``, ...) and the scene-file reader all check
their values with these functions, so the same bad value gets the same
message and the same exit code (2, :class:`~clrt.errors.InputError`) whichever
way it came in.  Only the name differs -- each entry point names the value the
way its user wrote it::

    --width must be an integer in 1..65536, got 0                    (CLI)
    width must be an integer in 1..65536, got 0                      (Python)
    scene.toml: camera.width must be an integer in 1..65536, got 0   (scene file)

Every check returns the value converted (``int``, ``float``, a tuple of
floats) or raises ``InputError("<name> must be <rule>, got <value>")``.
Ranges and names come from :mod:`clrt.config`.
"""

from __future__ import annotations

import functools
import inspect
import math
import re
from numbers import Integral, Real

from clrt import config
from clrt.errors import InputError


def show(value) -> str:
    """A value as a message shows it: numbers as written (2, 0.5, 1e+40),
    sequences of numbers as (1, 2, 3), anything else by repr, shortened."""
    if isinstance(value, Real) and not isinstance(value, bool):
        return _number_text(value)
    if isinstance(value, (list, tuple)) or type(value).__name__ == "ndarray":
        try:
            items = list(value)
        except TypeError:
            items = None
        if items is not None and all(isinstance(v, Real) and not isinstance(v, bool) for v in items):
            text = "(" + ", ".join(_number_text(v) for v in items) + ")"
            return text if len(text) <= 60 else text[:57] + "..."
    if type(value).__name__ == "ndarray":
        return f"an array of shape {tuple(value.shape)}"
    text = " ".join(repr(value).split())   # one line, whatever the repr
    return text if len(text) <= 60 else text[:57] + "..."


def _number_text(value) -> str:
    if isinstance(value, Integral):
        return str(int(value))
    value = float(value)
    text = f"{value:g}" if math.isfinite(value) and value == round(value, 6) else repr(value)
    return re.sub(r"e([+-]?)0(\d)", r"e\1\2", text).replace("e+", "e")   # 1e+09 -> 1e9, 1e-05 -> 1e-5


def fail(name: str, rule: str, value) -> InputError:
    """The one message shape: ``<name> must be <rule>, got <value>``."""
    return InputError(f"{name} must be {rule}, got {show(value)}")


# --------------------------------------------------------------------------- numbers

_OPS = {"gt": (">", lambda a, b: a > b), "ge": (">=", lambda a, b: a >= b),
        "lt": ("<", lambda a, b: a < b), "le": ("<=", lambda a, b: a <= b)}


def _range_text(limits: dict) -> str:
    if set(limits) == {"ge", "le"}:
        return f" in {_number_text(limits['ge'])}..{_number_text(limits['le'])}"
    return "".join(f"{' and' if i else ''} {_OPS[op][0]} {_number_text(bound)}"
                   for i, (op, bound) in enumerate(limits.items()))


def is_number(value) -> bool:
    """A real number; booleans are not numbers (TOML and Python both make them ints)."""
    return isinstance(value, Real) and not isinstance(value, bool)


def integer(name: str, value, lo: int, hi: int | None = None) -> int:
    """An integer (not a bool, not a float such as 2.0) in lo..hi."""
    if isinstance(value, Integral) and not isinstance(value, bool) and lo <= value and (hi is None or value <= hi):
        return int(value)
    rule = f"an integer in {lo}..{hi}" if hi is not None else f"an integer >= {lo}"
    if is_number(value) and not isinstance(value, Integral):
        # A float shows as one (2.0, not 2), so that the value does not look valid.
        text = repr(float(value)).replace("e+", "e")
        raise InputError(f"{name} must be {rule}, got {text}")
    raise fail(name, rule, value)


def number(name: str, value, **limits) -> float:
    """A finite number within ``limits`` (gt, ge, lt, le), e.g. ``number("fov", x, gt=0, lt=180)``."""
    if not is_number(value) or not math.isfinite(value) or not all(
            _OPS[op][1](float(value), bound) for op, bound in limits.items()):
        raise fail(name, "a number" + _range_text(limits), value)    # (the rule's text only for a message:
    return float(value)                                              # renders check numbers every frame)


def vector(name: str, value, n: int = 3, **limits) -> tuple:
    """``n`` finite numbers (a list, tuple or array), each within ``limits``
    and within +-MAX_COORDINATE (the device computes in float32); a tuple of floats.
    A NaN or infinity is named as such ("3 finite numbers"), and a value past the
    largest float32 (3.4e38, finite as a Python float) as overflowing float32."""
    try:
        items = list(value) if not isinstance(value, (str, bytes, dict)) else None
    except TypeError:
        items = None
    if items is None or len(items) != n or not all(is_number(v) for v in items):
        raise fail(name, f"{n} numbers" + _range_text(limits), value)
    if not all(math.isfinite(v) for v in items):
        raise fail(name, f"{n} finite numbers" + _range_text(limits), value)
    if not all(all(_OPS[op][1](float(v), b) for op, b in limits.items()) for v in items):
        raise fail(name, f"{n} numbers" + _range_text(limits), value)
    largest = max(abs(float(v)) for v in items)
    if largest > config.MAX_COORDINATE:
        error = fail(name, f"{n} numbers within +-{_number_text(config.MAX_COORDINATE)} "
                     "(the device computes in float32)", value)
        if largest > config.FLOAT32_MAX:
            error = InputError(f"{error}: {_number_text(largest)} overflows float32 (the largest float32 is "
                               f"about {config.FLOAT32_MAX:.2g})".replace("e+", "e"))
        raise error
    return tuple(float(v) for v in items)


def position(name: str, value) -> tuple:
    """A point or direction: 3 finite numbers within +-MAX_COORDINATE."""
    return vector(name, value)


def color(name: str, value) -> tuple:
    """A material colour: linear RGB, 3 numbers in 0..1."""
    return vector(name, value, ge=0, le=1)


def intensity(name: str, value) -> tuple:
    """A light colour, background or ambient light: linear RGB >= 0 (may exceed 1)."""
    return vector(name, value, ge=0)


def boolean(name: str, value) -> bool:
    if not isinstance(value, bool):
        raise fail(name, "true or false", value)
    return value


def text(name: str, value) -> str:
    if not isinstance(value, str):
        raise fail(name, "a string", value)
    return value


def choice(name: str, value, choices) -> str:
    """One of ``choices`` (a config table)."""
    choices = tuple(choices)
    if not isinstance(value, str) or value not in choices:
        raise fail(name, "one of " + ", ".join(choices), value)
    return value


# --------------------------------------------------------------------------- clrt's own values

def image_size(width, height, names=("width", "height")) -> tuple[int, int]:
    return (integer(names[0], width, 1, config.MAX_IMAGE_SIDE),
            integer(names[1], height, 1, config.MAX_IMAGE_SIDE))


def material_number(name: str, value, field: str) -> float:
    """A scalar material field (ambient, diffuse, ...) within its range of
    :data:`clrt.config.MATERIAL_RANGES`; all are finite in float32 on the device."""
    lo, hi = config.MATERIAL_RANGES[field]
    return number(name, value, ge=lo, le=hi)


def fov(value, name: str = "fov") -> float:
    return number(name, value, gt=0, lt=180)


def samples(value, name: str = "samples") -> int:
    return integer(name, value, 1, config.MAX_SAMPLES)


def max_depth(value, name: str = "max_depth", integrator: str | None = None) -> int:
    """A max_depth for ``integrator``: Whitted's bounces 0..MAX_BOUNCES; the path
    tracer's depth as Mitsuba counts it, -1 (unbounded) or 1..MAX_PATH_DEPTH;
    either of those where the integrator is not known yet (an option's value
    before the scene is read)."""
    if integrator == "whitted":
        return integer(name, value, 0, config.MAX_BOUNCES)
    if integrator == "path":
        whole = isinstance(value, Integral) and not isinstance(value, bool)
        if not (whole and (value == -1 or 1 <= value <= config.MAX_PATH_DEPTH)):
            raise fail(name, f"-1 (unbounded) or an integer in 1..{config.MAX_PATH_DEPTH} (the path tracer's "
                             "depth)", value)
        return int(value)
    return integer(name, value, -1, config.MAX_PATH_DEPTH)


def spp(value, name: str = "spp") -> int:
    """The path tracer's samples per pixel, 1..2**31 - 1."""
    return integer(name, value, 1, config.MAX_SPP)


def seed(value, name: str = "seed") -> int:
    return integer(name, value, 0, 2**32 - 1)


def exposure(value, name: str = "exposure") -> float:
    """Stops of exposure: the image x 2**exposure before it is clamped and encoded."""
    return number(name, value, ge=-64, le=64)


def crease(value, name: str = "crease") -> float:
    """A crease angle in degrees, 0..180 (180: smooth over every edge)."""
    return number(name, value, ge=0, le=180)


def accel_options(accel, builder, leaf_size, names=("accel", "builder", "leaf_size")) -> tuple:
    """The acceleration choices of Renderer, Accel and the CLI, from config's tables."""
    return (choice(names[0], accel, config.ACCELS), choice(names[1], builder, config.BUILDER_CHOICES),
            integer(names[2], leaf_size, 1, config.MAX_LEAF_SIZE))


def keyword_options(*former):
    """Decorator of a function whose options follow ``*`` (keyword only).  An
    option given positionally raises InputError that spells the call with
    keywords, reading the positional values in the ``former`` order (the order
    those options once had), rather than Python's bare count of arguments::

        Renderer(scene, "gpu") -> Renderer takes only the scene positionally:
                                  write Renderer(scene, device='gpu')

    help() and inspect.signature still show the function's own signature."""
    def wrap(func):
        params = list(inspect.signature(func).parameters.values())
        positional = [p.name for p in params
                      if p.kind in (inspect.Parameter.POSITIONAL_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)]
        shown = [name for name in positional if name not in ("self", "cls")]
        owner = func.__qualname__.removesuffix(".__init__")

        @functools.wraps(func)
        def checked(*args, **kwargs):
            extra = args[len(positional):]
            if extra:
                spelled = ", ".join(f"{name}={show(value)}" for name, value in zip(former, extra))
                if len(extra) > len(former):
                    spelled += ", ..."
                raise InputError(f"{owner} takes only the {' and '.join(shown)} positionally: write "
                                 f"{owner}({', '.join(shown)}, {spelled})")
            return func(*args, **kwargs)
        return checked
    return wrap


def aov_names(name: str, text) -> tuple[str, ...]:
    """'depth,normal' -> ('depth', 'normal'): per-pixel images of config.AOVS."""
    names = tuple(dict.fromkeys(n.strip().lower() for n in str(text).split(",") if n.strip()))
    if not names:
        raise InputError(f"{name} needs one or more of {','.join(config.AOVS)}")
    unknown = [n for n in names if n not in config.AOVS]
    if unknown:
        raise InputError(f"unknown AOV {unknown[0]!r}: choose from {','.join(config.AOVS)}")
    return names


_DEVICE_SPEC = re.compile(r"\d+(:\d+)?")


def device(value, name: str = "device") -> str | None:
    """A device spec: None (the default choice), 'gpu', 'cpu', 'P' or 'P:D'
    (platform and device indices, as ``clrt info`` lists them).  Only the
    syntax is checked here; a device that does not exist on this machine is
    OpenCL trouble (:class:`~clrt.errors.DeviceError`, exit 3)."""
    if value is None:
        return None
    rule = "'" + "', '".join(config.DEVICE_KINDS) + "', 'P' or 'P:D' (platform:device indices, see clrt info)"
    if not isinstance(value, str):
        raise fail(name, rule, value)
    spec = value.strip().lower()
    if spec not in config.DEVICE_KINDS and not _DEVICE_SPEC.fullmatch(spec):
        raise fail(name, rule, value)
    return spec


# --------------------------------------------------------------------------- host memory

def available_host_memory() -> int | None:
    """Bytes of host memory available to a new allocation (Linux: MemAvailable), or None."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def _gib(n: float) -> str:
    return f"{n / (1 << 30):.1f} GiB" if n >= 1 << 30 else f"{n / (1 << 20):.1f} MiB"


def host_memory(nbytes: int, what: str, advice: str) -> None:
    """TooLargeError naming the size needed when ``nbytes`` exceed the host
    memory available now: a clear line before the job, rather than numpy's
    MemoryError (or the kernel's OOM killer) part of the way through it."""
    from clrt.errors import TooLargeError
    available = available_host_memory()
    if available is not None and nbytes > available:
        raise TooLargeError(f"{what} needs {_gib(nbytes)} of host memory, only {_gib(available)} "
                            f"is available: {advice}")
