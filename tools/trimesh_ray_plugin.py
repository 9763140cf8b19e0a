"""pytest plugin: every ``mesh.ray`` of a trimesh mesh is a clrt.RayMeshIntersector,
and every ``mesh.nearest`` a clrt.ProximityQuery.

Loaded by tools/trimesh_ray_tests.py (``pytest -p trimesh_ray_plugin``) to run
trimesh's own ray and proximity tests on clrt.  ``Trimesh.ray`` becomes a
property: reading it gives the mesh's clrt intersector (made on first use, kept
with the mesh, so it is pickled and copied with it); assigning any other engine
to it (trimesh's constructor assigns its numpy or Embree intersector, tests
assign Embree's) leaves clrt in place.  ``Trimesh.nearest`` likewise (trimesh's
constructor assigns its own ``ProximityQuery``).  Intersectors and proximity
queries that a test builds and calls itself, without going through the mesh's
attribute, are left alone.

With CLRT_TEST_DEVICE set, the intersectors use that OpenCL device.
"""

from __future__ import annotations

import os

ATTRIBUTE = "_clrt_ray"
NEAREST = "_clrt_nearest"
made = {"intersectors": 0, "proximity": 0, "replaced": {}}


def _get_nearest(mesh):
    import clrt
    query = mesh.__dict__.get(NEAREST)
    if query is None or query.mesh is not mesh:
        query = clrt.ProximityQuery(mesh, device=os.environ.get("CLRT_TEST_DEVICE") or None)
        mesh.__dict__[NEAREST] = query
        made["proximity"] += 1
    return query


def _set_nearest(mesh, value):
    import clrt
    if isinstance(value, clrt.ProximityQuery) and value.mesh is mesh:
        mesh.__dict__[NEAREST] = value
        return
    name = f"{type(value).__module__}.{type(value).__qualname__}"
    made["replaced"][name] = made["replaced"].get(name, 0) + 1
    mesh.__dict__.pop(NEAREST, None)            # clrt's, made on first use


def _get(mesh):
    import clrt
    intersector = mesh.__dict__.get(ATTRIBUTE)
    if intersector is None or intersector.mesh is not mesh:
        intersector = clrt.RayMeshIntersector(mesh, device=os.environ.get("CLRT_TEST_DEVICE") or None)
        mesh.__dict__[ATTRIBUTE] = intersector
        made["intersectors"] += 1
    return intersector


def _set(mesh, value):
    import clrt
    if isinstance(value, clrt.RayMeshIntersector) and value.mesh is mesh:
        mesh.__dict__[ATTRIBUTE] = value
        return
    name = f"{type(value).__module__}.{type(value).__qualname__}"
    made["replaced"][name] = made["replaced"].get(name, 0) + 1
    mesh.__dict__.pop(ATTRIBUTE, None)          # clrt's, made on first use


def pytest_configure(config):
    import trimesh
    trimesh.Trimesh.ray = property(_get, _set, doc="clrt.RayMeshIntersector (trimesh_ray_plugin)")
    trimesh.Trimesh.nearest = property(_get_nearest, _set_nearest, doc="clrt.ProximityQuery (trimesh_ray_plugin)")


def pytest_terminal_summary(terminalreporter):
    replaced = ", ".join(f"{n} x{c}" for n, c in sorted(made["replaced"].items())) or "none"
    terminalreporter.write_line(f"trimesh_ray_plugin: {made['intersectors']} clrt intersectors and "
                                f"{made['proximity']} proximity queries made; engines replaced: {replaced}")
