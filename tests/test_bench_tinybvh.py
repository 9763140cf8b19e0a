"""benchmarks.tinybvh without tinybvh: the rays of issue 39 (their distribution
and their draw order), the inputs the driver gets, the comparison of answers,
fetching from a local clone, and one-line errors.  Timing tinybvh needs its
fetched sources and a C++ compiler: that is the benchmark's job, not a test's."""

import subprocess

import numpy as np
import pytest

from benchmarks import tinybvh
from benchmarks.raysets import read_rays, write_rays
from clrt.scene import primitives

BOUNDS = np.array([[-1.0, 2.0, 0.5], [3.0, 2.5, 4.5]])


def _reference_rays(bounds, count, seed):
    """The issue's recipe, written out: origins in the box grown by 10 % about its
    centre (N x 3 uniforms first), then z in [-1, 1), then phi in [0, 2 pi)."""
    rng = np.random.default_rng(seed)
    lo, hi = bounds
    size = 1.1 * (hi - lo)
    origins = (lo + hi) / 2 - size / 2 + rng.random((count, 3)) * size
    z = 2 * rng.random(count) - 1
    phi = 2 * np.pi * rng.random(count)
    s = np.sqrt(1 - z * z)
    return origins, np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)


def test_rays_follow_the_issues_recipe_and_seed():
    o, d = tinybvh.issue_rays(BOUNDS, 20_000, seed=0)
    assert o.dtype == d.dtype == np.float32 and o.shape == d.shape == (20_000, 3)
    ref_o, ref_d = _reference_rays(BOUNDS, 20_000, 0)
    assert np.allclose(o, ref_o, rtol=0, atol=1e-6) and np.allclose(d, ref_d, rtol=0, atol=1e-7)
    again = tinybvh.issue_rays(BOUNDS, 20_000, seed=0)
    assert np.array_equal(again[0], o) and np.array_equal(again[1], d)
    other = tinybvh.issue_rays(BOUNDS, 20_000, seed=1)
    assert not np.array_equal(other[0], o) and not np.array_equal(other[1], d)


def test_rays_fill_the_grown_box_and_the_sphere():
    o, d = tinybvh.issue_rays(BOUNDS, 50_000, seed=3)
    lo, hi = BOUNDS
    grown = np.array([lo - 0.05 * (hi - lo), hi + 0.05 * (hi - lo)])
    assert (o >= grown[0] - 1e-6).all() and (o <= grown[1] + 1e-6).all()
    # every 10 % slab of the grown box holds about a tenth of the origins
    cells = np.floor(10 * (o - grown[0]) / (grown[1] - grown[0])).clip(0, 9).astype(int)
    for axis in range(3):
        assert np.allclose(np.bincount(cells[:, axis], minlength=10) / len(o), 0.1, atol=0.01)
    assert np.allclose(np.linalg.norm(d.astype(np.float64), axis=1), 1, atol=1e-6)
    # uniform on the sphere: each coordinate uniform in [-1, 1] (Archimedes), no side preferred
    for axis in range(3):
        assert np.allclose(np.histogram(d[:, axis], bins=4, range=(-1, 1))[0] / len(d), 0.25, atol=0.01)
    assert np.abs(d.mean(axis=0)).max() < 0.01


def test_written_rays_read_back_bit_for_bit(tmp_path):
    o, d = tinybvh.issue_rays(BOUNDS, 1000, seed=0)
    write_rays(tmp_path / "rays.f32", o, d)
    got = read_rays(tmp_path / "rays.f32")
    assert np.array_equal(got[0], o) and np.array_equal(got[1], d)


