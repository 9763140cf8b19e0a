"""One table of clrt's names, defaults and limits.

Everything a user can choose by name (acceleration structure, builder, face
culling), every default of those choices, and every limit that more than one
place checks lives here once.  The CLI, the Python API, the scene-file reader
and the benchmarks read their choices and ranges from this module; the limits
the kernels also need reach them as ``-D`` defines (:func:`kernel_defines`,
added to every program build), so no ``.cl`` file repeats a number.
``tests/test_config.py`` checks that the kernels see the same values.
"""

from __future__ import annotations

# --------------------------------------------------------------------------- acceleration

#: Bounding-volume shapes of a BVH.  A shape is chosen when the program is
#: built (``VOLUME_DEFINES``); a new shape needs a fit in ``clrt/accel/volumes.py``
#: and ``clrt/kernels/build_fit.cl``, and a ray test in ``clrt/kernels/volumes.cl``
#: (docs/architecture.md, "Where to add").
VOLUMES = ("box", "sphere", "ellipse")
VOLUME_DEFINES = {"box": "VOLUME_BOX", "sphere": "VOLUME_SPHERE", "ellipse": "VOLUME_ELLIPSE"}
#: How the CLI names a BVH of each shape ("a sah BVH of spheres").
VOLUME_WORDS = {"box": "boxes", "sphere": "spheres", "ellipse": "ellipsoids"}
#: What ``accel=`` takes: a volume shape, or "none" (every ray against every triangle).
ACCELS = ("none",) + VOLUMES
#: BVH builders: the paper's median split and binned SAH on the host
#: (clrt.accel), PLOC on the OpenCL device (clrt.device.build).
HOST_BUILDERS = ("paper", "sah")
BUILDERS = HOST_BUILDERS + ("device",)
#: What ``builder=`` takes: a builder, or "auto" -- the device builder where the
#: device computes in float64 (it fits volumes in float64), else "sah".
BUILDER_CHOICES = BUILDERS + ("auto",)

DEFAULT_ACCEL = "box"
#: "auto": measured on the H200 (docs/benchmark-log.md, session 6), the device
#: builder takes 1.9 ms for a 75k-triangle mesh where the host SAH build takes
#: about 300 ms, and its trees trace primary rays 4 % slower (0.192 against
#: 0.184 ms a 1080p frame) -- a render or a batch of rays wins unless it traces
#: some 35,000 1080p frames of primary rays.
DEFAULT_BUILDER = "auto"
HOST_DEFAULT_BUILDER = "sah"   # the host front end's (clrt.accel.build)
DEFAULT_LEAF_SIZE = 4
MAX_LEAF_SIZE = 255

#: Traversal stacks are sized from the tree's depth, rounded up to a multiple of
#: this, so one compiled program serves every tree of about the same depth
#: instead of one program per depth (a binary walk's holds at least
#: clrt.device.geometry.STACK_DEPTH levels: one program for most trees).
STACK_SIZE_STEP = 16

# --------------------------------------------------------------------------- rendering

