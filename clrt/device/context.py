"""Finding an OpenCL device, and one cached context + profiling queue per device.

Selection order (see :func:`select_device`): the CLI's ``--device``, else the
``PYOPENCL_CTX`` environment variable, else the first GPU, the first CPU, any
device.  Every failure is a :class:`DeviceError` with a one-line message that
says what exists, so the CLI can print it and exit 3.
"""

from __future__ import annotations

import glob
import os
import re
import shutil
import subprocess
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Sequence

import pyopencl as cl

from clrt import checks
from clrt.device import sharing, warmup
from clrt.errors import DeviceError

NVIDIA_LIB = "libnvidia-opencl.so.1"
DEFAULT_VENDORS_DIR = "/etc/OpenCL/vendors"
INSTALL_HINT = ("install an OpenCL driver, e.g. `sudo apt-get install pocl-opencl-icd` (CPU) "
                "or your GPU vendor's driver")

# Where distributions and the NVIDIA container toolkit put the driver's libraries.
_NVIDIA_LIB_DIRS = (
    "/usr/lib/x86_64-linux-gnu",
    "/usr/lib64",
    "/usr/lib",
    "/usr/local/nvidia/lib64",
    "/usr/local/nvidia/lib",
    "/usr/lib/aarch64-linux-gnu",
)
_NVIDIA_LIB_GLOBS = (
    "/usr/local/cuda*/lib64",
    "/usr/local/cuda*/targets/*/lib",
    "/usr/local/cuda*/compat",
)

_SPEC_RE = re.compile(r"(\d+)(?::(\d+))?")


@dataclass(frozen=True)
class DeviceInfo:
    """Plain-data description of one OpenCL device."""

    platform_index: int
    device_index: int
    platform_name: str
    name: str
    type: str  # 'GPU', 'CPU', 'ACCELERATOR', 'CUSTOM' or 'OTHER'
    compute_units: int
    global_mem_bytes: int
    max_alloc_bytes: int
    local_mem_bytes: int
    opencl_version: str
    driver_version: str

    @property
    def index(self) -> str:
        """The 'P:D' spec that selects this device."""
        return f"{self.platform_index}:{self.device_index}"

    def short(self) -> str:
        """'0:0 name (CPU, platform)', for error messages."""
        return f"{self.index} {self.name} ({self.type}, {self.platform_name})"


# --------------------------------------------------------------------------- enumeration

def _platforms() -> list:
    """All platforms; none when the ICD loader finds no driver (pyopencl raises then)."""
    warmup.wait()        # the loader's first query, if a warm-up thread is making it
    sharing.driver_started()   # a child forked from now on cannot use it
    try:
        return cl.get_platforms()
    except (cl.Error, RuntimeError):
        return []


def _devices(platform) -> list:
    """A platform's devices; none when it refuses to list them (e.g. GPU not visible)."""
    try:
        return platform.get_devices()
    except (cl.Error, RuntimeError):
        return []


def device_kind(device: cl.Device) -> str:
    """"cpu" for a CPU device, else "gpu": the tuning tables that differ
    between the two (work-group sizes, build kernels, staging) are keyed by it."""
    return "cpu" if device.type & cl.device_type.CPU else "gpu"


def _type_name(device_type: int) -> str:
    # The type is a bit field (PoCL reports CPU|DEFAULT); the most specific bit wins.
    for bit, name in ((cl.device_type.GPU, "GPU"), (cl.device_type.ACCELERATOR, "ACCELERATOR"),
                      (cl.device_type.CPU, "CPU"), (cl.device_type.CUSTOM, "CUSTOM")):
        if device_type & bit:
            return name
    return "OTHER"


def _info(p: int, d: int, platform, device) -> DeviceInfo:
    return DeviceInfo(
        platform_index=p, device_index=d,
        platform_name=platform.name.strip(), name=device.name.strip(),
        type=_type_name(device.type), compute_units=device.max_compute_units,
        global_mem_bytes=device.global_mem_size, max_alloc_bytes=device.max_mem_alloc_size,
        local_mem_bytes=device.local_mem_size,
        opencl_version=device.version.strip(), driver_version=device.driver_version.strip())


def _enumerate(platforms: list) -> list[tuple[DeviceInfo, object]]:
    """(info, pyopencl.Device) for every device, in platform then device order."""
    return [(_info(p, d, platform, device), device)
            for p, platform in enumerate(platforms)
            for d, device in enumerate(_devices(platform))]


def list_devices() -> list[DeviceInfo]:
    """Every device of every OpenCL platform (empty when no driver is installed)."""
    return [info for info, _ in _enumerate(_platforms())]


# --------------------------------------------------------------------------- NVIDIA ICD diagnosis

