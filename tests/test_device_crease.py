"""The crease split, the smooth vertex normals and the per-slot TriangleInfo
made by the device (kernels/crease.cl, clrt.device.crease), as a Renderer on
a GPU makes them, against the host's (Mesh.split_at_creases,
Mesh.vertex_normals, flatten_scene) bit for bit: the same split vertices in
the same order, the same faces, the same normals -- on meshes with hard
edges, repeated vertices (STL), edges of three and more faces, degenerate
and duplicated triangles, -0.0 beside 0.0, unused vertices, one triangle;
at crease angles 0, 45 and 180 and flat (no split).  Then a Renderer forced
onto the device path renders the host path's image, without ever making
the split on the host."""

from pathlib import Path

import numpy as np
import pytest

import clrt
from clrt.device import crease as device_crease
from clrt.device import scene as device_scene
from clrt.device.context import create_context
from clrt.device.crease import crease_kernels, shade_on_device, upload_mesh
from clrt.device.program import expand_source, keep_kernels
from clrt.scene import primitives
from clrt.scene.arrays import flatten_scene
from clrt.scene.load import load_mesh
from clrt.scene.mesh import Mesh
from clrt.scene.scene import Camera, Material, Scene, SceneObject, scene_from_mesh

REPO = Path(__file__).resolve().parents[1]
SHARED_MESHES = REPO.parent / "shared" / "meshes"


def _book(pages: int = 5) -> Mesh:
    """Triangles sharing one edge (a non-manifold edge of ``pages`` faces),
    half of them running it the other way, listed in no order, with a page
    twice (the same triangle, and turned over) and a page in the plane of
    another (a smooth pair among creases)."""
    angles = np.linspace(0.0, np.pi, pages)
    tips = np.stack([np.cos(angles), np.sin(angles), np.full(pages, 0.5)], axis=1)
    vertices = np.concatenate([[[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]], tips, [[-1.0, 0.0, 0.25]]])
    faces = [(0, 1, 2 + k) if k % 2 else (1, 0, 2 + k) for k in range(pages)]
    faces += [(0, 1, 3), (1, 0, 3), (0, 1, 2 + pages)]
    order = np.random.default_rng(5).permutation(len(faces))
    return Mesh.from_arrays(vertices, np.array(faces)[order], "book")


def _soup(mesh: Mesh) -> Mesh:
    """A vertex per corner (an STL file's mesh)."""
    return Mesh.from_arrays(mesh.vertices[mesh.faces.reshape(-1)], np.arange(3 * len(mesh.faces)).reshape(-1, 3),
                            f"{mesh.name} soup")


def _degenerate() -> Mesh:
    """Zero-area triangles -- a corner repeated, collinear corners, all at one
    point, two corners at one position under different indices -- beside a
    proper fan, and vertices no face uses."""
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0], [1, 0, 0], [5, 5, 5], [0, 0, 1],
                         [-0.0, 0, 0], [9, 9, 9]], np.float32)
    faces = np.array([[0, 1, 2], [0, 0, 1], [0, 1, 3], [5, 5, 5], [0, 4, 1], [0, 2, 6], [7, 6, 2], [1, 2, 6],
                      [4, 6, 2]])
    return Mesh.from_arrays(vertices, faces, "degenerate")


def _fan(count: int = 90) -> Mesh:
    """A cone of ``count`` triangles round one apex (a vertex of more corners
    than the device sorts in private memory), its rim uneven."""
    angles = np.linspace(0.0, 2 * np.pi, count, endpoint=False)
    rim = np.stack([np.cos(angles), np.sin(angles), 0.3 * np.sin(5 * angles)], axis=1)
    faces = np.stack([np.zeros(count, int), 1 + np.arange(count), 1 + (np.arange(count) + 1) % count], axis=1)
    return Mesh.from_arrays(np.concatenate([[[0.0, 0.0, 0.8]], rim]), faces, "fan")


def _random(seed: int) -> Mesh:
    """Few positions (0.0 and -0.0 among them) for many corners: repeated
    vertices, edges of many faces, degenerate triangles."""
    rng = np.random.default_rng(seed)
    vertices = rng.choice(np.array([0.0, -0.0, 1.0, -1.0, 0.5], np.float32), size=(int(rng.integers(3, 30)), 3))
    faces = rng.integers(0, len(vertices), size=(int(rng.integers(1, 80)), 3))
    mesh = Mesh.from_arrays(vertices, faces, f"random {seed}")
    return _soup(mesh) if seed % 2 else mesh