#: Reflection/refraction bounces: ``max_depth`` is checked against this, and
#: the kernels' explicit ray stack (whitted.cl) holds MAX_BOUNCES + 1 rays.
MAX_BOUNCES = 16
DEFAULT_MAX_DEPTH = 5
#: Anti-aliasing: ``samples`` x ``samples`` rays per pixel.
MAX_SAMPLES = 16
#: Largest image side in pixels (width, height, and the pinhole images of queries).
MAX_IMAGE_SIDE = 65536
DEFAULT_WIDTH = 640
DEFAULT_HEIGHT = 480
DEFAULT_FOV = 45.0
#: Largest coordinate of a vertex, eye, target or light: the device computes in
#: float32 (largest 3.4e38), and products of coordinates must stay finite there.
MAX_COORDINATE = 1e30
#: The largest float32 (numpy.finfo(numpy.float32).max): a larger value, finite
#: as a Python float, becomes infinite on the device.
FLOAT32_MAX = 3.4028234663852886e38
#: Smooth shading: faces meeting at an edge at more than this angle (degrees)
#: keep the edge hard (a crease); flatter edges are smoothed over.  Blender's
#: auto-smooth and trimesh use 30; 45 keeps octagonal tubes round too, while
#: box edges (90) stay sharp.
DEFAULT_CREASE_ANGLE = 45.0
#: Default material, light and render values (docs/scene-files.md lists them).
DEFAULT_COLOR = (0.8, 0.8, 0.8)
DEFAULT_AMBIENT = 0.1
DEFAULT_DIFFUSE = 0.7
DEFAULT_SPECULAR = 0.3
DEFAULT_SHININESS = 32.0
DEFAULT_IOR = 1.5
#: The range of each scalar material field (docs/scene-files.md lists them): the
#: weights may exceed 1 (a bright highlight), but not so far that the shading
#: sums overflow float32 on the device; a Phong exponent of 10000 already makes
#: a highlight narrower than a pixel.
MATERIAL_RANGES = {"ambient": (0, 1000), "diffuse": (0, 1000), "specular": (0, 1000),
                   "shininess": (0, 10000), "reflectivity": (0, 1), "transparency": (0, 1), "ior": (1, 100),
                   # the path tracer's (glTF 2.0 metallic-roughness and its KHR extensions); a
                   # normal map's scale has no range in glTF, and any finite one is safe (the
                   # scaled normal is normalised), so this one only keeps it finite in float32
                   "metallic": (0, 1), "roughness": (0, 1), "specular_weight": (0, 1), "transmission": (0, 1),
                   "normal_scale": (-1000, 1000)}
#: KHR_materials_specular's colour factor may exceed 1 (the BSDF clamps F0 to 1);
#: this bound keeps it well inside float32.
MAX_SPECULAR_COLOR = 1000.0
DEFAULT_SPECULAR_COLOR = (1.0, 1.0, 1.0)
DEFAULT_EMISSION = (0.0, 0.0, 0.0)
DEFAULT_BACKGROUND = (0.0, 0.0, 0.0)
DEFAULT_AMBIENT_LIGHT = (1.0, 1.0, 1.0)
DEFAULT_LIGHT_COLOR = (1.0, 1.0, 1.0)
#: A spot light's cone: its half angle in degrees (Mitsuba's spot ``cutoff_angle`` default).
DEFAULT_SPOT_CUTOFF = 20.0
DEFAULT_UP = (0.0, 1.0, 0.0)
DEFAULT_SAMPLES = 1
#: ``clrt render``'s progress bar (tqdm, when installed): it shows once a frame has
#: run this many seconds (faster frames print nothing), and the first tile of a
#: frame then has at most this many pixels, so that the bar moves early -- a
#: quarter of a 1080p frame: every tile costs a wait, which fast GPU frames feel.
PROGRESS_DELAY = 1.0
PROGRESS_FIRST_TILE = 1 << 19

#: Integrators: the paper's Whitted model (the default, unchanged) and a
#: unidirectional path tracer with next-event estimation and MIS (path.cl).
INTEGRATORS = ("whitted", "path")
DEFAULT_INTEGRATOR = "whitted"
#: The path tracer's samples per pixel when none is given; the most it takes
#: (the RNG counts samples in 32 bits).
DEFAULT_SPP = 16
MAX_SPP = 2**31 - 1
#: The path tracer's max_depth, counted as Mitsuba counts it (1: emitters seen
#: directly, 2: direct light, ...; -1: unbounded, paths then end by Russian
#: roulette) -- and its largest finite value, which also bounds an "unbounded"
#: path in the kernel.  Whitted's max_depth counts bounces instead (0..MAX_BOUNCES).
DEFAULT_PATH_MAX_DEPTH = -1
MAX_PATH_DEPTH = 1024
#: Russian roulette starts at this depth (Mitsuba's rr_depth default).
PATH_RR_DEPTH = 5
#: Light sampling strategies of the path tracer (Renderer.render's ``strategy``,
#: a debugging aid): "mis" (the default: light and BSDF sampling combined by the
#: power heuristic), "light" (light sampling only: emitters hit by BSDF-sampled
#: rays add nothing, except after a specular bounce), "bsdf" (BSDF sampling
#: only: no light is sampled, so point and spot lights add nothing).  All three
#: converge to the same image for scenes without point lights.
PATH_STRATEGIES = {"mis": 0, "light": 1, "bsdf": 2}
#: Kinds of the path tracer's light table rows (LightEntry.kind in layouts.py).
LIGHT_KINDS = {"point": 0, "triangle": 1, "background": 2}

