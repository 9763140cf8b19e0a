"""Docs that run: every ```python block of README.md and docs/*.md, and the quick start.

The blocks of one file run in order in one namespace (later blocks use names
from earlier ones), in a temporary folder holding a copy of the repository's
``assets/``, on the device the suite tests (PoCL here).  A block that cannot
run here is preceded by ``<!-- docs-test: skip (reason) -->``; keep those few.
"""

import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

REPO = Path(__file__).resolve().parents[1]
DOC_FILES = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
FENCE = re.compile(r"(?P<before>(?:^[^\n]*\n){0,2})```python\n(?P<code>.*?)^```", re.S | re.M)
SKIP = re.compile(r"<!--\s*docs-test:\s*skip\s*\((?P<reason>[^)]+)\)\s*-->")


def python_blocks(path: Path) -> list[tuple[int, str, str | None]]:
    """(line, code, skip reason or None) of each python block of ``path``."""
    text = path.read_text()
    out = []
    for match in FENCE.finditer(text):
        skip = SKIP.search(match.group("before"))
        line = text.count("\n", 0, match.start("code")) + 1
        out.append((line, match.group("code"), skip.group("reason") if skip else None))
    return out


RUNNABLE = [p for p in DOC_FILES if python_blocks(p)]


def test_the_readme_and_the_guides_have_python_blocks():
    names = {p.name for p in RUNNABLE}
    assert {"README.md", "ray-queries.md", "scene-files.md"} <= names
    for path in RUNNABLE:
        for line, code, reason in python_blocks(path):
            if reason is None:
                assert 'device="gpu"' not in code, f"{path.name}:{line} needs a GPU: mark it skipped"


@pytest.mark.parametrize("path", RUNNABLE, ids=[p.name for p in RUNNABLE])
def test_python_blocks_run(path, tmp_path, monkeypatch, device):
    shutil.copytree(REPO / "assets", tmp_path / "assets")
    monkeypatch.chdir(tmp_path)
    if device:
        monkeypatch.setenv("PYOPENCL_CTX", device)
    # Run as a script is: a block guarded by `if __name__ == "__main__":` (as
    # distributed.md's must be, for Dask's worker processes) runs its body.
    namespace = {"__name__": "__main__"}
    ran = 0
    for line, code, reason in python_blocks(path):
        if reason is not None:
            continue
        # Line numbers in a traceback point into the Markdown file.
        exec(compile("\n" * (line - 1) + code, str(path), "exec"), namespace)
        ran += 1
    assert ran >= 1
    if path.name == "README.md":   # its refit passes the material again (without one it is the default)
        assert namespace["renderer"].scene.objects[0].material == namespace["scene"].objects[0].material
    if path.name == "distributed.md":   # the guarded example ran: its images are there
        assert sorted(p.name for p in (tmp_path / "out" / "knot").iterdir()) == [
            ".view-0000.png.clrt", ".view-0001.png.clrt", "view-0000.png", "view-0001.png"]