def _meshes() -> dict:
    makers = {
        "knot": lambda: load_mesh(REPO / "assets" / "meshes" / "knot.obj"),
        "box": lambda: primitives.box((1.0, 2.0, 0.5)),
        "box soup": lambda: _soup(primitives.box()),
        "torus soup": lambda: _soup(primitives.torus(1.0, 0.35, 24, 12)),
        "icosphere": lambda: primitives.icosphere(3),
        "book": _book,
        "fan": _fan,
        "fan soup": lambda: _soup(_fan()),
        "degenerate": _degenerate,
        "one triangle": lambda: Mesh.from_arrays([[0, 0, 0], [1, 0, 0], [0, 1, 0], [3, 3, 3]], [[0, 1, 2]], "one"),
        **{f"random {seed}": lambda seed=seed: _random(seed) for seed in range(6)},
    }
    for name in ("cow.off", "camel.off", "ChineseDragon-10kv.off"):   # (bunny00 takes longer, adds nothing)
        if (SHARED_MESHES / name).is_file():
            makers[name] = lambda name=name: load_mesh(SHARED_MESHES / name)
    return makers


MESHES = _meshes()


def _bits(a: np.ndarray) -> bytes:
    return np.ascontiguousarray(a).tobytes()


@pytest.fixture(scope="module")
def queue(device):
    return create_context(device)


@pytest.mark.parametrize("name", list(MESHES))
def test_the_device_split_and_normals_are_the_hosts(name, queue):
    """Every crease angle: the same split faces, vertices (each new vertex's
    input vertex, so its position) and normals, bit for bit."""
    context, q = queue
    mesh = MESHES[name]()
    uploaded = upload_mesh(context, q, mesh)
    for crease in (None, 0.0, 45.0, 180.0):
        made = shade_on_device(context, q, uploaded, crease, read_split=True)
        host = mesh if crease is None else mesh.split_at_creases(crease)
        assert made.num_vertices == len(host.vertices), crease
        assert np.array_equal(made.faces, host.faces), crease
        if crease is not None:
            assert _bits(mesh.vertices[made.sources]) == _bits(host.vertices), crease
        normals = made.read_normals(q)
        assert _bits(normals[:, :3]) == _bits(host.vertex_normals()), crease
        assert not normals[:, 3].any()
    if name in ("book", "box soup", "knot"):      # (and the joins did join: a split merges)
        assert made.num_vertices < 3 * len(mesh.faces) and made.rounds >= 1


def test_an_edge_of_many_faces_pairs_its_half_edges_by_index(queue):
    """The rule both follow: an edge's half-edges in index order, each joined
    with the next where smooth -- the fan of pages that lie in one plane
    (smooth at any angle) forms one chain, the others stay apart."""
    context, q = queue
    vertices = np.array([[0, 0, 0], [0, 0, 1], [1, 0, 0], [-1, 0, 0], [2, 0, 0], [0, 1, 0]], np.float32)
    # The edge 0-1 in five faces: its half-edges 1, 3, 7, 9, 12 (faces 0..4);
    # faces 1, 3 and 4 lie in the plane y = 0 facing +y, faces 0 and 2 in
    # x = 0, at right angles to them.
    faces = np.array([[5, 0, 1], [0, 1, 2], [5, 1, 0], [1, 0, 3], [0, 1, 4]])
    mesh = Mesh.from_arrays(vertices, faces)
    host = mesh.split_at_creases(10.0)
    made = shade_on_device(context, q, upload_mesh(context, q, mesh), 10.0, read_split=True)
    assert np.array_equal(made.faces, host.faces)
    # Pairs (1, 3), (3, 7), (7, 9), (9, 12): only faces 3 and 4 are joined
    # (at vertex 0 and at vertex 1); faces 1 and 3, parallel but with face 2
    # between them in index order, are not.
    corner = host.faces
    assert corner[3, 1] == corner[4, 0] and corner[3, 0] == corner[4, 1]
    assert corner[1, 0] != corner[3, 1] and corner[1, 1] != corner[3, 0]


