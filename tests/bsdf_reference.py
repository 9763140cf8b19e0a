"""A float64 numpy reference of the path tracer's BSDF (clrt/kernels/bsdf.cl).

Written from the equations, not from the kernel: glTF 2.0 Appendix B (Lambert,
GGX D in its N.H form, Schlick's Fresnel, fresnel_mix, the metal/dielectric
mix), KHR_materials_specular's fresnel_mix (layer weighted by
specular * F, base by 1 - specular * max(F)), KHR_materials_transmission's
base = mix(diffuse, btdf * baseColor, transmission), Smith's height-correlated
G2 = 1 / (1 + Lambda(wo) + Lambda(wi)) with Lambda from tan(theta), and
Walter et al. 2007's BTDF (eq. 21, with eta_o on wo's side):

    f_t = |wi.h| |wo.h| / (|wi.n| |wo.n|) eta_o^2 (1 - F) G D / (eta_i wi.h + eta_o wo.h)^2

The Lambert base's share follows bsdf.cl's departure from fresnel_mix:
(1 - s E(wo)) (1 - s E(wi)) / (1 - s E_avg), E read from the tables of
clrt/kernels/bsdf_albedo.cl (which a test holds to metal_albedo's quadrature
below) and interpolated here on its own.  The conventions bsdf.cl documents
are followed: the side (inside or outside
for transmissive materials) from ng; an opaque material is two-sided; inside
a transmissive one Schlick takes the cosine on the side of lower index (F = 1
under total internal reflection); wi counts only where the geometric and the
shading normal agree on its side; the shading normal is replaced by the
geometric one when wo is not above it.

Material rows are the probe's 12 floats: base rgb, metallic, alpha, specular
colour rgb, specular weight, transmission, ior, 0.
"""

import re
from functools import lru_cache
from pathlib import Path

import numpy as np

ALBEDO_TABLES = Path(__file__).resolve().parents[1] / "clrt" / "kernels" / "bsdf_albedo.cl"


def ggx_d(n_dot_h, alpha):
    """glTF's D = alpha^2 chi+(N.H) / (pi ((N.H)^2 (alpha^2 - 1) + 1)^2)."""
    a2 = alpha * alpha
    d = a2 / (np.pi * (n_dot_h**2 * (a2 - 1.0) + 1.0) ** 2)
    return np.where(n_dot_h > 0, d, 0.0)


def smith_lambda(cos, alpha):
    """Lambda(w) = (-1 + sqrt(1 + alpha^2 tan^2 theta)) / 2 for GGX."""
    tan2 = (1.0 - cos**2) / cos**2
    return 0.5 * (np.sqrt(1.0 + alpha**2 * tan2) - 1.0)


def smith_g2(cos_o, cos_i, alpha):
    return 1.0 / (1.0 + smith_lambda(cos_o, alpha) + smith_lambda(cos_i, alpha))


def schlick(f0, cos):
    return f0 + (1.0 - f0) * (1.0 - cos)[..., None] ** 5


def albedo_tables():
    """The tables of clrt/kernels/bsdf_albedo.cl, read from its text: name -> float64 array."""
    text = ALBEDO_TABLES.read_text()
    out = {}
    for name, dims, body in re.findall(r"__constant float (\w+)((?:\[\d+\])+) = (\{.*?\});", text, re.S):
        shape = [int(d) for d in re.findall(r"\d+", dims)]
        out[name] = np.array([float(v) for v in re.findall(r"([-\d.e]+)f", body)]).reshape(shape)
    return out


def layer_albedo(cos, alpha, f0, tables):
    """The table's E(c, alpha, f0) = f0 A + (1 - f0) B, bilinear in (sqrt(c), alpha^(1/4))."""
    a_tab, b_tab = tables["LAYER_ALBEDO_A"], tables["LAYER_ALBEDO_B"]
    rows, cols = a_tab.shape
    x = np.sqrt(np.clip(cos, 0, 1)) * (cols - 1)
    y = alpha ** 0.25 * (rows - 1)
    i, j = np.minimum(x.astype(int), cols - 2), np.minimum(y.astype(int), rows - 2)
    fx, fy = x - i, y - j

    def lerp2(t):
        return ((1 - fy) * ((1 - fx) * t[j, i] + fx * t[j, i + 1])
                + fy * ((1 - fx) * t[j + 1, i] + fx * t[j + 1, i + 1]))

    return f0 * lerp2(a_tab) + (1 - f0) * lerp2(b_tab)


