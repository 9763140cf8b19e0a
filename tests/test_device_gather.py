"""A mesh's corners gathered on the device by its build (build_frame.cl), as
Accel does (clrt.device.scene.gathers_on_device), against the host's gather
on the same device, with the GPU's choices (binary rows, no packets) and with
the device's own (a CPU's wide BVH and packets): the device frame, the box,
the uploaded triangles, the tree and every answer are the host path's, bit for
bit -- near the origin, far from it (a moved frame), with vertices no face
uses (outside the box), and so spread that the reach measures the corners."""

import numpy as np
import pyopencl as cl
import pytest

import clrt
from clrt.device import geometry, scene
from clrt.device.build_kernels import launched_kernels
from clrt.layouts import BVH_PAIR_NODE, TRIANGLE_VERTS
from clrt.query.results import POINT_FIELDS
from clrt.scene import primitives
from clrt.scene.mesh import Mesh


def _meshes():
    torus = primitives.torus(1.0, 0.35, 40, 20)
    v, f = torus.vertices.astype(np.float64), torus.faces
    far = Mesh.from_arrays(v * (1.0, 3.0, 0.5) + (3000.0, 0.5, -2000.0), f, "far")
    unused = Mesh.from_arrays(np.concatenate([v, [[50.0, -80.0, 9.0], [-1e6, 0.0, 0.0]]]), f, "unused vertices")
    spread = Mesh.from_arrays(np.concatenate([v, v + (2e9, 0.0, 0.0)]), np.concatenate([f, f + len(v)]), "spread")
    return {"torus": torus, "far": far, "unused": unused, "spread": spread}


def _read(queue, buffer):
    out = np.empty(buffer.size, np.uint8)
    cl.enqueue_copy(queue, out, buffer, is_blocking=True)
    return out


@pytest.mark.parametrize("name, rows", [("torus", "binary"), ("far", "binary"), ("unused", "binary"),
                                        ("spread", "binary"), ("torus", "own"), ("far", "own")])
def test_corners_gathered_by_the_device_are_the_hosts(name, rows, device, monkeypatch):
    mesh = _meshes()[name]
    if rows == "binary":
        monkeypatch.setattr(geometry, "WIDE_BVH_KINDS", ())
        monkeypatch.setattr(geometry, "RAY_PACKET_KINDS", ())
    monkeypatch.setattr(scene, "gathers_on_device", lambda accel, builder, device: False)
    host = clrt.Accel(mesh, builder="device", device=device)
    assert host.acceleration.frame is None
    monkeypatch.setattr(scene, "gathers_on_device", lambda accel, builder, device: True)
    fresh = Mesh.from_arrays(mesh.vertices, mesh.faces)      # no bounds computed yet
    gathered = clrt.Accel(fresh, builder="device", device=device)
    lo, hi, origin = gathered.acceleration.frame
    assert np.array_equal(origin, host.geometry.origin) and np.array_equal(gathered.geometry.origin, origin)
    assert origin.any() == (name == "far")
    assert np.array_equal(np.array([lo, hi]), mesh.bounds) and np.array_equal(fresh.bounds, mesh.bounds)
    assert gathered.geometry.reach.area == host.geometry.reach.area   # (measured on the corners for "spread")
    queue = host.queue
    used = {"tris": TRIANGLE_VERTS.itemsize * len(mesh.faces), "prim_ids": 4 * len(mesh.faces),
            "nodes": BVH_PAIR_NODE.itemsize * host.acceleration.num_rows}    # (the buffers may hold more)
    assert gathered.acceleration.num_rows == host.acceleration.num_rows
    if host.geometry.wide is not None:      # (a CPU's own: the wide nodes and packets collapsed on the device)
        assert gathered.geometry.wide.nbytes == host.geometry.wide.nbytes
        used["wide"] = host.geometry.wide.nbytes
    for name, nbytes in used.items():
        a, b = (_read(queue, accel.geometry.buffers[name][0])[:nbytes] for accel in (host, gathered))
        assert len(a) == nbytes and np.array_equal(a, b), name
    rng = np.random.default_rng(3)
    lo, hi = mesh.bounds
    origins = rng.uniform(lo - 0.2 * (hi - lo), hi + 0.2 * (hi - lo), (3000, 3))
    targets = mesh.vertices[mesh.faces[rng.integers(len(mesh.faces), size=3000), 0]].astype(np.float64)
    directions = targets + rng.normal(scale=0.3, size=(3000, 3)) - origins     # (toward the triangles)
    want, got = host.trace(origins, directions), gathered.trace(origins, directions)
    assert want.hit.sum() > 300
    for field in want._fields:
        assert np.array_equal(getattr(got, field), getattr(want, field)), field
    points = np.concatenate([rng.uniform(lo, hi, (500, 3)), targets[:500] + rng.normal(size=(500, 3))])
    want, got = host.closest_points(points), gathered.closest_points(points)
    for field in POINT_FIELDS:
        assert np.array_equal(getattr(got, field), getattr(want, field), equal_nan=True), field


def test_a_gathering_build_launches_the_gather(monkeypatch):
    """The build from a Mesh launches the two gather kernels, which its program keeps."""
    from clrt.device import build
    from clrt.device.context import create_context

    context, queue = create_context("cpu")
    built = build.build_on_device(context, queue, _meshes()["far"], profile=True)
    launched = {name for name, _, _ in built.launches}
    assert {"gather_corners", "shift_corners"} <= launched <= set(launched_kernels("cpu", tail=True, indexed=True))
    assert built.frame[2].any()