@dataclass(frozen=True)
class _IcdProblem:
    lib: str  # path of libnvidia-opencl.so.1
    vendors: str  # the ICD location the loader reads
    vendors_from_env: bool


def _ldconfig_lib() -> str | None:
    ldconfig = shutil.which("ldconfig") or ("/sbin/ldconfig" if os.path.exists("/sbin/ldconfig")
                                            else None)
    if ldconfig is None:
        return None
    try:
        out = subprocess.run([ldconfig, "-p"], capture_output=True, text=True, timeout=1).stdout
    except (OSError, subprocess.SubprocessError):
        return None
    for line in out.splitlines():
        # "	libnvidia-opencl.so.1 (libc6,x86-64) => /usr/lib/x86_64-linux-gnu/libnvidia-opencl.so.1"
        if line.strip().startswith(NVIDIA_LIB) and "=>" in line:
            return line.split("=>", 1)[1].strip()
    return None


def _default_lib_dirs() -> list[str]:
    dirs = [p for p in os.environ.get("LD_LIBRARY_PATH", "").split(":") if p]
    dirs += _NVIDIA_LIB_DIRS
    for pattern in _NVIDIA_LIB_GLOBS:
        dirs += sorted(glob.glob(pattern))
    return dirs


def _find_nvidia_lib(lib_dirs: Iterable[str | os.PathLike] | None) -> str | None:
    """Path of the NVIDIA OpenCL library; only known directories are looked at (fast)."""
    search_ldconfig = lib_dirs is None
    for d in (_default_lib_dirs() if lib_dirs is None else lib_dirs):
        candidate = os.path.join(d, NVIDIA_LIB)
        if os.path.exists(candidate):
            return candidate
    return _ldconfig_lib() if search_ldconfig else None


def _icd_files(vendors: str) -> list[Path]:
    path = Path(vendors)
    if path.is_dir():
        return sorted(path.glob("*.icd"))
    return [path] if path.is_file() else []


def _registers_nvidia(vendors: str) -> bool:
    for icd in _icd_files(vendors):
        try:
            if "nvidia" in icd.read_text(errors="replace").lower():
                return True
        except OSError:
            continue
    # ocl-icd also loads the libraries listed in OCL_ICD_FILENAMES.
    return "nvidia" in os.environ.get("OCL_ICD_FILENAMES", "").lower()


def _nvidia_problem(lib_dirs=None, vendors=None, platform_names=None) -> _IcdProblem | None:
    lib = _find_nvidia_lib(lib_dirs)
    if lib is None:
        return None
    if platform_names is None:
        platform_names = [p.name for p in _platforms()]
    if any("nvidia" in name.lower() for name in platform_names):
        return None
    env_vendors = os.environ.get("OCL_ICD_VENDORS") or None
    if vendors is None:
        vendors = env_vendors or DEFAULT_VENDORS_DIR
    vendors = str(vendors)
    if _registers_nvidia(vendors):
        # Registered but no platform: a driver/GPU-visibility problem, not an ICD one.
        return None
    return _IcdProblem(lib, vendors, vendors != DEFAULT_VENDORS_DIR)


def _user_fix(problem: _IcdProblem) -> str:
    return (f"mkdir -p /tmp/icd && echo {problem.lib} > /tmp/icd/nvidia.icd"
            f" && export OCL_ICD_VENDORS=/tmp/icd")


def _root_fix(problem: _IcdProblem) -> str:
    return f"echo {problem.lib} > {DEFAULT_VENDORS_DIR}/nvidia.icd"


def _copy_others(problem: _IcdProblem) -> str:
    src = problem.vendors if Path(problem.vendors).is_dir() else DEFAULT_VENDORS_DIR
    return f"cp {src}/*.icd /tmp/icd/"


def _problem_one_line(problem: _IcdProblem) -> str:
    return (f"NVIDIA's OpenCL library {problem.lib} exists but no ICD file in {problem.vendors}"
            f" registers it; fix: {_user_fix(problem)} (OCL_ICD_VENDORS makes the loader read"
            f" only that folder: `{_copy_others(problem)}` to keep PoCL), or as root:"
            f" {_root_fix(problem)}")


def _problem_text(problem: _IcdProblem) -> str:
    lines = [
        f"NVIDIA's OpenCL library is installed ({problem.lib}) but no ICD file in",
        f"{problem.vendors} registers it, so OpenCL cannot see the NVIDIA GPU.",
        "Fix without root (for this shell):",
        f"  {_user_fix(problem)}",
        "  OCL_ICD_VENDORS makes the loader read only that folder; to keep PoCL (CPU) too:",
        f"  {_copy_others(problem)}",
        "Fix as root (permanent):",
        f"  {_root_fix(problem)}",
    ]
    if problem.vendors_from_env:
        lines.append(f"  (only takes effect after `unset OCL_ICD_VENDORS`, now {problem.vendors})")
    return "\n".join(lines)


