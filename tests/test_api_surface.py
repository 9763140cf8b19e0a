"""The API as a new user meets it: docstrings that match the defaults, errors
at the call rather than deep inside, interchangeable mesh inputs, short reprs
(from an audit of the API surface).  Small meshes and images only."""

import importlib
import inspect
import re

import numpy as np
import pytest

import clrt
from clrt.scene import primitives


@pytest.fixture(scope="module")
def sphere():
    return primitives.icosphere(2)


# ---------------------------------------------------------------- docs vs behaviour

@pytest.mark.parametrize("cls", [clrt.Accel, clrt.Renderer])
def test_builder_default_in_docstring_is_the_real_default(cls):
    """The docstrings say ``"sah" (default)``; the default is "auto" (the
    device builder where the device has float64: PoCL, the H200)."""
    default = inspect.signature(cls).parameters["builder"].default
    doc = inspect.getdoc(cls)
    assert f'"{default}" (default' in doc, doc


def test_render_docstring_cross_reference_exists():
    """render's docstring points at clrt.scene.scene.as_scene, which does not exist
    (as_scene lives in clrt.scene.sources)."""
    for ref in re.findall(r":func:`~?([\w.]+)`", clrt.render.__doc__):
        module, _, name = ref.rpartition(".")
        assert hasattr(importlib.import_module(module), name), ref


@pytest.mark.parametrize("doc_of, rows", [
    (lambda: clrt.Hits, ("N",)), (lambda: clrt.Accel.trace, ("N",)), (lambda: clrt.trace, ("N",)),
    (lambda: clrt.Accel.trace_camera, ("H", "W")), (lambda: importlib.import_module("clrt.batch").trace, ("N",)),
], ids=["Hits", "Accel.trace", "clrt.trace", "Accel.trace_camera", "clrt.batch.trace"])
def test_every_hit_field_is_in_the_docstrings(doc_of, rows):
    """The fields of Accel.trace's result, with shape, dtype and miss value,
    were in source comments only: help() showed none of them."""
    from clrt.query.results import CLOSEST_FIELDS
    doc = inspect.getdoc(doc_of())
    for name, field in CLOSEST_FIELDS.items():
        shape = (*rows, *map(str, field.item_shape))
        kind = f"({', '.join(shape)}{',' if len(shape) == 1 else ''}) {np.dtype(field.dtype).name}"
        assert f"{name} : {kind}" in doc, (name, doc)
        assert f"{field.miss} on a miss" in " ".join(doc.split()), (name, doc)


@pytest.mark.parametrize("cls, table", [("Hits", "CLOSEST_FIELDS"), ("AllHits", "ALL_HITS_FIELDS"),
                                        ("CameraImages", "CAMERA_FIELDS"), ("ClosestPoints", "POINT_FIELDS")])
def test_result_classes_are_their_tables(cls, table):
    """One table per result: the named tuple's fields, their order, each field's
    help and the class docstring all come from it."""
    from clrt.query import results
    cls, table = getattr(clrt, cls), getattr(results, table)
    assert cls._fields == tuple(table)
    for name, field in table.items():
        assert field.meaning.split()[0] in getattr(cls, name).__doc__
        assert f"{name} : " in cls.__doc__


def test_trace_returns_what_the_table_says(sphere, device):
    """Dtypes, shapes and miss values of a real answer: one ray hits, one misses."""
    from clrt.query.results import CLOSEST_FIELDS
    hits = clrt.Accel(sphere, device=device).trace([[0, 0, 5], [0, 5, 5]], [[0, 0, -1], [0, 0, 1]])
    for name, field in CLOSEST_FIELDS.items():
        value = getattr(hits, name)
        assert value.dtype == field.dtype and value.shape == (2, *field.item_shape), name
        assert np.all(value[1] == eval(field.miss, {"inf": np.inf})), name   # the miss value as written
    assert hits.hit[0] and hits.prim[0] >= 0


def test_ray_queries_doc_lists_every_hit_field():
    """docs/ray-queries.md's table of clrt.Hits: every field with its shape and dtype."""
    from pathlib import Path
    from clrt.query.results import CLOSEST_FIELDS
    text = (Path(__file__).resolve().parents[1] / "docs" / "ray-queries.md").read_text()
    rows = [line for line in text.splitlines() if line.startswith("| `")]
    for name, field in CLOSEST_FIELDS.items():
        shape = "(N, 3)" if field.item_shape else "(N,)"
        assert any(f"`{name}`" in row.split("|")[1] and f"| {shape} | {np.dtype(field.dtype).name} |" in row
                   for row in rows), name


