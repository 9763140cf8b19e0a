"""clrt.RayMeshIntersector as a drop-in for trimesh's intersectors: copies and
pickles, one hit per surface crossing, and merging only what is one place.

Counts are checked against what the geometry says (a convex closed mesh is
crossed twice by a ray through its inside; two surfaces a millimetre apart are
two places) and against clrt's own per-triangle query (Accel.all_hits).
"""

import copy
import pickle

import numpy as np
import pytest
import trimesh

import clrt


def _down(n):
    return np.tile([0.0, 0.0, -1.0], (n, 1))


def _queries(r, origins, directions):
    """Every answer of an intersector, as plain arrays."""
    tri, ray, loc = r.intersects_id(origins, directions, return_locations=True)
    return [r.intersects_first(origins, directions), r.intersects_any(origins, directions), tri, ray, loc]


# --------------------------------------------------------------------------- copies and pickles

def test_pickle_deepcopy_and_copy_leave_the_device_behind(device):
    mesh = trimesh.creation.icosphere(subdivisions=2)
    mesh.ray = clrt.RayMeshIntersector(mesh, device=device, leaf_size=2)
    rng = np.random.default_rng(4)
    origins = rng.normal(size=(50, 3)) * 3
    directions = -origins + rng.normal(size=(50, 3)) * 0.3
    expected = _queries(mesh.ray, origins, directions)       # the device state now exists
    assert mesh.ray._accel is not None
    state = mesh.ray.__getstate__()
    assert not {"_accel", "_corners", "_normals"} & set(state)
    assert state["_options"]["leaf_size"] == 2

    unpickled = pickle.loads(pickle.dumps(mesh))             # the whole mesh, .ray included
    assert isinstance(unpickled.ray, clrt.RayMeshIntersector) and unpickled.ray.mesh is unpickled
    assert unpickled.ray._accel is None                       # made again on first use
    copies = [unpickled.ray, copy.deepcopy(mesh.ray), copy.copy(mesh.ray),
              pickle.loads(pickle.dumps(mesh.ray))]
    for other in copies:
        for got, want in zip(_queries(other, origins, directions), expected):
            assert np.array_equal(got, want)
    assert copies[1].mesh is not mesh and copies[2].mesh is mesh
    assert copies[0]._accel is not None and copies[0]._accel is not mesh.ray._accel
    # trimesh's own copies: a fresh mesh of the same shape, with its own intersector
    for other in (mesh.copy(), copy.deepcopy(mesh)):
        assert np.array_equal(other.ray.intersects_first(origins, directions), expected[0])


# --------------------------------------------------------------------------- one place, one hit

def test_a_millimetre_box_far_away_is_crossed_twice(device):
    """A 1 mm box seen from z = 1e4: the two faces are one float32 step or two
    apart in t there, but they are 1 mm apart, far more than the mesh's size
    allows to merge (1e-5 of it)."""
    box = trimesh.creation.box(extents=[1e-3] * 3)
    r = clrt.RayMeshIntersector(box, device=device)
    xy = np.linspace(-4.5e-4, 4.5e-4, 9)
    origins = np.array([[x, y, 1e4] for x in xy for y in xy] + [[0.0, 0.0, 1e4]])
    tri, ray, loc = r.intersects_id(origins, _down(len(origins)), return_locations=True)
    assert np.array_equal(np.bincount(ray, minlength=len(origins)), np.full(len(origins), 2))
    np.testing.assert_allclose(loc[:, 2], np.tile([5e-4, -5e-4], len(origins)), atol=1e-9)
    np.testing.assert_allclose(loc[:, :2], origins[ray, :2], atol=1e-12)
    assert (box.face_normals[tri][:, 2] == np.tile([1.0, -1.0], len(origins))).all()
    for every in (True, False):                               # with locations, both ways
        loc, ray, _ = r.intersects_location(origins, _down(len(origins)), every_triangle=every)
        assert (np.bincount(ray, minlength=len(origins)) == 2).all()
    # and the same box at the origin, seen from 10 mm
    near = clrt.RayMeshIntersector(box, device=device)
    _, ray = near.intersects_id(origins - [0, 0, 1e4 - 1e-2], _down(len(origins)))
    assert (np.bincount(ray, minlength=len(origins)) == 2).all()


