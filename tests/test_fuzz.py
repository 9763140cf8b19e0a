"""Fuzzing the loaders (tools/fuzz.py) for a bounded number of cases.

Each case is a mutated real file loaded in a worker process with bounded time
and address space; only MeshLoadError (or a valid mesh) may come out.  The
long run is a separate command: ``python tools/fuzz.py --seconds 600 --jobs 2
--corpus ../shared/meshes``.  tests/test_load.py has the in-process byte
mutations; this adds truncation, huge header counts, NaN/inf numbers, slices
and splices, real files as seeds, and the memory and hang bounds.
"""

import importlib.util
import sys

import numpy as np
import pytest

from conftest import REPO, SHARED_MESHES


def _load_tool():
    """tools/fuzz.py, a script beside tools/mutate.py (not a package clrt ships)."""
    spec = importlib.util.spec_from_file_location("clrt_fuzz_tool", REPO / "tools" / "fuzz.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module          # dataclasses look the module up while it loads
    spec.loader.exec_module(module)
    return module


fuzz = _load_tool()

CORPUS = [SHARED_MESHES] if SHARED_MESHES.is_dir() else []


def test_loaders_survive_mutated_files():
    report = fuzz.run(cases=2500, seed=20240611, corpus_dirs=CORPUS, max_file_kb=200, case_seconds=2.0,
                      memory_mb=1024)
    assert report.cases == 2500
    assert not report.failures, "\n".join(f"{f.index} {f.status}: {f.detail} [{f.sample}: {f.mutation}]"
                                          for f in report.failures[:10])
    assert report.counts.get("ok", 0) > 50 and report.counts.get("error", 0) > 500, report.counts


def test_harness_catches_hangs_crashes_bugs_and_memory(monkeypatch):
    monkeypatch.setenv("CLRT_FUZZ_INJECT", "hang:2,crash:4,bug:6,memory:8")
    report = fuzz.run(cases=10, seed=1, formats=("obj", "3ds"), case_seconds=1.0, hang_seconds=2.0,
                      memory_mb=512)
    assert report.cases == 10
    assert [(f.index, f.status) for f in sorted(report.failures, key=lambda f: f.index)] == [
        (2, "hang"), (4, "crash"), (6, "bug"), (8, "memory")]
    assert all(f.sample and f.mutation for f in report.failures)


def test_the_command(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("CLRT_FUZZ_INJECT", "bug:3")
    assert fuzz.main(["--cases", "20", "--seed", "5", "--format", "ply", "--save", str(tmp_path)]) == 1
    out = capsys.readouterr().out
    assert "case 5:3 bug" in out and "1 failure(s)" in out and "--replay 5:<case>" in out
    saved = list(tmp_path.iterdir())
    assert len(saved) == 1 and saved[0].name.startswith("seed5-case3-bug-")
    monkeypatch.delenv("CLRT_FUZZ_INJECT")
    assert fuzz.main(["--cases", "20", "--seed", "5", "--format", "ply"]) == 0
    with pytest.raises(SystemExit):
        fuzz.main(["--format", "xyz"])


def test_every_mutation_works_on_every_sample():
    samples = fuzz.corpus()
    assert {s.ext for s in samples} == set(fuzz.FORMATS)
    rng = np.random.default_rng(0)
    for sample in samples:
        for name, mutate in fuzz.MUTATIONS.items():
            for _ in range(5):
                data, description = mutate(sample.data, rng, sample, samples)
                assert isinstance(data, bytes) and description, (sample.name, name)


def test_huge_counts_hit_the_header_fields():
    samples = {s.name: s for s in fuzz.corpus()}
    rng = np.random.default_rng(1)
    expected = {"sphere.off": ["number at"], "sphere-binary.ply": ["number at"],
                "sphere-binary.stl": ["4-byte field at 80"], "scene.glb": ["huge count: number at"],
                "two-objects.3ds": ["4-byte field", "2-byte field"]}
    for name, fragments in expected.items():
        descriptions = " | ".join(fuzz.MUTATIONS["huge-count"](samples[name].data, rng, samples[name], [])[1]
                                  for _ in range(60))
        for fragment in fragments:
            assert fragment in descriptions, (name, fragment)


def test_cases_are_reproducible():
    samples = fuzz.corpus()
    assert fuzz.make_case(samples, 3, 17) == fuzz.make_case(samples, 3, 17)
    assert fuzz.make_case(samples, 3, 17)[1] != fuzz.make_case(samples, 3, 18)[1]