def test_triangle_info_follows_the_slots_and_the_face_materials(queue):
    """triangle_info: the split's vertex numbers and the material row of the
    triangle in each slot of the BVH, as flatten_scene's tri_info in slot order."""
    from clrt.device.acceleration import build_acceleration
    context, q = queue
    mesh = load_mesh(REPO / "assets" / "meshes" / "knot.obj")
    ids = np.random.default_rng(2).integers(-1, 3, len(mesh.faces)).astype(np.int32)
    mesh = mesh.with_detail(face_material=ids)
    scene = Scene([SceneObject(mesh, Material(), [Material(color=(1, 0, 0))] * 3)], [(2, 3, 4)])
    host = flatten_scene(scene)
    uploaded = upload_mesh(context, q, mesh)
    acceleration = build_acceleration(mesh, "box", "device", 4, uploaded=uploaded)
    made = shade_on_device(context, q, uploaded, 45.0, acceleration.device_buffers.prim_ids, mesh.face_material)
    slots = acceleration.slot_order()
    assert np.array_equal(made.read_tri_info(q), host.tri_info[slots])
    assert _bits(made.read_normals(q)) == _bits(host.vertex_normals)
    assert np.array_equal(flatten_scene(scene, device_shading=True).triangle_materials, host.tri_info["material"])


def test_a_call_compiles_only_the_kernels_it_launches():
    source = expand_source("crease.cl")
    everything = set(device_crease.CREASE_KERNELS)
    assert set(crease_kernels(True, True)) == everything
    flat = set(crease_kernels(False, False))
    assert "weld_insert" not in flat and "triangle_info" not in flat and "vertex_normals" in flat
    kept = keep_kernels(source, flat)
    assert "void weld_insert(" not in kept and "void vertex_normals(" in kept


def _force_device_path(monkeypatch):
    """The Renderer's GPU path on this device: the tree built from the mesh,
    the shading arrays made by the device (as on a GPU)."""
    from clrt.device import geometry
    monkeypatch.setattr(device_scene, "shades_on_device", lambda accel, builder, device: True)
    monkeypatch.setattr(geometry, "WIDE_BVH_KINDS", ())
    monkeypatch.setattr(geometry, "RAY_PACKET_KINDS", ())


@pytest.mark.parametrize("material", [{}, {"smooth": False}, {"crease": 180.0, "specular": 0.9}],
                         ids=["smooth", "flat", "crease 180"])
def test_a_renderer_on_the_device_path_renders_the_hosts_image(material, device, monkeypatch):
    """The same image, hits and shading buffers as the host path, and the
    mesh's crease split never made on the host."""
    from clrt.device import geometry as device_geometry
    monkeypatch.setattr(device_geometry, "WIDE_BVH_KINDS", ())
    monkeypatch.setattr(device_geometry, "RAY_PACKET_KINDS", ())
    mesh = _soup(load_mesh(REPO / "assets" / "meshes" / "knot.obj"))
    scene = scene_from_mesh(mesh, material)
    camera = Camera.framing(scene.bounds, 64, 48)
    with monkeypatch.context() as m:    # the host's path on any device (a GPU's own would take the device's)
        m.setattr(device_scene, "shades_on_device", lambda accel, builder, device: False)
        host = clrt.Renderer(scene, device=device)
    assert host.arrays.shading is None
    expected = host.render(camera, hits=True)

    _force_device_path(monkeypatch)
    fresh = scene_from_mesh(Mesh.from_arrays(mesh.vertices, mesh.faces, mesh.name), material)
    renderer = clrt.Renderer(fresh, device=device)
    assert renderer.arrays.shading is not None
    frame = renderer.render(camera, hits=True)
    for field in ("image", "prim", "t"):
        assert np.array_equal(getattr(frame, field), getattr(expected, field)), field
    assert frame.triangles == expected.triangles == len(mesh.faces)
    shaded = fresh.objects[0].mesh
    if material.get("smooth", True):
        assert shaded.crease_split_of is not None
        assert "faces" not in shaded.__dict__ and "vertices" not in shaded.__dict__     # never split on the host
    else:
        assert shaded.crease_split_of is None
    import pyopencl as cl
    for name, want in (("tri_info", host.arrays.tri_info[host.acceleration.slot_order()]),
                       ("vertex_normals", host.arrays.vertex_normals)):
        got = np.empty_like(want)
        cl.enqueue_copy(renderer.queue, got, renderer.geometry.buffers[name][0], is_blocking=True)
        assert _bits(got) == _bits(want), name
    # The host's arrays, made where asked for, are the host path's.
    assert _bits(renderer.arrays.tri_info) == _bits(host.arrays.tri_info)
    assert _bits(renderer.arrays.corners) == _bits(host.arrays.corners)


