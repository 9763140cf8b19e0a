"""clrt.ProximityQuery, the drop-in for trimesh's ``mesh.nearest``, against
trimesh's own brute force (``trimesh.proximity.closest_point_naive``, numpy)
and the exact winding number: the same closest points and distances, the
triangle facing the point among equally near ones (as trimesh picks it),
trimesh's sign convention, a changed mesh followed, pickles, one-line errors.
tools/trimesh_ray_tests.py runs trimesh's own proximity tests through it."""

import copy
import pickle

import numpy as np
import pytest
import trimesh

import clrt
from clrt.errors import InputError
from test_inside import exact_winding_numbers


def _meshes():
    return {"icosphere": trimesh.creation.icosphere(subdivisions=2), "box": trimesh.creation.box((1.0, 0.6, 1.4)),
            "torus": trimesh.creation.torus(1.0, 0.35, major_sections=24, minor_sections=12)}


def _points(mesh, seed=0):
    rng = np.random.default_rng(seed)
    lo, hi = mesh.bounds
    around = lo + (rng.random((150, 3)) * 1.6 - 0.3) * (hi - lo)
    # the last five: just outside the surface, within trimesh's tol.merge (1e-8) of it
    return np.concatenate([around, mesh.vertices[:10] * 1.2, mesh.vertices[10:15] + 1e-10 * mesh.vertex_normals[10:15]])


@pytest.mark.parametrize("name", sorted(_meshes()))
def test_on_surface_is_trimesh_brute_force(name, device):
    mesh = _meshes()[name]
    points = _points(mesh)
    closest, distance, tid = clrt.ProximityQuery(mesh, device=device).on_surface(points)
    assert closest.dtype == np.float64 and distance.dtype == np.float64 and tid.dtype == np.int64
    want_closest, want_distance, want_tid = trimesh.proximity.closest_point_naive(mesh, points)
    np.testing.assert_allclose(distance, want_distance, rtol=0, atol=1e-12)
    # the same triangle, or one as near (a shared edge or corner) that faces the point at least as much
    same = tid == want_tid
    assert same.mean() > 0.5
    np.testing.assert_allclose(closest[same], want_closest[same], rtol=0, atol=1e-12)
    vector = points - closest
    facing = lambda t: np.einsum("ij,ij->i", mesh.face_normals[t], vector)   # noqa: E731
    assert (facing(tid)[~same] >= facing(want_tid)[~same] - 1e-12).all()
    np.testing.assert_allclose(np.linalg.norm(vector, axis=1), distance, rtol=0, atol=1e-12)


def test_equally_near_triangles_go_to_the_one_facing_the_point(device):
    """Points beyond a sharp edge: both faces on it are as near, and each
    point gets the face its side of the edge sees -- trimesh's choice, which
    its own test_acute_edge_case asks for."""
    v = [[-1, 0.5, 0], [1, 0.5, 0], [0, -1, -0.5], [0, -1, 0.5]]
    mesh = trimesh.Trimesh(v, [[0, 1, 2], [0, 2, 3], [0, 3, 1], [3, 2, 1]])
    points = np.stack([np.zeros(10), np.ones(10), np.linspace(-1, 1, 10)], axis=1)
    closest, distance, tid = clrt.ProximityQuery(mesh, device=device).on_surface(points)
    np.testing.assert_allclose(closest, np.tile([0, 0.5, 0], (10, 1)), atol=1e-12)
    below, above = tid[:5], tid[5:]
    assert len(set(below)) == 1 and len(set(above)) == 1 and below[0] != above[0]
    for side, faces in ((-1, below), (1, above)):   # the chosen face's normal leans to the points' side
        assert np.sign(mesh.face_normals[faces[0], 2]) == side


def test_signed_distance_has_trimeshs_sign(device):
    mesh = _meshes()["torus"]
    points = _points(mesh, seed=1)
    mesh.nearest = clrt.ProximityQuery(mesh, device=device)   # the one-line switch
    got = mesh.nearest.signed_distance(points)
    _, distance, _ = trimesh.proximity.closest_point_naive(mesh, points)
    inside = exact_winding_numbers(points, mesh.triangles) > 0.5
    on = distance <= 1e-8
    assert on.sum() == 5 and not inside[on].any() and inside.sum() >= 20
    np.testing.assert_allclose(np.abs(got), distance, atol=1e-12)
    assert (got[inside & ~on] > 0).all() and (got[~inside & ~on] < 0).all() and (got[on] > 0).all()
    box = trimesh.creation.box()
    near_box = clrt.ProximityQuery(box, device=device)
    # far outside yet in a face's plane, far outside off it, and the centre
    got = near_box.signed_distance([box.bounds[0] + [100, 0, 0], box.bounds[0] + [100, 100, 100], [0, 0, 0]])
    assert got[0] < 0 and got[1] < 0 and got[2] == pytest.approx(0.5)


def test_a_changed_mesh_is_followed_and_copies_work(device):
    mesh = trimesh.creation.icosphere(subdivisions=2)
    query = clrt.ProximityQuery(mesh, device=device)
    point = [[0.0, 0.0, 3.0]]
    assert query.on_surface(point)[1][0] == pytest.approx(2.0, abs=1e-6)
    mesh.vertices = mesh.vertices * 2
    assert query.on_surface(point)[1][0] == pytest.approx(1.0, abs=1e-6)
    for other in (pickle.loads(pickle.dumps(query)), copy.deepcopy(query)):
        np.testing.assert_array_equal(other.on_surface(point)[1], query.on_surface(point)[1])
    empty = query.on_surface(np.zeros((0, 3)))
    assert empty[0].shape == (0, 3) and empty[1].shape == (0,) and empty[2].shape == (0,)


@pytest.mark.parametrize("points, message", [
    ([[0, 0, np.nan]], "point 0 is [0.0, 0.0, nan]: points must be finite"),
    (np.zeros((4, 2)), "points must have shape (3,) or (N, 3), got (4, 2)"),
])
def test_bad_points_are_one_line(points, message, device):
    query = clrt.ProximityQuery(trimesh.creation.icosphere(subdivisions=1), device=device)
    for call in (query.on_surface, query.signed_distance):
        with pytest.raises(InputError) as err:
            call(points)
        assert message in str(err.value) and "\n" not in str(err.value)
