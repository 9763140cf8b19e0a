"""The layering contract of the package, read from the code's own imports
(function-level imports included): imports run one way, from the pipeline's
early stages to its late ones; no module imports another in a circle; no
module reaches for another module's private names; developer tools
(benchmarks/, tools/) are never imported by the package; and ``import clrt``
stays cheap.  docs/architecture.md draws the same floors."""

import ast
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

# Floors, lowest first: a unit (a top-level module or a subpackage of clrt)
# imports only units of its own floor or below -- and on its own floor only
# itself (two units side by side know nothing of each other).
FLOORS = [
    ("clrt.errors", "clrt.config"),
    ("clrt.layouts", "clrt.checks"),
    ("clrt.scene",),                                    # meshes, files, materials, cameras, scene files
    ("clrt.accel", "clrt.reference", "clrt.output"),    # host trees; the brute-force reference; output files
    ("clrt.device", "clrt.options"),                    # devices, uploads, programs; the render options
    ("clrt.query", "clrt.renderer"),                    # ray queries; frames
    ("clrt.batch",),                                    # many frames or rays on Dask
    ("clrt.bench",),                                    # the paper's tables (clrt bench)
    ("clrt.cli",),
    ("clrt.__main__", "clrt"),                          # python -m clrt; the package's front (lazy names)
]
# What `import clrt` loads of the package (the rest comes on first use: clrt/__init__.py).
IMPORT_CLRT_LOADS = ["clrt", "clrt.errors"]


def _modules() -> dict[str, Path]:
    mods = {}
    for path in (REPO / "clrt").rglob("*.py"):
        name = ".".join(path.relative_to(REPO).with_suffix("").parts)
        mods[name.removesuffix(".__init__")] = path
    return mods


def _imports(mods) -> dict[str, set[tuple[str, str | None]]]:
    """module -> {(imported module, name taken from it or None)}."""
    out = {}
    for name, path in mods.items():
        found = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                found |= {(a.name, None) for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                for a in node.names:
                    full = f"{node.module}.{a.name}"
                    found.add((full, None) if full in mods else (node.module, a.name))
        out[name] = found
    return out


def _unit(module: str) -> str:
    return ".".join(module.split(".")[:2])


def _floor(unit: str) -> int:
    for level, units in enumerate(FLOORS):
        if unit in units:
            return level
    raise AssertionError(f"{unit} is on no floor of tests/test_layers.py: place it")


def test_every_import_runs_down_the_floors():
    mods = _modules()
    wrong = []
    for module, imported in _imports(mods).items():
        for target, _ in imported:
            if not target.startswith("clrt.") or _unit(target) == _unit(module) or target == "clrt":
                continue
            a, b = _floor(_unit(module)), _floor(_unit(target))
            if b >= a:
                wrong.append(f"{module} imports {target} ({'the same floor' if a == b else 'upward'})")
    assert not wrong, "\n".join(wrong)


def test_no_import_cycles_between_modules():
    mods = _modules()
    graph = {m: {t for t, _ in imported if t in mods and t != m and not t.startswith(m + ".")
                 and not m.startswith(t + ".")}
             for m, imported in _imports(mods).items()}
    seen, done, cycles = set(), set(), []

    def walk(m, path):
        seen.add(m)
        for t in graph.get(m, ()):
            if t in path:
                cycles.append(" -> ".join(path[path.index(t):] + [t]))
            elif t not in done and t not in seen:
                walk(t, path + [t])
        done.add(m)

    for m in sorted(graph):
        if m not in done:
            seen.clear()
            walk(m, [m])
    assert not cycles, cycles[:5]


def test_no_private_names_across_modules_and_no_developer_tools():
    mods = _modules()
    wrong = []
    for module, imported in _imports(mods).items():
        for target, name in imported:
            if target.split(".")[0] in ("benchmarks", "tools"):
                wrong.append(f"{module} imports the developer tool {target}")
            if (target.startswith("clrt") and name and name.startswith("_") and not name.startswith("__")
                    and _unit(target) != "clrt" and target != module):
                wrong.append(f"{module} imports {target}.{name}")
    assert not wrong, "\n".join(wrong)


def test_import_clrt_stays_cheap():
    code = ("import sys, clrt; print(' '.join(sorted(m for m in sys.modules if m == 'clrt' or m.startswith(('clrt.', "
            "'trimesh', 'pyopencl', 'PIL', 'dask')))))")
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO,
                            check=True).stdout.split()
    assert loaded == IMPORT_CLRT_LOADS
