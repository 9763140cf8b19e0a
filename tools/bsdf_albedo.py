"""Write clrt/kernels/bsdf_albedo.cl: the directional albedo of the GGX
specular layer that bsdf.cl puts over its Lambert base.

    python tools/bsdf_albedo.py            # rewrites clrt/kernels/bsdf_albedo.cl
    python tools/bsdf_albedo.py --check    # exit 1 if the file is not what this writes

The layer (height-correlated Smith G2, Schlick's Fresnel F = f0 + (1 - f0)
(1 - wo.h)^5) reflects, from a direction at cosine c, the albedo

    E(c, alpha, f0) = f0 A(c, alpha) + (1 - f0) B(c, alpha)

with A the albedo for F = 1 and B the albedo for F = (1 - wo.h)^5 alone;
E_avg = 2 int_0^1 E(c) c dc is its average over the hemisphere.  bsdf.cl
scales the Lambert base by (1 - s E(c_o)) (1 - s E(c_i)) / (1 - s E_avg) so
that layer and base together reflect at most what arrives (docs/path-tracing.md,
"Materials").  Tables: A and B on 48 roughnesses r = sqrt(alpha) = (j / 47)^2 by 48
cosines c = (k / 47)^2, both denser near 0: the albedo dips where c is near
alpha (single scattering loses up to 11% there), a ridge that equal steps of r
would cut too coarsely for smooth surfaces at grazing views;
A_avg and B_avg per roughness.  Float64 Gauss-Legendre quadrature over the
microfacet normals drawn from D(h) h.z (so the integrand F G2 (wo.h) / (c_o h.z)
is smooth but for the horizon's cut); r = 0 is the smooth limit (A = 1,
B = (1 - c)^5).  tests/test_bsdf.py checks the kernel's lookups against an
independent quadrature.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROUGHNESSES, COSINES = 48, 48
NODES = 512                  # per axis of the quadrature over microfacet normals
AVERAGE_NODES = 48           # over c for the hemispherical averages
TARGET = Path(__file__).resolve().parents[1] / "clrt" / "kernels" / "bsdf_albedo.cl"


def _microfacet_grid(alpha: float):
    """Normals h (N, N, 3) distributed as D(h) h.z through u -> theta = atan(alpha sqrt(u / (1 - u))),
    and their quadrature weights (summing to 1)."""
    x, w = np.polynomial.legendre.leggauss(NODES)
    u, wu = 0.5 * (x + 1.0), 0.5 * w
    theta = np.arctan(alpha * np.sqrt(u / (1.0 - u)))
    phi = 2.0 * np.pi * u
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    h = np.stack(np.broadcast_arrays(st * np.cos(phi)[None, :], st * np.sin(phi)[None, :], ct), axis=-1)
    return h, np.outer(wu, wu)


def layer_albedos(cosines, alpha: float) -> np.ndarray:
    """(A, B) at each cosine (K,) for one alpha > 0: (K, 2)."""
    h, weights = _microfacet_grid(alpha)

    def root(z):      # |z| sqrt(1 + alpha^2 tan^2) for a unit direction of cosine z
        return np.sqrt(z * z + alpha * alpha * (1.0 - z * z))

    out = []
    for cos_o in np.atleast_1d(np.asarray(cosines, np.float64)):
        wo = np.array([np.sqrt(max(0.0, 1.0 - cos_o * cos_o)), 0.0, cos_o])
        oh = h @ wo
        ci = 2.0 * oh * h[..., 2] - cos_o                      # wi.z of the mirror direction about h
        visible = (oh > 0) & (ci > 0)
        ci_safe = np.where(visible, ci, 1.0)
        g2_over_co = 2.0 * ci_safe / (ci_safe * root(cos_o) + cos_o * root(ci_safe))   # finite at c_o = 0
        base = np.where(visible, g2_over_co * oh / h[..., 2], 0.0)
        schlick = np.clip(1.0 - oh, 0.0, 1.0) ** 5
        out.append((np.sum(weights * base), np.sum(weights * base * schlick)))
    return np.array(out)


def tables():
    """A, B (ROUGHNESSES x COSINES) and A_avg, B_avg (ROUGHNESSES)."""
    r = (np.arange(ROUGHNESSES) / (ROUGHNESSES - 1)) ** 2
    c = (np.arange(COSINES) / (COSINES - 1)) ** 2
    xa, wa = np.polynomial.legendre.leggauss(AVERAGE_NODES)
    ca, wca = 0.5 * (xa + 1.0), 0.5 * wa
    a, b = np.ones((ROUGHNESSES, COSINES)), np.ones((ROUGHNESSES, COSINES))
    a_avg, b_avg = np.ones(ROUGHNESSES), np.ones(ROUGHNESSES)
    b[0] = (1.0 - c) ** 5
    b_avg[0] = 1.0 / 21.0                 # 2 int (1 - c)^5 c dc
    for j in range(1, ROUGHNESSES):
        alpha = r[j] ** 2
        a[j], b[j] = layer_albedos(c, alpha).T
        pairs = layer_albedos(ca, alpha)
        a_avg[j], b_avg[j] = 2.0 * np.sum((wca * ca)[:, None] * pairs, axis=0)
    return a, b, a_avg, b_avg


def _array(name: str, values: np.ndarray) -> str:
    def row(v):
        return "{" + ", ".join(f"{x:.7f}f" for x in v) + "}"

    if values.ndim == 1:
        return f"__constant float {name}[{len(values)}] = {row(values)};\n"
    rows = ",\n    ".join(row(v) for v in values)
    return f"__constant float {name}[{values.shape[0]}][{values.shape[1]}] = {{\n    {rows}}};\n"


def source() -> str:
    a, b, a_avg, b_avg = tables()
    return (
        "// Directional albedo of bsdf.cl's GGX specular layer (height-correlated Smith\n"
        "// G2, Schlick's F): E(c, alpha, f0) = f0 A + (1 - f0) B, and its hemispherical\n"
        "// average.  Written by tools/bsdf_albedo.py (float64 quadrature; it says how):\n"
        f"// do not edit, run it again.  Rows: roughness r = sqrt(alpha) = (j / {ROUGHNESSES - 1})^2; columns:\n"
        f"// cosine c = (k / {COSINES - 1})^2.\n"
        "#ifndef CLRT_BSDF_ALBEDO_CL\n#define CLRT_BSDF_ALBEDO_CL\n\n"
        f"#define LAYER_ALBEDO_ROUGHNESSES {ROUGHNESSES}\n#define LAYER_ALBEDO_COSINES {COSINES}\n\n"
        + _array("LAYER_ALBEDO_A", a) + _array("LAYER_ALBEDO_B", b)
        + _array("LAYER_ALBEDO_A_AVERAGE", a_avg) + _array("LAYER_ALBEDO_B_AVERAGE", b_avg)
        + "\n#endif\n")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if the file differs from what would be written")
    args = parser.parse_args(argv)
    text = source()
    if args.check:
        same = TARGET.is_file() and TARGET.read_text() == text
        print(f"{TARGET.name}: {'up to date' if same else 'differs'}")
        return 0 if same else 1
    TARGET.write_text(text)
    print(f"wrote {TARGET}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
