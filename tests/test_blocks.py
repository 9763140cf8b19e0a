"""Large arrays worked in blocks on several threads (clrt.scene.blocks) give
what one pass over the whole array gives: the mesh checks (the same one-line
errors, whichever block the bad value lies in), the bounds of the vertices
the faces use, and the triangles' corners, moved into the device's frame."""

import numpy as np
import pytest

from clrt.errors import MeshLoadError
from clrt.scene import blocks
from clrt.scene import mesh as mesh_module
from clrt.scene.arrays import device_origin, triangle_corners
from clrt.scene.mesh import Mesh, column_bounds, min_max
from clrt.scene.primitives import torus


@pytest.fixture
def small_blocks(monkeypatch):
    """Blocks of 64 rows on four threads, so that a test mesh spans many, and
    min_max reducing 16 rows at a time in each."""
    monkeypatch.setattr(blocks, "BLOCK_ROWS", 64)
    monkeypatch.setattr(blocks, "thread_count", lambda: 4)
    monkeypatch.setattr(mesh_module, "MIN_MAX_ROWS", 16)


def _mesh(seed=3, far=0.0) -> tuple[np.ndarray, np.ndarray]:
    base = torus(n_major=40, n_minor=20)
    rng = np.random.default_rng(seed)
    vertices = (base.vertices + rng.normal(0.0, 0.01, base.vertices.shape) + far).astype(np.float32)
    unused = np.full((7, 3), 1e6 + far, np.float32)                # never used by a face: not in the bounds
    return np.concatenate([vertices, unused]), base.faces


def test_blocks_cover_every_row_once(small_blocks):
    for rows in (0, 1, 63, 64, 127, 128, 255, 256, 1000):
        spans = blocks.spans(rows)
        assert len(spans) <= 4 and spans[0][0] == 0 and spans[-1][1] == rows
        assert all(a[1] == b[0] for a, b in zip(spans, spans[1:]))
    assert blocks.map_blocks(lambda start, stop: (start, stop), 1000) == blocks.spans(1000)


@pytest.mark.parametrize("far", (0.0, 3.0e4))
def test_bounds_and_corners_in_blocks_are_those_of_one_pass(small_blocks, far):
    vertices, faces = _mesh(far=far)
    mesh = Mesh(vertices, faces)
    used = vertices[np.unique(faces)].astype(np.float64)
    assert np.array_equal(mesh.bounds, np.stack([used.min(axis=0), used.max(axis=0)]))
    assert np.array_equal(column_bounds(vertices), np.stack([vertices.min(axis=0), vertices.max(axis=0)]))
    origin = device_origin(mesh.bounds)
    assert np.any(origin) == (far > 0)                          # the far copy is moved into its own frame
    want = vertices[faces] - origin.astype(np.float32)
    assert np.array_equal(triangle_corners(mesh, origin), want)
    assert np.array_equal(triangle_corners(mesh), vertices[faces])
    assert min_max(faces) == (faces.min(), faces.max())


@pytest.mark.parametrize("corner", (0, 1, 2, None))
def test_bounds_mark_the_used_vertices_corner_by_corner(small_blocks, monkeypatch, corner):
    """Mesh.bounds marks the vertices the faces' first corners use, then the
    second's, then the third's (casting 16 rows' indices at a time here): a
    far vertex used by one face's ``corner`` alone (None: by no face) is in
    the bounds exactly when it is used."""
    monkeypatch.setattr(mesh_module, "MARK_ROWS", 16)
    vertices, faces = _mesh()
    faces = faces.copy()
    if corner is not None:
        faces[300, corner] = len(vertices) - 1                     # one of the far vertices
    used = vertices[np.unique(faces)].astype(np.float64)
    bounds = Mesh(vertices, faces).bounds
    assert np.array_equal(bounds, np.stack([used.min(axis=0), used.max(axis=0)]))
    assert (bounds[1] >= 1e6).all() == (corner is not None)


@pytest.mark.parametrize("row", (0, 70, 500, -1))
def test_bad_values_in_any_block_give_the_one_line_errors(small_blocks, row):
    vertices, faces = _mesh()
    bad = vertices.copy()
    bad[row, 1] = np.nan
    with pytest.raises(MeshLoadError, match=r"^1 vertices have NaN or infinite coordinates \(the first: vertex "):
        Mesh(bad, faces)
    far = vertices.astype(np.float64)
    far[row, 2] = 3e30
    with pytest.raises(MeshLoadError, match=r"^vertex coordinates must lie within \+-1e30"):
        Mesh(far, faces)
    wrong = faces.copy()
    wrong[row % len(faces), 0] = len(vertices)
    with pytest.raises(MeshLoadError, match=rf"^face index out of range \(indices 0..{len(vertices)}, "):
        Mesh(vertices, wrong)


def test_a_forked_child_works_in_blocks_too(small_blocks):
    """A child forked after the parent's threads worked blocks (a process pool
    loading meshes) has none of those threads: it makes its own, rather than
    waiting forever on blocks no thread will take."""
    import multiprocessing
    vertices, faces = _mesh()
    Mesh(vertices, faces).bounds                                   # the parent's pool is running
    context = multiprocessing.get_context("fork")
    with context.Pool(1) as pool:
        got = pool.apply_async(_child_bounds, (vertices, faces)).get(timeout=60)
    assert np.array_equal(got, Mesh(vertices, faces).bounds)


def _child_bounds(vertices, faces):
    blocks.BLOCK_ROWS, blocks.thread_count = 64, lambda: 4        # (the fixture's patch, in the child too)
    return Mesh(vertices, faces).bounds