def diagnose_nvidia_icd(lib_dirs: Sequence[str | os.PathLike] | None = None,
                        vendors: str | os.PathLike | None = None,
                        platform_names: Sequence[str] | None = None) -> str | None:
    """Multi-line fix when NVIDIA's OpenCL library exists but the ICD loader doesn't know it.

    ``lib_dirs``: directories to look for ``libnvidia-opencl.so.1`` in (default: the
    usual driver directories, ``LD_LIBRARY_PATH`` and ``ldconfig -p``).  ``vendors``:
    ICD directory or single ``.icd`` file (default: ``$OCL_ICD_VENDORS``, else
    /etc/OpenCL/vendors).  ``platform_names``: default the platforms OpenCL lists.
    Returns None when the library is absent, registered (by an ICD file or by
    ``OCL_ICD_FILENAMES``), or its platform shows up.
    """
    problem = _nvidia_problem(lib_dirs, vendors, platform_names)
    return None if problem is None else _problem_text(problem)


def _no_device_hint(platforms: list, fallback: str = INSTALL_HINT) -> str:
    """The NVIDIA fix when it applies, else ``fallback`` (one line)."""
    problem = _nvidia_problem(platform_names=[p.name for p in platforms])
    return _problem_one_line(problem) if problem else fallback


# --------------------------------------------------------------------------- selection

def _available(devices: list[tuple[DeviceInfo, object]]) -> str:
    return "available: " + "; ".join(info.short() for info, _ in devices)


def _by_spec(spec: str, source: str, devices, platforms):
    """The (info, device) a spec names, or DeviceError saying what exists."""
    norm = spec.strip().lower()
    if norm in ("gpu", "cpu"):
        for entry in devices:
            if entry[0].type == norm.upper():
                return entry
        msg = f"no {norm.upper()} OpenCL device ({source}); {_available(devices)}"
        if norm == "gpu":
            msg += "; " + _no_device_hint(platforms, "install your GPU vendor's OpenCL driver")
        raise DeviceError(msg)
    match = _SPEC_RE.fullmatch(norm)
    if match is None:
        raise DeviceError(f"invalid OpenCL device spec ({source}): expected 'gpu', 'cpu',"
                          f" 'P:D' or 'P' (platform:device indices); {_available(devices)}")
    p, d = int(match.group(1)), int(match.group(2) or 0)
    if p >= len(platforms):
        raise DeviceError(f"OpenCL platform {p} does not exist ({source});"
                          f" {len(platforms)} platform(s), {_available(devices)}")
    for entry in devices:
        if (entry[0].platform_index, entry[0].device_index) == (p, d):
            return entry
    raise DeviceError(f"OpenCL device {p}:{d} does not exist ({source});"
                      f" {_available(devices)}")


def _resolve(spec: str | None, platforms: list):
    """(info, device, reason) following the selection order; DeviceError if none fits."""
    if not platforms:
        raise DeviceError(f"no OpenCL platform found; {_no_device_hint(platforms)}")
    devices = _enumerate(platforms)
    if not devices:
        names = ", ".join(p.name.strip() for p in platforms)
        raise DeviceError(f"no OpenCL device found on platform(s) {names};"
                          f" {_no_device_hint(platforms)}")
    if spec is not None and spec.strip():
        source = f"--device {spec.strip()}"
    else:
        # pyopencl treats an empty PYOPENCL_CTX as "ask interactively"; we never ask.
        spec = os.environ.get("PYOPENCL_CTX", "").strip() or None
        source = f"PYOPENCL_CTX={spec}"
        # Its syntax is bad input (InputError, exit 2), as --device's is; a
        # well-formed spec naming no device here is OpenCL trouble (exit 3).
        checks.device(spec, "PYOPENCL_CTX")
    if spec is not None:
        info, device = _by_spec(spec, source, devices, platforms)
        return info, device, f"from {source}"
    for wanted, reason in (("GPU", "first GPU"), ("CPU", "no GPU, first CPU")):
        for info, device in devices:
            if info.type == wanted:
                return info, device, reason
    info, device = devices[0]
    return info, device, "no GPU or CPU, first device"


def select_device(spec: str | None = None):
    """The pyopencl.Device named by ``spec`` ('gpu', 'cpu', 'P:D', 'P') or chosen by default."""
    return _resolve(spec, _platforms())[1]


# --------------------------------------------------------------------------- context cache

_CONTEXTS: dict[tuple[int, int], tuple[cl.Context, cl.CommandQueue]] = {}
_CONTEXTS_LOCK = threading.Lock()


