"""Inside and outside (Accel.winding_number, contains, signed_distance,
sdf_grid and their one-call forms) against a float64 numpy reference written
here: the exact sum of the triangles' solid angles (van Oosterom and
Strackee), and brute-force distances (tests/test_point_queries.py's).
Winding numbers lie within WINDING_NUMBER_ERROR of the exact sum through every
volume, builder and after a refit (exact without a BVH); signed distances are
the distances bit for bit, negative exactly where the exact winding number of
a closed mesh says inside, by every sign rule; bad input is one line."""

import re
from pathlib import Path

import numpy as np
import pytest

import clrt
from clrt.errors import InputError
from clrt.query.inside import GRID_MARGIN, pseudo_normals
from clrt.query.results import INSIDE_FIELDS, WINDING_NUMBER_ERROR
from clrt.scene import primitives
from clrt.scene.mesh import Mesh
from test_point_queries import _bound, reference


# The directions of the parity rule's rays, read from the kernel (point.cl).
PARITY_DIRECTIONS = np.array([[float(x) for x in re.findall(r"-?\d+\.\d+", row)] for row in re.findall(
    r"\{(-?[\d.]+f, -?[\d.]+f, -?[\d.]+f)\}",
    (Path(clrt.__file__).parent / "kernels" / "point.cl").read_text())])


def exact_winding_numbers(points, corners) -> np.ndarray:
    """(N,) float64: the sum of every triangle's signed solid angle seen from
    each point, over 4 pi; a triangle whose plane holds the point exactly
    gives 0 (the mean of the two sides', as winding.cl takes it)."""
    p = np.asarray(points, np.float64)[:, None]
    c = np.asarray(corners, np.float64)[None]
    a, b, d = c[:, :, 0] - p, c[:, :, 1] - p, c[:, :, 2] - p
    la, lb, ld = (np.linalg.norm(x, axis=2) for x in (a, b, d))
    det = np.einsum("nfk,nfk->nf", a, np.cross(b, d))
    den = (la * lb * ld + np.einsum("nfk,nfk->nf", a, b) * ld + np.einsum("nfk,nfk->nf", b, d) * la
           + np.einsum("nfk,nfk->nf", d, a) * lb)
    angle = np.where(det == 0, 0.0, 2 * np.arctan2(det, den))
    return angle.sum(axis=1) / (4 * np.pi)


def points_across_one_half(a, b, corners) -> np.ndarray:
    """float32 points just either side of where the exact winding number of
    the triangles ``corners`` crosses 1/2 on segments a -> b (those it crosses
    on): found by bisection, then offset 1e-5 to 1e-3 along each segment."""
    wa, wb = exact_winding_numbers(a, corners), exact_winding_numbers(b, corners)
    keep = (wa - 0.5) * (wb - 0.5) < 0
    a, b, wa = a[keep], b[keep], wa[keep]
    for _ in range(40):   # bisection on the exact winding number
        mid = (a + b) / 2
        wm = exact_winding_numbers(mid, corners)
        same = (wm - 0.5) * (wa - 0.5) > 0
        a, wa = np.where(same[:, None], mid, a), np.where(same, wm, wa)
        b = np.where(same[:, None], b, mid)
    along = (b - a) / np.linalg.norm(b - a, axis=1, keepdims=True)
    offsets = np.array([-1e-3, -1e-4, -1e-5, 1e-5, 1e-4, 1e-3])
    points = (a[:, None] + offsets[None, :, None] * along[:, None]).reshape(-1, 3).astype(np.float32)
    return points


def _slab() -> Mesh:
    """A plate 2 x 2 x 0.02: thin, so points inside lie near both large faces."""
    return primitives.box((2.0, 2.0, 0.02))


def _split_box() -> Mesh:
    """A box whose triangles share no vertex (a triangle soup of a closed
    surface): pseudo-normals must merge corners by position."""
    box = primitives.box((1.0, 0.6, 1.4))
    corners = box.vertices[box.faces].reshape(-1, 3)
    return Mesh.from_arrays(corners, np.arange(len(corners)).reshape(-1, 3), "split box")


def _tetrahedron() -> Mesh:
    """Sharp edges (70.5 degrees inside): outside them, one face's normal alone
    may give the wrong side where the other face's is right."""
    v = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], np.float64)
    return Mesh.from_arrays(v, np.array([[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]]), "tetrahedron")