def test_quickstart_resolves_paths_from_the_callers_directory(tmp_path, device):
    """`scripts/quickstart.sh render ../x/mesh.obj -o out.png` from any folder."""
    python = REPO / ".venv" / "bin" / "python"
    if not python.exists():
        pytest.skip("needs the repository's .venv (the quick start's own environment)")
    venv = tmp_path / "venv"   # stands in for a set-up environment: no install is attempted
    (venv / "bin").mkdir(parents=True)
    for name in ("python", "clrt"):
        (venv / "bin" / name).write_text(f'#!/bin/sh\nexec "{REPO / ".venv" / "bin" / name}" "$@"\n')
        (venv / "bin" / name).chmod(0o755)
    (venv / ".clrt-installed").touch()
    os.utime(venv / ".clrt-installed", (2**31, 2**31))   # newer than pyproject.toml
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "tri.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    work = tmp_path / "work"
    work.mkdir()
    env = {**os.environ, "CLRT_VENV": "../venv"}
    if device:
        env["PYOPENCL_CTX"] = device
    result = subprocess.run([str(REPO / "scripts" / "quickstart.sh"), "render", "../meshes/tri.obj",
                             "-o", "tri.png", "--width", "16", "--height", "12", "-q"],
                            cwd=work, env=env, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == str(work / "tri.png")
    assert (work / "tri.png").is_file() and not (REPO / "tri.png").exists()
    assert np.asarray(Image.open(work / "tri.png")).shape == (12, 16, 3)


def _doc_commands(prefix: str) -> list[str]:
    text = (REPO / "docs" / "benchmarks.md").read_text()
    return [m.group(0) for m in re.finditer(re.escape(prefix) + r"[^`]*", text)]


def test_documented_clrt_bench_commands_parse():
    """Every `clrt bench ...` command in docs/benchmarks.md parses with today's
    options (--builder takes paper, sah, device or all)."""
    import shlex
    from clrt.cli import _parser
    commands = _doc_commands("clrt bench --")
    assert len(commands) >= 2
    bad = []
    for line in commands:
        argv = shlex.split(line.split("#")[0])[1:]
        try:
            _parser(bench=True).parse_args(argv)
        except (SystemExit, Exception):   # the CLI parser raises InputError
            bad.append(line)
    assert not bad, bad


def test_documented_raysets_commands_take_one_mesh():
    """python -m benchmarks.raysets takes one mesh: the docs loop over meshes
    rather than give a {a,b} brace expansion (two meshes to the shell)."""
    texts = [(REPO / "README.md").read_text(), *(p.read_text() for p in (REPO / "docs").glob("*.md"))]
    assert not [t for t in texts if "{bunny00,camel}" in t]
    commands = _doc_commands("python -m benchmarks.raysets")
    assert commands and not [c for c in commands if "{" in c and "," in c]


BENCHMARKS = sorted(p.stem for p in (REPO / "benchmarks").glob("*.py") if "def main(" in p.read_text())
# The history (docs/benchmark-log.md) keeps the commands as they were run, under their old names.
CURRENT_DOCS = [p for p in DOC_FILES if p.name != "benchmark-log.md"]


def _benchmark_parser(name: str):
    """The argument parser of benchmarks.NAME, caught before it parses anything."""
    import argparse
    import importlib
    module = importlib.import_module(f"benchmarks.{name}")
    parsers = []

    def keep(parser, *args, **kwargs):
        parsers.append(parser)
        raise SystemExit(0)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(argparse.ArgumentParser, "parse_args", keep)
        with pytest.raises(SystemExit):
            module.main([])
    return parsers[0]


def test_the_benchmarks_page_states_todays_figures_on_one_page():
    """docs/benchmarks.md: at most 400 lines, and every `python -m benchmarks.NAME ...`
    on it names a module of benchmarks/ and parses with that module's options."""
    import shlex
    text = (REPO / "docs" / "benchmarks.md").read_text()
    assert len(text.splitlines()) <= 400
    commands = re.findall(r"python3? -m benchmarks\.(\w+)([^`\n;#]*)", text)
    named = {name for name, _ in commands}
    assert named <= set(BENCHMARKS), named - set(BENCHMARKS)
    assert {"build", "rays", "raysets", "frame", "first_image", "batch", "scale", "speed"} <= named
    bad = []
    for name, args in commands:
        try:
            _benchmark_parser(name).parse_args(shlex.split(args))
        except SystemExit:
            bad.append(f"python -m benchmarks.{name}{args}")
    assert not bad, bad
    assert (REPO / "docs" / "benchmark-log.md").is_file()


def test_docs_name_benchmarks_and_tools_where_they_are():
    """README.md and docs/ (but the history) run benchmarks as `python -m
    benchmarks.NAME` and the fuzzer as `python tools/fuzz.py`; only `clrt bench`
    stays in the package."""
    stale = []
    for path in CURRENT_DOCS:
        text = path.read_text()
        for name in re.findall(r"python3? -m benchmarks\.([a-z_]+)", text):
            if name not in BENCHMARKS:
                stale.append(f"{path.name}: benchmarks.{name}")
        stale += [f"{path.name}: {m}" for m in re.findall(r"clrt[./](?:bench[./](?!paper)\w+|tools\b)", text)]
    assert not stale, stale


@pytest.mark.parametrize("name", BENCHMARKS)
def test_every_benchmark_module_explains_itself(name, capsys):
    """`python -m benchmarks.NAME --help`: a usage naming that command, a
    description that ends as a sentence (not cut off before its example), and
    a line of help for every option."""
    import importlib
    module = importlib.import_module(f"benchmarks.{name}")
    with pytest.raises(SystemExit):
        module.main(["--help"])
    usage, _, rest = capsys.readouterr().out.partition("\n\n")
    assert usage.startswith(f"usage: python -m benchmarks.{name} [-h]")
    description = rest.split("\n\n")[0]
    assert description.rstrip().endswith("."), description
    bare = [a.option_strings[0] for a in _benchmark_parser(name)._actions if a.option_strings and not a.help]
    assert not bare, f"options without help: {bare}"