def create_context(spec: str | None = None) -> tuple[cl.Context, cl.CommandQueue]:
    """Context and profiling-enabled queue for the selected device, created once per
    device (and process: DeviceError in a child forked after the driver started)."""
    sharing.check_process()
    info, device, _ = _resolve(spec, _platforms())
    key = (info.platform_index, info.device_index)
    with _CONTEXTS_LOCK:   # threads making their first Accel at once share one context
        if key not in _CONTEXTS:
            try:
                warm = warmup.take_context(device.int_ptr)
                ctx = cl.Context.from_int_ptr(warm, retain=False) if warm else cl.Context([device])
                queue = cl.CommandQueue(
                    ctx, properties=cl.command_queue_properties.PROFILING_ENABLE)
            except cl.Error as exc:
                raise DeviceError(f"cannot open OpenCL device {info.short()}: {exc}") from None
            _CONTEXTS[key] = (ctx, queue)
        return _CONTEXTS[key]


# OpenCL status codes that mean "not enough memory" (on the device or the host).
_OUT_OF_MEMORY_CODES = {cl.status_code.MEM_OBJECT_ALLOCATION_FAILURE, cl.status_code.OUT_OF_RESOURCES,
                        cl.status_code.OUT_OF_HOST_MEMORY, cl.status_code.INVALID_BUFFER_SIZE}


def is_out_of_memory(exc: BaseException) -> bool:
    if isinstance(exc, MemoryError):
        return True
    try:
        return isinstance(exc, cl.Error) and exc.code in _OUT_OF_MEMORY_CODES
    except Exception:   # noqa: BLE001 -- an Error made without a status code
        return False


def error_name(exc: BaseException) -> str:
    try:
        return cl.status_code.to_string(exc.code)
    except Exception:   # noqa: BLE001
        return type(exc).__name__


# --------------------------------------------------------------------------- reporting

def _short_version(version: str) -> str:
    """'OpenCL 3.0 CUDA' -> 'OpenCL 3.0'."""
    return " ".join(version.split()[:2])


def format_bytes(n: float) -> str:
    """'1.5 GiB', '12.0 MiB', '512 B'."""
    for unit, size in (("GiB", 1 << 30), ("MiB", 1 << 20), ("KiB", 1 << 10)):
        if n >= size:
            return f"{n / size:.1f} {unit}"
    return f"{int(n)} B"


def device_label(device) -> str:
    """'NVIDIA H200 (NVIDIA CUDA, OpenCL 3.0)', for the render summary."""
    return (f"{device.name.strip()} ({device.platform.name.strip()},"
            f" {_short_version(device.version)})")


def describe_devices(selected=None) -> str:
    """The text of `clrt info`: platforms, devices, the one in use (``*``) and why.

    ``selected``: a ``--device`` spec string, a pyopencl.Device, or None for the
    default choice.  Always returns text; with no usable device the text is the
    no-platform/no-device message and hint, and the caller should treat
    ``not list_devices()`` as failure (exit 3).  A bad spec raises DeviceError.
    """
    platforms = _platforms()
    diagnosis = diagnose_nvidia_icd(platform_names=[p.name for p in platforms])
    if not platforms:
        return "no OpenCL platform found.\n" + (diagnosis or f"To fix: {INSTALL_HINT}.")
    devices = _enumerate(platforms)
    chosen, reason = None, None
    if isinstance(selected, cl.Device):
        chosen = next((i for i, d in devices if d == selected), None)
        reason = "given device"
    elif devices:
        chosen, _, reason = _resolve(selected, platforms)

    lines = []
    for p, platform in enumerate(platforms):
        lines.append(f"Platform {p}: {platform.name.strip()} ({platform.vendor.strip()})")
        mine = [info for info, _ in devices if info.platform_index == p]
        if not mine:
            lines.append("    (no devices)")
        for info in mine:
            mark = "*" if info == chosen else " "
            lines.append(f"  {mark} {info.index}  {info.name}")
            lines.append(
                f"        {info.type}, {info.compute_units} compute units,"
                f" {format_bytes(info.global_mem_bytes)} global, {format_bytes(info.max_alloc_bytes)} max alloc,"
                f" {format_bytes(info.local_mem_bytes)} local, {_short_version(info.opencl_version)},"
                f" driver {info.driver_version}")
    if chosen is not None:
        lines.append(f"selected: {chosen.index} {chosen.name} ({reason})")
    elif not devices and not diagnosis:
        lines.append(f"no OpenCL device found; {INSTALL_HINT}")
    # Shown also when PoCL works: that is when a user silently renders on the CPU.
    if diagnosis:
        lines += ["", diagnosis]
    return "\n".join(lines)