@pytest.mark.parametrize("given", ["arrays", "mesh"])
def test_a_bare_meshs_tree_is_built_before_its_scene(given, device, monkeypatch):
    """Renderer((V, F)) on the device path builds the tree first and frames
    the scene by the box the build found: the host never finds the mesh's
    bounds, and the scene, image and hits are those of the scene made first
    (its bounds found by the host).  Some vertices unused, so that the box is
    the used vertices' (as Mesh.bounds)."""
    from clrt.scene import mesh as mesh_module
    knot = load_mesh(REPO / "assets" / "meshes" / "knot.obj")
    far = np.array([[40.0, -7.0, 3.0], [-9.0, 50.0, 1.0]], np.float32)     # used by no face
    vertices = np.concatenate([knot.vertices, far]).astype(np.float32)
    faces = np.ascontiguousarray(knot.faces, np.int32)
    made_first = scene_from_mesh(Mesh.from_arrays(vertices, faces))
    camera = Camera.framing(made_first.bounds, 64, 48)
    _force_device_path(monkeypatch)
    expected = clrt.Renderer(made_first, device=device).render(camera, hits=True)

    def no_host_bounds(points):
        raise AssertionError("the host found the mesh's bounds")

    monkeypatch.setattr(mesh_module, "column_bounds", no_host_bounds)
    source = (vertices, faces) if given == "arrays" else Mesh.from_arrays(vertices, faces)
    renderer = clrt.Renderer(source, device=device)
    assert renderer.arrays.shading is not None and renderer.timings["acceleration build"] > 0
    assert np.array_equal(renderer.scene.bounds, made_first.bounds)
    assert renderer.scene.camera == made_first.camera and renderer.scene.lights == made_first.lights
    frame = renderer.render(camera, hits=True)
    for field in ("image", "prim", "t"):
        assert np.array_equal(getattr(frame, field), getattr(expected, field)), field
    assert np.array_equal(renderer.render().image, clrt.Renderer(made_first, device=device).render().image)


def test_scenes_the_device_does_not_shade_take_the_host_path(device, monkeypatch):
    """Several objects, authored normals, corner colours, placed meshes: the
    host's arrays, on the device path as elsewhere."""
    sphere = primitives.icosphere(1)
    two = Scene([SceneObject(sphere), SceneObject(primitives.box())], [(2, 3, 4)])
    authored = scene_from_mesh(sphere.with_detail(normals=sphere.vertices))
    coloured = scene_from_mesh(sphere.with_detail(colors=np.ones((len(sphere.faces), 3, 3))))
    placed = Scene([SceneObject(sphere, transforms=np.eye(4))], [(2, 3, 4)])
    for scene in (two, authored, coloured, placed):
        assert flatten_scene(scene, device_shading=True).shading is None
    assert flatten_scene(scene_from_mesh(sphere), device_shading=True).shading is not None
    _force_device_path(monkeypatch)
    camera = Camera.framing(two.bounds, 24, 16)
    renderer = clrt.Renderer(two, device=device)
    assert renderer.arrays.shading is None and renderer.render(camera).visible


def test_a_crease_split_is_made_when_first_used():
    """split_at_creases defers the split: bounds, counts, repr and pickles
    need none; the vertices and faces, made on first use, are the split's."""
    import pickle
    mesh = _soup(primitives.icosphere(2))
    split = mesh.split_at_creases(30.0)
    assert split.crease_split_of == (mesh, 30.0) and split is mesh.split_at_creases(30)
    assert np.array_equal(split.bounds, mesh.bounds) and split.num_triangles == len(mesh.faces)
    assert "when first used" in repr(split)
    copy = pickle.loads(pickle.dumps(split))
    assert "faces" not in split.__dict__ and "faces" not in copy.__dict__
    assert len(split.vertices) == len(primitives.icosphere(2).vertices)      # the soup welded again
    assert np.array_equal(copy.faces, split.faces) and _bits(copy.vertices) == _bits(split.vertices)
    assert "when first used" not in repr(split)
    assert len(pickle.dumps(split)) < len(pickle.dumps(mesh)) + 500        # travels as its mesh and angle
