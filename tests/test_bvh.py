"""BVH builders, depth-first layout and bounding volumes (host only, no OpenCL).

Every (builder x volume x leaf size) is checked on generated meshes, a triangle soup
full of tiny, degenerate and coincident triangles, and a mesh whose centroids and
box centres all coincide: tree structure, conservative volumes tested in float32
the way the kernel tests them (corners inside, rays along edges entering every
ancestor), the paper builder's median / axis rule, the SAH leaf policy, and
determinism (threads included).
"""

from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest

from clrt import accel
from clrt.accel import sah
from clrt.accel.rows import child_refs
from clrt.accel.volumes import fit
from clrt.config import HOST_BUILDERS as BUILDERS, VOLUMES
from clrt.layouts import BVH_PAIR_NODE
from clrt.accel import topdown as bvh_module
from clrt.errors import InputError
from clrt.scene import primitives

SHARED_MESHES = Path(__file__).resolve().parents[1].parent / "shared" / "meshes"
LEAF_SIZES = (1, 4, 8)


def _soup() -> np.ndarray:
    """Random triangles plus many tiny, zero-area, needle, duplicate, axis-flat and
    far-away ones."""
    rng = np.random.default_rng(7)
    centres = rng.uniform(-2, 2, (400, 1, 3))
    normal = centres + 0.05 * rng.standard_normal((400, 3, 3))
    tiny = centres[:120] + 1e-7 * rng.standard_normal((120, 3, 3))
    points = np.repeat(centres[:40], 3, axis=1)                       # zero area
    t = rng.random((40, 3, 1))
    needles = centres[40:80] + t * rng.standard_normal((40, 1, 3))    # collinear corners
    duplicates = normal[:60].copy()                                   # coincident faces
    flat = normal[100:140].copy()
    flat[:, :, 2] = 0.5                                               # in the plane z = 0.5
    far = normal[200:230] + np.array([1e4, -3e3, 7e2])                # large coordinates
    return np.concatenate([normal, tiny, points, needles, duplicates, flat, far]).astype(np.float32)


def _same_centre() -> np.ndarray:
    """Triangles of many shapes whose centroids and box centres are all exactly
    equal: on each axis the three corners sit at offsets t, -t and 0 (in some
    order) around one point, dyadic values, so no rounding anywhere."""
    rng = np.random.default_rng(3)
    t = rng.integers(-64, 65, (150, 1, 3)) / 64.0
    corner_offsets = np.stack([rng.permutation([1.0, -1.0, 0.0]) for _ in range(150 * 3)])
    offsets = corner_offsets.reshape(150, 3, 3).transpose(0, 2, 1) * t   # (triangle, corner, axis)
    offsets[:10] = 0.0                                                # point triangles
    offsets[10:20] = offsets[20:30]                                   # duplicates
    return (np.array([0.25, -0.5, 1.0]) + offsets).astype(np.float32)


def _mesh_triangles(mesh) -> np.ndarray:
    return mesh.vertices[mesh.faces]


MESHES = {
    "icosphere": lambda: _mesh_triangles(primitives.icosphere(2)),
    "torus": lambda: _mesh_triangles(primitives.torus(1.0, 0.35, 24, 12)),
    "heightfield": lambda: _mesh_triangles(primitives.heightfield(16)),
    "box": lambda: _mesh_triangles(primitives.box((1.0, 0.6, 1.4))),
    "soup": _soup,
    "same_centre": _same_centre,
}


@lru_cache(maxsize=None)
def triangles(name: str) -> np.ndarray:
    return MESHES[name]()


# One node of the tree as the tests walk it, rebuilt from the rows the kernels
# read (BVH_PAIR_NODE): volume (sphere: centre and radius in bound_a), first
# slot or left child, triangle count (0: inner), right child -- depth-first.
NODE = np.dtype([("bound_a", np.float32, 4), ("bound_b", np.float32, 4), ("left_first", np.int32),
                 ("count", np.int32), ("right", np.int32)])


