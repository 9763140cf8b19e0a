"""Fuzzing the mesh loaders with mutated real files, each case bounded in time and memory.

    python tools/fuzz.py --seconds 600                      # every format, ten minutes
    python tools/fuzz.py --cases 5000 --format 3ds,ply      # a fixed number of cases
    python tools/fuzz.py --corpus ../shared/meshes --save fuzz-failures --jobs 2
    python tools/fuzz.py --replay 0:1234                    # rerun one case here, with a traceback

The corpus is a set of valid files: small meshes written by trimesh's exporters
and our 3DS writer in every format (always), plus the files of ``--corpus``
folders up to ``--max-file-kb``.  Case ``i`` of seed ``s`` is a deterministic
function of ``(s, i)``: one corpus file and one to three mutations of it --

* truncation (anywhere, or within the header),
* byte flips (random bytes; digits, signs and dots in text formats),
* huge counts: a number in a text header (OFF counts, PLY element counts, glTF
  accessor counts and offsets) or a binary count / length field (STL triangle
  count, 3DS chunk lengths and vertex / face counts, GLB chunk lengths, PLY list
  lengths) replaced by 0, -1, 2^31, 2^32, 10^12, ...,
* numbers replaced by nan, inf, 1e39,
* deleted, duplicated or inserted slices, and splices of two files.

Cases run in worker processes (``--jobs``) whose address space is limited to
``--memory-mb`` above what the imports took (``RLIMIT_AS``).  A case fails
when ``load_mesh`` raises anything but :class:`MeshLoadError`, returns a mesh
that breaks :class:`Mesh`'s invariants, runs out of memory, takes longer than
``--case-seconds``, hangs (the worker is killed after ``--hang-seconds``) or
kills its worker.  Failing inputs are written to ``--save`` for replay; the
exit status is 1 when any case failed.  ``tests/test_fuzz.py`` runs a bounded
number of cases through the same harness.
"""

from __future__ import annotations

import argparse
import os
import re
import select
import struct
import subprocess
import sys
import tempfile
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]   # the repository: tools/ and clrt/ beside each other
if __name__ == "__main__":   # python tools/fuzz.py: this checkout's clrt, imported from the repository
    sys.path[0] = str(ROOT)

from clrt.scene.load import SUPPORTED_EXTENSIONS

FORMATS = tuple(ext[1:] for ext in SUPPORTED_EXTENSIONS)   # "3ds", "glb", ...: every format clrt reads
_TEXT = {"obj", "off", "gltf"}   # ASCII PLY and STL are recognised per file
_HUGE_TEXT = ("0", "1", "2", "-1", "65535", "65536", "2147483647", "2147483648", "4294967295",
              "4294967296", "1000000000000", "18446744073709551616", "99999999999999999999999")
_HUGE_U32 = (0, 1, 0xFFFF, 0x10000, 0x7FFFFFFF, 0x80000000, 0xFFFFFFFF, 0xFFFFFFF0)
_BAD_FLOATS = ("nan", "-nan", "inf", "-inf", "1e39", "-1e39", "1e-45", "1e308", "0x1p3", "1e")


# ---------------------------------------------------------------------------
# Corpus


@dataclass(frozen=True)
class Sample:
    name: str
    ext: str        # without the dot, lower case
    data: bytes


