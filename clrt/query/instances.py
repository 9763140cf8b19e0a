"""What an Accel is made from: one mesh, or several meshes placed as
instances (a list of meshes or of ``(mesh, transform)`` pairs, a
clrt.Instances, a glTF file whose nodes place meshes more than once, or a
Scene whose objects place their meshes by transforms) --
a two-level scene on the device (docs/instances.md).

    >>> mesh, instances, scene = query_scene([bunny, (bunny, lifted)], accel="box", ...)
"""

from __future__ import annotations

import numpy as np

from clrt import checks
from clrt.accel import as_triangles
from clrt.device.instances import instanced_scene, move_instances, refit_meshes
from clrt.device.scene import DeviceScene
from clrt.device.sharing import one_at_a_time
from clrt.errors import InputError
from clrt.scene.arrays import device_origin, triangle_corners
from clrt.scene.instances import Instances, is_gltf_file, is_instance_list, placed_meshes
from clrt.scene.mesh import Mesh
from clrt.scene.placed import scene_instances
from clrt.scene.scene import Scene
from clrt.scene.sources import as_mesh


def query_scene(source, *, accel: str, builder: str, leaf_size: int, device: str | None,
                **upload) -> tuple[Mesh | None, Instances | None, DeviceScene]:
    """(the mesh, None, its DeviceScene) for one mesh -- anything
    clrt.scene.sources.as_mesh takes, a glTF file with one mesh node among
    them --, (None, the Instances, their two-level DeviceScene) for several;
    options checked already, as Accel takes them (``upload``:
    max_buffer_bytes, max_buffer_label)."""
    options = dict(accel=accel, builder=builder, leaf_size=leaf_size, device=device, **upload)
    if isinstance(source, Scene) and source.instanced:   # a Scene of placed meshes: its placements
        mesh = scene_instances(source)
    else:
        mesh = placed_meshes(source) if is_instance_list(source) or is_gltf_file(source) else as_mesh(source)
    if isinstance(mesh, Instances):
        return None, mesh, instanced_scene(mesh, **options)
    # Its corners and the device's frame (clrt.scene.arrays) made by DeviceScene: on a GPU by its build.
    return mesh, None, DeviceScene(mesh, bounds=None, origin=None, **options)


def source_of(mesh: Mesh | None, instances: Instances | None):
    """What an Accel of ``mesh`` or ``instances`` is made again from (a copy, a
    pickle): the instances, or the mesh's vertices and faces (its surface
    detail plays no part in queries)."""
    if instances is not None:
        return instances
    return Mesh(np.asarray(mesh.vertices), np.asarray(mesh.faces), mesh.name)


class SceneMoves:
    """What an Accel does besides queries: its scene moved, a mesh's vertices
    refitted or the instances placed anew (mixed into clrt.query.accel.Accel)."""

    @one_at_a_time
    def refit(self, vertices, *, mesh: int | None = None, rebuild: bool = False) -> None:
        """Move a mesh's vertices to ``vertices`` ((V, 3), the same count; the faces
        stay) and refit its BVH to them on the device: the tree is kept and
        every volume fitted anew, so queries stay exact (a refitted tree finds
        the hits of brute force) and only get slower as the motion tangles the
        tree -- ``rebuild=True`` builds a new one instead.

        In an Accel of instances, ``mesh`` names the distinct mesh that moves
        (an index into ``instances.meshes``; it may be left out where there is
        one): its slots and its rows are refitted, every instance of it moves
        with it, and the instance table and the top level are built again over
        the instances' new boxes (as :meth:`move_instances` builds them) -- the
        queries then answer as an Accel made of the moved instances."""
        k = self._refit_mesh_index(mesh)
        own = self.mesh if self.instances is None else self.instances.meshes[k]
        vertices = np.asarray(vertices)
        if vertices.shape != own.vertices.shape:
            raise InputError(f"refit needs vertices of shape {own.vertices.shape}, got {vertices.shape}")
        if self._options is None:
            raise InputError("these queries share a Renderer's scene: use Renderer.refit")
        moved = Mesh.from_arrays(vertices, own.faces, own.name)
        if self.instances is not None:
            meshes = list(self.instances.meshes)
            meshes[k] = moved
            moved = Instances(meshes, self.instances.mesh_of, self.instances.transforms)
        if rebuild or self.geometry.shifts is not None:
            fresh = type(self)(moved, **self._options).__dict__
            fresh.pop("_lock")   # the threads waiting on this one's
            self.__dict__.update(fresh)
            return
        if self.instances is None:
            # The frame chosen for the moved mesh, as a new Accel would choose it.
            origin = device_origin(moved.bounds)
            self.geometry.refit(self.queue, as_triangles(triangle_corners(moved, origin)), moved.bounds, origin)
            self.mesh = moved
            return
        changed = refit_meshes(self.device_scene, moved, [k])
        self.instances = moved
        if changed:   # a deeper or shallower top level: a program of another stack size
            self.kernels = self.query_kernels()

    def _refit_mesh_index(self, mesh) -> int:
        """The distinct mesh that ``refit``'s ``mesh`` names (0 for one mesh)."""
        count = 1 if self.instances is None else len(self.instances.meshes)
        if mesh is None:
            if count > 1:
                raise InputError(f"refit of an Accel of {count} meshes needs mesh=: the index of the one whose "
                                 f"vertices move (0..{count - 1}, as instances.meshes lists them)")
            return 0
        return checks.integer("mesh", mesh, 0, count - 1)

    @one_at_a_time
    def move_instances(self, transforms) -> None:
        """Place the instances anew: ``transforms`` (I, 4, 4), object -> world,
        one for each instance in its order (checked as when made).  Only the
        instance table and the top level are built again, over the old ones:
        on the device where the device built the meshes (the default where it
        has float64), else on the host (docs/instances.md says how long each
        takes); each mesh's BVH stays.  The queries then answer as an Accel
        made of the moved instances does, bit for bit."""
        if self.instances is None:
            raise InputError("move_instances needs an Accel of instances (a list of meshes or of (mesh, "
                             "transform) pairs, a clrt.Instances, a glTF file); one mesh's vertices move by refit")
        if self._options is None:
            raise InputError("these queries share a Renderer's scene: use Renderer.move_instances")
        self.instances, changed = move_instances(self.device_scene, self.instances, transforms)
        if changed:   # a deeper or shallower top level: a program of another stack size
            self.kernels = self.query_kernels()