class Built:
    """A build seen through its device rows: ``nodes`` (NODE, depth-first),
    ``prim_id``, ``depth``, ``stats()`` -- what the kernels get."""

    def __init__(self, acc):
        self.acc, self.prim_id, self.depth = acc, acc.prim_ids, acc.depth
        self.volume, self.builder, self.leaf_size = acc.accel, acc.builder, acc.leaf_size
        self.boxes = acc.boxes
        rows, refs = acc.rows, child_refs(acc.rows)
        assert rows.dtype == BVH_PAIR_NODE and rows.ndim == 1
        nodes = []

        def add(ref, count, a, b):
            i = len(nodes)
            node = np.zeros(1, NODE)[0]
            node["bound_a"][:3], node["count"] = a[:3], count
            if acc.accel == "sphere":
                node["bound_a"][3] = b[0]
            else:
                node["bound_b"][:3] = b[:3]
            nodes.append(node)
            if count > 0:
                node["left_first"], node["right"] = ref, -1
                return i
            row = rows[ref]
            node["left_first"] = add(refs[ref, 0], refs[ref, 1], row["left_a"], row["left_b"])
            node["right"] = add(refs[ref, 2], refs[ref, 3], row["right_a"], row["right_b"])
            return i

        # The root's own volume is never read by the kernels (they test its
        # children); it is fitted here so that every node has one.
        root_a, root_b = fit(acc.accel, acc.boxes[:1])
        root_b = root_a[0, 3:] if acc.accel == "sphere" else root_b[0]
        if refs[0, 3] == -1:        # one leaf, held on the left of the only row
            add(refs[0, 0], refs[0, 1], rows[0]["left_a"], rows[0]["left_b"])
        else:
            add(0, 0, root_a[0], root_b)
        self.nodes = np.array(nodes, NODE)

    def stats(self):
        return self.acc.stats()


def build_bvh(tri, volume="box", builder="sah", leaf_size=4) -> Built:
    return Built(accel.build(tri, volume, builder, leaf_size))


@lru_cache(maxsize=None)
def built(name: str, builder: str, volume: str, leaf_size: int):
    return build_bvh(triangles(name), volume=volume, builder=builder, leaf_size=leaf_size)


def centroids(tri: np.ndarray) -> np.ndarray:
    """The builders' centroid: mean of the float32 corners, summed in float64."""
    return (tri[:, 0].astype(np.float64) + tri[:, 1] + tri[:, 2]) / 3.0


# --------------------------------------------------------------------------------------
# Independent walks of the depth-first layout (plain loops: the meshes are small).


def subtree_info(nodes):
    """Per node: number of nodes in its subtree, depth (root 1) and slot range."""
    n = len(nodes)
    size = np.ones(n, np.int64)
    lo = np.zeros(n, np.int64)
    hi = np.zeros(n, np.int64)
    for i in range(n - 1, -1, -1):
        node = nodes[i]
        if node["count"] > 0:
            lo[i], hi[i] = node["left_first"], node["left_first"] + node["count"]
        else:
            left, right = node["left_first"], node["right"]
            size[i] = 1 + size[left] + size[right]
            assert hi[left] == lo[right], "subtree slot ranges are not contiguous"
            lo[i], hi[i] = lo[left], hi[right]
    depth = np.zeros(n, np.int64)
    depth[0] = 1
    for i in range(n):
        if nodes[i]["count"] == 0:
            depth[nodes[i]["left_first"]] = depth[nodes[i]["right"]] = depth[i] + 1
    return size, depth, lo, hi


