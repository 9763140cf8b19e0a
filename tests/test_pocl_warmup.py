"""A machine's first builds on PoCL (clrt.device.pocl_warmup): on the host,
while a background process compiles the device builder's kernels; later
builds on the device; the same answers either way.

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
from clrt.device import pocl_warmup, pocl_warmup_process
from clrt.device.context import create_context
from clrt.device.program import on_pocl
from clrt.scene import primitives


@pytest.fixture
def fresh(tmp_path, monkeypatch):
    """The rule on, no record yet, no background build started."""
    monkeypatch.setenv("CLRT_POCL_WARMUP", "1")
    monkeypatch.setenv("CLRT_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("CLRT_NO_PROGRAM_CACHE", raising=False)
    monkeypatch.delenv("POCL_KERNEL_CACHE", raising=False)
    monkeypatch.setattr(pocl_warmup, "_helpers", [])
    return tmp_path / "pocl-ready"


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


def test_first_build_on_the_host_then_on_the_device(fresh, device, monkeypatch):
    started = []
    popen = pocl_warmup.subprocess.Popen
    monkeypatch.setattr(pocl_warmup.subprocess, "Popen", lambda *a, **k: started.append(a) or popen(*a, **k))
    mesh = primitives.torus(1.0, 0.3, 40, 20)
    first = clrt.Accel(mesh, device=device)
    if not _on_pocl(device):     # (the suite on a GPU: the rule is PoCL's alone)
        assert first.acceleration.builder == "device" and not started and not _files(fresh)
        return
    assert first.acceleration.builder == "sah" and len(started) == 1
    during = clrt.Accel(mesh, device=device)     # while it runs (or just after): no second background build
    assert len(started) == 1 and during.acceleration.builder in ("sah", "device")
    assert pocl_warmup.wait(600) in ([0], [])    # ([]: it ended before, collected by the second call)
    name = pocl_warmup.record_name(create_context(device)[0], "box", len(mesh.faces))
    assert _files(fresh) == [name]               # the record; no lock, no corners left
    second = clrt.Accel(mesh, device=device)
    assert second.acceleration.builder == "device" and len(started) == 1
    _same_answers([first, second], mesh, device)


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
        return built and not pocl_warmup._helpers

    monkeypatch.setenv("CLRT_POCL_WARMUP", "off")
    assert on_the_device()
    monkeypatch.setenv("CLRT_POCL_WARMUP", "1")
    with monkeypatch.context() as m:
        m.setattr(sys, "executable", "/opt/app/bin/blender")     # no Python to start
        assert on_the_device()
    with monkeypatch.context() as m:
        m.setattr(pocl_warmup, "HOST_FIRST_MAX_TRIANGLES", len(mesh.faces) - 1)
        assert on_the_device()
    assert on_the_device(builder="device")
    assert build_acceleration(corners, "box", "auto", 4, device, statistics=True).builder == "device"
    assert not pocl_warmup._helpers
    forget()
    assert not on_the_device() or not _on_pocl(device)            # and the rule itself, on PoCL: the host
    pocl_warmup.wait(600)


def test_an_unwritable_cache_builds_on_the_device(tmp_path, fresh, device, monkeypatch):
    (tmp_path / "afile").write_text("")
    monkeypatch.setenv("CLRT_CACHE_DIR", str(tmp_path / "afile" / "clrt"))
    mesh = primitives.torus(1.0, 0.3, 12, 8)
    assert clrt.Accel(mesh, device=device).acceleration.builder == "device" and not pocl_warmup._helpers


def test_a_failed_background_build_leaves_its_kind_to_the_call(fresh, device):
    """The background process's own failure (here: its corners unreadable)
    leaves NAME.failed and frees the lock; that kind then builds in the call
    (on the device, as without the rule), with the right answers; a lock
    left older than LOCK_SECONDS counts as a failure too."""
    mesh = primitives.torus(1.0, 0.3, 16, 8)
    context = create_context(device)[0]
    if not _on_pocl(device):
        assert not pocl_warmup.applies(context)
        return
    name = pocl_warmup.record_name(context, "box", len(mesh.faces))
    fresh.mkdir(parents=True)
    lock = fresh / pocl_warmup.LOCK
    lock.write_text(name)
    bad = fresh / "bad.npy"
    bad.write_bytes(b"not an array")
    assert pocl_warmup_process.main([str(bad), "box", "4", "", name, str(lock)]) == 1
    assert _files(fresh) == [f"{name}.failed"]
    accel = clrt.Accel(mesh, device=device)
    assert accel.acceleration.builder == "device" and not pocl_warmup._helpers
    _same_answers([accel], mesh, device, 500)

    for p in fresh.iterdir():
        p.unlink()
    lock.write_text(name)                        # a background build that died: its lock, long ago
    old = time.time() - pocl_warmup.LOCK_SECONDS - 5
    os.utime(lock, (old, old))
    assert clrt.Accel(mesh, device=device).acceleration.builder == "device" and not pocl_warmup._helpers
    assert f"{name}.failed" in _files(fresh) and pocl_warmup.LOCK not in _files(fresh)


def test_a_background_build_that_cannot_start_frees_the_lock(fresh, device, monkeypatch):
    mesh = primitives.torus(1.0, 0.3, 16, 8)
    if not _on_pocl(device):
        return
    monkeypatch.setattr(pocl_warmup.subprocess, "Popen", lambda *a, **k: (_ for _ in ()).throw(OSError("no")))
    assert clrt.Accel(mesh, device=device).acceleration.builder == "device"
    assert [n for n in _files(fresh) if n.endswith((".lock", ".npy"))] == []