#: Material flag bits (``Material.flags`` in layouts.py): smooth shading;
#: emission from both faces (else from the front one only, as glTF's doubleSided false).
MATERIAL_SMOOTH = 1
MATERIAL_DOUBLE_SIDED = 2
#: How a texture coordinate outside 0..1 is mapped back into the image (glTF's
#: sampler modes REPEAT, CLAMP_TO_EDGE, MIRRORED_REPEAT): name -> the code the
#: kernels compare with (``Texture.wrap_s``/``wrap_t`` in layouts.py).
TEXTURE_WRAPS = {"repeat": 0, "clamp": 1, "mirror": 2}
#: Texture coordinates are clamped to +-this many texels before they become
#: integers (float32 holds every integer up to 2**24 exactly, int32 far more),
#: so absurd or infinite coordinates from a file stay defined.
TEXEL_LIMIT = 1 << 23

# --------------------------------------------------------------------------- ray queries

#: Face culling of ray queries: name -> the code the kernels compare with.
CULL_MODES = {"none": 0, "back": 1, "front": 2}
#: What the query kernels check of every ray (rays.cl), in the order of their
#: report slots: the kernels see BAD_ORIGIN = 0, BAD_DIRECTION = 1, ...
#: "reach": the origin lies within the float32 range of the triangle test
#: (clrt.device.reach).
RAY_CHECKS = ("origin", "direction", "tmin", "tmax", "reach")

# --------------------------------------------------------------------------- devices

#: What ``device=`` / ``--device`` takes besides "P:D" or "P" (platform and device indices).
DEVICE_KINDS = ("gpu", "cpu")
#: The per-pixel images of ``clrt render --aov`` (clrt.query.aov), in their order.
AOVS = ("depth", "distance", "normal", "prim", "instance", "hit", "front")
#: The formats of output files, and what each can hold: clrt.output.writers.WRITERS.

# --------------------------------------------------------------------------- instances (docs/instances.md)

#: Instance.flags (clrt/layouts.py): the instance's transform has a negative
#: determinant (a mirror), so a triangle's winding turns over in the world.
INSTANCE_MIRROR = 1
#: The most instances of one scene: results report an instance as an int32.
MAX_INSTANCES = 2**31 - 1
#: An instance transform whose linear part has a larger condition number (the
#: ratio of its largest to its smallest singular value) is refused as
#: singular: its float32 inverse would keep less than a few bits of the
#: scene's coordinates.
MAX_TRANSFORM_CONDITION = 1e6

# --------------------------------------------------------------------------- device buffers

#: Most parts one scene buffer is split into when it exceeds the device's
#: largest allocation (split.cl).  Four always suffice: OpenCL promises a
#: largest allocation of at least a quarter of the device memory.
MAX_PARTS = 4
#: Outputs one ray-query launch can write (QueryLaunch.field_at in layouts.h):
#: the closest hit's eight fields; query_all's three, its hit counter and the hits' instances.
RESULT_SLOTS = 8
#: QueryLaunch.field_at of an output not asked for (no byte of `results` is one).
NO_RESULT = 2**64 - 1

# --------------------------------------------------------------------------- batch jobs (clrt.batch)