def builtin_corpus() -> list[Sample]:
    """Small valid files in every format, written by trimesh's exporters and ours."""
    import trimesh

    from clrt.scene import primitives
    from clrt.scene.formats.tds import encode_3ds

    sphere = primitives.icosphere(1)
    box = primitives.box()
    tm = trimesh.Trimesh(sphere.vertices.astype(np.float64), sphere.faces, process=False)
    scene = trimesh.Scene()
    scene.add_geometry(tm, node_name="a", geom_name="a")
    scene.add_geometry(trimesh.Trimesh(box.vertices.astype(np.float64), box.faces, process=False),
                       node_name="b", geom_name="b", transform=np.diag([2.0, 2.0, 2.0, 1.0]))
    quads_obj = ("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nvt 0 0\nvn 0 0 1\n"
                 "usemtl a\nf 1/1/1 2/1/1 3/1/1 4/1/1\nf -5 -4 -1\n")
    coff = ("COFF\n5 2 0\n0 0 0 255 0 0 255\n1 0 0 255 0 0 255\n1 1 0 255 0 0 255\n"
            "0 1 0 255 0 0 255\n0 0 1 255 0 0 255\n4 0 1 2 3 0.5 0.5 0.5\n3 0 1 4\n")
    ply_quads = ("ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\n"
                 "property float z\nelement face 2\nproperty list uchar int vertex_indices\n"
                 "property uchar red\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n0 0 1\n4 0 1 2 3 9\n3 0 1 4 9\n")
    samples = [
        Sample("sphere.obj", "obj", tm.export(file_type="obj").encode()),
        Sample("quads.obj", "obj", quads_obj.encode()),
        Sample("sphere.off", "off", trimesh.exchange.off.export_off(tm).encode()),
        Sample("coloured.off", "off", coff.encode()),
        Sample("sphere-ascii.ply", "ply", tm.export(file_type="ply", encoding="ascii")),
        Sample("sphere-binary.ply", "ply", tm.export(file_type="ply", encoding="binary")),
        Sample("quads.ply", "ply", ply_quads.encode()),
        Sample("sphere-binary.stl", "stl", tm.export(file_type="stl")),
        Sample("sphere-ascii.stl", "stl", tm.export(file_type="stl_ascii").encode()),
        Sample("scene.glb", "glb", scene.export(file_type="glb")),
        Sample("scene.gltf", "gltf", trimesh.exchange.gltf.export_gltf(scene, embed_buffers=True)["model.gltf"]),
        Sample("two-objects.3ds", "3ds", encode_3ds([sphere, box])),
    ]
    return samples


def file_corpus(folders, max_bytes: int) -> list[Sample]:
    """Mesh files (supported extensions, at most ``max_bytes``) of ``folders``, sorted."""
    out = []
    for folder in folders:
        for path in sorted(Path(folder).iterdir()):
            ext = path.suffix.lower().lstrip(".")
            if ext in FORMATS and path.is_file() and path.stat().st_size <= max_bytes:
                out.append(Sample(path.name, ext, path.read_bytes()))
    return out


def corpus(folders=(), max_bytes: int = 256 << 10, formats=FORMATS) -> list[Sample]:
    samples = builtin_corpus() + file_corpus(folders, max_bytes)
    return [s for s in samples if s.ext in formats]


# ---------------------------------------------------------------------------
# Mutations: (data, rng, sample, corpus) -> (data, description)


def _is_text(sample: Sample, data: bytes) -> bool:
    return sample.ext in _TEXT or not (b"\0" in data[:512] or sample.data.startswith(b"ply\nformat b"))


def _truncate(data, rng, sample, _corpus):
    if len(data) < 2:
        return data[:0], "truncate to 0"
    limit = len(data) if rng.random() < 0.5 else min(len(data), 256)
    size = int(rng.integers(0, limit))
    return data[:size], f"truncate to {size}"


def _flip(data, rng, sample, _corpus):
    if not data:
        return data, "flip nothing"
    out = bytearray(data)
    positions = rng.integers(0, len(out), int(rng.integers(1, 9)))
    text = _is_text(sample, data)
    for p in positions:
        out[p] = ord(rng.choice(list("0123456789-.e "))) if text and rng.random() < 0.7 else int(rng.integers(256))
    return bytes(out), f"flip {len(positions)} bytes at {positions.tolist()[:4]}"


def _replace_number(data, rng, pattern, choices, window):
    matches = list(re.finditer(pattern, data[:window]))
    if not matches:
        return None
    m = matches[int(rng.integers(len(matches)))]
    group = 1 if m.re.groups else 0          # a pattern may name the number as group 1
    value = choices[int(rng.integers(len(choices)))].encode()
    return (data[:m.start(group)] + value + data[m.end(group):],
            f"number at {m.start(group)} -> {value.decode()}")