def layer_albedo_average(alpha, f0, tables):
    a_avg, b_avg = tables["LAYER_ALBEDO_A_AVERAGE"], tables["LAYER_ALBEDO_B_AVERAGE"]
    y = alpha ** 0.25 * (len(a_avg) - 1)
    j = np.minimum(y.astype(int), len(a_avg) - 2)
    fy = y - j
    return f0 * ((1 - fy) * a_avg[j] + fy * a_avg[j + 1]) + (1 - f0) * ((1 - fy) * b_avg[j] + fy * b_avg[j + 1])


def _rows(a):
    return np.asarray(a, np.float64).reshape(-1, 3)


def _dot(a, b):
    return np.sum(a * b, axis=-1)


def bsdf_times_cos(materials, n, ng, wo, wi, delta_alpha):
    """f(wo, wi) |n.wi| for rows of materials (N, 12) and unit vectors (N, 3),
    the delta lobes (alpha < delta_alpha) left out: (N, 3) float64."""
    m = np.asarray(materials, np.float64).reshape(-1, 12)
    n, ng, wo, wi = (_rows(v) for v in (n, ng, wo, wi))
    count = len(wo)
    m = np.broadcast_to(m, (count, 12))
    base, metallic, alpha = m[:, 0:3], m[:, 3], m[:, 4]
    spec_color, spec, trans, ior = m[:, 5:8], m[:, 8], m[:, 9], m[:, 10]
    dielectric = 1.0 - metallic
    smooth = alpha < delta_alpha
    f0 = np.minimum(((ior - 1.0) / (ior + 1.0))[:, None] ** 2 * spec_color, 1.0)
    opaque = trans <= 0

    outside = _dot(wo, ng) > 0
    ng_wo = np.where(outside[:, None], ng, -ng)
    ns = np.where((_dot(n, ng_wo) < 0)[:, None], -n, n)
    ns = np.where((_dot(wo, ns) > 0)[:, None], ns, ng_wo)
    eta_o = np.where(outside | opaque, 1.0, ior)          # index on wo's side
    eta_i_t = np.where(outside | opaque, ior, 1.0)         # index a refracted wi enters
    cos_o = _dot(ns, wo)
    cos_i = _dot(ns, wi)
    reflected = (_dot(wi, ng_wo) > 0) & (cos_i > 0)
    transmitted = (_dot(wi, ng_wo) < 0) & (cos_i < 0) & ~opaque

    def fresnel_dielectric(c_wo_side):
        """Schlick on the lower-index side's cosine; F = 1 under total internal reflection."""
        eta_other = eta_i_t
        sin2_other = (eta_o / eta_other) ** 2 * (1.0 - c_wo_side**2)
        tir = sin2_other >= 1.0
        c_other = np.sqrt(np.clip(1.0 - sin2_other, 0.0, None))
        c = np.where(opaque | (eta_o <= eta_other), c_wo_side, c_other)
        f = schlick(f0, c)
        return np.where((tir & ~opaque)[:, None], 1.0, f)

    out = np.zeros((count, 3))

    # reflection: Lambert + the two GGX layers, h the half vector
    h = wo + wi
    h /= np.linalg.norm(h, axis=1)[:, None]
    c = np.abs(_dot(wo, h))
    fd = fresnel_dielectric(c)
    fm = schlick(base, c)
    # the Lambert base's share: what the layer (albedo E from the tables) leaves at both ends, normalised
    # (a smooth layer, a mirror without masking, is the tables' alpha = 0 row)
    tables = albedo_tables()
    layer_f0 = np.where(outside | opaque, f0.max(axis=1), 1.0)
    layer_alpha = np.where(smooth, 0.0, alpha)
    left_o = 1.0 - spec * layer_albedo(cos_o, layer_alpha, layer_f0, tables)
    left_i = 1.0 - spec * layer_albedo(cos_i, layer_alpha, layer_f0, tables)
    left_avg = 1.0 - spec * layer_albedo_average(layer_alpha, layer_f0, tables)
    share = np.where(left_avg > 1e-6, left_o * left_i / np.where(left_avg > 1e-6, left_avg, 1.0), 0.0)
    diffuse = (dielectric * (1.0 - trans) * share)[:, None] * base / np.pi
    with np.errstate(divide="ignore", invalid="ignore"):
        micro = ggx_d(_dot(ns, h), alpha) * smith_g2(cos_o, cos_i, alpha) / (4.0 * cos_o * cos_i)
    micro = np.where(smooth, 0.0, micro)
    layers = (dielectric * spec)[:, None] * fd + metallic[:, None] * fm
    f_r = diffuse + layers * micro[:, None]
    out = np.where(reflected[:, None], f_r * np.abs(cos_i)[:, None], out)

    # transmission: Walter's BTDF with the generalised half vector
    eta_i = eta_i_t
    ht = -(eta_i[:, None] * wi + eta_o[:, None] * wo)
    ht /= np.linalg.norm(ht, axis=1)[:, None]
    ht = np.where((_dot(ht, ns) < 0)[:, None], -ht, ht)
    oh, ih = _dot(wo, ht), _dot(wi, ht)
    valid = transmitted & (oh > 0) & (ih < 0) & ~smooth
    fd_t = fresnel_dielectric(np.abs(oh))
    with np.errstate(divide="ignore", invalid="ignore"):
        btdf = (np.abs(ih) * np.abs(oh) / (np.abs(cos_i) * np.abs(cos_o)) * eta_o**2
                * ggx_d(_dot(ns, ht), alpha) * smith_g2(np.abs(cos_o), np.abs(cos_i), alpha)
                / (eta_i * ih + eta_o * oh) ** 2)
    f_t = ((dielectric * trans)[:, None] * (1.0 - spec[:, None] * fd_t.max(axis=1)[:, None]) * base
           * btdf[:, None])
    out = np.where(valid[:, None], f_t * np.abs(cos_i)[:, None], out)
    return out


