"""How fast clrt says no: ``python -m benchmarks.fail_fast``.

    python -m benchmarks.fail_fast
    python -m benchmarks.fail_fast --cases 1000 --repeat 9

Each row times, in this process, work that must end quickly rather than well.
The NVIDIA ICD diagnosis over the default driver folders, which ``clrt info``
and the no-device message run (target 0.2 s).  Mesh files whose headers
promise 10^12 vertices or faces (OFF, ASCII and binary PLY): the loaders must
refuse them before they allocate; an OBJ polygon of 40,000 concave corners,
which the ear clipping's budget must keep to a second or so.  And ``--cases`` copies per format of a small
valid file with one to three random bytes changed, as tests/test_load.py makes
them: each loads or is refused with MeshLoadError.  Printed: the median and the
slowest ms of each row, and how many mutated files loaded or were refused; a row
whose slowest call passes ``--limit-ms`` is marked slow (the exit status stays 0:
this is a table, not a test).  tools/fuzz.py bounds each case's time and memory
over far more kinds of damage.
"""

from __future__ import annotations

import sys

if not __package__:   # run as a script, python benchmarks/NAME.py: import from the repository, not this folder
    import os.path
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.common import POSITIVE, exit_code

HUGE = 10 ** 12
HUGE_HEADERS = {
    "OFF, 10^12 vertices and faces": ("huge.off", f"OFF\n{HUGE} {HUGE} 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"),
    **{f"PLY {encoding.split('_')[0]}, 10^12 vertices": (
        f"huge-{encoding}.ply",
        f"ply\nformat {encoding} 1.0\nelement vertex {HUGE}\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n")
       for encoding in ("ascii", "binary_little_endian")},
}


def samples() -> dict[str, bytes]:
    """One small valid file per format (a tetrahedron; two in the 3DS file)."""
    import trimesh

    from clrt.scene.formats.tds import encode_3ds
    from clrt.scene.mesh import Mesh
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float64)
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    source = trimesh.Trimesh(v, f, process=False)
    obj = "".join(f"v {x} {y} {z}\n" for x, y, z in v) + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in f)
    return {
        "3ds": encode_3ds([Mesh.from_arrays(v, f, "a"), Mesh.from_arrays(v + (2, 0, 0), f, "b")]),
        "off": trimesh.exchange.off.export_off(source).encode(),
        "obj": obj.encode(),
        "ply": source.export(file_type="ply", encoding="binary"),
        "ply-ascii": source.export(file_type="ply", encoding="ascii"),
        "stl": source.export(file_type="stl"),
        "stl-ascii": source.export(file_type="stl_ascii").encode(),
        "glb": source.export(file_type="glb"),
    }


def mutated(data: bytes, rng) -> bytes:
    """``data`` with one to three bytes changed: half random, half a digit (text formats break on digits)."""
    out = bytearray(data)
    for _ in range(rng.integers(1, 4)):
        position = rng.integers(len(out))
        out[position] = rng.integers(256) if rng.random() < 0.5 else ord(str(rng.integers(10)))
    return bytes(out)


def _timed(call) -> tuple[float, object]:
    start = time.perf_counter()
    result = call()
    return 1e3 * (time.perf_counter() - start), result


def _load(path) -> str:
    """'loaded' or 'refused' (MeshLoadError); anything else raised is a bug, and propagates."""
    from clrt.errors import MeshLoadError
    from clrt.scene.load import load_mesh
    try:
        load_mesh(path)
    except MeshLoadError:
        return "refused"
    return "loaded"


def measure(cases: int, repeat: int, seed: int = 20240521) -> list[dict]:
    """One row per check: what, calls, median and slowest ms, and the mutations' outcomes."""
    from clrt.device.context import diagnose_nvidia_icd
    rows = []
    ms = [_timed(diagnose_nvidia_icd)[0] for _ in range(repeat)]
    rows.append({"what": "NVIDIA ICD diagnosis, default folders", "ms": ms, "outcome": "-"})
    with tempfile.TemporaryDirectory(prefix="clrt-fail-fast-") as folder:
        folder = Path(folder)
        valid = samples()
        for kind, data in valid.items():   # untimed: the loaders (and trimesh's) imported, each format read once
            path = folder / f"warm.{kind.split('-')[0]}"
            path.write_bytes(data)
            _load(path)
        # A 40,000-corner concave polygon: ear clipping it would take a minute;
        # past its work budget (clrt/scene/formats/triangulate.py) it keeps its fan.
        teeth = 10_000
        comb = [(0, 0), (2 * teeth - 1, 0)]
        for k in range(teeth - 1, -1, -1):
            comb += [(2 * k + 1, 3), (2 * k, 3)] + ([(2 * k, 1), (2 * k - 1, 1)] if k else [])
        hostile = {"OBJ, one concave polygon of 40,000 corners": (
            "comb.obj", "".join(f"v {x} {y} 0\n" for x, y in comb) + "f " + " ".join(map(str, range(1, len(comb) + 1))))}
        for what, (name, text) in {**HUGE_HEADERS, **hostile}.items():
            path = folder / name
            path.write_text(text)
            runs = [_timed(lambda: _load(path)) for _ in range(repeat)]
            outcomes = {outcome for _, outcome in runs}
            rows.append({"what": what, "ms": [t for t, _ in runs], "outcome": ", ".join(sorted(outcomes))})
        rng = np.random.default_rng(seed)
        for kind, data in valid.items():
            runs = []
            for case in range(cases):
                path = folder / f"m{case}.{kind.split('-')[0]}"
                path.write_bytes(mutated(data, rng))
                runs.append(_timed(lambda: _load(path)))
            loaded = sum(outcome == "loaded" for _, outcome in runs)
            rows.append({"what": f"{kind}, one to three bytes changed", "ms": [t for t, _ in runs],
                         "outcome": f"{loaded} loaded, {len(runs) - loaded} refused"})
    return rows


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.fail_fast", description=__doc__.split("\n")[0])
    p.add_argument("--cases", type=POSITIVE, default=200, help="mutated files per format (default 200)")
    p.add_argument("--repeat", type=POSITIVE, default=5,
                   help="calls of the diagnosis and of each huge header, median kept (default 5)")
    p.add_argument("--limit-ms", type=float, default=1000.0,
                   help="mark a row whose slowest call takes longer (default 1000)")
    args = p.parse_args(argv)
    return exit_code(_report, args)


def _report(args) -> None:
    rows = measure(args.cases, args.repeat)
    print(f"wall ms in this process, the loaders warm; {args.repeat} calls of each check, "
          f"{args.cases} mutated files a format\n")
    print("| check | calls | median ms | slowest ms | outcome | within the limit |")
    print("|---|---:|---:|---:|---|---|")
    for r in rows:
        slowest = max(r["ms"])
        within = "yes" if slowest <= args.limit_ms else f"**slow** (> {args.limit_ms:g} ms)"
        print(f"| {r['what']} | {len(r['ms'])} | {statistics.median(r['ms']):.2f} | {slowest:.2f} | "
              f"{r['outcome']} | {within} |")


if __name__ == "__main__":
    sys.exit(main())