def check_structure(bvh, n_tri: int, leaf_size: int):
    nodes = bvh.nodes
    assert nodes.dtype == NODE and nodes.ndim == 1
    assert bvh.prim_id.dtype == np.int32 and bvh.prim_id.shape == (n_tri,)
    assert np.array_equal(np.sort(bvh.prim_id), np.arange(n_tri)), "prim_id is not a permutation"
    N = len(nodes)
    idx = np.arange(N)
    leaf = nodes["count"] > 0
    inner = ~leaf
    assert (nodes["count"] >= 0).all()
    assert (nodes["count"][leaf] <= leaf_size).all(), "leaf larger than leaf_size"
    assert (nodes["right"][leaf] == -1).all()
    left, right = nodes["left_first"][inner], nodes["right"][inner]
    assert ((left > idx[inner]) & (left < N) & (right > left) & (right < N)).all()

    # Depth-first order: left child right after its parent, right child after the
    # whole left subtree; the root's subtree holds every node exactly once.
    size, depth, lo, hi = subtree_info(nodes)
    assert (left == idx[inner] + 1).all()
    assert (right == left + size[left]).all()
    assert size[0] == N
    # Leaves, in node order, tile the slots 0..F-1 with no gap and no overlap.
    first, count = nodes["left_first"][leaf], nodes["count"][leaf]
    assert first[0] == 0 and (first[1:] == first[:-1] + count[:-1]).all()
    assert first[-1] + count[-1] == n_tri
    assert lo[0] == 0 and hi[0] == n_tri
    assert bvh.depth == depth.max()
    stats = bvh.stats()
    assert stats["nodes"] == N and stats["leaves"] == leaf.sum() and stats["depth"] == bvh.depth
    assert stats["max_leaf_size"] == count.max() <= leaf_size
    assert len(bvh.acc.rows) == max(int(inner.sum()), 1)       # one 64-byte row per inner node
    assert stats["device_bytes"] == 64 * len(bvh.acc.rows) + n_tri * 4 + n_tri * 48
    assert np.isfinite(stats["sah_cost"]) and stats["sah_cost"] >= 1.0


def check_pair_rows(bvh):
    """The rows the kernels walk (one per inner node, both children's volumes and
    references, layouts.py) against the depth-first tree: walked from row 0 as
    accel_bvh.cl walks them, they hold each child's volume bit for bit and reach
    every leaf slot exactly once."""
    nodes = bvh.nodes
    rows = bvh.acc.rows
    refs = child_refs(rows)
    assert len(rows) == max(int((nodes["count"] == 0).sum()), 1)
    reached = np.zeros(len(bvh.prim_id), np.int64)

    def volume(row, side):
        a, b = rows[f"{side}_a"][row], rows[f"{side}_b"][row]
        if bvh.volume == "sphere":
            return np.r_[a[:3], b[0]]                  # radius kept in b.x
        return np.r_[a[:3], b[:3]]

    def expected(node):
        a, b = nodes["bound_a"][node], nodes["bound_b"][node]
        return np.r_[a[:3], a[3]] if bvh.volume == "sphere" else np.r_[a[:3], b[:3]]

    if nodes["count"][0] > 0:                          # one leaf: hung on the left of row 0
        assert tuple(refs[0]) == (0, nodes["count"][0], -1, -1)
        assert np.array_equal(volume(0, "left"), expected(0))
        reached[:nodes["count"][0]] += 1
    else:
        todo = [(0, 0)]                                # (row, its node)
        while todo:
            row, node = todo.pop()
            for k, (side, child) in enumerate((("left", nodes["left_first"][node]),
                                               ("right", nodes["right"][node]))):
                ref, count = refs[row, 2 * k], refs[row, 2 * k + 1]
                assert count == nodes["count"][child]
                assert np.array_equal(volume(row, side), expected(child)), (row, side)
                if count > 0:
                    assert ref == nodes["left_first"][child]
                    reached[ref:ref + count] += 1
                else:
                    todo.append((ref, child))
    assert (reached == 1).all(), "every slot in exactly one leaf row"


