"""Regenerate knot.obj: a tube around a (3, 2) torus knot, 180 x 12 quads.

Run from anywhere: ``python assets/meshes/make_knot.py``.  Needs only numpy,
and is deterministic, so the committed OBJ is exactly what this writes.
"""

from pathlib import Path

import numpy as np

P, Q = 3, 2              # winds P times around the y axis and Q times through the hole
R, A, TUBE = 1.0, 0.45, 0.16
N_ALONG, N_AROUND = 180, 12


def knot_tube():
    t = np.linspace(0.0, 2 * np.pi, N_ALONG, endpoint=False)
    ring = R + A * np.cos(Q * t)
    curve = np.stack([ring * np.cos(P * t), A * np.sin(Q * t), ring * np.sin(P * t)], 1)
    tangent = np.roll(curve, -1, 0) - np.roll(curve, 1, 0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)

    # Parallel transport (rotation-minimising frames) avoids the twists and flips of
    # Frenet frames; the leftover angle where the loop closes is spread evenly.
    normal = np.empty_like(curve)
    n = np.cross(tangent[0], [0.0, 1.0, 0.0])
    normal[0] = n / np.linalg.norm(n)
    for i in range(1, N_ALONG):
        n = normal[i - 1] - tangent[i] * (normal[i - 1] @ tangent[i])
        normal[i] = n / np.linalg.norm(n)
    end = normal[-1] - tangent[0] * (normal[-1] @ tangent[0])
    end /= np.linalg.norm(end)
    gap = np.arctan2(np.cross(end, normal[0]) @ tangent[0], end @ normal[0])
    binormal = np.cross(tangent, normal)
    twist = gap * np.arange(N_ALONG) / N_ALONG
    normal, binormal = (np.cos(twist)[:, None] * normal + np.sin(twist)[:, None] * binormal,
                        -np.sin(twist)[:, None] * normal + np.cos(twist)[:, None] * binormal)

    phi = np.linspace(0.0, 2 * np.pi, N_AROUND, endpoint=False)
    offset = np.cos(phi)[None, :, None] * normal[:, None] + np.sin(phi)[None, :, None] * binormal[:, None]
    vertices = (curve[:, None] + TUBE * offset).reshape(-1, 3)

    i, j = np.meshgrid(np.arange(N_ALONG), np.arange(N_AROUND), indexing="ij")
    a = i * N_AROUND + j
    b = ((i + 1) % N_ALONG) * N_AROUND + j
    c = ((i + 1) % N_ALONG) * N_AROUND + (j + 1) % N_AROUND
    d = i * N_AROUND + (j + 1) % N_AROUND
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    # Wind the triangles outwards: the enclosed volume must come out positive.
    tri = vertices[faces]
    if np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() < 0:
        faces = faces[:, ::-1]
    return vertices, faces


def main():
    vertices, faces = knot_tube()
    lines = [f"# (3,2) torus-knot tube, {len(vertices)} vertices, {len(faces)} triangles; "
             "written by make_knot.py"]
    lines += [f"v {x:.5f} {y:.5f} {z:.5f}" for x, y, z in vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    out = Path(__file__).with_name("knot.obj")
    out.write_text("\n".join(lines) + "\n")
    print(f"wrote {out} ({out.stat().st_size} bytes)")


if __name__ == "__main__":
    main()
