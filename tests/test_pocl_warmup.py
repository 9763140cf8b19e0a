"""A machine's first builds on PoCL (clrt.device.pocl_warmup): on the host,
while a background process compiles the device builder's kernels; later
builds on the device; the same answers either way.

The rest of the suite turns the rule off (conftest.py); these tests turn it
on, with clrt's cache in a folder of their own (PoCL's own cache may hold
the builder's kernels already: the rule goes by clrt's record of them).
"""

import numpy as np
import pytest

import clrt
from clrt.device import pocl_warmup, pocl_warmup_process
from clrt.device.context import create_context
from clrt.scene import primitives


@pytest.fixture
def fresh(tmp_path, monkeypatch):
    """The rule on, no record yet, no background build started."""
    monkeypatch.setenv("CLRT_POCL_WARMUP", "1")
    monkeypatch.setenv("CLRT_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("CLRT_NO_PROGRAM_CACHE", raising=False)
    monkeypatch.setattr(pocl_warmup, "_started", set())
    monkeypatch.setattr(pocl_warmup, "_helpers", [])
    return tmp_path / "pocl-ready"


def _on_pocl(device) -> bool:
    return all(d.platform.name == "Portable Computing Language" for d in create_context(device)[0].devices)


def _rays(mesh, n=3000):
    rng = np.random.default_rng(7)
    lo, hi = mesh.bounds
    origins = lo - 0.2 * (hi - lo) + 1.4 * (hi - lo) * rng.random((n, 3))
    return origins, rng.normal(size=(n, 3))


def _answers(accel, origins, directions):
    hits = accel.trace(origins, directions)
    return hits.prim, hits.t


def test_first_build_on_the_host_then_on_the_device(fresh, device):
    mesh = primitives.torus(1.0, 0.3, 40, 20)
    origins, directions = _rays(mesh)
    first = clrt.Accel(mesh, device=device)
    if not _on_pocl(device):     # (the suite on a GPU: the rule is PoCL's alone)
        assert first.acceleration.builder == "device" and not pocl_warmup._helpers
        return
    assert first.acceleration.builder == "sah" and len(pocl_warmup._helpers) == 1
    pocl_warmup.wait(600)
    assert pocl_warmup._helpers[0].returncode == 0
    records = sorted(p.name for p in fresh.iterdir())
    assert len(records) == 1 and records[0].endswith("-small"), records   # no lock, no corners left
    second = clrt.Accel(mesh, device=device)
    assert second.acceleration.builder == "device" and len(pocl_warmup._helpers) == 1
    brute = clrt.Accel(mesh, device=device, accel="none")
    want = _answers(brute, origins, directions)
    for accel in (first, second):
        prim, t = _answers(accel, origins, directions)
        assert np.array_equal(prim, want[0]) and np.array_equal(t, want[1])
    assert (want[0] >= 0).sum() > 500


def test_off_too_large_or_asked_for_the_device_builds_on_the_device(fresh, device, monkeypatch):
    mesh = primitives.torus(1.0, 0.3, 12, 8)
    assert clrt.Accel(mesh, device=device, builder="device").acceleration.builder == "device"
    monkeypatch.setattr(pocl_warmup, "HOST_FIRST_MAX_TRIANGLES", len(mesh.faces) - 1)
    assert clrt.Accel(mesh, device=device).acceleration.builder == "device"
    monkeypatch.setattr(pocl_warmup, "HOST_FIRST_MAX_TRIANGLES", 10 ** 6)
    monkeypatch.setenv("CLRT_POCL_WARMUP", "0")
    assert clrt.Accel(mesh, device=device).acceleration.builder == "device"
    assert not pocl_warmup._helpers


def test_a_failed_background_build_is_marked_and_not_started_again(fresh, device):
    """The background process's own failure (here: its corners unreadable)
    leaves NAME.failed in place of its lock, and no other starts while it
    is recent: the builds go on on the host, with the right answers."""
    if not _on_pocl(device):
        assert not pocl_warmup.applies(create_context(device)[0])
        return
    mesh = primitives.torus(1.0, 0.3, 16, 8)
    context = create_context(device)[0]
    name = pocl_warmup.record_name(context, "box", len(mesh.faces))
    fresh.mkdir(parents=True)
    lock = fresh / f"{name}.lock"
    assert pocl_warmup._take(lock)
    bad = fresh / "bad.npy"
    bad.write_bytes(b"not an array")
    assert pocl_warmup_process.main([str(bad), "box", "4", "", name, str(lock)]) == 1
    assert sorted(p.name for p in fresh.iterdir()) == [f"{name}.failed"]
    assert not pocl_warmup._take(lock)
    accel = clrt.Accel(mesh, device=device)
    assert accel.acceleration.builder == "sah" and not pocl_warmup._helpers
    origins, directions = _rays(mesh, 500)
    want = _answers(clrt.Accel(mesh, device=device, accel="none"), origins, directions)
    got = _answers(accel, origins, directions)
    assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