CLOSED = {"torus": lambda: primitives.torus(1.0, 0.35, 24, 12), "icosphere": lambda: primitives.icosphere(2),
          "box": lambda: primitives.box((1.0, 0.6, 1.4)), "slab": _slab, "split box": _split_box,
          "tetrahedron": _tetrahedron}
OPEN = {"heightfield": lambda: primitives.heightfield(12),
        "hemisphere": lambda: _hemisphere()}


def _hemisphere() -> Mesh:
    sphere = primitives.icosphere(2)
    keep = sphere.vertices[sphere.faces][:, :, 1].min(axis=1) > -0.3
    return Mesh.from_arrays(sphere.vertices, sphere.faces[keep], "open sphere")


def _beside_edges(mesh, rng, count: int, size: float) -> np.ndarray:
    """Points off ``count`` edges that two faces share (vertices merged by
    position), each near one face's normal and leaning to the other's: the
    closest feature is the edge, where one face's normal may point wrong."""
    _, merged = np.unique(mesh.vertices, axis=0, return_inverse=True)
    f = merged.reshape(-1)[mesh.faces]
    keys = np.concatenate([np.sort(f[:, [k, (k + 1) % 3]], axis=1) for k in range(3)])
    face = np.tile(np.arange(len(f)), 3)
    order = np.lexsort(keys.T[::-1])
    same = (keys[order][1:] == keys[order][:-1]).all(axis=1)
    pairs = np.stack([face[order][:-1][same], face[order][1:][same]], axis=1)
    pairs = pairs[rng.permutation(len(pairs))[:count]]
    corners = mesh.vertices[mesh.faces].astype(np.float64)
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    out = []
    for a, b in pairs:
        shared = [v for v in mesh.vertices[mesh.faces[a]] if np.isclose(mesh.vertices[mesh.faces[b]], v).all(1).any()]
        mid = (shared[0] + shared[1]) / 2
        for n1, n2 in ((normal[a], normal[b]), (normal[b], normal[a])):
            lean = 0.9 * n1 + 0.1 * n2
            out.append(mid + 0.02 * size * lean / np.linalg.norm(lean))
    return np.array(out).reshape(-1, 3)