def _binary_fields(data: bytes, sample: Sample) -> list[tuple[int, int]]:
    """(offset, size) of count and length fields of a binary file."""
    if sample.ext == "stl" and len(data) >= 84:
        return [(80, 4)]
    if sample.ext == "3ds":
        return _3ds_fields(data)
    if sample.ext == "glb" and len(data) >= 20:
        json_len = struct.unpack_from("<I", data, 12)[0]
        return [(8, 4), (12, 4), (20 + json_len, 4)]
    return []


def _3ds_fields(data: bytes) -> list[tuple[int, int]]:
    """Chunk length fields and vertex / face counts of a 3DS file, depth first."""
    fields: list[tuple[int, int]] = []
    containers = (0x4D4D, 0x3D3D, 0x4100)

    def walk(start: int, end: int) -> None:
        pos = start
        while pos + 6 <= end and len(fields) < 256:
            cid, length = struct.unpack_from("<HI", data, pos)
            fields.append((pos + 2, 4))
            if length < 6 or pos + length > end:
                return
            if cid == 0x4000:                       # object: a name, then chunks
                nul = data.find(b"\0", pos + 6, pos + length)
                if nul >= 0:
                    walk(nul + 1, pos + length)
            elif cid in containers:
                walk(pos + 6, pos + length)
            elif cid in (0x4110, 0x4120):
                fields.append((pos + 6, 2))         # vertex / face count
            pos += length

    walk(0, len(data))
    return fields


def _huge_count(data, rng, sample, _corpus):
    if sample.ext == "glb":
        return _glb_json(data, rng, lambda j: _replace_number(
            j, rng, rb'"(?:count|byteLength|byteOffset|byteStride|bufferView|indices|POSITION)":(-?\d+)',
            _HUGE_TEXT, len(j)), "huge count")
    if _is_text(sample, data) or sample.ext == "ply":
        window = data.find(b"end_header") + 1 if sample.ext == "ply" else 2048
        pattern = rb'"(?:count|byteLength|byteOffset|byteStride)":(-?\d+)' if sample.ext == "gltf" else rb"-?\b\d+\b"
        done = _replace_number(data, rng, pattern, _HUGE_TEXT, window if window > 0 else 2048)
        if done:
            return done[0], "huge count: " + done[1]
    fields = _binary_fields(data, sample)
    if not fields:
        return _flip(data, rng, sample, _corpus)
    offset, size = fields[int(rng.integers(len(fields)))]
    if offset + size > len(data):
        return data, "huge count: field beyond the end"
    value = int(_HUGE_U32[int(rng.integers(len(_HUGE_U32)))]) & ((1 << (8 * size)) - 1)
    out = bytearray(data)
    out[offset:offset + size] = value.to_bytes(size, "little")
    return bytes(out), f"huge count: {size}-byte field at {offset} -> {value:#x}"


def _glb_json(data, rng, change, what):
    """Apply ``change`` to the JSON chunk of a GLB file, keeping the chunk lengths right."""
    if len(data) < 20 or data[:4] != b"glTF":
        return _flip(data, rng, Sample("x.glb", "glb", data), None)
    json_len = struct.unpack_from("<I", data, 12)[0]
    body = data[20:20 + json_len]
    changed = change(body)
    if changed is None:
        return data, f"{what}: no number"
    new, desc = changed
    new += b" " * (-len(new) % 4)
    rest = data[20 + json_len:]
    out = data[:8] + struct.pack("<I", 20 + len(new) + len(rest)) + struct.pack("<I", len(new)) + data[16:20] + new + rest
    return out, f"{what}: {desc}"


