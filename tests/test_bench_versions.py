"""benchmarks.versions runs two checkouts side by side (here: this one twice,
on a small mesh) and tells whether their answers agree."""

from benchmarks import versions
from clrt.scene import primitives


def test_versions_compares_answers_and_times(tmp_path, device, capsys):
    mesh = primitives.icosphere(2)
    lines = ["OFF", f"{len(mesh.vertices)} {len(mesh.faces)} 0"]
    lines += [" ".join(map(repr, v)) for v in mesh.vertices.tolist()]
    lines += ["3 " + " ".join(map(str, f)) for f in mesh.faces.tolist()]
    (tmp_path / "ico.off").write_text("\n".join(lines) + "\n")
    assert versions.main(["--base", str(versions.REPO), "--mesh-dir", str(tmp_path), "--meshes", "ico",
                          "--device", device or "cpu", "--rounds", "1", "--rays", "2048", "--size", "32x24",
                          "--repeat", "2"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == out[1].replace("this:", "base:") and out[1].endswith("clrt/__init__.py")   # what each measured
    rows = [[cell.strip() for cell in line.strip("|").split("|")] for line in out[5:]]
    answers = [r for r in rows if "answers" in r[1] or "pixels" in r[1]]
    assert len(answers) == 5 and all(r[4] == "the same" for r in answers)
    times = [r for r in rows if r[1].endswith(" ms")]
    assert times and all(float(r[2]) > 0 and float(r[3]) > 0 for r in times)