def check_conservative(bvh, tri: np.ndarray):
    """Every corner of every subtree's triangles passes the node's float32 test."""
    nodes = bvh.nodes
    _, _, lo, hi = subtree_info(nodes)
    owner = np.repeat(np.arange(len(nodes)), hi - lo)                    # (node, slot) pairs
    slot = np.arange(len(owner)) - np.repeat(np.cumsum(hi - lo) - (hi - lo), hi - lo) \
        + np.repeat(lo, hi - lo)
    p = tri[bvh.prim_id[slot]]                                          # (M, 3, 3) float32
    a = nodes["bound_a"][owner][:, None, :]                             # (M, 1, 4)
    b = nodes["bound_b"][owner][:, None, :]
    assert p.dtype == np.float32 and a.dtype == np.float32
    if bvh.volume == "box":
        inside = ((p >= a[..., :3]) & (p <= b[..., :3])).all(axis=2)
        # Strictly outside the exact box, so faces on the box never graze its boundary.
        exact = bvh.boxes
        assert (nodes["bound_a"][:, :3] < exact[:, 0]).all()
        assert (nodes["bound_b"][:, :3] > exact[:, 1]).all()
    elif bvh.volume == "sphere":
        d = p - a[..., :3]
        r = a[..., 3]
        inside = d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1] + d[..., 2] * d[..., 2] <= r * r
    else:
        q = (p - a[..., :3]) * b[..., :3]
        inside = q[..., 0] * q[..., 0] + q[..., 1] * q[..., 1] + q[..., 2] * q[..., 2] <= 1
        assert (nodes["bound_b"][:, :3] > 0).all() and np.isfinite(nodes["bound_b"]).all()
    assert inside.all(), f"{int((~inside).sum())} corners outside their node's {bvh.volume}"


def check_tight(bvh):
    """Padding stays tiny: volumes are close to the exact box they enclose."""
    box = bvh.boxes.astype(np.float64)
    extent = (box[:, 1] - box[:, 0]).max(axis=1)
    mag = np.abs(box).max(axis=(1, 2))
    slack = 1e-5 * extent + 1e-6 * mag + 1e-25
    a = bvh.nodes["bound_a"].astype(np.float64)
    b = bvh.nodes["bound_b"].astype(np.float64)
    if bvh.volume == "box":
        assert (box[:, 0] - a[:, :3] <= slack[:, None]).all()
        assert (b[:, :3] - box[:, 1] <= slack[:, None]).all()
    elif bvh.volume == "sphere":
        half_diag = 0.5 * np.linalg.norm(box[:, 1] - box[:, 0], axis=1)
        assert (a[:, 3] <= half_diag + 2 * slack).all()


# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("leaf_size", LEAF_SIZES)
@pytest.mark.parametrize("volume", VOLUMES)
@pytest.mark.parametrize("builder", BUILDERS)
@pytest.mark.parametrize("mesh", sorted(MESHES))
def test_structure_and_conservative_volumes(mesh, builder, volume, leaf_size):
    tri = triangles(mesh)
    bvh = built(mesh, builder, volume, leaf_size)
    assert (bvh.volume, bvh.builder, bvh.leaf_size) == (volume, builder, leaf_size)
    check_structure(bvh, len(tri), leaf_size)
    check_pair_rows(bvh)
    check_conservative(bvh, tri)
    check_tight(bvh)


def volume_test_f32(volume, a, b, o, d):
    """The kernel's ray/volume tests in float32, without their own slack (so the
    builder's padding alone must suffice).  a, b: (M, 4); o, d: (M, 3) float32."""
    if volume == "box":                                   # slab test
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = np.float32(1) / d
            t0 = (a[:, :3] - o) * inv
            t1 = (b[:, :3] - o) * inv
        enter = np.fmin(t0, t1).max(axis=1)
        leave = np.fmax(t0, t1).min(axis=1)
        return (enter <= leave) & (leave >= 0)
    if volume == "sphere":                                # closest approach
        oc = a[:, :3] - o
        along = (oc * d).sum(axis=1, dtype=np.float32)
        perp = oc - along[:, None] * d
        return a[:, 3] * a[:, 3] - (perp * perp).sum(axis=1, dtype=np.float32) >= 0
    os = (o - a[:, :3]) * b[:, :3]                        # ellipsoid -> unit sphere
    ds = d * b[:, :3]
    along = -(os * ds).sum(axis=1, dtype=np.float32) / (ds * ds).sum(axis=1, dtype=np.float32)
    perp = os + along[:, None] * ds
    return np.float32(1) - (perp * perp).sum(axis=1, dtype=np.float32) >= 0