@lru_cache(maxsize=None)
def _gauss_legendre(nodes):
    """Nodes and weights on 0..1 (numpy's leggauss costs O(nodes^3): computed once)."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    return 0.5 * (x + 1.0), 0.5 * w


def metal_albedo(alpha, cos_o, f0=1.0, nodes=160):
    """Directional albedo of the GGX metal lobe (single scattering) for wo at
    cos_o, by Gauss-Legendre quadrature over microfacet normals drawn from
    D(h) cos(theta_h) (theta_h = atan(alpha sqrt(u / (1 - u)))): the
    integrand F G2 (wo.h) / (wo.n h.n) is then smooth.  Float64."""
    u1, w1 = _gauss_legendre(nodes)
    u2, w2 = u1, w1
    uu1, uu2 = np.meshgrid(u1, u2, indexing="ij")
    weights = np.outer(w1, w2)
    theta = np.arctan(alpha * np.sqrt(uu1 / (1.0 - uu1)))
    phi = 2.0 * np.pi * uu2
    h = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=-1)
    wo = np.array([np.sqrt(1.0 - cos_o**2), 0.0, cos_o])
    oh = h @ wo
    wi = 2.0 * oh[..., None] * h - wo
    cos_i = wi[..., 2]
    ok = (oh > 0) & (cos_i > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        g2 = smith_g2(cos_o, np.where(ok, cos_i, 0.5), alpha)
        f = f0 + (1.0 - f0) * (1.0 - oh) ** 5
        integrand = np.where(ok, f * g2 * oh / (cos_o * h[..., 2]), 0.0)
    return float(np.sum(weights * integrand))