def _points(mesh, seed=0) -> np.ndarray:
    """Points around and inside the mesh's box, at its vertices, far away,
    inside its thin parts (a shell just under the surface) and beside its
    edges; float32."""
    rng = np.random.default_rng(seed)
    lo, hi = mesh.bounds.astype(np.float64)
    size = np.linalg.norm(hi - lo)
    around = lo + (rng.random((120, 3)) * 1.3 - 0.15) * (hi - lo)
    vertices = mesh.vertices[rng.integers(len(mesh.vertices), size=12)]
    far = (lo + hi) / 2 + 50 * size * rng.normal(size=(8, 3))
    corners = mesh.vertices[mesh.faces].astype(np.float64)
    f = rng.integers(len(corners), size=30)
    w = rng.dirichlet((1, 1, 1), size=30)
    normal = np.cross(corners[f, 1] - corners[f, 0], corners[f, 2] - corners[f, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    under = np.einsum("nk,nkj->nj", w, corners[f]) - 2e-3 * size * normal * rng.choice([-1, 1], size=(30, 1))
    edges = _beside_edges(mesh, rng, 12, size)
    return np.concatenate([around, vertices, far, under, edges]).astype(np.float32)


def _exact(mesh, points):
    return exact_winding_numbers(points, mesh.vertices[mesh.faces].astype(np.float32))


@pytest.mark.parametrize("name", sorted(CLOSED) + sorted(OPEN))
def test_winding_numbers_match_the_exact_sum(name, device):
    mesh = {**CLOSED, **OPEN}[name]()
    points = _points(mesh)
    exact = _exact(mesh, points)
    accel = clrt.Accel(mesh, device=device)
    w = accel.winding_number(points)
    assert w.dtype == np.float32 and w.shape == (len(points),)
    assert np.abs(w - exact).max() <= WINDING_NUMBER_ERROR
    if name in CLOSED:   # the reference itself: 1 inside, 0 outside (but at the vertices, _points' 120..131)
        off_surface = np.delete(exact, np.s_[120:132])
        assert ((np.abs(off_surface) < 1e-9) | (np.abs(off_surface - 1) < 1e-9)).all()
        assert 20 < (exact > 0.5).sum() < len(points) - 20
    else:
        assert ((exact > 0.05) & (exact < 0.95)).sum() >= 10   # an open mesh's fractions
    np.testing.assert_array_equal(accel.contains(points), w >= 0.5)
    # brute force sums every triangle exactly, as the reference does, in double precision
    brute = clrt.Accel(mesh, accel="none", device=device).winding_number(points)
    assert np.abs(brute - exact).max() <= 1e-6


def test_contains_decides_near_one_half_as_the_winding_number(device):
    """contains takes a first walk that opens few children and decides only
    where its proven error bound leaves no doubt (winding.cl's
    winding_inside): points of an open bowl whose exact winding numbers lie
    within 1e-6 to 1e-3 of 1/2 (found by bisection along random segments) are
    inside exactly where winding_number says so, and where the exact sum
    does (away from 1/2 by more than winding_number's error)."""
    bowl = primitives.icosphere(3)
    bowl = Mesh.from_arrays(bowl.vertices, bowl.faces[bowl.vertices[bowl.faces][:, :, 1].min(axis=1) > 0.2], "bowl")
    corners = bowl.vertices[bowl.faces].astype(np.float32)
    rng = np.random.default_rng(23)
    # vertical segments through the bowl's opening (y = 0.2), under its dome (y > 0.7 there): w is
    # continuous along them, above 1/2 at the top, below at the bottom
    xz = rng.uniform(-0.5, 0.5, (400, 2))
    a = np.stack([xz[:, 0], np.full(400, 0.6), xz[:, 1]], axis=1)
    b = np.stack([xz[:, 0], np.full(400, -0.3), xz[:, 1]], axis=1)
    points = points_across_one_half(a, b, corners)
    exact = _exact(bowl, points)
    assert len(points) >= 300 and (np.abs(exact - 0.5) < 1e-4).sum() >= 100
    accel = clrt.Accel(bowl, device=device)
    inside, w = accel.contains(points), accel.winding_number(points)
    np.testing.assert_array_equal(inside, w >= 0.5)
    clear = np.abs(exact - 0.5) > WINDING_NUMBER_ERROR
    np.testing.assert_array_equal(inside[clear], exact[clear] >= 0.5)


def test_points_on_a_face_and_at_corners(device):
    """A point on a face of a box (exactly in the plane of two triangles) has
    winding number 1/2; one at a corner, the exact sum of the others'."""
    mesh = primitives.box((1.0, 0.6, 1.4))
    points = np.array([[0.1, 0.2, 0.7], [0.5, -0.1, 0.3], [0.0, 0.3, 0.0], *mesh.vertices], np.float32)
    w = clrt.Accel(mesh, device=device).winding_number(points)
    exact = _exact(mesh, points)
    np.testing.assert_allclose(exact[:3], 0.5, atol=1e-12)
    assert np.abs(w - exact).max() <= WINDING_NUMBER_ERROR


@pytest.mark.parametrize("name", sorted(CLOSED))
def test_signed_distances_by_every_rule(name, device):
    """Distances bit for bit the distance query's; negative exactly where the
    exact winding number says inside, away from the surface."""
    mesh = CLOSED[name]()
    points = _points(mesh, seed=1)
    accel = clrt.Accel(mesh, device=device)
    distance = accel.distance(points)
    inside = _exact(mesh, points) > 0.5
    clear = distance > 1e-4 * np.linalg.norm(np.ptp(mesh.bounds, axis=0))
    assert clear.sum() >= len(points) - 15 and inside[clear].sum() >= 20
    for sign in ("winding", "parity", "normal"):
        got = accel.signed_distance(points, sign=sign)
        assert got.dtype == np.float32 and got.shape == (len(points),)
        np.testing.assert_array_equal(np.abs(got), distance, err_msg=sign)
        np.testing.assert_array_equal(got[clear] < 0, inside[clear], err_msg=sign)
    # rays through vertices: each point sees a vertex exactly along one of the
    # parity rule's directions (there a ray meets every triangle around it)
    aimed = (mesh.vertices[:, None] - 0.3 * np.linalg.norm(np.ptp(mesh.bounds, axis=0))
             * PARITY_DIRECTIONS[None]).reshape(-1, 3).astype(np.float32)
    aimed_inside = _exact(mesh, aimed) > 0.5
    aimed_clear = accel.distance(aimed) > 1e-4
    assert aimed_clear.sum() > len(aimed) // 2
    np.testing.assert_array_equal(accel.signed_distance(aimed, sign="parity")[aimed_clear] < 0,
                                  aimed_inside[aimed_clear])
    # the float64 brute force's distances, as the distance query is held to
    exact = reference(points, mesh.vertices[mesh.faces])[0].min(axis=1)
    assert (np.abs(np.abs(accel.signed_distance(points)) - exact) <= _bound(mesh, points)).all()


def test_every_volume_and_builder_gives_the_same_answers(device):
    mesh = primitives.torus(1.0, 0.35, 24, 12)
    points = _points(mesh, seed=2)
    exact = _exact(mesh, points)
    away = np.abs(exact - 0.5) > 0.1
    first = None
    for accel in ("none", "box", "sphere", "ellipse"):
        for builder in (("sah",) if accel == "none" else ("sah", "paper", "device")):
            a = clrt.Accel(mesh, accel=accel, builder=builder, leaf_size=2, device=device)
            w = a.winding_number(points)
            assert np.abs(w - exact).max() <= WINDING_NUMBER_ERROR, (accel, builder)
            answers = [a.contains(points)[away]] + [a.signed_distance(points, sign=s) for s in
                                                     ("winding", "parity", "normal")]
            if first is None:
                first = answers
            for got, want in zip(answers, first):
                np.testing.assert_array_equal(got, want, err_msg=f"{accel} {builder}")


def test_a_refitted_accel_answers_for_the_moved_mesh(device):
    mesh = primitives.torus(1.0, 0.35, 24, 12)
    points = _points(mesh, seed=3)
    accel = clrt.Accel(mesh, device=device)
    before = accel.winding_number(points)
    assert np.abs(before - _exact(mesh, points)).max() <= WINDING_NUMBER_ERROR
    moved = Mesh.from_arrays(mesh.vertices * [1.3, 0.8, 1.1] + [0.1, 0, 0], mesh.faces)
    accel.refit(moved.vertices)
    assert np.abs(accel.winding_number(points) - _exact(moved, points)).max() <= WINDING_NUMBER_ERROR
    want = clrt.Accel(moved, accel="none", device=device).signed_distance(points, sign="normal")
    np.testing.assert_array_equal(accel.signed_distance(points, sign="normal"), want)


def test_chunks_single_points_device_arrays_and_one_call_forms(device):
    import pyopencl.array as cla
    mesh = primitives.icosphere(2)
    points = _points(mesh, seed=4)
    accel = clrt.Accel(mesh, device=device)
    whole = {"w": accel.winding_number(points), "sd": accel.signed_distance(points, sign="parity")}
    chunked = clrt.Accel(mesh, device=device, chunk_rays=7)
    np.testing.assert_array_equal(chunked.winding_number(points), whole["w"])
    np.testing.assert_array_equal(chunked.signed_distance(points, sign="parity"), whole["sd"])
    assert accel.winding_number(points[5]).shape == (1,) and accel.winding_number(points[5])[0] == whole["w"][5]
    np.testing.assert_array_equal(accel.winding_number(points.astype(np.float64)), whole["w"])
    on_device = cla.to_device(accel.queue, points)
    got = accel.winding_number(on_device)
    assert isinstance(got, cla.Array)
    np.testing.assert_array_equal(got.get(), whole["w"])
    np.testing.assert_array_equal(accel.contains(on_device).get(), (whole["w"] >= 0.5).astype(np.uint8))
    np.testing.assert_array_equal(accel.signed_distance(on_device, sign="parity").get(), whole["sd"])
    np.testing.assert_array_equal(clrt.winding_number(mesh, points, device=device), whole["w"])
    np.testing.assert_array_equal(clrt.contains(mesh, points, device=device), whole["w"] >= 0.5)
    np.testing.assert_array_equal(clrt.signed_distance(mesh, points, sign="parity", device=device), whole["sd"])
    assert accel.winding_number(np.zeros((0, 3))).shape == (0,)
    assert accel.contains(np.zeros((0, 3))).dtype == INSIDE_FIELDS["inside"].dtype
    split = clrt.Accel(mesh, device=device, max_buffer_bytes=8192)
    assert split.geometry.parts() > 1
    # split buffers walk the binary rows, where a CPU device walks the wide BVH otherwise: the far fields of
    # other children, as close to the exact sum
    assert np.abs(split.winding_number(points) - _exact(mesh, points)).max() <= WINDING_NUMBER_ERROR
    np.testing.assert_array_equal(split.contains(points), split.winding_number(points) >= 0.5)
    np.testing.assert_array_equal(split.signed_distance(points, sign="normal"),
                                  accel.signed_distance(points, sign="normal"))


def test_sdf_grid_samples_and_bounds(device):
    mesh = primitives.torus(1.0, 0.35, 24, 12)
    accel = clrt.Accel(mesh, device=device, chunk_rays=100)
    grid = accel.sdf_grid((6, 5, 4))
    assert grid.shape == (6, 5, 4) and grid.dtype == np.float32
    lo, hi = mesh.bounds
    margin = GRID_MARGIN * np.ptp(mesh.bounds, axis=0).max()
    axes = [np.linspace(lo[k] - margin, hi[k] + margin, n) for k, n in enumerate((6, 5, 4))]
    samples = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    np.testing.assert_array_equal(grid.reshape(-1), accel.signed_distance(samples))
    assert (grid < 0).any() and (grid > 0).any()
    bounds = ((-1.5, -0.5, -1.5), (1.5, 0.5, 1.5))
    cube = clrt.sdf_grid(mesh, 5, bounds, sign="normal", device=device)
    samples = np.stack(np.meshgrid(*[np.linspace(bounds[0][k], bounds[1][k], 5) for k in range(3)],
                                   indexing="ij"), axis=-1).reshape(-1, 3)
    np.testing.assert_array_equal(cube.reshape(-1), accel.signed_distance(samples, sign="normal"))
    assert cube[2, 2, 2] > 0 and cube[0, 2, 2] > 0   # the hole, and a point outside
    ring = np.array([1.0, 0.0, 0.0])   # on the tube's centre line: inside, about 0.34 from the facets
    assert -0.35 < accel.signed_distance(ring)[0] < -0.33


def test_pseudo_normals_merge_split_corners():
    box, split = primitives.box((1.0, 0.6, 1.4)), _split_box()
    a = pseudo_normals(box.vertices, box.faces)
    b = pseudo_normals(split.vertices, split.faces)
    np.testing.assert_allclose(b["edge"], a["edge"], atol=1e-6)
    np.testing.assert_allclose(b["vertex"], a["vertex"], atol=1e-6)
    # a box corner's pseudo-normal points along its diagonal (three right angles, weighted alike)
    corner = a["vertex"][0, 0, :3]
    np.testing.assert_allclose(np.abs(corner), np.full(3, 3 ** -0.5), atol=1e-6)


@pytest.mark.parametrize("call", ["winding_number", "contains", "signed_distance"])
@pytest.mark.parametrize("points, message", [
    ([[0, 0, np.nan]], "point 0 is [0.0, 0.0, nan]: points must be finite"),
    ([[1, 2, 3], [0, np.inf, 0]], "point 1 is [0.0, inf, 0.0]: points must be finite"),
    ([[1e39, 0, 0]], "point 0 is [1e+39, 0.0, 0.0]: 1e39 overflows float32"),
    (np.zeros((4, 2)), "points must have shape (3,) or (N, 3), got (4, 2)"),
    (np.zeros(3, "U1"), "points must be real numbers, got dtype <U1"),
])
def test_bad_points_are_one_line(call, points, message, device):
    accel = _small(device)
    with pytest.raises(InputError) as err:
        getattr(accel, call)(points)
    assert message in str(err.value) and "\n" not in str(err.value)


_ACCELS = {}


def _small(device):
    if device not in _ACCELS:
        _ACCELS[device] = clrt.Accel(primitives.icosphere(1), device=device)
    return _ACCELS[device]


@pytest.mark.parametrize("call, message", [
    (lambda a: a.signed_distance([0, 0, 0], sign="inside"), "sign must be one of winding, parity, normal, got "),
    (lambda a: a.sdf_grid(8, sign=None), "sign must be one of winding, parity, normal, got None"),
    (lambda a: a.sdf_grid(1), "resolution must be an integer >= 2, got 1"),
    (lambda a: a.sdf_grid(8.0), "resolution must be an integer >= 2, got 8.0"),
    (lambda a: a.sdf_grid((4, 4)), "resolution must be an integer >= 2 or 3 of them, got "),
    (lambda a: a.sdf_grid((4, 4, "x")), "resolution must be an integer >= 2, got "),
    (lambda a: a.sdf_grid(4, bounds=(0, 1)), "bounds must be ((xmin, ymin, zmin), (xmax, ymax, zmax)), got "),
    (lambda a: a.sdf_grid(4, bounds=((0, 0, 0), (1, np.nan, 1))), "bounds[1] must be 3 finite numbers, got "),
    (lambda a: a.sdf_grid(4, bounds=((0, 0, 0), (1, 0, 1))), "bounds must have min < max on every axis"),
    (lambda a: a.sdf_grid(10 ** 6), "an SDF grid of 1000000 x 1000000 x 1000000 samples needs "),
])
def test_bad_options_are_one_line(call, message, device):
    with pytest.raises(clrt.ClrtError) as err:
        call(_small(device))
    assert str(err.value).startswith(message) and "\n" not in str(err.value)


@pytest.mark.parametrize("call", [clrt.winding_number, clrt.contains, clrt.signed_distance,
                                  lambda mesh, points, **kw: clrt.sdf_grid(mesh, 4, **kw)])
def test_a_mesh_without_faces_is_one_line(call, device):
    with pytest.raises(InputError) as err:
        call((np.zeros((3, 3)), np.zeros((0, 3), int)), [0, 0, 0], device=device)
    assert "\n" not in str(err.value)
    with pytest.raises(InputError, match="^sign must be one of"):
        clrt.signed_distance(primitives.icosphere(1), [0, 0, 0], sign="nearest", device=device)


def test_the_guide_lists_every_inside_value():
    """docs/ray-queries.md's table of the inside queries' values, in its own section."""
    text = (Path(__file__).resolve().parents[1] / "docs" / "ray-queries.md").read_text()
    section = text[text.index("## Inside and outside"):]
    section = section[:section.index("\n## ", 1)]
    rows = [line for line in section.splitlines() if line.startswith("| `")]
    assert len(rows) == len(INSIDE_FIELDS)
    for name, field in INSIDE_FIELDS.items():
        assert any(row.startswith(f"| `{name}` | (N,) | {np.dtype(field.dtype).name} |") for row in rows), name


@pytest.mark.parametrize("name", sorted(CLOSED) + sorted(OPEN))
def test_cell_regions_of_gpus_keep_the_answers(name, device, monkeypatch):
    """GPUs take a child's far field only where the whole cell of the point is
    far from it (POINT_CELL_REGIONS, point_order.cl's point_region): the same
    program choice on this device, through the binary walk (sphere volumes),
    stays within the documented error, contains agrees with it, and the
    distances of the signed distances are the per-point walk's bit for bit."""
    import clrt.query.accel as query_accel

    mesh = {**CLOSED, **OPEN}[name]()
    points = _points(mesh, seed=3)
    exact = _exact(mesh, points)
    # (both programs chosen here: a GPU's own choice has the cell regions)
    monkeypatch.setattr(query_accel, "point_defines", lambda _: {})
    plain = clrt.Accel(mesh, accel="sphere", device=device)
    monkeypatch.setattr(query_accel, "point_defines", lambda _: {"POINT_CELL_REGIONS": None})
    regions = clrt.Accel(mesh, accel="sphere", device=device)
    w = regions.winding_number(points)
    assert np.abs(w - exact).max() <= WINDING_NUMBER_ERROR
    np.testing.assert_array_equal(regions.contains(points), w >= 0.5)
    assert not np.array_equal(w, plain.winding_number(points))   # the regions did change the walk
    np.testing.assert_array_equal(np.abs(regions.signed_distance(points)), np.abs(plain.signed_distance(points)))