@pytest.mark.parametrize("volume", VOLUMES)
@pytest.mark.parametrize("builder", BUILDERS)
@pytest.mark.parametrize("mesh", ["box", "heightfield", "icosphere", "soup"])
def test_rays_along_edges_enter_every_ancestor(mesh, builder, volume):
    """A ray running along a triangle edge (axis-parallel in face planes for the
    box) passes the float32 test of every node above that triangle."""
    tri = triangles(mesh)
    bvh = built(mesh, builder, volume, 1)
    nodes = bvh.nodes
    _, _, lo, hi = subtree_info(nodes)
    slot_of = np.argsort(bvh.prim_id)
    tri_id, node = [], []
    for i in range(len(nodes)):                           # (triangle, ancestor) pairs
        ids = bvh.prim_id[lo[i]:hi[i]]
        tri_id.append(ids)
        node.append(np.full(len(ids), i))
    tri_id, node = np.concatenate(tri_id), np.concatenate(node)
    assert (slot_of[tri_id] >= lo[node]).all()
    for i, j in ((0, 1), (1, 2), (2, 0)):
        start, end = tri[tri_id, i], tri[tri_id, j]
        edge = end - start
        length = np.linalg.norm(edge, axis=1)
        ok = length > 1e-3 * np.abs(start).max(axis=1).clip(1e-30)
        d = (edge[ok] / length[ok, None]).astype(np.float32)
        o = (start[ok] - edge[ok]).astype(np.float32)         # one edge length before
        hit = volume_test_f32(volume, nodes["bound_a"][node[ok]], nodes["bound_b"][node[ok]], o, d)
        assert hit.all(), f"{int((~hit).sum())} edge rays miss an ancestor {volume}"