@pytest.mark.parametrize("doc_of", [lambda: clrt.ClosestPoints, lambda: clrt.Accel.closest_points,
                                    lambda: clrt.closest_points],
                         ids=["ClosestPoints", "Accel.closest_points", "clrt.closest_points"])
def test_every_point_field_is_in_the_docstrings(doc_of):
    from clrt.query.results import POINT_FIELDS
    doc = " ".join(inspect.getdoc(doc_of()).split())
    for name, field in POINT_FIELDS.items():
        shape = ("N", *map(str, field.item_shape))
        kind = f"({', '.join(shape)}{',' if len(shape) == 1 else ''}) {np.dtype(field.dtype).name}"
        assert f"{name} : {kind}" in doc and f"{field.miss} on a miss" in doc, (name, doc)


def test_closest_points_return_what_the_table_says(sphere, device):
    """Dtypes, shapes and miss values of a real answer: one point found, one beyond max_distance."""
    from clrt.query.results import POINT_FIELDS
    near = clrt.Accel(sphere, device=device).closest_points([[0, 0, 1.5], [0, 0, 9]], max_distance=2)
    for name, field in POINT_FIELDS.items():
        value = getattr(near, name)
        assert value.dtype == field.dtype and value.shape == (2, *field.item_shape), name
        assert np.array_equal(value[1], np.broadcast_to(eval(field.miss, {"inf": np.inf, "NaN": np.nan}),
                                                        value[1].shape), equal_nan=True), name
    assert near.prim[0] >= 0


def test_ray_queries_doc_lists_every_point_field():
    """docs/ray-queries.md's table of clrt.ClosestPoints, in its point queries' section."""
    from pathlib import Path
    from clrt.query.results import POINT_FIELDS
    text = (Path(__file__).resolve().parents[1] / "docs" / "ray-queries.md").read_text()
    section = text[text.index("## Point queries"):]
    section = section[:section.index("\n## ", 1)]
    rows = [line for line in section.splitlines() if line.startswith("| `")]
    for name, field in POINT_FIELDS.items():
        shape = "(N, 3)" if field.item_shape else "(N,)"
        assert any(f"`{name}`" in row.split("|")[1] and f"| {shape} | {np.dtype(field.dtype).name} |" in row
                   and f"`{field.miss}`" in row for row in rows), name


# ---------------------------------------------------------------- one calling convention

SHARED_OPTIONS = ("accel", "builder", "leaf_size", "device")


@pytest.mark.parametrize("func", [clrt.Renderer, clrt.Accel, clrt.RayMeshIntersector, clrt.Accel.from_renderer])
def test_only_the_source_goes_by_position(func):
    """Renderer took (scene, device, accel, builder, leaf_size) and Accel (mesh,
    accel, builder, leaf_size, device): a call moved from one to the other meant
    something else.  Now the scene or mesh is the only positional argument and
    the shared options keep one order."""
    params = inspect.signature(func).parameters.values()
    assert [p.name for p in params if p.kind is not p.KEYWORD_ONLY] in (["scene"], ["mesh"], ["renderer"])
    shared = [p.name for p in params if p.name in SHARED_OPTIONS]
    assert shared == [name for name in SHARED_OPTIONS if name in shared]


@pytest.mark.parametrize("call, spelled", [
    (lambda m: clrt.Renderer(m, "cpu"), "Renderer(scene, device='cpu')"),
    (lambda m: clrt.Renderer(m, None, "none"), "Renderer(scene, device=None, accel='none')"),
    (lambda m: clrt.Accel(m, "none"), "Accel(mesh, accel='none')"),
    (lambda m: clrt.Accel(m, "box", "sah", 2, "cpu"),
     "Accel(mesh, accel='box', builder='sah', leaf_size=2, device='cpu')"),
    (lambda m: clrt.RayMeshIntersector(m, True), "RayMeshIntersector(mesh, accel=True)"),
    (lambda m: clrt.Accel.from_renderer(m, 4096), "Accel.from_renderer(renderer, chunk_rays=4096)"),
    (lambda m: clrt.Renderer(clrt.scene_from_mesh(m)).render(None, True, True),
     "Renderer.render(camera, linear=True, hits=True)"),
])
def test_a_positional_option_says_how_to_write_it(sphere, call, spelled):
    """The former positional orders fail at the call, naming the keywords they
    meant, instead of building something else (or a TypeError's bare count)."""
    with pytest.raises(clrt.InputError, match=re.escape(spelled) + "$"):
        call(sphere)


