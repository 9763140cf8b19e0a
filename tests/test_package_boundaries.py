"""The package holds what a user runs: the developer tools (benchmarks/, tools/) import clrt,
never the other way round, and `clrt bench` (clrt/bench) loads neither the batch engine nor
anything the CLI does not need for that command."""

import ast
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _imports(path: Path) -> set[str]:
    """Every module an import statement of ``path`` names, function-level ones included."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names |= {node.module} | {f"{node.module}.{a.name}" for a in node.names}
    return names


def test_clrt_never_imports_the_developer_tools():
    upward = {f"{p.relative_to(REPO)}: {name}" for p in (REPO / "clrt").rglob("*.py") for name in _imports(p)
              if name.split(".")[0] in ("benchmarks", "tools")}
    assert not upward, sorted(upward)


def test_clrt_bench_holds_only_the_papers_command():
    assert sorted(p.name for p in (REPO / "clrt" / "bench").glob("*.py")) == [
        "__init__.py", "common.py", "paper.py", "paper_meshes.py", "paper_report.py"]
    assert not (REPO / "clrt" / "tools").exists()
    lines = sum(len(p.read_text().splitlines()) for p in (REPO / "clrt" / "bench").glob("*.py"))
    assert lines <= 1600, lines


def _loaded(code: str) -> list[str]:
    out = subprocess.run([sys.executable, "-c", f"import sys; {code}; print(' '.join(sorted(sys.modules)))"],
                         cwd=REPO, capture_output=True, text=True, check=True).stdout.split()
    return [m for m in out if m.split(".")[0] in ("clrt", "benchmarks", "tools")]


def test_clrt_bench_does_not_load_the_batch_engine():
    loaded = _loaded("import clrt.bench.paper")
    assert "clrt.bench.paper" in loaded and not [m for m in loaded if m.startswith("clrt.batch")], loaded


def test_the_cli_loads_clrt_bench_only_for_that_command():
    loaded = _loaded("import clrt.cli; clrt.cli._parser()")
    assert "clrt.cli" in loaded and not [m for m in loaded if m.startswith("clrt.bench")], loaded