@pytest.mark.parametrize("leaf_size", LEAF_SIZES)
@pytest.mark.parametrize("volume", VOLUMES)
@pytest.mark.parametrize("mesh", sorted(MESHES))
def test_paper_builder_splits_at_the_median(mesh, volume, leaf_size):
    """Leaf iff <= leaf_size triangles; otherwise the left child holds exactly the
    floor(n/2) triangles with the smallest (centroid[axis], id), where axis is the
    longest axis of the centroid bounds, or depth mod 3 for spheres."""
    tri = triangles(mesh)
    cen = centroids(tri)
    bvh = built(mesh, "paper", volume, leaf_size)
    nodes = bvh.nodes
    _, depth, lo, hi = subtree_info(nodes)
    for i, node in enumerate(nodes):
        ids = bvh.prim_id[lo[i]:hi[i]]
        if node["count"] > 0:
            assert len(ids) <= leaf_size
            continue
        assert len(ids) > leaf_size
        c = cen[ids]
        if volume == "sphere":
            axis = (depth[i] - 1) % 3
        else:
            axis = int(np.argmax(c.max(axis=0) - c.min(axis=0)))
        order = ids[np.lexsort((ids, c[:, axis]))]
        child = node["left_first"]
        assert hi[child] - lo[child] == len(ids) // 2
        assert set(order[:len(ids) // 2]) == set(bvh.prim_id[lo[child]:hi[child]])


def test_paper_sphere_cycles_axes_even_when_one_is_longest():
    """A soup stretched 100x along x: boxes always split x, spheres x, y, z, x."""
    rng = np.random.default_rng(1)
    tri = (rng.random((512, 1, 3)) * [100.0, 1.0, 1.0]
           + 0.01 * rng.standard_normal((512, 3, 3))).astype(np.float32)
    cen = centroids(tri)
    for volume, expected in (("box", [0, 0, 0, 0]), ("sphere", [0, 1, 2, 0])):
        bvh = build_bvh(tri, volume=volume, builder="paper", leaf_size=4)
        _, depth, lo, hi = subtree_info(bvh.nodes)
        for i, node in enumerate(bvh.nodes):
            if node["count"] > 0 or depth[i] > 4:
                continue
            l_ids = bvh.prim_id[lo[node["left_first"]]:hi[node["left_first"]]]
            r_ids = bvh.prim_id[lo[node["right"]]:hi[node["right"]]]
            axis = expected[depth[i] - 1]
            assert cen[l_ids, axis].max() <= cen[r_ids, axis].min()


@pytest.mark.parametrize("builder", BUILDERS)
def test_coincident_centres_split_by_triangle_id(builder):
    """Neither the paper's key (centroid) nor SAH's (box centre) tells these apart."""
    tri = _same_centre()
    bvh = build_bvh(tri, builder=builder, leaf_size=4)
    # Halving by id at every level leaves the slots in id order.
    assert np.array_equal(bvh.prim_id, np.arange(len(tri)))
    assert bvh.depth == int(np.ceil(np.log2(len(tri) / 4))) + 1


@pytest.mark.parametrize("mesh", ["icosphere", "torus", "soup"])
def test_sah_builder_beats_the_median_split(mesh):
    paper_cost = built(mesh, "paper", "box", 4).stats()["sah_cost"]
    sah_cost = built(mesh, "sah", "box", 4).stats()["sah_cost"]
    assert sah_cost < paper_cost


def test_sah_leaf_rule_below_leaf_size():
    """Two far-apart triangles: splitting is cheaper than one leaf even though the
    leaf size allows both; two coincident triangles stay one leaf."""
    one = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    apart = np.stack([one, one + [100, 0, 0]])
    assert build_bvh(apart, builder="sah", leaf_size=8).stats()["leaves"] == 2
    same = np.stack([one, one])
    assert build_bvh(same, builder="sah", leaf_size=8).stats()["leaves"] == 1
    # leaf_size is a hard cap even when SAH would rather not split.
    assert build_bvh(same, builder="sah", leaf_size=1).stats()["leaves"] == 2


def test_sah_depth_is_bounded_on_adversarial_input():
    """Triangles growing geometrically: SAH would peel one off per level."""
    k = np.arange(300, dtype=np.float64)
    scale = 1.3 ** k
    one = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float64)
    tri = (one[None] * scale[:, None, None] + np.stack([scale, 0 * k, 0 * k], 1)[:, None]).astype(np.float32)
    bvh = build_bvh(tri, builder="sah", leaf_size=1)
    check_structure(bvh, len(tri), 1)
    check_conservative(bvh, tri)
    assert bvh.depth <= sah.MAX_SAH_DEPTH + int(np.ceil(np.log2(len(tri)))) + 1


@pytest.mark.parametrize("volume", VOLUMES)
@pytest.mark.parametrize("builder", BUILDERS)
def test_builds_are_deterministic(builder, volume):
    tri = triangles("soup")
    a = build_bvh(tri, volume=volume, builder=builder, leaf_size=4)
    b = build_bvh(tri.copy(), volume=volume, builder=builder, leaf_size=4)
    # the uploaded rows and slot order, byte for byte
    assert a.acc.rows.tobytes() == b.acc.rows.tobytes()
    assert np.array_equal(a.prim_id, b.prim_id)
    assert a.depth == b.depth


@pytest.mark.parametrize("builder", BUILDERS)
def test_threads_do_not_change_the_tree(builder, monkeypatch):
    """Every level in threads (one per axis) builds the tree of the serial build."""
    tri = np.concatenate([triangles("soup"), triangles("torus")])
    monkeypatch.setattr(bvh_module, "BUILD_THREADS", 1)
    serial = build_bvh(tri, builder=builder, leaf_size=4)
    monkeypatch.setattr(bvh_module, "BUILD_THREADS", 3)
    monkeypatch.setattr(bvh_module, "THREADED_MIN", 0)
    threaded = build_bvh(tri, builder=builder, leaf_size=4)
    assert threaded.acc.rows.tobytes() == serial.acc.rows.tobytes()
    assert np.array_equal(threaded.prim_id, serial.prim_id)


def test_float32_key_order_is_the_stable_argsort():
    """The engine's packed integer sort of float32 keys: ties (-0.0 == +0.0
    included) by id, subnormals and huge values in place."""
    rng = np.random.default_rng(5)
    special = np.array([-3e38, -1.5, -1e-40, -0.0, 0.0, 1e-45, 2.0, 7e37], np.float32)
    keys = rng.choice(special, 5000)
    keys[::3] = rng.standard_normal(len(keys[::3])).astype(np.float32)
    assert np.array_equal(bvh_module._sorted_ids(keys), np.argsort(keys, kind="stable"))


@pytest.mark.parametrize("builder", BUILDERS)
def test_tiny_inputs(builder):
    one = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], np.float32)
    bvh = build_bvh(one, builder=builder, leaf_size=1)
    assert len(bvh.nodes) == 1 and bvh.depth == 1 and bvh.nodes[0]["count"] == 1
    assert bvh.stats()["sah_cost"] == 1.0
    tri = triangles("torus")[:200]
    big_leaves = build_bvh(tri, builder=builder, leaf_size=255)
    check_structure(big_leaves, len(tri), 255)
    if builder == "paper":
        assert len(big_leaves.nodes) == 1


