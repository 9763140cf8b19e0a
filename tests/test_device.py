"""Device selection, context caching and the NVIDIA ICD diagnosis (runs on PoCL)."""

import numpy as np
import pyopencl as cl
import pytest

from clrt.device import context as ctxmod
from clrt.device.context import (DeviceInfo, create_context, describe_devices, device_label,
                                 diagnose_nvidia_icd, list_devices, select_device)
from clrt.errors import DeviceError

NVLIB = "libnvidia-opencl.so.1"


@pytest.fixture(autouse=True)
def clean_env(monkeypatch):
    """The user's OpenCL environment must not steer the tests."""
    for var in ("PYOPENCL_CTX", "OCL_ICD_FILENAMES"):
        monkeypatch.delenv(var, raising=False)


def _raise_device_error(spec):
    with pytest.raises(DeviceError) as excinfo:
        select_device(spec)
    msg = str(excinfo.value)
    assert msg and "\n" not in msg
    return msg


# --------------------------------------------------------------------------- listing / selection

def test_list_devices_finds_a_cpu():
    devices = list_devices()
    assert any(d.type == "CPU" for d in devices)
    d = devices[0]
    assert isinstance(d, DeviceInfo)
    assert d.compute_units >= 1 and d.global_mem_bytes > 0 and d.max_alloc_bytes > 0
    assert d.opencl_version.startswith("OpenCL")
    with pytest.raises(Exception):
        d.name = "x"  # frozen


def test_select_default_cpu_and_indices():
    assert isinstance(select_device(None), cl.Device)
    assert select_device("cpu").type & cl.device_type.CPU
    first = list_devices()[0]
    assert select_device("0:0").name.strip() == first.name
    assert select_device(" 0 ") == select_device("0:0")


def test_bad_specs_raise_one_line_errors():
    if any(d.type == "GPU" for d in list_devices()):
        pytest.skip("a GPU is present")
    name = list_devices()[0].name
    assert name in _raise_device_error("gpu")
    assert "platform 9" in _raise_device_error("9:9")
    assert "0:99" in _raise_device_error("0:99")
    msg = _raise_device_error("banana")
    assert "banana" in msg and "P:D" in msg and name in msg


def test_pyopencl_ctx(monkeypatch):
    monkeypatch.setenv("PYOPENCL_CTX", "0:0")
    assert select_device() == select_device("0:0")
    assert "from PYOPENCL_CTX=0:0" in describe_devices()
    monkeypatch.setenv("PYOPENCL_CTX", "7")
    assert "PYOPENCL_CTX" in _raise_device_error(None)
    select_device("cpu")  # --device wins over the environment
    monkeypatch.setenv("PYOPENCL_CTX", "")  # empty = unset, never interactive
    assert isinstance(select_device(), cl.Device)


def test_no_platform(monkeypatch, tmp_path):
    def no_icd():
        raise cl.LogicError("clGetPlatformIDs failed: PLATFORM_NOT_FOUND_KHR")

    monkeypatch.setattr(ctxmod.cl, "get_platforms", no_icd)
    monkeypatch.setattr(ctxmod, "_default_lib_dirs", lambda: [str(tmp_path / "nolib")])
    monkeypatch.setattr(ctxmod, "_ldconfig_lib", lambda: None)
    assert list_devices() == []
    msg = _raise_device_error(None)
    assert "no OpenCL platform" in msg and "pocl-opencl-icd" in msg
    assert "pocl-opencl-icd" in describe_devices()

    # With the NVIDIA library unregistered, the fix replaces the generic hint.
    libdir, vendors = _fake_driver(tmp_path)
    monkeypatch.setattr(ctxmod, "_default_lib_dirs", lambda: [str(libdir)])
    monkeypatch.setenv("OCL_ICD_VENDORS", str(vendors))
    msg = _raise_device_error(None)
    assert "OCL_ICD_VENDORS=/tmp/icd" in msg and str(libdir / NVLIB) in msg
    assert "OCL_ICD_VENDORS" in describe_devices()


# --------------------------------------------------------------------------- NVIDIA diagnosis