# ---------------------------------------------------------------- same call, same image

def test_render_says_how_it_lights_a_mesh():
    """clrt.render(mesh, cam) places the default light for ``cam`` (as the CLI
    does); a Renderer keeps its scene's light: the docstring says so."""
    assert "keeps the light" in " ".join(clrt.render.__doc__.split())


# ---------------------------------------------------------------- silently ignored / deep errors

def test_camera_images_does_not_ignore_width_with_a_camera(sphere, device):
    """camera_images(mesh, camera, width=16) returns the camera's 640x480 images:
    width/height/pixel_center are silently dropped (K and pose are rejected)."""
    cam = clrt.Camera((0, 0, 4), (0, 0, 0))
    try:
        images = clrt.camera_images(sphere, cam, width=16, device=device)
    except clrt.InputError:
        return
    assert images.depth.shape[1] == 16


@pytest.mark.parametrize("bad", ["cam", np.eye(3)])
def test_camera_images_checks_its_camera(sphere, device, bad):
    """A K matrix passed positionally (or any non-Camera) ends in
    AttributeError: '...' object has no attribute 'basis' (clrt/device/args.py)."""
    with pytest.raises(clrt.InputError):
        clrt.camera_images(sphere, bad, width=8, height=6, device=device)


def test_trace_camera_checks_its_camera(sphere, device):
    accel = clrt.Accel(sphere, device=device)
    with pytest.raises(clrt.InputError):
        accel.trace_camera(None)


# ---------------------------------------------------------------- what "a mesh" may be

def test_trimesh_scene_is_a_mesh_source():
    """trimesh.load("x.glb") gives a trimesh.Scene: as_mesh takes it (each
    geometry placed by its node; tests/test_trimesh_objects.py has the rest)."""
    trimesh = pytest.importorskip("trimesh")
    from clrt.scene.sources import as_mesh
    scene = trimesh.Scene(trimesh.creation.box())
    assert len(as_mesh(scene).faces) == 12


def test_vertices_faces_as_a_list():
    """(V, F) works, [V, F] does not: 'expected ... (vertices, faces), got list'."""
    from clrt.scene.sources import as_mesh
    box = primitives.box((1.0, 1.0, 1.0))
    assert len(as_mesh([box.vertices, box.faces]).faces) == len(box.faces)


def test_single_light_position_error_says_to_wrap_it():
    """lights=(0, 3, 0) gives 'light position must be 3 numbers, got 0' although a
    single Light is accepted."""
    box = primitives.box((1.0, 1.0, 1.0))
    try:
        scene = clrt.scene_from_mesh(box, lights=(0, 3, 0))
    except clrt.InputError as exc:
        assert "list" in str(exc), str(exc)
    else:
        assert len(scene.lights) == 1


# ---------------------------------------------------------------- repr / eq of the main objects

def test_mesh_equality_and_hash_do_not_raise():
    """Mesh is a frozen dataclass with eq=True over numpy arrays: m1 == m2 and
    ``m in [..]`` raise ValueError, hash(m) TypeError (Texture uses eq=False)."""
    box = primitives.box((1.0, 1.0, 1.0))
    a, b = clrt.Mesh(box.vertices.copy(), box.faces.copy()), clrt.Mesh(box.vertices.copy(), box.faces.copy())
    a == b   # noqa: B015
    a in [b]   # noqa: B015
    {a: 1}


def test_reprs_are_short_and_informative(device):
    """A 162-vertex Mesh repr is ~15,000 characters (every coordinate); the
    built-in scene's repr 55,000 (1,800 lines); Renderer/Accel are <... object at 0x..>."""
    sphere = primitives.icosphere(2)
    assert len(repr(sphere)) < 400 and str(len(sphere.faces)) in repr(sphere)
    assert len(repr(clrt.default_scene(coarse=True))) < 4000
    renderer = clrt.Renderer(sphere, device=device)
    assert "object at 0x" not in repr(renderer)
    assert "object at 0x" not in repr(clrt.Accel(sphere, device=device))