def _bad_float(data, rng, sample, _corpus):
    pattern = rb"-?\d+\.\d+(?:[eE][-+]?\d+)?"
    if sample.ext == "glb":
        return _glb_json(data, rng, lambda j: _replace_number(j, rng, pattern, _BAD_FLOATS, len(j)), "bad float")
    if _is_text(sample, data):
        done = _replace_number(data, rng, pattern, _BAD_FLOATS, len(data))
        if done:
            return done[0], "bad float: " + done[1]
    # Binary: overwrite a float32 with NaN, inf or a huge value.
    if len(data) < 8:
        return data, "bad float: too short"
    p = int(rng.integers(0, len(data) - 4))
    value = struct.pack("<f", float(rng.choice([np.nan, np.inf, -np.inf, 3e38])))
    return data[:p] + value + data[p + 4:], f"bad float at {p}"


def _slices(data, rng, sample, _corpus):
    n = len(data)
    a = int(rng.integers(0, n + 1))
    b = min(n, a + int(rng.integers(1, 64)))
    kind = int(rng.integers(3))
    if kind == 0:
        return data[:a] + data[b:], f"delete [{a}:{b}]"
    if kind == 1:
        return data[:b] + data[a:b] * int(rng.integers(1, 4)) + data[b:], f"duplicate [{a}:{b}]"
    junk = rng.integers(0, 256, int(rng.integers(1, 32)), dtype=np.uint8).tobytes()
    return data[:a] + junk + data[a:], f"insert {len(junk)} bytes at {a}"


def _splice(data, rng, sample, samples):
    same = [s for s in samples if s.ext == sample.ext]
    other = same[int(rng.integers(len(same)))].data
    a, b = int(rng.integers(0, len(data) + 1)), int(rng.integers(0, len(other) + 1))
    return data[:a] + other[b:], f"splice [:{a}] + other[{b}:]"


MUTATIONS = {"truncate": _truncate, "flip": _flip, "huge-count": _huge_count, "bad-float": _bad_float,
             "slices": _slices, "splice": _splice}
_WEIGHTS = {"truncate": 2, "flip": 3, "huge-count": 3, "bad-float": 1, "slices": 1, "splice": 1}


def make_case(samples: list[Sample], seed: int, index: int) -> tuple[Sample, bytes, str]:
    """(sample, mutated bytes, description) of case ``index`` of ``seed``."""
    rng = np.random.default_rng([seed, index])
    sample = samples[int(rng.integers(len(samples)))]
    names = list(MUTATIONS)
    p = np.array([_WEIGHTS[n] for n in names], dtype=float)
    data, steps = sample.data, []
    for _ in range(int(rng.choice([1, 1, 1, 2, 3]))):
        name = names[int(rng.choice(len(names), p=p / p.sum()))]
        data, desc = MUTATIONS[name](data, rng, sample, samples)
        steps.append(f"{name} ({desc})")
    return sample, data, "; ".join(steps)


# ---------------------------------------------------------------------------
# One case, in the worker


def check_case(path: str) -> tuple[str, str]:
    """Load ``path``; (status, detail) with status ok, error (a MeshLoadError: fine),
    memory, invalid (a mesh breaking the invariants) or bug (any other exception)."""
    from clrt.errors import MeshLoadError
    from clrt.scene.load import load_mesh
    try:
        mesh = load_mesh(path)
    except MeshLoadError as exc:
        text = str(exc)
        if "MemoryError" in text:
            return "memory", text
        if "\n" in text:
            return "invalid", "multi-line error message: " + text.replace("\n", "\\n")[:200]
        return "error", text
    except MemoryError:
        return "memory", "MemoryError"
    except Exception as exc:  # noqa: BLE001 -- exactly what the fuzzer looks for
        return "bug", f"{type(exc).__name__}: {exc}"[:300]
    v, f = mesh.vertices, mesh.faces
    if not (v.dtype == np.float32 and f.dtype == np.int32 and v.ndim == 2 and v.shape[1:] == (3,)
            and f.ndim == 2 and f.shape[1:] == (3,) and len(f) > 0):
        return "invalid", f"arrays {v.dtype}{v.shape}, {f.dtype}{f.shape}"
    if f.min() < 0 or f.max() >= len(v) or not np.isfinite(v).all():
        return "invalid", "face index out of range or non-finite vertex"
    return "ok", f"{len(f)} triangles"