def test_float64_corners_give_the_float32_tree():
    mesh = primitives.torus(1.0, 0.35, 16, 8)
    a = accel.build(mesh.vertices[mesh.faces].astype(np.float64), "ellipse", "sah")
    b = accel.build(mesh.vertices[mesh.faces].astype(np.float32), "ellipse", "sah")
    assert a.rows.tobytes() == b.rows.tobytes() and np.array_equal(a.prim_ids, b.prim_ids)


@pytest.mark.parametrize("kwargs", [
    {"volume": "cube"}, {"builder": "lbvh"}, {"leaf_size": 0}, {"leaf_size": 256},
    {"leaf_size": 2.5}, {"leaf_size": True}, {"leaf_size": "4"},
])
def test_bad_options_raise_input_error(kwargs):
    with pytest.raises(InputError) as info:
        build_bvh(triangles("box"), **kwargs)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("tri", [
    np.zeros((0, 3, 3), np.float32), np.zeros((4, 3), np.float32), np.zeros((2, 3, 2)),
    np.array([[[0, 0, 0], [1, 0, 0], [0, np.nan, 0]]]), [["a"]],
    np.array([[[0, 0, 0], [1e39, 0, 0], [0, 1, 0]]]),
])
def test_bad_triangles_raise_input_error(tri):
    with pytest.raises(InputError) as info:
        build_bvh(tri)
    assert "\n" not in str(info.value)


@pytest.mark.skipif(not SHARED_MESHES.is_dir(), reason=f"{SHARED_MESHES} not present")
@pytest.mark.parametrize("name", ["camel.off", "cow.off"])
def test_conservative_on_shared_meshes(name):
    trimesh = pytest.importorskip("trimesh")
    mesh = trimesh.load(SHARED_MESHES / name, process=False, force="mesh")
    tri = np.asarray(mesh.vertices, np.float32)[np.asarray(mesh.faces)]
    for builder in BUILDERS:
        for volume in VOLUMES:
            bvh = build_bvh(tri, volume=volume, builder=builder, leaf_size=4)
            check_structure(bvh, len(tri), 4)
            check_conservative(bvh, tri)
