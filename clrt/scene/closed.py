"""Transmitting materials need closed meshes (issue #35, bad input).

The path tracer's dielectric decides from the side a ray meets a triangle on
whether it enters or leaves the material (the front, counter-clockwise side is
outside), and light that enters must find a way out: a glass pane of one open
sheet, or a sphere with a missing cap, would trap or leak it, and the image
would be wrong without a word.  So before a path-traced render, the faces of
each object whose materials transmit (``Material.pbr_values().transmission``
> 0, the Phong ``transparency`` included) must close: welded by position
(texture seams and crease splits duplicate vertices), every edge is met by as
many faces running along it one way as the other way -- a closed surface whose
faces all face the same side.  The Whitted renderer refracts through open
meshes as the paper's model does, and does not ask.
"""

from __future__ import annotations

import numpy as np

from clrt.errors import InputError


def check_closed_transmission(scene) -> None:
    """InputError, one line, for the first object of ``scene`` whose
    transmitting faces do not close, naming the scene's file, the object and
    the material, and where an open edge is:

        glass.glb: object 'glass' (file material 1, transmission 0.9): a
        transmitting material needs a closed mesh, but 12 edges are open (the
        first from (0, 0, 0) to (1, 0, 0))
    """
    for k, obj in enumerate(scene.objects):
        problem = _open_edges(obj)
        if problem is None:
            continue
        count, first_face, edge, flipped, material = problem
        mats = (obj.material, *obj.materials)
        which = "its material" if material == 0 else f"file material {material - 1}"
        name = f"object {obj.mesh.name!r}" if obj.mesh.name else f"object {k}"
        where = f"{scene.source}: " if scene.source else ""
        a, b = (", ".join(f"{float(x):.6g}" for x in obj.mesh.vertices[v]) for v in edge)
        what = (f"but {count} edge{'s' if count != 1 else ''} join faces that face opposite ways"
                if flipped else f"but {count} edge{'s are' if count != 1 else ' is'} open")
        raise InputError(f"{where}{name} ({which}, transmission {mats[material].pbr_values().transmission:g}): "
                         f"a transmitting material needs a closed mesh whose faces face one way, {what} "
                         f"(the first from ({a}) to ({b}), triangle {first_face})")


def _open_edges(obj):
    """(open edge count, a triangle at the first, its corners (vertex rows),
    whether the edges are closed but flipped, the material row) of an object's
    transmitting faces; None when they close (or there are none)."""
    mats = (obj.material, *obj.materials)
    transmits = np.array([m.pbr_values().transmission > 0 for m in mats])
    if not transmits.any():
        return None
    mesh = obj.mesh
    ids = np.zeros(len(mesh.faces), np.int64) if mesh.face_material is None else \
        np.where(mesh.face_material >= 0, mesh.face_material + 1, 0)
    faces = np.flatnonzero(transmits[ids])
    if not len(faces):
        return None
    _, welded = np.unique(mesh.vertices, axis=0, return_inverse=True)
    corners = welded.reshape(-1)[mesh.faces[faces]]
    # every directed edge (a -> b) of the triangles, degenerate ones (a == b) dropped
    a = corners.reshape(-1)
    b = np.roll(corners, -1, axis=1).reshape(-1)
    tri = np.repeat(faces, 3)
    keep = a != b
    a, b, tri = a[keep], b[keep], tri[keep]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = lo * (int(welded.max()) + 1) + hi
    order = np.argsort(key, kind="stable")
    key_sorted = key[order]
    starts = np.flatnonzero(np.r_[True, key_sorted[1:] != key_sorted[:-1]])
    along = np.add.reduceat((a < b)[order].astype(np.int64), starts)     # faces running lo -> hi
    total = np.diff(np.r_[starts, len(key_sorted)])
    bad = along * 2 != total                                              # not as many one way as the other
    if not bad.any():
        return None
    first = order[starts[np.argmax(bad)]]
    odd = total[bad] % 2 == 1
    flipped = not odd.any()
    if not flipped:   # name an edge that is really open, not only flipped
        first = order[starts[np.flatnonzero(bad)[np.argmax(odd)]]]
    corner_rows = mesh.faces[tri[first]]
    rows = {int(welded[v]): int(v) for v in corner_rows}
    count = int(bad.sum()) if flipped else int(odd.sum())
    return count, int(tri[first]), (rows[int(a[first])], rows[int(b[first])]), flipped, int(ids[tri[first]])
