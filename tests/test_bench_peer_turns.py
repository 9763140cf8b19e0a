"""benchmarks.peer_turns: clrt beside Open3D and Embree, taking turns -- the
ratios and the table from given times, the --open3d option, and (where Open3D
is installed) the same hits as clrt's on the same rays."""

import statistics
import sys

import numpy as np
import pytest

import clrt
from benchmarks import peer_turns, raysets
from clrt.reference import intersect
from clrt.scene.scene import Camera

from conftest import TEST_MESHES


def test_paired_ratios_pair_each_turn():
    ours = [10.0, 20.0, 40.0]
    theirs = [30.0, 20.0, 20.0]     # 3x, 1x, 0.5x: the pairs' median is 1, the medians' ratio 20 / 20
    other = [5.0, 60.0, 120.0]      # 0.5x, 3x, 3x
    assert peer_turns.paired_ratio(ours, theirs) == 1.0
    assert peer_turns.paired_ratio(ours, other) == 3.0
    # the fastest peer of each turn: 5 / 10, 20 / 20, 20 / 40
    assert peer_turns.best_ratio(ours, [theirs, other]) == statistics.median([0.5, 1.0, 0.5])
    assert peer_turns.best_ratio(ours, [other]) == peer_turns.paired_ratio(ours, other)


def test_the_table_has_a_cell_per_column_and_names_differing_hits():
    header = peer_turns.turns_header(["Open3D", "Embree x2"])
    columns = header.splitlines()[0].count("|") - 1
    assert header.splitlines()[1] == "|---" * columns + "|"
    times = {"clrt": [10.0, 12.0, 11.0], "Open3D": [20.0, 24.0, 22.0], "Embree x2": [30.0, 12.0, 33.0]}
    build = peer_turns.turns_row("build from arrays", None, times)
    same = peer_turns.turns_row("random, closest", 1_000_000, times, {"clrt": 7, "Open3D": 7, "Embree x2": 7},
                                {"clrt": 0, "Open3D": 0})
    odd = peer_turns.turns_row("random, closest", 1_000_000, times, {"clrt": 7, "Open3D": 7, "Embree x2": 9},
                               {"clrt": 0, "Open3D": 2})
    for row in (build, same, odd):
        assert row.count("|") - 1 == columns, row
    cells = [c.strip() for c in same.split("|")[1:-1]]
    assert cells[:3] == ["random, closest", "1,000,000", "11.0 (90.9)"]   # median ms, 1M rays / 11 ms
    assert cells[5:8] == ["2.00", "3.00", "2.00"]   # Open3D 2x every turn; Embree 3, 1, 3; best 2, 1, 2
    assert cells[8] == "7, all equal"
    assert [c.strip() for c in build.split("|")[1:3]] == ["build from arrays", "-"]
    assert build.split("|")[3].strip() == "11.0" and build.split("|")[-2].strip() == "-"
    assert odd.split("|")[-2].strip() == "7; Open3D 7 (2 rays differ), Embree x2 9"
    one = peer_turns.turns_row("random, closest", 10, times, {"clrt": 7, "Open3D": 6, "Embree x2": 7},
                               {"clrt": 0, "Open3D": 1})
    assert one.split("|")[-2].strip() == "7; Open3D 6 (1 ray differs)"
    alone = peer_turns.turns_row("camera, occlusion", 10, {"clrt": [1.0]}, {"clrt": 3}, {"clrt": 0})
    assert alone.split("|")[-3:-1] == [" - ", " 3 "]


def test_open3d_option_without_open3d_fails_in_one_line(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "open3d", None)   # as if not installed: its import raises ImportError
    with pytest.raises(SystemExit) as exit_info:
        raysets.main(["--open3d", "--rays", "1K"])
    assert exit_info.value.code == 2
    assert capsys.readouterr().err.strip().splitlines()[-1] == (
        "python -m benchmarks.raysets: error: --open3d needs Open3D: pip install open3d-cpu")


@pytest.fixture(scope="module")
def torus():
    return TEST_MESHES["torus"]()


def test_open3d_finds_the_hits_clrt_finds(torus, device):
    """The same rays through Open3D's RaycastingScene: the same rays hit, closest
    and occlusion, as clrt's and as the loop over every triangle (AO rays: with
    their reach)."""
    pytest.importorskip("open3d", reason="the comparison with Open3D needs open3d-cpu")
    accel = clrt.Accel(torus, device=device)
    camera = Camera.framing(torus.bounds, 48, 32, 45.0)
    corners = torus.vertices[torus.faces].astype(np.float32)
    for kind in ("random", "camera", "ao"):
        o, d, reach = raysets.make_ray_set(kind, torus, 2000, 5, accel, camera)
        m = peer_turns.measure_in_turns(accel, torus, o, d, reach, open3d=True, repeat=2, warmup=1)
        _, prim_ref, _, _ = intersect(o, d, corners, np.zeros(len(o), np.float32), np.full(len(o), reach, np.float32))
        expected = int((prim_ref >= 0).sum())
        assert 0 < expected < len(o), kind
        for query in ("closest", "any"):
            assert m["hits"]["clrt"][query] == m["hits"]["Open3D"][query] == expected, (kind, query)
            assert m["differ"]["Open3D"][query] == 0, (kind, query)
            assert len(m["times"]["Open3D"][query]) == len(m["times"]["clrt"][query]) == 2


def test_the_command_prints_the_peers_table(tmp_path, capsys, device):
    pytest.importorskip("open3d", reason="the comparison with Open3D needs open3d-cpu")
    from test_raysets import _off
    mesh = tmp_path / "torus.off"
    mesh.write_text(_off())
    args = [str(mesh), "--rays", "500", "--set", "random", "--set", "camera", "--size", "24x16", "--repeat", "1",
            "--warmup", "0", "--builder", "auto", "--open3d"] + (["--device", device] if device else [])
    assert raysets.main(args) == 0
    text = capsys.readouterr().out
    table = text[text.index("| case |"):].splitlines()
    assert table[0] == peer_turns.turns_header(["Open3D"]).splitlines()[0]
    rows = [line for line in table[2:] if line.startswith("|")]
    assert [r.split("|")[1].strip() for r in rows] == ["build from arrays", "random, closest", "random, occlusion",
                                                       "camera, closest", "camera, occlusion"]
    for row in rows[1:]:
        assert row.endswith(", all equal |"), row
    assert "auto: " in text   # the builder "auto" chose is named