#: The environment variable that gives a Dask worker process its OpenCL device ('gpu', 'cpu', 'P:D').
DEVICE_ENV = "CLRT_DEVICE"
#: Scenes (and their uploaded acceleration structures) each worker keeps for later jobs.
BATCH_CACHE_SCENES = 4
#: Most views of one source rendered by one task (a task reports, and is retried, as a whole).
BATCH_VIEWS_PER_TASK = 8
#: Images a worker encodes and writes in threads while it renders the next views
#: (PNG encoding took 17 of a worker's 36 ms per 1080p frame on an H200,
#: docs/distributed.md); also the most finished images it holds at once.
BATCH_IMAGE_WRITERS = 2
#: The format of a batch's frames (--format; clrt.output.writers.WRITERS).
BATCH_FORMAT = "png"
#: Most views per source (--views), most worker processes of a local cluster (--workers).
MAX_VIEWS = 100_000
MAX_WORKERS = 4096
#: The manifest (JSON lines) in the output folder, and how often it is rewritten while jobs finish.
BATCH_MANIFEST = "manifest.jsonl"
BATCH_MANIFEST_SECONDS = 1.0
#: Retries of a task that raised an unexpected error; a task whose worker died is
#: retried elsewhere by Dask (distributed.scheduler.allowed-failures, default 3).
BATCH_TASK_RETRIES = 1
#: Dask gives up on a task (KilledWorker) once allowed-failures + 1 workers died
#: while it was sent to them, waiting or running.  clrt reports such a task only
#: once it was running at allowed-failures + 1 deaths; until then -- it waited
#: behind the task that crashed the workers -- it is submitted again, as a new
#: task, at most this many times.  So a task that kills its worker every time
#: costs allowed-failures + 1 worker deaths (4 with Dask's default), at most
#: 2 x allowed-failures + 1 (7) when it also waited behind another crashing
#: task, and never more than (allowed-failures + 1) x (this + 1) (16: runs that
#: crash before the task notes its start, or an output folder where it cannot)
#: (clrt.batch.engine._execute).
BATCH_KILLED_RESUBMITS = 3
#: A finished task whose result was lost with its worker (Dask's future status
#: "lost": the worker died before the client fetched the records) is submitted
#: again, at most this many times; its images are on disk, so the new task
#: finds them.
BATCH_LOST_RESUBMITS = 2
#: Seconds a batch with tasks left waits while no worker is up -- connected with
#: its device set up (clrt.batch.worker.DevicePlugin) -- before it stops: its
#: tasks are then "device", exit 3.  Every worker process dying while it starts
#: (a driver that crashes when a context is made) would otherwise have the
#: nanny restart it for ever, and no task is ever charged with the deaths.  A
#: worker's start -- a new Python process importing Dask, pyopencl and clrt,
#: then listing the devices -- took 1.9 s on the 2-core development machine
#: (0.06 s of it the device set-up, PoCL); not measured on the GPU hosts, where
#: the driver's start adds some, and longer when many start at once on a loaded
#: host: 60 s leaves ample room.  Program builds are no part of it (they come
#: with a worker's first task, while it counts as up).  A --scheduler cluster
#: with no worker at all stops after the same time (clrt.batch.watch.Watchdog).
BATCH_NO_WORKER_TIMEOUT = 60.0
#: A task is taken to hang once it has run -- since the batch saw it start --
#: longer than BATCH_HANG_FACTOR x the median seconds of the frames this batch
#: rendered so far x its views, and at least BATCH_HANG_FLOOR seconds (which
#: also covers a worker's set-up of a new source: load, BVH build, upload,
#: program builds; 0.7-2.2 s a source on an H200 worker, docs/distributed.md).
#: Before any frame has finished there is nothing to compare with: a task then
#: hangs once it has run longer than BATCH_FIRST_TASK_SETUP seconds plus
#: BATCH_FIRST_TASK_RAY_SECONDS per camera ray of its views (width x height x
#: samples^2 each: the batch's options, else the scene file's, else the
#: defaults).  Measured on the 2-core development machine with PoCL (the
#: slowest device clrt runs on): loading and building the BVH of a 75k-triangle
#: mesh took 0.68 s, some 9 us a triangle, so 600 s of set-up is room for some
#: 60 M triangles; a 1080p frame of the glass showcase scene, 2x2 samples, took
#: 5.8 s, 0.7 us a camera ray with its bounces and the PNG, so 10 us is 15
#: times that (a task of 8 views at 640x480: 625 s; 8 at 1080p: 766 s).  A
#: legitimately slower first task is given more with --task-timeout, which
#: also caps the median's limit (task_timeout= in Python).  A hung task is
#: cancelled, its worker restarted, and the task submitted again, at most
#: BATCH_HANG_RETRIES times; hanging once more, its frames are "device" (exit
#: 3) with one line naming it (clrt.batch.watch).
BATCH_HANG_FACTOR = 10.0
BATCH_HANG_FLOOR = 120.0
BATCH_FIRST_TASK_SETUP = 600.0
BATCH_FIRST_TASK_RAY_SECONDS = 1e-5
BATCH_HANG_RETRIES = 1
#: Seconds to wait for an existing Dask scheduler (--scheduler).
BATCH_CONNECT_TIMEOUT = 10.0
#: Seconds past BATCH_CONNECT_TIMEOUT that a scheduler has to finish Dask's
#: handshake before clrt gives up on it (clrt.batch.cluster.connect).
BATCH_HANDSHAKE_SLACK = 5.0
#: Rays per chunk when clrt.batch.trace is given numpy arrays.
BATCH_RAY_CHUNK = 1 << 20


