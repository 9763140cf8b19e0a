"""benchmarks.fail_fast prints how long clrt takes to say no (the timing the load and
device tests used to assert); here only that it runs and what its table says."""

from benchmarks import fail_fast


def test_fail_fast_prints_a_row_per_check(capsys):
    assert fail_fast.main(["--cases", "5", "--repeat", "1"]) == 0
    out = capsys.readouterr().out
    rows = [line.split(" | ") for line in out.splitlines() if line.startswith("| ") and "---" not in line][1:]
    assert [r[0].lstrip("| ") for r in rows[:4]] == ["NVIDIA ICD diagnosis, default folders",
                                                    "OFF, 10^12 vertices and faces", "PLY ascii, 10^12 vertices",
                                                    "PLY binary, 10^12 vertices"]
    assert [r[4] for r in rows[1:4]] == ["refused"] * 3        # the huge headers, every call
    assert rows[4][0].lstrip("| ").startswith("OBJ, one concave polygon") and rows[4][4] == "loaded"
    mutations = rows[5:]
    assert len(mutations) == 8 and all(r[1] == "5" for r in mutations)
    for r in mutations:                                          # every file loaded or was refused
        loaded, refused = (int(part.split()[0]) for part in r[4].split(", "))
        assert loaded + refused == 5
