"""A machine's first builds (clrt.device.first_build): on the host, while a
background process makes the device builder ready -- on PoCL by building on
the device, on a GPU by compiling the builder's and the crease split's
programs into clrt's cache; later builds on the device; the same answers
and images either way.

The rest of the suite turns the rule off (conftest.py); these tests turn it
on, with clrt's cache in a folder of their own (PoCL's own cache may hold
the builder's kernels already: the rule goes by clrt's record of them).
"""

import os
import sys
import time

import numpy as np
import pytest

import clrt
from clrt.device import first_build, first_build_process
from clrt.device.context import create_context
from clrt.device.program import on_pocl
from clrt.scene import primitives


@pytest.fixture
def fresh(tmp_path, monkeypatch):
    """The rule on, no record yet, no background build started."""
    monkeypatch.setenv("CLRT_FIRST_BUILD", "1")
    monkeypatch.setenv("CLRT_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("CLRT_NO_PROGRAM_CACHE", raising=False)
    monkeypatch.delenv("POCL_KERNEL_CACHE", raising=False)
    monkeypatch.setattr(first_build, "_helpers", [])
    return tmp_path / "first-build"


def _on_pocl(device) -> bool:
    return on_pocl(create_context(device)[0])


def _files(folder) -> list[str]:
    return sorted(p.name for p in folder.iterdir()) if folder.exists() else []


def _rays(mesh, n=3000):
    rng = np.random.default_rng(7)
    lo, hi = mesh.bounds
    origins = lo - 0.2 * (hi - lo) + 1.4 * (hi - lo) * rng.random((n, 3))
    return origins, rng.normal(size=(n, 3))


def _same_answers(accels, mesh, device, n=3000):
    """Each Accel's closest hits are brute force's, triangle and distance."""
    origins, directions = _rays(mesh, n)
    brute = clrt.Accel(mesh, device=device, accel="none").trace(origins, directions)
    for accel in accels:
        hits = accel.trace(origins, directions)
        assert np.array_equal(hits.prim, brute.prim) and np.array_equal(hits.t, brute.t)
    assert (brute.prim >= 0).sum() > n // 10


def _ready_file(fresh, device, mesh, indexed: bool = True) -> str:
    """What says the builder is ready after a background build for ``mesh``:
    PoCL's record, a GPU's program binary -- of the program for a Mesh's
    vertices and faces, which the device gathers itself (an Accel's; a
    Renderer's on a GPU), else for its corners."""
    context = create_context(device)[0]
    name = first_build.record_name(context, "box", len(mesh.faces), indexed=indexed)
    return str(fresh / name) if on_pocl(context) else str(fresh.parent / "programs" / f"{name}.bin")


def test_first_build_on_the_host_then_on_the_device(fresh, device, monkeypatch):
    started = []
    popen = first_build.subprocess.Popen
    monkeypatch.setattr(first_build.subprocess, "Popen", lambda *a, **k: started.append(a) or popen(*a, **k))
    mesh = primitives.torus(1.0, 0.3, 40, 20)
    first = clrt.Accel(mesh, device=device)
    assert first.acceleration.builder == "sah" and len(started) == 1
    during = clrt.Accel(mesh, device=device)     # while it runs (or just after): no second background build
    assert len(started) == 1 and during.acceleration.builder in ("sah", "device")
    assert first_build.wait(600) in ([0], [])    # ([]: it ended before, collected by the second call)
    assert os.path.exists(_ready_file(fresh, device, mesh))
    assert [p for p in _files(fresh) if not p.endswith(".bin")] == (
        [os.path.basename(_ready_file(fresh, device, mesh))] if _on_pocl(device) else [])   # no lock, no corners
    second = clrt.Accel(mesh, device=device)
    assert second.acceleration.builder == "device" and len(started) == 1
    assert second.acceleration.frame is not None     # (its corners gathered by the device)
    _same_answers([first, second], mesh, device)


def test_a_first_render_on_the_host_is_the_later_renders_image(fresh, device):
    """A Renderer's first build on the host (on a GPU its gather and crease
    split too), the next on the device: the same image and hits."""
    mesh = primitives.torus(1.0, 0.3, 48, 24)
    camera = clrt.Camera.framing(mesh.bounds, 96, 64)
    first = clrt.Renderer(mesh, device=device)
    assert first.acceleration.builder == "sah"
    expected = first.render(camera, hits=True)
    first_build.wait(600)
    assert os.path.exists(_ready_file(fresh, device, mesh, indexed=not _on_pocl(device)))   # (PoCL: corners)
    second = clrt.Renderer(mesh, device=device)
    assert second.acceleration.builder == "device"
    frame = second.render(camera, hits=True)
    for field in ("image", "prim", "t"):
        assert np.array_equal(getattr(frame, field), getattr(expected, field)), field
    assert (frame.prim >= 0).sum() > 300


def test_off_too_large_statistics_or_asked_for_the_device_builds_on_the_device(fresh, device, monkeypatch):
    """Each case builds on the device and starts nothing; each starts from no
    record (a device build writes one, which would hide a broken rule)."""
    from clrt.device.acceleration import build_acceleration
    mesh = primitives.torus(1.0, 0.3, 12, 8)
    corners = mesh.vertices[mesh.faces].astype(np.float32)

    def forget() -> None:
        for p in (fresh.iterdir() if fresh.exists() else ()):
            p.unlink()

    def on_the_device(**options) -> bool:
        built = clrt.Accel(mesh, device=device, **options).acceleration.builder == "device"
        forget()
        return built and not first_build._helpers

    monkeypatch.setenv("CLRT_FIRST_BUILD", "off")
    assert on_the_device()
    monkeypatch.setenv("CLRT_FIRST_BUILD", "1")
    with monkeypatch.context() as m:
        m.setattr(sys, "executable", "/opt/app/bin/blender")     # no Python to start
        assert on_the_device()
    with monkeypatch.context() as m:
        m.setattr(first_build, "HOST_FIRST_MAX_TRIANGLES", len(mesh.faces) - 1)
        assert on_the_device()
    assert on_the_device(builder="device")
    assert build_acceleration(corners, "box", "auto", 4, device, statistics=True).builder == "device"
    assert not first_build._helpers
    forget()
    assert not on_the_device()                                     # and the rule itself: the host
    first_build.wait(600)


def test_an_unwritable_cache_builds_on_the_device(tmp_path, fresh, device, monkeypatch):
    (tmp_path / "afile").write_text("")
    monkeypatch.setenv("CLRT_CACHE_DIR", str(tmp_path / "afile" / "clrt"))
    mesh = primitives.torus(1.0, 0.3, 12, 8)
    assert clrt.Accel(mesh, device=device).acceleration.builder == "device" and not first_build._helpers


def test_a_failed_background_build_leaves_its_kind_to_the_call(fresh, device):
    """The background process's own failure (here: its corners unreadable)
    leaves NAME.failed and frees the lock; that kind then builds in the call
    (on the device, as without the rule), with the right answers; a lock
    left older than LOCK_SECONDS counts as a failure too."""
    mesh = primitives.torus(1.0, 0.3, 16, 8)
    context = create_context(device)[0]
    name = first_build.record_name(context, "box", len(mesh.faces), indexed=True)
    fresh.mkdir(parents=True)
    lock = fresh / first_build.LOCK
    lock.write_text(name)
    bad = fresh / "bad.npy"
    bad.write_bytes(b"not an array")
    assert first_build_process.main(["build", str(bad), "box", "4", "", name, str(lock)]) == 1
    assert _files(fresh) == [f"{name}.failed"]
    accel = clrt.Accel(mesh, device=device)
    assert accel.acceleration.builder == "device" and not first_build._helpers
    _same_answers([accel], mesh, device, 500)

    for p in fresh.iterdir():
        p.unlink()
    lock.write_text(name)                        # a background build that died: its lock, long ago
    old = time.time() - first_build.LOCK_SECONDS - 5
    os.utime(lock, (old, old))
    assert clrt.Accel(mesh, device=device).acceleration.builder == "device" and not first_build._helpers
    assert f"{name}.failed" in _files(fresh) and first_build.LOCK not in _files(fresh)


def test_a_background_build_that_cannot_start_frees_the_lock(fresh, device, monkeypatch):
    mesh = primitives.torus(1.0, 0.3, 16, 8)
    monkeypatch.setattr(first_build.subprocess, "Popen", lambda *a, **k: (_ for _ in ()).throw(OSError("no")))
    assert clrt.Accel(mesh, device=device).acceleration.builder == "device"
    assert [n for n in _files(fresh) if n.endswith((".lock", ".npy"))] == []


class _NotStarted:
    """A background build that is only recorded (its command), never run."""

    def __init__(self, command, **kwargs):
        self.command = command

    def poll(self):
        return 0

    def wait(self, timeout=None):
        return 0


def test_a_gpus_record_is_the_program_a_build_from_a_mesh_compiles(device, monkeypatch):
    """Elsewhere than on PoCL the record is the builder's binary in clrt's
    cache: record_name(indexed=True) must name the program build_on_device
    builds from a Mesh (and indexed=False the one from corners)."""
    from clrt.device import build as device_build
    from clrt.device.program import program_digest
    monkeypatch.setattr(first_build, "on_pocl", lambda context: False)
    monkeypatch.setattr(first_build, "_names", {})
    built = []

    def spy(context, entry, defines=None, extra_options=(), kernels=None):
        built.append(program_digest(context, entry, defines, kernels))
        return real(context, entry, defines, extra_options, kernels)
    real = device_build.build_program
    monkeypatch.setattr(device_build, "build_program", spy)
    mesh = primitives.torus(1.0, 0.3, 40, 20)
    context, queue = create_context(device)
    device_build.build_on_device(context, queue, mesh)
    device_build.build_on_device(context, queue, mesh.vertices[mesh.faces].astype(np.float32))
    assert built == [first_build.record_name(context, "box", len(mesh.faces), indexed=True),
                     first_build.record_name(context, "box", len(mesh.faces), indexed=False)]
    assert built[0] != built[1]


def test_a_gpus_first_render_shades_on_the_host_while_the_programs_compile(fresh, device, monkeypatch):
    """The GPU's rule on this device (the device gathering a mesh as a GPU
    does, the record a program binary): the first Renderer builds on the
    host and shades there (no upload of the mesh), and starts one background
    build that compiles the builder for a mesh; once its binary is there,
    the next Renderer gathers and shades on the device -- the same image."""
    from clrt.device import geometry
    from clrt.device import scene as device_scene
    from clrt.device.program import cache_dir
    monkeypatch.setattr(first_build, "on_pocl", lambda context: False)
    monkeypatch.setattr(first_build, "_names", {})
    monkeypatch.setattr(device_scene, "shades_on_device",
                        lambda accel, builder, device: accel != "none" and builder in ("device", "auto"))
    monkeypatch.setattr(geometry, "WIDE_BVH_KINDS", ())
    monkeypatch.setattr(geometry, "RAY_PACKET_KINDS", ())
    started = []
    monkeypatch.setattr(first_build.subprocess, "Popen", lambda command, **k: started.append(command)
                        or _NotStarted(command))
    mesh = primitives.torus(1.0, 0.3, 48, 24)
    camera = clrt.Camera.framing(mesh.bounds, 96, 64)
    assert clrt.Accel(mesh, device=device, accel="none").acceleration.builder != "sah" and not started   # no tree
    first = clrt.Renderer(mesh, device=device)
    assert first.acceleration.builder == "sah" and first.arrays.shading is None
    name = first_build.record_name(create_context(device)[0], "box", len(mesh.faces), indexed=True)
    assert len(started) == 1 and started[0][3:] == ["compile", "box", str(len(mesh.faces)), "indexed",
                                                   device or "", name, str(fresh / first_build.LOCK)]
    expected = first.render(camera, hits=True)
    assert clrt.Renderer(mesh, device=device).acceleration.builder == "sah" and len(started) == 1   # (lock held)

    (fresh / first_build.LOCK).unlink()          # what the background build leaves: the binary, no lock
    cache_dir().mkdir(parents=True, exist_ok=True)
    (cache_dir() / f"{name}.bin").write_bytes(b"")
    second = clrt.Renderer(mesh, device=device)
    assert second.acceleration.builder == "device" and second.arrays.shading is not None and len(started) == 1
    frame = second.render(camera, hits=True)
    for field in ("image", "prim", "t"):
        assert np.array_equal(getattr(frame, field), getattr(expected, field)), field