def _fake_driver(tmp_path, with_lib=True, nvidia_icd=False):
    libdir, vendors = tmp_path / "lib", tmp_path / "vendors"
    libdir.mkdir(exist_ok=True)
    vendors.mkdir(exist_ok=True)
    if with_lib:
        (libdir / NVLIB).write_bytes(b"")
    (vendors / "pocl.icd").write_text("libpocl.so.2\n")
    if nvidia_icd:
        (vendors / "nvidia.icd").write_text(f"{libdir / NVLIB}\n")
    return libdir, vendors


def test_diagnose_unregistered_library(tmp_path):
    libdir, vendors = _fake_driver(tmp_path)
    hint = diagnose_nvidia_icd([libdir], vendors, ["Portable Computing Language"])
    assert hint is not None and len(hint.splitlines()) > 1
    lib = str(libdir / NVLIB)
    assert f"echo {lib} > /tmp/icd/nvidia.icd" in hint
    assert "export OCL_ICD_VENDORS=/tmp/icd" in hint
    assert f"echo {lib} > /etc/OpenCL/vendors/nvidia.icd" in hint
    assert "pocl" in hint.lower()  # how to keep PoCL when OCL_ICD_VENDORS narrows the loader


def test_diagnose_nothing_to_fix(tmp_path):
    libdir, vendors = _fake_driver(tmp_path, nvidia_icd=True)
    assert diagnose_nvidia_icd([libdir], vendors, []) is None
    # OCL_ICD_VENDORS may name a single .icd file.
    assert diagnose_nvidia_icd([libdir], vendors / "nvidia.icd", []) is None
    (vendors / "nvidia.icd").unlink()
    assert diagnose_nvidia_icd([libdir], vendors / "pocl.icd", []) is not None
    # The platform already shows up: whatever registered it works.
    assert diagnose_nvidia_icd([libdir], vendors, ["NVIDIA CUDA"]) is None
    (libdir / NVLIB).unlink()
    assert diagnose_nvidia_icd([libdir], vendors, []) is None


def test_diagnose_default_roots():
    """The real driver folders, LD_LIBRARY_PATH and ldconfig: a fix or nothing, never an
    error (how long it takes: python -m benchmarks.fail_fast)."""
    diagnosis = diagnose_nvidia_icd()
    assert diagnosis is None or "libnvidia-opencl" in diagnosis


# --------------------------------------------------------------------------- text and contexts

def test_describe_devices_marks_selection():
    info = list_devices()[0]
    text = describe_devices()
    assert info.name in text and "*" in text and "selected:" in text
    assert "from --device cpu" in describe_devices("cpu")
    assert "*" in describe_devices(select_device("0:0"))
    with pytest.raises(DeviceError):
        describe_devices("banana")


def test_device_label():
    device = select_device("0:0")
    label = device_label(device)
    assert label.startswith(device.name.strip()) and "OpenCL" in label


def test_create_context_profiling_and_cache():
    ctx, queue = create_context("0:0")
    assert queue.properties & cl.command_queue_properties.PROFILING_ENABLE
    assert create_context("0:0") == (ctx, queue)
    assert create_context("0")[1] is queue  # cached per device, not per spelling

    host = np.arange(16, dtype=np.float32)
    buf = cl.Buffer(ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=host)
    event = cl.enqueue_copy(queue, np.empty_like(host), buf)
    event.wait()
    assert event.profile.end >= event.profile.start


def test_program_binaries_are_kept_on_disk_except_on_pocl(device, tmp_path, monkeypatch):
    """clrt keeps a built program's binary in CLRT_CACHE_DIR and a new process
    loads it -- except on PoCL, whose own cache keeps programs, and where
    taking a binary would compile every kernel for any work-group size."""
    from clrt.device import program
    monkeypatch.setenv("CLRT_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("CLRT_NO_PROGRAM_CACHE", raising=False)
    context, _ = create_context(device)
    defines = {"CLRT_TEST_BINARY_CACHE": 1}   # a program of its own, whatever else this process built
    monkeypatch.setattr(program, "_programs", {})
    program.build_program(context, "lanes.cl", defines)
    stored = list((tmp_path / "programs").glob("*.bin")) if (tmp_path / "programs").is_dir() else []
    pocl = context.devices[0].platform.name == "Portable Computing Language"
    assert program.keeps_binaries(context) == (not pocl)
    assert len(stored) == (0 if pocl else 1)
    monkeypatch.setattr(program, "_programs", {})     # as a new process
    program.build_program(context, "lanes.cl", defines)
    assert [b.from_disk for b in program.builds[-2:]] == [False, not pocl]
