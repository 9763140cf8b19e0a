"""benchmarks.tree_counts counts what a walk of the rows does: a one-leaf
tree's counts are known exactly, its hits agree with clrt's on a real mesh,
and the table compares the builders' trees."""

import numpy as np
import pytest

import clrt
from benchmarks import tree_counts
from clrt import accel
from clrt.device.context import create_context

from conftest import SHARED_MESHES, TEST_MESHES


@pytest.fixture(scope="module")
def queue(device):
    return create_context(device)


def test_a_one_leaf_tree_is_counted_exactly(queue):
    """Three triangles of one box (the SAH has no plane to split them at):
    one leaf.  Every ray opens the root row once; a ray through the box tests
    the leaf's three triangles and hits the one under it, a ray beside it
    tests nothing."""
    corners = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[1, 1, 0], [0, 1, 0], [1, 0, 0]],
                        [[0, 0, 0], [1, 1, 0], [0, 1, 0]]], np.float32)
    built = accel.build(corners, "box", "sah", 4)
    assert len(built.rows) == 1
    origins = np.array([[0.2, 0.1, -1.0], [5.0, 5.0, -1.0]], np.float32)
    directions = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]], np.float32)
    counts = tree_counts.count_walks(*queue, built.rows, corners[built.prim_ids], origins, directions)
    assert counts[:, :3].tolist() == [[1, 1, 3], [1, 0, 0]]
    assert built.prim_ids[counts[0, 3]] == 0 and counts[1, 3] == -1


def test_hits_agree_with_clrt_and_rows_are_counted_per_row(queue):
    """On a torus the counted walk hits what clrt's traversal hits (it tests
    triangles with Moller-Trumbore, clrt watertight: rays at edges may
    differ), and the per-row visits add up to the rows opened."""
    mesh = TEST_MESHES["torus"]()
    rng = np.random.default_rng(4)
    origins = (rng.random((4000, 3)) * 4 - 2).astype(np.float32)
    directions = rng.normal(size=(4000, 3)).astype(np.float32)
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    corners = mesh.vertices[mesh.faces].astype(np.float32)
    built = accel.build(corners, "box", "sah", 4)
    counts, visits = tree_counts.count_walks(*queue, built.rows, corners[built.prim_ids], origins, directions,
                                             row_visits=True)
    hits = clrt.trace(mesh, origins, directions, accel="none")
    assert (counts[:, 3] >= 0).mean() > 0.1 and ((counts[:, 3] >= 0) == (hits.prim >= 0)).mean() > 0.999
    agree = counts[:, 3] >= 0
    assert (built.prim_ids[counts[agree, 3]] == hits.prim[agree]).mean() > 0.999
    assert visits.sum() == counts[:, 0].sum() and visits[0] == len(origins)      # every ray opens the root


@pytest.mark.skipif(not SHARED_MESHES.is_dir(), reason="needs ../shared/meshes")
def test_the_table_compares_the_trees(device, capsys):
    code = tree_counts.main(["--meshes", "camel", "--builders", "sah,device/reinsert=0,device/reinsert=4", "--size", "96x54",
                             "--random", "3K"] + (["--device", device] if device else []))
    assert code == 0
    rows = [line.split("|") for line in capsys.readouterr().out.splitlines() if line.startswith("| camel ")]
    assert [(r[2].strip(), r[6].strip()) for r in rows] == [(b, s) for b in ("sah", "device/reinsert=0", "device/reinsert=4")
                                                             for s in ("primary", "random")]
    sah = {r[2].strip(): float(r[4]) for r in rows}
    assert float(rows[0][5]) == 1.0 and float(rows[0][11]) == 1.0          # ratios to the first builder
    assert sah["device/reinsert=4"] < sah["device/reinsert=0"]
    assert all(float(r[14]) == 100.0 for r in rows)                         # every tree hits the same rays