# Point queries visit their points cell by cell of a grid over the scene's box
# (kernels/point_order.cl says why): 2^POINT_CELL_BITS cells an axis, counted
# into places by one work-group of POINT_OFFSETS_GROUP work-items.
POINT_CELL_BITS = 5
POINT_OFFSETS_GROUP = 256
POINT_CELLS = 1 << (3 * POINT_CELL_BITS)
# CPU devices sort the points by the cells of a finer grid, 2^POINT_RUN_CELL_BITS
# cells an axis (their walks in groups of neighbours take 3-8 % less time than
# by POINT_CELL_BITS: docs/benchmark-log.md), counted in runs of consecutive
# points, a work-item a run with POINT_RUN_CELLS counters of its own
# (point_order.cl's point_run_*): POINT_RUNS_PER_UNIT runs a compute unit, at
# most POINT_RUNS_MAX (one work-item adds up all the counters), and no run of
# fewer than POINT_RUN_POINTS points but one (zeroing its counters would
# outweigh it); a launch of fewer points takes the atomics' order.
POINT_RUN_CELL_BITS = 6
POINT_RUN_CELLS = 1 << (3 * POINT_RUN_CELL_BITS)
POINT_RUNS_PER_UNIT = 1
POINT_RUNS_MAX = 8
POINT_RUN_POINTS = 1 << 15
# CPU devices walk closest points POINT_LANES at a time (8 or 16: the lanes
# of float8 or float16 values; kernels/point_group.cl), POINT_GROUPS such
# groups a work-item, one after the other, each seeded by the one before, and
# a point keeps POINT_CANDIDATES triangles to visit at the end of its walk
# (docs/benchmark-log.md has the measurements that chose them).
POINT_LANES = 16
POINT_GROUPS = 8
POINT_CANDIDATES = 8


def kernel_defines() -> dict:
    """The limits above that the kernels use, as ``-D`` defines of every program."""
    return {
        "MAX_BOUNCES": MAX_BOUNCES,
        "MATERIAL_SMOOTH": f"{MATERIAL_SMOOTH}u",
        "MATERIAL_DOUBLE_SIDED": f"{MATERIAL_DOUBLE_SIDED}u",
        "MAX_PARTS": MAX_PARTS,
        "RESULT_SLOTS": RESULT_SLOTS,
        "NO_RESULT": f"{NO_RESULT:#x}UL",
        **{f"CULL_{name.upper()}": code for name, code in CULL_MODES.items()},
        **{f"WRAP_{name.upper()}": f"{code}u" for name, code in TEXTURE_WRAPS.items()},
        "TEXEL_LIMIT": f"{float(TEXEL_LIMIT)!r}f",
        "MAX_PATH_DEPTH": MAX_PATH_DEPTH,
        **{f"PATH_{name.upper()}": f"{code}u" for name, code in PATH_STRATEGIES.items()},
        **{f"LIGHT_{name.upper()}": f"{code}u" for name, code in LIGHT_KINDS.items()},
        **{f"BAD_{name.upper()}": slot for slot, name in enumerate(RAY_CHECKS)},
        "INSTANCE_MIRROR": f"{INSTANCE_MIRROR}u",
        "POINT_CELL_BITS": POINT_CELL_BITS,
        "POINT_OFFSETS_GROUP": POINT_OFFSETS_GROUP,
        "POINT_RUN_CELL_BITS": POINT_RUN_CELL_BITS,
    }


def stack_size(depth: int) -> int:
    """Traversal stack entries for a tree of ``depth`` levels (see STACK_SIZE_STEP)."""
    return max(STACK_SIZE_STEP, -(-int(depth) // STACK_SIZE_STEP) * STACK_SIZE_STEP)