def test_surfaces_merge_only_where_they_are_one_place(device):
    # two separate parallel squares 1e-4 of the size apart: two places ...
    square = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    gap = 2.8e-4                                              # 1e-4 of the size (2 sqrt 2)
    two = trimesh.Trimesh(np.r_[square, square + [0, 0, -gap]], np.r_[faces, faces + 4], process=False)
    origins = np.array([[0.3, 0.1, 1.0], [-0.5, 0.7, 1.0]])
    for every in (False, True):
        r = clrt.RayMeshIntersector(two, device=device, every_triangle=every)
        _, ray, loc = r.intersects_id(origins, _down(2), return_locations=True)
        assert np.array_equal(ray, [0, 0, 1, 1])
        np.testing.assert_allclose(loc[:, 2], [0, -gap, 0, -gap], atol=1e-12)
    # ... and a copy of one square on itself (no shared vertex): one place
    same = trimesh.Trimesh(np.r_[square, square], np.r_[faces, faces + 4], process=False)
    r = clrt.RayMeshIntersector(same, device=device)
    tri, ray = r.intersects_id(origins, _down(2))
    assert np.array_equal(ray, [0, 1]) and set(tri) <= {0, 1}       # the lower index of the pair
    assert len(r.intersects_id(origins, _down(2), every_triangle=True)[1]) == 4
    # a sharp roof: two faces sharing the ridge, crossed at two places by a ray
    # parallel to it -- touching triangles, yet two crossings
    roof = trimesh.Trimesh([[-1, 0, 0], [1, 0, 0], [0, -1, 0.01], [0, 1, 0.01]], [[0, 1, 2], [1, 0, 3]],
                           process=False)
    r = clrt.RayMeshIntersector(roof, device=device)
    _, ray, loc = r.intersects_id([[0.2, -2.0, 0.005]], [[0.0, 1.0, 0.0]], return_locations=True)
    assert len(ray) == 2 and abs(loc[1, 1] - loc[0, 1]) > 0.9


def _crossing_rays(mesh, rng, count):
    """Rays through the mesh's centre region that pass exactly through vertices
    and through points on edges (from outside, both ways)."""
    v = mesh.vertices
    edge = mesh.edges_unique[rng.integers(0, len(mesh.edges_unique), count)]
    w = rng.random((count, 1))
    on_edge = (1 - w) * v[edge[:, 0]] + w * v[edge[:, 1]]
    targets = np.r_[v[rng.integers(0, len(v), count)], on_edge]
    inner = rng.normal(size=targets.shape) * 0.2 * mesh.scale / 4
    origins = inner + 3 * (targets - inner)                 # outside, on the line through both
    return origins, targets - origins


@pytest.mark.parametrize("name", ["icosphere", "cylinder"])
def test_rays_through_vertices_and_edges_cross_a_convex_mesh_twice(name, device):
    mesh = {"icosphere": lambda: trimesh.creation.icosphere(subdivisions=2),
            "cylinder": lambda: trimesh.creation.cylinder(radius=1.0, height=4.0, sections=32)}[name]()
    rng = np.random.default_rng(8)
    origins, directions = _crossing_rays(mesh, rng, 300)
    # trimesh's issue 457 rays too: along the cylinder's axis, some through the
    # caps' fan edges and one through the centre vertex every cap triangle shares
    xy = np.r_[np.linspace(-0.6, 0.6, 16), 0.0]
    axis_origins = np.array([[x, y, -5.0] for x in xy for y in xy])
    origins = np.r_[origins, axis_origins]
    directions = np.r_[directions, np.tile([0.0, 0.0, 1.0], (len(axis_origins), 1))]
    r = clrt.RayMeshIntersector(mesh, device=device)
    _, ray = r.intersects_id(origins, directions)
    assert (np.bincount(ray, minlength=len(origins)) == 2).all()
    # every triangle met, as clrt's own count (and trimesh's numpy engine) lists them
    _, every = r.intersects_id(origins, directions, every_triangle=True)
    per_triangle = np.bincount(every, minlength=len(origins))
    assert np.array_equal(per_triangle, r.accel.count(origins, directions, tmin=-1e-30))
    assert (per_triangle > 2).sum() > 50, "the rays meet shared edges and vertices"
    # locations: the crossings are where the rays enter and leave
    loc, lray, _ = r.intersects_location(origins, directions)
    assert (np.bincount(lray, minlength=len(origins)) == 2).all()
    assert r.contains_points(loc.reshape(-1, 2, 3).mean(axis=1)).all()


def test_a_ray_from_a_vertex_on_the_surface_counts_it_at_t_zero(device):
    """trimesh's test_embree_duplicate_hits: from a vertex on the top face of a
    subdivided box, straight down: the top face (at t = 0) and the bottom face,
    at every scale."""
    for scale in (1e-4, 1.0, 1e4, 1e8):
        mesh = trimesh.creation.box().subdivide().subdivide()
        mesh.apply_scale(scale)
        r = clrt.RayMeshIntersector(mesh, device=device)
        tri, _, loc = r.intersects_id([[0.0, 0.0, scale / 2]], _down(1), return_locations=True)
        assert len(tri) == 2, scale
        np.testing.assert_allclose(loc[:, 2], [scale / 2, -scale / 2], rtol=1e-12)
        assert r.intersects_first([[0.0, 0.0, scale / 2]], _down(1))[0] == tri[0]
        # every triangle at those two vertices
        assert len(r.intersects_id([[0.0, 0.0, scale / 2]], _down(1), every_triangle=True)[0]) > 2
