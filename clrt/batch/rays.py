"""Ray queries on dask arrays: each chunk of rays is traced by the worker that
holds it, against the mesh uploaded once per worker.

    >>> import dask.array as da, clrt.batch
    >>> origins = da.from_array(o, chunks=(1_000_000, 3))
    >>> hits = clrt.batch.trace(mesh, origins, directions)    # Hits of dask arrays, lazy
    >>> t, prim = dask.compute(hits.t, hits.prim)             # compute fields together: one trace
    >>> blocked = clrt.batch.occluded(mesh, origins, directions, tmax=dist)   # (N,) bool dask array

The answers are those of :func:`clrt.trace` and :func:`clrt.occluded`, ray for
ray (a ray's answer never depends on the batch it is in).
"""

from __future__ import annotations

import numpy as np

from clrt.batch.worker import hit_records, trace_chunk
from clrt.config import BATCH_RAY_CHUNK, DEFAULT_ACCEL, DEFAULT_BUILDER, DEFAULT_LEAF_SIZE
from clrt.errors import InputError
from clrt.query.accel import check_fields
from clrt.query.results import CLOSEST_FIELDS, Hits, with_fields
from clrt.scene.sources import as_mesh


@with_fields(CLOSEST_FIELDS, heading="Returns", lead="Hits, a named tuple of these dask arrays:")
def trace(mesh, origins, directions, *, tmin=0.0, tmax=np.inf, cull: str = "none",
          accel: str = DEFAULT_ACCEL, builder: str = DEFAULT_BUILDER, leaf_size: int = DEFAULT_LEAF_SIZE,
          device: str | None = None, chunk_rays: int | None = None, client=None, fields=None) -> Hits:
    """Closest hits of dask (or numpy) arrays of rays: a :class:`clrt.Hits` whose
    fields are dask arrays chunked as ``origins`` -- only ``fields`` (e.g.
    ``("t", "prim")``) when given, the others None: less to compute, pack and move.

    ``origins``, ``directions``: (N, 3); ``tmin``, ``tmax``: scalars or (N,)
    arrays.  ``client``: accepted for older callers and unused: the mesh
    travels in the task graph, so that a killed worker loses nothing that
    cannot be sent again (the chunks it held are traced again elsewhere, as
    Dask retries a task whose worker died).  ``device``: None uses
    each worker's own device (clrt.batch.worker).  Nothing runs until computed;
    compute the fields together (``dask.compute(*hits)``) to trace once.
    """
    dtype = hit_records(None if fields is None else check_fields(fields))
    records = _query("trace", mesh, origins, directions, tmin, tmax, cull, accel, builder, leaf_size,
                     device, chunk_rays, client, dtype.names if fields is not None else None)
    arrays = {}
    for name in dtype.names:
        shape = dtype.fields[name][0].shape
        if shape:
            arrays[name] = records.map_blocks(_field, name, dtype=dtype.fields[name][0].base, new_axis=1,
                                              chunks=(records.chunks[0], shape))
        else:
            arrays[name] = records.map_blocks(_field, name, dtype=dtype.fields[name][0])
    return Hits(**{name: arrays.get(name) for name in Hits._fields})


def occluded(mesh, origins, directions, *, tmin=0.0, tmax=np.inf, cull: str = "none",
             accel: str = DEFAULT_ACCEL, builder: str = DEFAULT_BUILDER, leaf_size: int = DEFAULT_LEAF_SIZE,
             device: str | None = None, chunk_rays: int | None = None, client=None):
    """(N,) bool dask array: is each ray blocked in (tmin, tmax]? (see :func:`trace`)"""
    return _query("occluded", mesh, origins, directions, tmin, tmax, cull, accel, builder, leaf_size,
                  device, chunk_rays, client)


def _field(records, name):
    return records[name]


def _query(query, mesh, origins, directions, tmin, tmax, cull, accel, builder, leaf_size, device,
           chunk_rays, client, fields=None):
    import dask
    import dask.array as da
    from dask.base import tokenize

    mesh = as_mesh(mesh)
    origins = _rays(origins, "origins")
    directions = _rays(directions, "directions")
    if origins.shape[0] != directions.shape[0]:
        if origins.shape[0] == 1:
            origins = da.broadcast_to(origins, directions.shape)
        elif directions.shape[0] == 1:
            directions = da.broadcast_to(directions, origins.shape)
        else:
            raise InputError(f"origins and directions must have the same number of rays, "
                             f"got {origins.shape[0]} and {directions.shape[0]}")
    rows = origins.chunks[0] if origins.numblocks[0] >= directions.numblocks[0] else directions.chunks[0]
    origins = origins.rechunk((rows, 3))
    directions = directions.rechunk((rows, 3))
    tmin, tmax = (_limit(x, name, rows) for x, name in ((tmin, "tmin"), (tmax, "tmax")))

    options = {"accel": accel, "builder": builder, "leaf_size": leaf_size, "chunk_rays": chunk_rays}
    token = tokenize(mesh.vertices, mesh.faces)
    # The mesh travels in the task graph, not scattered to the workers
    # (client.scatter): scattered data that dies with its workers cannot be
    # made again -- one killed worker of one failed the whole compute ("lost
    # dependencies") -- while a value of the graph is sent again to the worker
    # that takes the dead one's tasks.  Each worker still builds its Accel once.
    shipped = dask.delayed(mesh, pure=True, traverse=False)
    dtype = np.dtype(bool) if query == "occluded" else hit_records(fields)
    limits = [a for x in (tmin, tmax) for a in ((x, "i") if isinstance(x, da.Array) else (x, None))]
    name = f"clrt-{query}-{tokenize(origins, directions, tmin, tmax, token, options, device, cull, fields)}"
    # One task per chunk of rays ("i"), each with whole rows of both arrays ("ij" -> "i").
    return da.blockwise(_trace_rows, "i", origins, "ij", directions, "ij", *limits, concatenate=False,
                        mesh=shipped, mesh_token=token, options=options, device=device, cull=cull, query=query,
                        fields=fields,
                        dtype=dtype, meta=np.empty((0,), dtype), name=name)


def _trace_rows(origins, directions, tmin, tmax, **options):
    """trace_chunk of one chunk of rays, whose arrays come as blockwise hands a
    contracted axis over without concatenate: a list of its blocks, here one
    (both arrays are chunked (rows, 3)).  Concatenating that one block would copy
    it: 12 bytes a ray for each array, 16 ms for 4M rays' origins on a 2-core
    machine (docs/distributed.md)."""
    return trace_chunk(origins[0], directions[0], tmin, tmax, **options)


def _rays(values, name: str):
    import dask.array as da
    if not isinstance(values, da.Array):
        values = np.asarray(values)
        values = da.from_array(values, chunks=(BATCH_RAY_CHUNK,) + values.shape[1:])
    if values.ndim == 1 and values.shape == (3,):
        values = values[None, :]
    if values.ndim != 2 or values.shape[1] != 3:
        raise InputError(f"{name} must have shape (N, 3) or (3,), got {values.shape}")
    return values


def _limit(value, name: str, rows):
    """A scalar limit as it is, an (N,) array chunked as the rays."""
    import dask.array as da
    if np.ndim(value) == 0 and not isinstance(value, da.Array):
        return value
    if not isinstance(value, da.Array):
        value = da.from_array(np.asarray(value), chunks=(rows,))
    if value.ndim != 1 or value.shape[0] != sum(rows):
        raise InputError(f"{name} must be a number or have shape (N,), got {value.shape}")
    return value.rechunk((rows,))