def test_the_triangle_soup_is_the_mesh_in_face_order():
    mesh = primitives.icosphere(1)
    soup = tinybvh.triangle_soup(mesh)
    assert soup.dtype == np.float32 and soup.shape == (len(mesh.faces), 3, 4)
    assert (soup[..., 3] == 0).all()
    for f in (0, len(mesh.faces) // 2, len(mesh.faces) - 1):
        assert np.array_equal(soup[f, :, :3], np.asarray(mesh.vertices, np.float32)[mesh.faces[f]])


def test_agreement_counts_rays_that_differ():
    clrt_prims = np.array([3, -1, 5, 7, -1])
    assert tinybvh.agreement("closest", clrt_prims, clrt_prims.copy()) == \
        "the same rays hit, each on the same triangle"
    text = tinybvh.agreement("closest", clrt_prims, np.array([3, 2, 5, 8, -1]))
    assert "1 rays differ on hit or miss" in text and "1 of the 3 hits on another triangle" in text
    hits = np.array([True, False, True])
    assert tinybvh.agreement("any", hits, hits.copy()) == "the same rays hit"
    assert "2 rays differ" in tinybvh.agreement("any", hits, np.array([False, True, True]))


def _git(*args, cwd):
    subprocess.run(["git", *args], cwd=cwd, check=True, capture_output=True)


def test_fetch_from_a_local_clone_takes_the_pinned_commit(tmp_path, monkeypatch, capsys):
    clone = tmp_path / "clone"
    clone.mkdir()
    _git("init", "-q", cwd=clone)
    (clone / "tiny_bvh.h").write_text("pinned\n")
    (clone / "kernels").mkdir()
    (clone / "kernels" / "walk.cl").write_text("kernel\n")
    _git("add", ".", cwd=clone)
    _git("-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "pinned", cwd=clone)
    pinned = subprocess.run(["git", "rev-parse", "HEAD"], cwd=clone, capture_output=True, text=True).stdout.strip()
    (clone / "tiny_bvh.h").write_text("later\n")
    _git("-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qam", "later", cwd=clone)
    monkeypatch.setattr(tinybvh, "PINNED_COMMIT", pinned)
    monkeypatch.setattr(tinybvh, "FILES", {"tiny_bvh.h": "tiny_bvh.h", "kernels/walk.cl": "walk.cl"})
    dest = tmp_path / "sources"
    with pytest.raises(tinybvh.InputError, match="no tinybvh sources"):
        tinybvh.check_sources(dest)
    assert tinybvh.main(["fetch", str(dest), "--from", str(clone)]) == 0
    assert pinned in capsys.readouterr().out
    assert (dest / "tiny_bvh.h").read_text() == "pinned\n" and (dest / "walk.cl").read_text() == "kernel\n"
    tinybvh.check_sources(dest)
    (dest / "COMMIT").write_text("0" * 40 + "\n")
    with pytest.raises(tinybvh.InputError, match="not the pinned"):
        tinybvh.check_sources(dest)
    monkeypatch.setattr(tinybvh, "FILES", {"missing.h": "missing.h"})
    assert tinybvh.main(["fetch", str(dest), "--from", str(clone)]) == 2
    assert "no missing.h at tinybvh commit" in capsys.readouterr().err


@pytest.mark.parametrize("argv, message", [
    ([], "required"),
    (["run"], "required"),
    (["run", "m.off", "--device", "tpu"], "invalid choice"),
    (["run", "m.off", "--rays", "r.f32", "--count", "5"], "--rays reads a ray file"),
    (["run", "m.off", "--rays", "r.f32", "--seed", "1"], "--rays reads a ray file"),
    (["run", "m.off", "--builds", "sah,bvh8"], "--builds"),
    (["run", "m.off", "--builds", "sah,sah"], "--builds"),
    (["run", "m.off", "--count", "0"], "--count"),
    (["run", "m.off", "--repeat", "0"], "--repeat"),
    (["run", "m.off", "--driver", "/no/such/driver"], "no such file"),
    (["fetch", "--from", "/no/such/clone"], "no such folder"),
])
def test_bad_arguments_fail_in_one_line(argv, message, capsys):
    assert tinybvh.main(argv) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and err.startswith("clrt: ") and message in err, err


def test_a_run_without_sources_says_how_to_fetch_them(tmp_path, capsys):
    assert tinybvh.main(["run", "m.off", "--sources", str(tmp_path / "none")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "python -m benchmarks.tinybvh fetch" in err, err


def test_fetch_leaves_a_folder_of_other_files_alone(tmp_path, capsys):
    (tmp_path / "mine.txt").write_text("keep")
    assert tinybvh.main(["fetch", str(tmp_path), "--from", str(tmp_path)]) == 2
    assert "not a tinybvh fetch" in capsys.readouterr().err and (tmp_path / "mine.txt").read_text() == "keep"
