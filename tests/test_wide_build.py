"""The wide BVH collapsed on the device (clrt/device/wide_build.py,
build_wide.cl) is the host's collapse (clrt/accel/wide.py) bit for bit:
nodes, packets, each lane's binary child and the depth, for trees of every
builder and leaf size -- one leaf, leaves of one triangle, leaves of two and
more packets, subtrees merged into one leaf -- and tie scenes.  The host's
collapse is itself checked against the SAH optimum and for every box and
triangle (tests/test_wide.py)."""

import numpy as np
import pyopencl as cl
import pytest

import clrt
from clrt.accel.wide import collapse
from clrt.device import geometry
from clrt.device.acceleration import build_acceleration
from clrt.device.context import create_context
from clrt.device.wide_build import DeviceWideBvh, collapse_on_device
from clrt.layouts import BVH_PAIR_NODE, TRIANGLE_VERTS
from clrt.scene.arrays import triangle_corners, triangle_verts

from conftest import TEST_MESHES
from test_ties import SCENES
from test_wide import knot

CORNERS = {
    "knot": lambda: triangle_corners(knot()).astype(np.float32),
    "torus": lambda: triangle_corners(TEST_MESHES["torus"]()).astype(np.float32),
    "heightfield": lambda: triangle_corners(TEST_MESHES["heightfield"]()).astype(np.float32),
    **{f"ties-{name}": (lambda make=make: triangle_corners(make(np.random.default_rng(3))).astype(np.float32))
       for name, make in SCENES.items()},
    "one triangle": lambda: np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], np.float32),
    "three triangles": lambda: np.random.default_rng(1).random((3, 3, 3)).astype(np.float32),
}


def _on_device(context, queue, rows: np.ndarray, slotted: np.ndarray) -> DeviceWideBvh:
    """collapse_on_device of host rows and slot-ordered corners, uploaded."""
    mf = cl.mem_flags
    rows_buffer = cl.Buffer(context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(rows))
    tris = cl.Buffer(context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=triangle_verts(slotted))
    return collapse_on_device(context, queue, rows_buffer, len(rows), tris)


def _same(got: DeviceWideBvh, want) -> None:
    assert got.depth == want.depth
    assert got.packets_at == want.packets_at and got.nbytes == want.nbytes
    assert np.array_equal(got.sources, want.sources)
    assert got.nodes.tobytes() == want.nodes.tobytes()
    assert got.packets.tobytes() == want.packets.tobytes()


@pytest.mark.parametrize("builder, leaf", [("sah", 1), ("sah", 4), ("paper", 8), ("sah", 16), ("device", 4),
                                           ("device", 2)])
@pytest.mark.parametrize("name", list(CORNERS))
def test_device_collapse_is_the_host_collapse(name, builder, leaf, device):
    context, queue = create_context(device)
    if "cl_khr_fp64" not in queue.device.extensions:
        pytest.skip("the collapse's costs are float64")
    corners = CORNERS[name]()
    acc = build_acceleration(corners, "box", builder, leaf, device)
    slotted = corners[acc.prim_ids]
    want = collapse(acc.rows, slotted)
    _same(_on_device(context, queue, acc.rows, slotted), want)
    if name == "one triangle":        # the whole tree one leaf, on the left of the root row
        assert len(want.nodes) == 1 and (want.nodes["count"][0] >= 0).sum() == 1


def test_accel_takes_the_device_collapse_of_its_device_build(device):
    """An Accel of a tree built on a CPU device walks the wide BVH collapsed
    there (none is uploaded from the host); its host copies are the host's
    collapse, and a refit moves the boxes and corners on the device."""
    mesh = knot()
    accel = clrt.Accel(mesh, builder="device", device=device)
    rows_as_built = accel.acceleration.rows.copy()
    if accel.geometry.wide is None:
        pytest.skip("the device under test does not walk the wide BVH")
    wide = accel.geometry.wide
    assert isinstance(wide, DeviceWideBvh) and accel.geometry.buffers["wide"] == (wide.buffer,)
    corners = triangle_corners(mesh).astype(np.float32)
    want = collapse(accel.acceleration.rows, corners[accel.acceleration.prim_ids])
    _same(wide, want)
    assert accel.geometry.packets_at == want.packets_at
    accel.refit(mesh.vertices * np.array([1.2, 0.9, 1.0]))      # (tests/test_wide.py: its answers)
    tris = np.empty(len(mesh.faces), TRIANGLE_VERTS)
    cl.enqueue_copy(accel.queue, tris, accel.geometry.buffers["tris"][0])     # the device's frame, slot order
    refitted = collapse(rows_as_built, corners[accel.acceleration.prim_ids])   # the tree as built, refitted
    refitted.refit(accel.acceleration.rows, tris.view(np.float32).reshape(-1, 3, 4)[:, :, :3])
    on_device = np.empty(want.nbytes, np.uint8)
    cl.enqueue_copy(accel.queue, on_device, wide.buffer)
    assert on_device.tobytes() == refitted.nodes.tobytes() + refitted.packets.tobytes()
    assert refitted.nodes.tobytes() != want.nodes.tobytes()


def test_host_trees_are_collapsed_on_the_host(device, monkeypatch):
    """A tree built on the host is collapsed there and uploaded (the device
    collapse starts from a device build's buffers)."""
    accel = clrt.Accel(knot(), builder="sah", device=device)
    if accel.geometry.wide is None:
        pytest.skip("the device under test does not walk the wide BVH")
    assert not isinstance(accel.geometry.wide, DeviceWideBvh)
    monkeypatch.setattr(geometry, "WIDE_BVH_KINDS", ())
    assert clrt.Accel(knot(), builder="device", device=device).geometry.wide is None
    assert BVH_PAIR_NODE.itemsize == 64 and TRIANGLE_VERTS.itemsize == 48    # (as build_wide.cl reads them)