_INJECT = "CLRT_FUZZ_INJECT"   # for the harness's own test: "hang:3,crash:5,bug:7,memory:9"


def _injected(index: int) -> str | None:
    for item in os.environ.get(_INJECT, "").split(","):
        kind, _, at = item.partition(":")
        if at.strip() == str(index):
            return kind.strip()
    return None


def _run_injected(kind: str, memory_mb: int) -> tuple[str, str]:
    if kind == "hang":
        while True:
            time.sleep(1)
    if kind == "crash":
        os._exit(70)
    if kind == "memory":
        try:
            np.empty((2 * memory_mb) << 20, np.uint8)    # untouched: costs nothing unless capped
        except MemoryError:
            return "memory", "MemoryError (injected)"
        return "bug", f"allocating {2 * memory_mb} MiB succeeded: no memory limit"
    return "bug", "RuntimeError: injected"


def _limit_memory(extra_mb: int) -> None:
    """Cap the address space at what the process has now plus ``extra_mb``."""
    try:
        import resource
        with open("/proc/self/status") as fh:
            vm = next(int(line.split()[1]) * 1024 for line in fh if line.startswith("VmSize:"))
        limit = vm + (extra_mb << 20)
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    except (ImportError, OSError, StopIteration, ValueError):
        pass   # not Linux: no memory bound, the time bound still holds


def worker(args) -> int:
    """Run cases start, start + stride, ... and report each on stdout."""
    samples = corpus(args.corpus, args.max_file_kb << 10, args.formats)
    import clrt.scene.load  # noqa: F401 -- imports before the memory cap
    import trimesh  # noqa: F401
    _limit_memory(args.memory_mb)
    with tempfile.TemporaryDirectory(prefix="clrt-fuzz-", dir="/dev/shm" if os.path.isdir("/dev/shm") else None) as d:
        index = args.start
        while args.end is None or index < args.end:
            sample, data, _ = make_case(samples, args.seed, index)
            path = os.path.join(d, f"case.{sample.ext}")
            with open(path, "wb") as fh:
                fh.write(data)
            print(f"B {index}", flush=True)
            start = time.perf_counter()
            kind = _injected(index)
            status, detail = _run_injected(kind, args.memory_mb) if kind else check_case(path)
            ms = 1e3 * (time.perf_counter() - start)
            print(f"E {index} {status} {ms:.1f} {' '.join(detail.split())}", flush=True)
            index += args.stride
    return 0


# ---------------------------------------------------------------------------
# The harness, in the parent


@dataclass
class Failure:
    index: int
    status: str       # bug, invalid, memory, slow, hang, crash
    detail: str
    sample: str
    mutation: str


@dataclass
class Report:
    seed: int
    cases: int = 0
    counts: dict = field(default_factory=dict)
    failures: list = field(default_factory=list)
    slowest_ms: float = 0.0
    seconds: float = 0.0

    def summary(self) -> str:
        counts = ", ".join(f"{k} {v}" for k, v in sorted(self.counts.items()))
        return (f"{self.cases} cases in {self.seconds:.1f} s (seed {self.seed}): {counts}; "
                f"slowest {self.slowest_ms:.0f} ms; {len(self.failures)} failure(s)")


class _Worker:
    def __init__(self, options: list[str], start: int, stride: int, end: int | None):
        cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", "--start", str(start), "--stride", str(stride),
               *options] + ([] if end is None else ["--end", str(end)])
        env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
        env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
        self.stderr = tempfile.TemporaryFile()
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=self.stderr, env=env)
        self.stride, self.end = stride, end
        self.current: int | None = None       # case begun, not ended
        self.next = start                     # first case not begun
        self.began = time.monotonic()         # of the current case (or of the start-up)
        self.buffer = b""

    def fileno(self) -> int:
        return self.proc.stdout.fileno()

    def lines(self) -> list[str]:
        chunk = os.read(self.fileno(), 65536)
        if not chunk:
            return []
        self.buffer += chunk
        *done, self.buffer = self.buffer.split(b"\n")
        return [line.decode("utf-8", "replace") for line in done]

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()
        self.proc.stdout.close()
        self.stderr.close()

    def error_output(self) -> str:
        self.stderr.seek(0)
        return self.stderr.read().decode("utf-8", "replace").strip()[-2000:]


