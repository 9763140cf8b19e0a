"""benchmarks.batch --breakdown: where a batch's time goes, one row per source."""

import io

import pytest

from clrt.scene import primitives

pytest.importorskip("distributed")


def test_breakdown_has_a_row_per_source_with_its_set_up_and_frame(tmp_path, device):
    from benchmarks.batch import _breakdown

    sources = []
    for name, mesh in (("ball", primitives.icosphere(2)), ("ring", primitives.torus(1.0, 0.3, 24, 12))):
        path = tmp_path / f"{name}.obj"
        path.write_text("".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in mesh.vertices.tolist())
                        + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in mesh.faces.tolist()))
        sources.append((path, len(mesh.faces)))
    out = io.StringIO()
    _breakdown([p for p, _ in sources], 3, (40, 30), 1, device, {1: 0.05, 2: 0.08}, out)
    text = out.getvalue()
    assert "once per worker, the context and the builder's and renderer's programs:" in text
    rows = [line.split("|")[1:-1] for line in text.splitlines() if line.startswith("| ") and ".obj" in line]
    assert [r[0].strip() for r in rows] == ["ball.obj", "ring.obj"]
    for row, (_, triangles) in zip(rows, sources):
        assert int(row[1].replace(",", "")) == triangles
        assert all(float(cell) >= 0 for cell in row[2:])
    worker_lines = [line for line in text.splitlines() if "worker(s):" in line]
    assert [line.split(":")[0].strip() for line in worker_lines] == ["1 worker(s)", "2 worker(s)"]
    assert "50.0 ms," in worker_lines[0] and "80.0 ms," in worker_lines[1]