def run(seconds: float | None = None, cases: int | None = None, seed: int = 0, formats=FORMATS,
        corpus_dirs=(), max_file_kb: int = 256, case_seconds: float = 2.0, hang_seconds: float | None = None,
        memory_mb: int = 1024, jobs: int = 1, save: str | None = None, log=None) -> Report:
    """Run fuzz cases 0, 1, ... of ``seed`` until ``cases`` ran or ``seconds`` passed."""
    if seconds is None and cases is None:
        raise ValueError("give seconds or cases")
    formats = tuple(formats)
    samples = corpus(corpus_dirs, max_file_kb << 10, formats)
    if not samples:
        raise ValueError(f"no corpus files for formats {formats}")
    hang_seconds = hang_seconds or max(10.0, 5 * case_seconds)
    options = ["--seed", str(seed), "--format", ",".join(formats), "--max-file-kb", str(max_file_kb),
               "--memory-mb", str(memory_mb)]
    for d in corpus_dirs:
        options += ["--corpus", str(d)]
    report = Report(seed)
    start = time.monotonic()
    deadline = None if seconds is None else start + seconds
    jobs = max(1, min(jobs, cases or jobs))
    workers = [_Worker(options, k, jobs, cases) for k in range(jobs)]
    startup = 120.0    # imports and corpus before the first case

    def fail(index: int, status: str, detail: str) -> None:
        sample, data, mutation = make_case(samples, seed, index)
        report.failures.append(Failure(index, status, detail, sample.name, mutation))
        if save:
            os.makedirs(save, exist_ok=True)
            Path(save, f"seed{seed}-case{index}-{status}-{sample.name}").write_bytes(data)
        if log:
            log(f"case {seed}:{index} {status}: {detail} [{sample.name}: {mutation}]")

    def restart(w: _Worker, after: int) -> _Worker:
        w.stop()
        nxt = after + w.stride
        return _Worker(options, nxt, w.stride, w.end)

    try:
        while workers:
            if deadline is not None and time.monotonic() >= deadline:
                break
            ready, _, _ = select.select(workers, [], [], 0.2)
            for w in list(ready):
                lines = w.lines()
                if not lines and w.proc.poll() is not None:   # the worker ended
                    workers.remove(w)
                    if w.current is not None:
                        code = w.proc.returncode
                        fail(w.current, "crash", f"worker died (exit status {code}) during the case")
                        report.cases += 1
                        report.counts["crash"] = report.counts.get("crash", 0) + 1
                        workers.append(restart(w, w.current))
                    else:
                        code, text = w.proc.returncode, w.error_output()
                        w.stop()
                        if code != 0:
                            raise RuntimeError(f"fuzz worker failed (exit status {code}):\n{text}")
                    continue
                for line in lines:
                    kind, _, rest = line.partition(" ")
                    if kind == "B":
                        w.current, w.began = int(rest), time.monotonic()
                    elif kind == "E":
                        index, status, ms, detail = (rest.split(" ", 3) + [""])[:4]
                        index, ms = int(index), float(ms)
                        w.current, w.began = None, time.monotonic()
                        if status in ("ok", "error") and ms > 1e3 * case_seconds:
                            status, detail = "slow", f"{ms:.0f} ms ({detail})"
                        report.cases += 1
                        report.counts[status] = report.counts.get(status, 0) + 1
                        report.slowest_ms = max(report.slowest_ms, ms)
                        if status not in ("ok", "error"):
                            fail(index, status, detail)
            now = time.monotonic()
            for w in list(workers):
                limit = hang_seconds if w.current is not None else startup
                if now - w.began > limit:
                    workers.remove(w)
                    if w.current is None:
                        w.stop()
                        raise RuntimeError("a fuzz worker did not start")
                    fail(w.current, "hang", f"no answer within {hang_seconds:g} s; worker killed")
                    report.cases += 1
                    report.counts["hang"] = report.counts.get("hang", 0) + 1
                    workers.append(restart(w, w.current))
    finally:
        for w in workers:
            w.stop()
    report.seconds = time.monotonic() - start
    return report


def replay(seed: int, index: int, formats, corpus_dirs, max_file_kb: int) -> int:
    """Rerun one case in this process and show what load_mesh does, traceback included."""
    from clrt.scene.load import load_mesh
    samples = corpus(corpus_dirs, max_file_kb << 10, formats)
    sample, data, mutation = make_case(samples, seed, index)
    print(f"case {seed}:{index}: {sample.name}, {len(data)} bytes: {mutation}", flush=True)
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, f"case.{sample.ext}")
        Path(path).write_bytes(data)
        try:
            mesh = load_mesh(path)
            print(f"loaded: {len(mesh.faces)} triangles, {len(mesh.vertices)} vertices")
        except Exception:  # noqa: BLE001
            traceback.print_exc()
    return 0


def _formats(text: str) -> tuple:
    names = tuple(x.strip().lower().lstrip(".") for x in text.split(",") if x.strip())
    bad = [n for n in names if n not in FORMATS]
    if bad or not names:
        raise argparse.ArgumentTypeError(f"unknown format(s) {bad}: choose from {', '.join(FORMATS)}")
    return names


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python tools/fuzz.py", description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seconds", type=float, help="run for this long (default: 60 unless --cases)")
    p.add_argument("--cases", type=int, help="run this many cases")
    p.add_argument("--seed", type=int, default=int(time.time()) % 100000,
                   help="seed of the cases (default: from the clock; printed)")
    p.add_argument("--format", dest="formats", type=_formats, default=FORMATS,
                   help=f"comma-separated formats (default: all: {','.join(FORMATS)})")
    p.add_argument("--corpus", action="append", default=[],
                   help="folder of mesh files to mutate besides the built-in ones (repeatable)")
    p.add_argument("--max-file-kb", type=int, default=256, help="skip larger corpus files (default 256)")
    p.add_argument("--case-seconds", type=float, default=2.0, help="a slower case fails (default 2)")
    p.add_argument("--hang-seconds", type=float, help="kill a worker stuck this long (default 5x case)")
    p.add_argument("--memory-mb", type=int, default=1024,
                   help="address space a worker may add after start-up (default 1024)")
    p.add_argument("--jobs", type=int, default=1, help="worker processes (default 1)")
    p.add_argument("--save", help="folder to write failing inputs to")
    p.add_argument("--replay", metavar="SEED:INDEX", help="rerun one case in this process")
    p.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--start", type=int, default=0, help=argparse.SUPPRESS)
    p.add_argument("--stride", type=int, default=1, help=argparse.SUPPRESS)
    p.add_argument("--end", type=int, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker:
        return worker(args)
    if args.replay:
        seed, _, index = args.replay.partition(":")
        return replay(int(seed), int(index), args.formats, args.corpus, args.max_file_kb)
    seconds = args.seconds if args.seconds is not None or args.cases is not None else 60.0
    print(f"fuzzing {', '.join(args.formats)} (seed {args.seed}) for "
          + (f"{seconds:g} s" if seconds is not None else f"{args.cases} cases"), flush=True)
    report = run(seconds, args.cases, args.seed, args.formats, args.corpus, args.max_file_kb,
                 args.case_seconds, args.hang_seconds, args.memory_mb, args.jobs, args.save,
                 log=lambda line: print(line, flush=True))
    print(report.summary())
    if report.failures:
        print(f"replay one with: python tools/fuzz.py --replay {report.seed}:<case>"
              + "".join(f" --corpus {d}" for d in args.corpus))
    return 1 if report.failures else 0


if __name__ == "__main__":
    sys.exit(main())
