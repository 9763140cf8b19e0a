"""The path tracer's BSDF (clrt/kernels/bsdf.cl) and its warps (sampling.cl),
run on the device through the test-only kernels of tests/kernels/bsdf_probe.cl.

- Sampling matches the density it reports: a chi-square goodness-of-fit test
  of sampled directions against bsdf_pdf integrated over each histogram cell,
  as Mitsuba 3's test suite does (low-expected cells pooled, the significance
  level corrected for the number of tests), for every warp and for diffuse,
  metal, dielectric + diffuse, specular-tinted and transmissive materials at
  several incident angles, inside and outside, with a tilted shading normal.
- A sample's weight is bsdf_eval / bsdf_pdf and its pdf is bsdf_pdf.
- Reflection is reciprocal, refraction reciprocal up to Walter's eta^2; values
  are finite and non-negative at grazing angles and at roughness 0 and 1.
- Albedo <= 1; the rough metal's (single-scattering) loss matches a float64
  quadrature; smooth glass keeps all energy; the path tracer's white furnace
  with these materials; the specular layer's albedo table (bsdf_albedo.cl)
  against an independent quadrature.
- bsdf_eval matches tests/bsdf_reference.py, float64 numpy written from the
  glTF equations, within float32 tolerance.
- Delta lobes exactly below BSDF_DELTA_ALPHA; frames orthonormal at the poles;
  no double in the kernels.
Fixed seeds throughout.
"""

import math
import re
from pathlib import Path

import numpy as np
import pyopencl as cl
import pytest

from bsdf_reference import albedo_tables, bsdf_times_cos, layer_albedo, layer_albedo_average, metal_albedo
from clrt.device.context import create_context
from clrt.device.program import build_options, expand_source

PROBE = Path(__file__).resolve().parent / "kernels" / "bsdf_probe.cl"
KERNELS = Path(__file__).resolve().parents[1] / "clrt" / "kernels"


class Probe:
    """The probe program on one device, with numpy in and out."""

    def __init__(self, device):
        self.context, self.queue = create_context(device)
        text = PROBE.read_text()
        source = re.sub(r'^#include "bsdf.cl"$', lambda _: expand_source("bsdf.cl"), text, flags=re.M)
        program = cl.Program(self.context, source).build(options=build_options(self.context))
        self.kernels = {k.function_name: k for k in program.all_kernels()}
        (constants,) = self._launch("probe_constants", 1, [], [], [np.zeros(1, np.float32)])
        self.delta_alpha = float(constants[0])

    def _launch(self, name, count, scalars_before, inputs, outputs, scalars_after=()):
        """Run kernel `name` on `count` items: scalars, input arrays (copied in),
        scalars, output arrays (filled and returned)."""
        mf = cl.mem_flags
        ins = [cl.Buffer(self.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=a) for a in inputs]
        outs = [cl.Buffer(self.context, mf.WRITE_ONLY, o.nbytes) for o in outputs]
        self.kernels[name](self.queue, (count,), None, *scalars_before, *ins, *scalars_after, *outs)
        for o, buf in zip(outputs, outs):
            cl.enqueue_copy(self.queue, o, buf)
        return outputs

    def eval(self, materials, n, ng, wo, wi):
        """(f cos (N, 3), pdf (N,)); materials, n, ng, wo: one row for all, or N rows."""
        shared = np.int32(len(np.atleast_2d(wo)) == 1 and len(wi) > 1)
        (out,) = self._launch("probe_eval", len(wi), [], [_mat(materials), *map(_f4, (n, ng, wo, wi))],
                              [np.empty((len(wi), 4), np.float32)], [shared])
        return out[:, :3], out[:, 3]

    def sample(self, materials, n, ng, wo, u):
        """(wi (N, 3), pdf (N,), weight (N, 3), flag (N,): 0 none, 1 sampled, 2 delta)."""
        shared = np.int32(len(np.atleast_2d(wo)) == 1 and len(u) > 1)
        wi_pdf, weight = self._launch("probe_sample", len(u), [], [_mat(materials), *map(_f4, (n, ng, wo, u))],
                                      [np.empty((len(u), 4), np.float32) for _ in range(2)], [shared])
        return wi_pdf[:, :3], wi_pdf[:, 3], weight[:, :3], weight[:, 3].astype(int)

    def warp(self, which, param, u):
        (out,) = self._launch("probe_warp", len(u), [np.int32(which), _param(param)], [_f4(u)],
                              [np.empty((len(u), 4), np.float32)])
        return out[:, :3], out[:, 3]

    def warp_pdf(self, which, param, d):
        (out,) = self._launch("probe_warp_pdf", len(d), [np.int32(which), _param(param)], [_f4(d)],
                              [np.empty(len(d), np.float32)])
        return out

    def frames(self, normals):
        (out,) = self._launch("probe_frame", len(normals), [], [_f4(normals)],
                              [np.empty((len(normals) * 3, 4), np.float32)])
        return out[:, :3].reshape(-1, 3, 3)


def _f4(a):
    a = np.atleast_2d(np.asarray(a, np.float32))
    out = np.zeros((len(a), 4), np.float32)
    out[:, :a.shape[1]] = a
    return out


def _param(p):
    v = np.zeros(4, np.float32)
    v[:len(p)] = p
    return cl.cltypes.make_float4(*v.tolist())


def _mat(rows):
    return np.ascontiguousarray(np.atleast_2d(np.asarray(rows, np.float32)))


def material(base=(0.8, 0.8, 0.8), metallic=0.0, roughness=0.5, specular_color=(1, 1, 1), specular=1.0,
             transmission=0.0, ior=1.5):
    """A probe material row (12 float32); alpha = roughness^2 as glTF's."""
    return np.array([*base, metallic, roughness**2, *specular_color, specular, transmission, ior, 0], np.float32)


def unit(v):
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def direction(theta_deg, phi_deg=0.0, below=False):
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p),
                     -math.cos(t) if below else math.cos(t)])


def random_directions(rng, count):
    return unit(rng.normal(size=(count, 3)))


@pytest.fixture(scope="module")
def probe(device):
    return Probe(device)


# ---------------------------------------------------------------------------- chi-square machinery


def chi2_sf(x, dof):
    """P(X >= x) for X chi-square with dof degrees of freedom: the regularised
    upper incomplete gamma function Q(dof / 2, x / 2), by its power series
    below a + 1 and by Legendre's continued fraction (modified Lentz) above."""
    a, x = 0.5 * dof, 0.5 * x
    if x <= 0:
        return 1.0
    log_prefactor = -x + a * math.log(x) - math.lgamma(a)
    if x < a + 1:
        term = total = 1.0 / a
        k = a
        while abs(term) > abs(total) * 1e-16:
            k += 1
            term *= x / k
            total += term
        return max(0.0, 1.0 - total * math.exp(log_prefactor))
    tiny = 1e-300
    b = x + 1 - a
    c, d = 1 / tiny, 1 / b
    h = d
    for i in range(1, 100000):
        an = -i * (i - a)
        b += 2
        d = an * d + b
        d = tiny if abs(d) < tiny else d
        c = b + an / c
        c = tiny if abs(c) < tiny else c
        d = 1 / d
        h *= d * c
        if abs(d * c - 1) < 1e-16:
            break
    return math.exp(log_prefactor) * h


def chi2_pvalue(observed, expected, min_expected=5.0):
    """Pearson's chi-square of histogram counts against expected counts; cells
    expecting fewer than min_expected are pooled into one (into the smallest
    other cell if the pool stays below it).  Returns (p-value, statistic, cells)."""
    obs, exp = np.asarray(observed, float).ravel(), np.asarray(expected, float).ravel()
    low = exp < min_expected
    cells_o, cells_e = list(obs[~low]), list(exp[~low])
    pool_o, pool_e = obs[low].sum(), exp[low].sum()
    if pool_e >= min_expected or not cells_e:
        cells_o.append(pool_o)
        cells_e.append(pool_e)
    else:
        i = int(np.argmin(cells_e))
        cells_o[i] += pool_o
        cells_e[i] += pool_e
    cells_o, cells_e = np.array(cells_o), np.array(cells_e)
    stat = float(np.sum((cells_o - cells_e) ** 2 / cells_e))
    return chi2_sf(stat, len(cells_e) - 1), stat, len(cells_e)


def test_chi2_sf_matches_closed_forms():
    for x in (0.01, 0.5, 1.0, 3.0, 10.0, 40.0):
        assert chi2_sf(x, 2) == pytest.approx(math.exp(-x / 2), rel=1e-12)
        assert chi2_sf(x, 4) == pytest.approx(math.exp(-x / 2) * (1 + x / 2), rel=1e-12)
        assert chi2_sf(x, 1) == pytest.approx(math.erfc(math.sqrt(x / 2)), rel=1e-10)
    # large dof: the mean sits near p = 0.5 (the median of chi2_k is about k (1 - 2/(9k))^3)
    k = 1000
    assert chi2_sf(k * (1 - 2 / (9 * k)) ** 3, k) == pytest.approx(0.5, abs=2e-3)


# Directions are binned in (theta, phi) about a pole, theta in equal steps (so
# that cells stay small at both ends, unlike equal steps of cos theta), the
# pole on the lobe under test; a cell's solid angle is sin theta dtheta dphi.
THETA_BINS, PHI_BINS = 36, 48
# Gauss-Legendre points a cell and axis for the expected counts.  The rows at
# either end, where a lobe on the pole peaks, are split into END_SPLIT
# intervals along theta; cells that a plane where the density jumps crosses
# (the surface's horizon: samples below it are dropped) into EDGE_SPLIT^2 parts.
NODES, END_ROWS, END_SPLIT, EDGE_SPLIT = 6, 3, 8, 8


def _pole_frame(pole):
    z = unit(pole)
    helper = np.array([1.0, 0, 0]) if abs(z[0]) < 0.9 else np.array([0, 1.0, 0])
    x = unit(np.cross(helper, z))
    return np.stack([x, np.cross(z, x), z])


def histogram(directions, pole):
    local = unit(np.asarray(directions, np.float64) @ _pole_frame(pole).T)
    theta = np.arccos(np.clip(local[:, 2], -1.0, 1.0))
    phi = np.arctan2(local[:, 1], local[:, 0])
    counts, _, _ = np.histogram2d(theta, phi, bins=[THETA_BINS, PHI_BINS], range=[[0, np.pi], [-np.pi, np.pi]])
    return counts


def _local_directions(theta, phi, pole):
    local = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=-1)
    return local @ _pole_frame(pole)


def _cell_points(cells, theta_split, phi_split, pole):
    """World directions (K, M, 3) and quadrature weights (K, M) (solid angle
    sin theta dtheta dphi included) of Gauss-Legendre points over the cells
    (K, 2) of (row, column), each cut into theta_split x phi_split parts."""
    x, w = np.polynomial.legendre.leggauss(NODES)

    def axis(split):
        nodes = ((np.arange(split)[:, None] + (x[None, :] + 1) / 2) / split).ravel()   # in 0..1 of a cell
        return nodes, np.tile(w / (2 * split), split)

    tn, tw = axis(theta_split)
    pn, pw = axis(phi_split)
    dtheta, dphi = np.pi / THETA_BINS, 2 * np.pi / PHI_BINS
    theta = (cells[:, 0, None] + tn[None, :]) * dtheta                 # (K, A)
    phi = -np.pi + (cells[:, 1, None] + pn[None, :]) * dphi            # (K, B)
    tt, pp = np.broadcast_arrays(theta[:, :, None], phi[:, None, :])
    weights = np.sin(tt) * (tw[None, :, None] * dtheta) * (pw[None, None, :] * dphi)
    return _local_directions(tt, pp, pole).reshape(len(cells), -1, 3), weights.reshape(len(cells), -1)


def _cell_corners(cells, pole):
    theta = np.stack([cells[:, 0], cells[:, 0] + 1] * 2, axis=1) * (np.pi / THETA_BINS)
    phi = -np.pi + np.stack([cells[:, 1]] * 2 + [cells[:, 1] + 1] * 2, axis=1) * (2 * np.pi / PHI_BINS)
    return _local_directions(theta, phi, pole)


def cell_integrals(pdf_at, pole, planes=()):
    """The integral of a density over each (theta, phi) cell.  pdf_at maps
    (M, 3) world directions to (M,) densities; planes: normals of the planes
    across which it may jump."""
    rows, cols = np.meshgrid(np.arange(THETA_BINS), np.arange(PHI_BINS), indexing="ij")
    cells = np.stack([rows.ravel(), cols.ravel()], axis=1)

    def integrate(chosen, theta_split, phi_split):
        dirs, weights = _cell_points(chosen, theta_split, phi_split, pole)
        density = pdf_at(dirs.reshape(-1, 3)).astype(np.float64).reshape(weights.shape)
        return np.sum(density * weights, axis=1), dirs

    total, dirs = integrate(cells, 1, 1)
    ends = (cells[:, 0] < END_ROWS) | (cells[:, 0] >= THETA_BINS - END_ROWS)
    total[ends] = integrate(cells[ends], END_SPLIT, 1)[0]
    edge_dirs = np.concatenate([dirs, _cell_corners(cells, pole)], axis=1)
    crossed = np.zeros(len(cells), bool)
    for normal in planes:
        side = edge_dirs @ np.asarray(normal, np.float64)
        crossed |= (side.min(axis=1) < 0) & (side.max(axis=1) > 0)
    if crossed.any():
        total[crossed] = integrate(cells[crossed], EDGE_SPLIT, EDGE_SPLIT)[0]
    return total.reshape(THETA_BINS, PHI_BINS)


# ---------------------------------------------------------------------------- cases

WARPS = {  # name: (probe index, param (wo, alpha) for the visible normals, pole)
    "cosine_hemisphere": (0, (), (0, 0, 1)),
    "uniform_hemisphere": (1, (), (0, 0, 1)),
    "uniform_sphere": (2, (), (0, 0, 1)),
    "ggx_visible_normals_a0.3_60deg": (3, (*direction(60), 0.3), (0, 0, 1)),
    "ggx_visible_normals_a0.05_85deg": (3, (*direction(85), 0.05), (0, 0, 1)),
    "ggx_visible_normals_a1_0deg": (3, (*direction(0), 1.0), (0, 0, 1)),
}

WHITE_GLASS = dict(base=(1, 1, 1), specular=1.0, transmission=1.0, ior=1.5)
PLASTIC = dict(base=(0.5, 0.3, 0.2), specular=1.0)
BSDF_CASES = {  # name: (material, theta_o, wo inside the surface, pole, shading normal tilt in degrees)
    "diffuse_0deg": (material(specular=0.0), 0, False, "normal", 0),
    "diffuse_tilted_normal_70deg": (material(specular=0.0), 70, False, "normal", 30),
    "plastic_r0.3_30deg": (material(roughness=0.3, **PLASTIC), 30, False, "mirror", 0),
    "plastic_r0.7_70deg": (material(roughness=0.7, **PLASTIC), 70, False, "normal", 0),
    "metal_r0.2_0deg": (material(base=(0.9, 0.6, 0.3), metallic=1, roughness=0.2), 0, False, "mirror", 0),
    "metal_r0.5_45deg": (material(base=(0.9, 0.6, 0.3), metallic=1, roughness=0.5), 45, False, "mirror", 0),
    "metal_r1_80deg": (material(base=(0.9, 0.6, 0.3), metallic=1, roughness=1.0), 80, False, "normal", 0),
    "mix_specular_color_r0.4_50deg": (material(base=(0.2, 0.6, 0.4), metallic=0.3, roughness=0.4,
                                               specular_color=(1, 0.5, 0.2), specular=0.6), 50, False, "mirror", 0),
    "smooth_plastic_diffuse_part_40deg": (material(roughness=0.0, **PLASTIC), 40, False, "normal", 0),
    "glass_r0.3_enter_20deg": (material(roughness=0.3, **WHITE_GLASS), 20, False, "refract", 0),
    "glass_r0.6_enter_70deg": (material(roughness=0.6, **WHITE_GLASS), 70, False, "refract", 0),
    "glass_r0.3_leave_25deg": (material(roughness=0.3, **WHITE_GLASS), 25, True, "refract", 0),
    "glass_r0.5_leave_50deg_tir": (material(roughness=0.5, **WHITE_GLASS), 50, True, "mirror", 0),
    "half_transmissive_r0.5_35deg": (material(base=(0.7, 0.8, 0.9), metallic=0.2, roughness=0.5,
                                              transmission=0.5, ior=1.33), 35, False, "normal", 0),
    "metal_r0.5_tilted_normal_60deg": (material(base=(0.9, 0.9, 0.9), metallic=1, roughness=0.5), 60, False,
                                       "mirror", 25),
    "plastic_r0.4_tilted_normal_75deg": (material(roughness=0.4, **PLASTIC), 75, False, "normal", -20),
}
CHI2_TESTS = len(WARPS) + len(BSDF_CASES)
# Mitsuba's level, 1%, Sidak-corrected so that the whole family of tests fails
# by chance at most 1% of the time.
SIGNIFICANCE = 1.0 - (1.0 - 0.01) ** (1.0 / CHI2_TESTS)
SAMPLES = 250_000


def _shading_point(theta_o, inside, tilt):
    ng = np.array([0.0, 0.0, 1.0])
    n = direction(tilt, 90.0) if tilt >= 0 else direction(-tilt, -90.0)
    wo = direction(theta_o, 0.0, below=inside)
    return n, ng, wo


def _pole(kind, mat, n, ng, wo):
    side = 1.0 if wo @ ng > 0 else -1.0
    ns = n * side
    if kind == "normal":
        return ns
    if kind == "mirror":
        return 2 * (ns @ wo) * ns - wo
    eta = mat[10] if side > 0 else 1 / mat[10]          # refraction about the normal
    c = ns @ wo
    ct = math.sqrt(1 - (1 - c * c) / eta**2)
    return -wo / eta + (c / eta - ct) * ns


@pytest.mark.parametrize("name", sorted(WARPS))
def test_warps_sample_their_pdf(probe, name):
    which, param, pole = WARPS[name]
    u = np.random.default_rng(7).random((SAMPLES, 2), dtype=np.float32)
    d, pdf = probe.warp(which, param, u)
    assert np.all(np.isfinite(d)) and np.allclose(np.linalg.norm(d, axis=1), 1, atol=1e-5)
    # the pdf returned with each sample is the pdf function's at that direction
    np.testing.assert_allclose(pdf, probe.warp_pdf(which, param, d), rtol=1e-5)
    expected = SAMPLES * cell_integrals(lambda w: probe.warp_pdf(which, param, w), pole, planes=[(0, 0, 1)])
    p, stat, cells = chi2_pvalue(histogram(d, pole), expected)
    assert expected.sum() == pytest.approx(SAMPLES, rel=2e-3)     # each warp's density integrates to 1
    assert p > SIGNIFICANCE, f"{name}: chi2 {stat:.1f} over {cells} cells, p = {p:.2e}"


@pytest.mark.parametrize("name", sorted(BSDF_CASES))
def test_bsdf_samples_follow_bsdf_pdf(probe, name):
    mat, theta_o, inside, pole_kind, tilt = BSDF_CASES[name]
    n, ng, wo = _shading_point(theta_o, inside, tilt)
    u = np.random.default_rng(11).random((SAMPLES, 3), dtype=np.float32)
    wi, pdf, weight, flag = probe.sample(mat, n, ng, wo, u)
    pole = _pole(pole_kind, mat, n, ng, wo)
    drawn = flag == 1
    expected = SAMPLES * cell_integrals(lambda w: probe.eval(mat, n, ng, wo, w)[1], pole, planes=[n, ng])
    p, stat, cells = chi2_pvalue(histogram(wi[drawn], pole), expected)
    assert p > SIGNIFICANCE, f"{name}: chi2 {stat:.1f} over {cells} cells, p = {p:.2e}"
    assert drawn.sum() > 0.3 * SAMPLES
    if "smooth" in name:
        # the delta lobe took the rest: its share is its discrete probability
        delta = flag == 2
        assert delta.sum() / SAMPLES == pytest.approx(pdf[delta][0], abs=4 * math.sqrt(0.25 / SAMPLES))
    # the density integrates to the share of samples it describes (binomial noise)
    share = drawn.mean()
    assert expected.sum() / SAMPLES == pytest.approx(share, abs=4 * math.sqrt(share * (1 - share) / SAMPLES) + 1e-4)


# ---------------------------------------------------------------------------- random shading points


def random_materials(rng, count, transmissive=None):
    """Rows of materials spanning the model: metallic 0, 1 or between; roughness
    0 (delta), 1 or between; specular weight and colour; transmission 0, 1 or
    between (or as `transmissive` says); ior away from 1."""
    pick = rng.integers(0, 3, (count, 3))
    metallic = np.choose(pick[:, 0], [np.zeros(count), np.ones(count), rng.random(count)])
    roughness = np.choose(pick[:, 1], [np.zeros(count), np.ones(count), rng.uniform(0.05, 1, count)])
    transmission = np.choose(pick[:, 2], [np.zeros(count), np.ones(count), rng.random(count)])
    if transmissive is not None:
        transmission = rng.uniform(0.2, 1, count) if transmissive else np.zeros(count)
    m = np.zeros((count, 12), np.float32)
    m[:, 0:3] = rng.random((count, 3))
    m[:, 3] = metallic
    m[:, 4] = roughness**2
    m[:, 5:8] = rng.uniform(0, 1.5, (count, 3))
    m[:, 8] = rng.random(count)
    m[:, 9] = transmission
    m[:, 10] = rng.uniform(1.2, 2.4, count)
    return m


def tilted(rng, normals, max_deg):
    """Normals tilted by up to max_deg degrees in random directions."""
    axis = unit(np.cross(normals, random_directions(rng, len(normals))))
    angle = np.radians(rng.uniform(0, max_deg, len(normals)))[:, None]
    return unit(normals * np.cos(angle) + np.cross(axis, normals) * np.sin(angle))


def random_points(rng, count, tilt_deg=30.0):
    """(n, ng, wo) rows: random geometric normals, half of the shading normals
    tilted from them, wo on either side."""
    ng = random_directions(rng, count)
    n = np.where(rng.random(count)[:, None] < 0.5, ng, tilted(rng, ng, tilt_deg))
    return n, ng, random_directions(rng, count)


def test_sample_weight_is_eval_over_pdf_and_its_pdf_is_bsdf_pdf(probe):
    rng = np.random.default_rng(3)
    count = 40_000
    mats = random_materials(rng, count)
    n, ng, wo = random_points(rng, count)
    wi, pdf, weight, flag = probe.sample(mats, n, ng, wo, rng.random((count, 3), dtype=np.float32))
    assert np.isin(flag, [0, 1, 2]).all() and (flag == 1).sum() > count // 2 and (flag == 2).sum() > count // 10
    drawn = flag == 1
    f, pdf_again = probe.eval(mats[drawn], n[drawn], ng[drawn], wo[drawn], wi[drawn])
    # the same float32 function of (wo, wi), once from the sampler's local wi and
    # once from the world wi: only the frame's rounding differs, which the
    # narrowest lobes (pdf up to 1e6) magnify to a few 1e-3
    rel = np.abs(pdf_again / pdf[drawn] - 1)
    assert np.median(rel) < 1e-6 and np.quantile(rel, 0.999) < 1e-3 and rel.max() < 1e-2
    assert pdf[drawn].max() > 1e4
    np.testing.assert_allclose(weight[drawn], f / pdf_again[:, None], rtol=1e-2, atol=1e-6)
    wrel = np.abs(weight[drawn] - f / pdf_again[:, None]) / np.maximum(weight[drawn], 1e-6)
    assert np.quantile(wrel, 0.999) < 1e-3
    # delta samples: bsdf_eval and bsdf_pdf know nothing of a smooth metal's mirror
    metal = (flag == 2) & (mats[:, 3] == 1)
    assert metal.sum() > 100
    f, p = probe.eval(mats[metal], n[metal], ng[metal], wo[metal], wi[metal])
    assert (f == 0).all() and (p == 0).all()
    assert np.all(pdf[flag == 2] > 0) and np.all(pdf[flag == 2] <= 1)


def test_reflection_is_reciprocal(probe):
    rng = np.random.default_rng(4)
    count = 20_000
    mats = random_materials(rng, count)
    ng = random_directions(rng, count)
    wo, wi = random_directions(rng, count), random_directions(rng, count)
    wo *= np.sign(np.sum(wo * ng, axis=1))[:, None]
    wi *= np.sign(np.sum(wi * ng, axis=1))[:, None]
    f_oi, _ = probe.eval(mats, ng, ng, wo, wi)
    f_io, _ = probe.eval(mats, ng, ng, wi, wo)
    cos_o, cos_i = np.sum(wo * ng, axis=1), np.sum(wi * ng, axis=1)
    keep = (cos_o > 1e-3) & (cos_i > 1e-3)
    forward = f_oi[keep] / cos_i[keep, None]
    backward = f_io[keep] / cos_o[keep, None]
    assert (forward > 0).any(axis=1).mean() > 0.7      # all but the smooth metals and glasses
    np.testing.assert_allclose(forward, backward, rtol=2e-4, atol=1e-7)


def test_refraction_is_reciprocal_up_to_eta_squared(probe):
    """Walter et al. 2007: f_t(wo, wi) / eta_o^2 = f_t(wi, wo) / eta_i^2 for
    radiance (wo outside, index 1; wi inside, index ior)."""
    rng = np.random.default_rng(5)
    count = 20_000
    mats = random_materials(rng, count, transmissive=True)
    mats[:, 4] = rng.uniform(0.1, 1, count) ** 2
    ng = random_directions(rng, count)
    wo, wi = random_directions(rng, count), random_directions(rng, count)
    wo *= np.sign(np.sum(wo * ng, axis=1))[:, None]
    wi *= -np.sign(np.sum(wi * ng, axis=1))[:, None]
    f_oi, _ = probe.eval(mats, ng, ng, wo, wi)
    f_io, _ = probe.eval(mats, ng, ng, wi, wo)
    cos_o, cos_i = np.abs(np.sum(wo * ng, axis=1)), np.abs(np.sum(wi * ng, axis=1))
    keep = (cos_o > 1e-3) & (cos_i > 1e-3)
    ior = mats[keep, 10].astype(np.float64)[:, None]
    forward = f_oi[keep] / cos_i[keep, None]
    backward = f_io[keep] / cos_o[keep, None] / ior**2
    assert (forward > 0).any(axis=1).sum() > 2000      # random pairs often lie outside the refraction cone
    np.testing.assert_allclose(forward, backward, rtol=2e-3, atol=1e-7 * forward.max())


def test_values_are_finite_and_non_negative_at_the_extremes(probe):
    """Grazing and exactly tangent directions, normal incidence, wo = +-wi,
    roughness 0, 1 and around the delta threshold, tilted shading normals."""
    rng = np.random.default_rng(6)
    d = probe.delta_alpha
    alphas = [0.0, 1e-7, 0.5 * d, d, 1.01 * d, 2 * d, 1e-2, 0.3, 1.0]
    cosines = [1.0, 0.7, 1e-2, 1e-4, 1e-7, 0.0, -1e-7, -1e-3, -0.5, -1.0]
    rows = []
    for alpha in alphas:
        for c in cosines:
            for base in (material(base=(1, 1, 1), metallic=1), material(transmission=1, ior=1.5),
                         material(base=(0.5, 0.5, 0.5), metallic=0.5, transmission=0.5, ior=1.33),
                         material(specular=0.0), material(ior=1.0, transmission=1.0), material(ior=0.0)):
                m = base.copy()
                m[4] = alpha
                rows.append((m, c))
    count = len(rows)
    mats = np.array([r[0] for r in rows])
    c = np.array([r[1] for r in rows])
    wo = np.stack([np.sqrt(1 - c**2), np.zeros(count), c], axis=1)
    ng = np.tile([0.0, 0.0, 1.0], (count, 1))
    n = np.where((np.arange(count) % 2 == 0)[:, None], ng, tilted(rng, ng, 40))
    special = [ng[0], -ng[0], [1.0, 0, 0], [0, 1.0, 0]]
    wis = [random_directions(rng, count), wo, -wo, *[np.tile(s, (count, 1)) for s in special],
           np.stack([-wo[:, 0], wo[:, 1], wo[:, 2]], axis=1),            # the mirror direction
           unit(np.stack([-wo[:, 0], wo[:, 1], -wo[:, 2] + 1e-6], axis=1))]
    for wi in wis:
        f, pdf = probe.eval(mats, n, ng, wo, wi)
        assert np.isfinite(f).all() and np.isfinite(pdf).all()
        assert (f >= 0).all() and (pdf >= 0).all()
    for seed in range(4):
        u = np.random.default_rng(seed).random((count, 3), dtype=np.float32)
        if seed == 3:
            u[:] = np.float32(1) - np.float32(2**-24)       # the largest float below 1, everywhere
        wi, pdf, weight, flag = probe.sample(mats, n, ng, wo, u)
        assert np.isfinite(wi).all() and np.isfinite(pdf).all() and np.isfinite(weight).all()
        assert (weight >= 0).all() and (pdf[flag > 0] > 0).all()
        assert np.allclose(np.linalg.norm(wi[flag > 0], axis=1), 1, atol=1e-5)
    # an exactly tangent wo has no side: nothing is scattered, nothing sampled
    tangent = c == 0
    f, pdf = probe.eval(mats[tangent], n[tangent], ng[tangent], wo[tangent], wis[0][tangent])
    assert (f == 0).all() and (pdf == 0).all()


def _energy_albedo(probe, mat, n, ng, wo, samples, seed):
    """Mean and standard error of the sampling weights, with refraction's
    radiance scaling 1 / eta^2 taken out (energy, not radiance)."""
    u = np.random.default_rng(seed).random((samples, 3), dtype=np.float32)
    wi, pdf, weight, flag = probe.sample(mat, n, ng, wo, u)
    crossed = (wi @ ng) * (wo @ ng) < 0
    eta = mat[10] if wo @ ng > 0 else 1 / mat[10]
    energy = np.where(crossed[:, None], weight.astype(np.float64) * eta**2, weight)
    return energy.mean(axis=0), energy.std(axis=0) / math.sqrt(samples), energy


ALBEDO_MATERIALS = {
    "white_diffuse": material(base=(1, 1, 1), specular=0.0),
    "white_plastic_r0.5": material(base=(1, 1, 1), roughness=0.5),
    "white_plastic_smooth": material(base=(1, 1, 1), roughness=0.0),
    "tinted_specular_r0.3": material(base=(0.9, 1, 0.8), roughness=0.3, specular_color=(1, 0.3, 1), ior=1.8),
    "white_metal_r0.4": material(base=(1, 1, 1), metallic=1, roughness=0.4),
    "white_glass_r0.4": material(base=(1, 1, 1), roughness=0.4, transmission=1),
    "white_half_glass_r0.7": material(base=(1, 1, 1), roughness=0.7, transmission=0.5, metallic=0.3),
}


@pytest.mark.parametrize("name", sorted(ALBEDO_MATERIALS))
def test_albedo_is_at_most_one(probe, name):
    mat = ALBEDO_MATERIALS[name]
    for theta in (0, 45, 75, 89):
        for inside in ((False, True) if mat[9] > 0 else (False,)):
            n, ng, wo = _shading_point(theta, inside, 0)
            mean, err, energy = _energy_albedo(probe, mat, n, ng, wo, 50_000, 21)
            assert np.all(mean <= 1 + 4 * err + 1e-6), (name, theta, inside, mean, err)
    if name == "white_diffuse":
        assert np.all(energy == 1)       # f cos / pdf is the base colour, sample by sample


def test_smooth_glass_keeps_all_energy_sample_by_sample(probe):
    """Reflection chosen with probability F: every sample of white smooth glass
    carries energy 1, radiance 1 / eta^2 where it crosses."""
    mat = material(base=(1, 1, 1), roughness=0.0, transmission=1.0, ior=1.5)
    for theta in (0, 30, 41, 43, 60, 89):             # inside, 41.8 degrees is the critical angle
        for inside in (False, True):
            n, ng, wo = _shading_point(theta, inside, 0)
            mean, err, energy = _energy_albedo(probe, mat, n, ng, wo, 4000, 5)
            np.testing.assert_allclose(energy, 1, rtol=1e-5)


def test_white_metal_albedo_matches_the_float64_quadrature(probe):
    """Single-scattering GGX loses the light that bounces between facets: the
    sampled albedo of a white metal matches bsdf_reference.metal_albedo, and
    the loss grows with roughness (docs/path-tracing.md gives the table)."""
    previous = 1.0
    for roughness in (0.25, 0.5, 0.75, 1.0):
        for cos_o in (1.0, 0.5, 0.2):
            mat = material(base=(1, 1, 1), metallic=1, roughness=roughness)
            wo = np.array([math.sqrt(1 - cos_o**2), 0, cos_o])
            ng = np.array([0.0, 0, 1])
            mean, err, _ = _energy_albedo(probe, mat, ng, ng, wo, 100_000, 8)
            expected = metal_albedo(roughness**2, cos_o)
            assert mean[0] == pytest.approx(expected, abs=4 * err[0] + 1e-4), (roughness, cos_o)
        assert metal_albedo(roughness**2, 1.0) < previous
        previous = metal_albedo(roughness**2, 1.0)
    assert metal_albedo(1e-4, 1.0) == pytest.approx(1.0, abs=1e-3)      # smooth: no loss


FURNACE = {  # name: (Material keywords, keeps energy)
    "white_plastic_r0.5": (dict(roughness=0.5, specular_weight=1.0, metallic=0.0), True),
    "white_plastic_r0.1": (dict(roughness=0.1, specular_weight=1.0, metallic=0.0), True),
    "smooth_glass": (dict(roughness=0.0, metallic=0.0, specular_weight=1.0, transmission=1.0, ior=1.5), True),
    # The metal lobe at every roughness where single scattering keeps the
    # energy (within 0.1 % at the views of the sphere's centre, docs'
    # table): the mirror (delta), the narrowest rough lobe just above
    # BSDF_DELTA_ALPHA, and on to 0.15 ...
    "mirror": (dict(roughness=0.0, metallic=1.0), True),
    "white_metal_r0.035": (dict(roughness=0.035, metallic=1.0), True),
    "white_metal_r0.1": (dict(roughness=0.1, metallic=1.0), True),
    "white_metal_r0.15": (dict(roughness=0.15, metallic=1.0), True),
    # ... and those that lose by design what bounces between facets (from
    # roughness 0.25 on: 0.4 % at normal view, 5 % at grazing; 69 % at 1).
    "white_metal_r0.25": (dict(roughness=0.25, metallic=1.0), False),
    "white_metal_r0.5": (dict(roughness=0.5, metallic=1.0), False),
    "white_metal_r1": (dict(roughness=1.0, metallic=1.0), False),
}


@pytest.mark.parametrize("name", sorted(FURNACE))
def test_white_furnace_through_the_path_tracer(name, device):
    """A white sphere under uniform radiance 1, rendered by the path tracer:
    materials that keep energy vanish (mean 1, less the little that the
    wedges of its interpolated normals drop at the silhouette); a rough metal
    shows its single-scattering loss, pixel by pixel the float64 quadrature's
    directional albedo at the pixel's view angle (a convex sphere: one
    bounce, then the sky)."""
    from clrt.reference import camera_rays
    from clrt.renderer import Renderer
    from clrt.scene import primitives
    from clrt.scene.scene import Camera, Material, Scene, SceneObject

    keywords, keeps = FURNACE[name]
    material = Material(color=(1.0, 1.0, 1.0), specular=1.0, **keywords)
    scene = Scene([SceneObject(primitives.icosphere(2), material)], [], background=(1.0, 1.0, 1.0),
                  integrator="path")
    camera = Camera((0.0, 0.0, 2.6), (0.0, 0.0, 0.0), width=16, height=16, fov=50)
    image = Renderer(scene, device=device).render(camera, linear=True, spp=64 if keeps else 256, seed=3).image
    centre = image[5:11, 5:11].mean()       # the sphere seen head on
    if keeps:
        assert abs(image.mean() - 1.0) < 0.006 and abs(centre - 1.0) < 0.01, (image.mean(), centre)
        return
    # The view cosine of each pixel centre's ray at the unit sphere (where it meets it away from the rim).
    origins, dirs = (a.astype(np.float64) for a in camera_rays(camera))
    b = np.einsum("ij,ij->i", origins, dirs)
    disc = b * b - (np.einsum("ij,ij->i", origins, origins) - 1.0)
    t = -b - np.sqrt(np.maximum(disc, 0.0))
    cos_view = np.where(disc > 0, -np.einsum("ij,ij->i", origins + t[:, None] * dirs, dirs), 0.0)
    face = (cos_view > 0.5).reshape(16, 16)
    alpha = keywords["roughness"] ** 2
    grid = np.linspace(0.45, 1.0, 12)
    expected = np.interp(cos_view, grid, [metal_albedo(alpha, c) for c in grid]).reshape(16, 16)
    assert face.sum() > 40 and expected[face].max() < 0.997
    # The mean over those pixels within four of its standard errors (measured
    # from their spread about the quadrature) and 0.002 (a pixel's jitter
    # averages its view cosines about the centre's).
    diff = image[face].mean(axis=-1) - expected[face]
    error = diff.std() / math.sqrt(diff.size)
    assert abs(diff.mean()) < 4.0 * error + 0.002, (diff.mean(), error)


def test_the_docs_table_of_metal_albedo_is_the_quadratures():
    text = (Path(__file__).resolve().parents[1] / "docs" / "path-tracing.md").read_text()
    rows = re.findall(r"^\| (\d\.\d+) \| (\d\.\d+) \| (\d\.\d+) \| (\d\.\d+) \|$", text, re.M)
    assert len(rows) >= 4
    for roughness, *values in rows:
        for cos_o, value in zip((1.0, 0.5, 0.2), values):
            assert metal_albedo(float(roughness) ** 2, cos_o) == pytest.approx(float(value), abs=6e-4)


def test_the_layer_albedo_tables_are_the_quadratures():
    """bsdf_albedo.cl (tools/bsdf_albedo.py) against bsdf_reference.metal_albedo, an
    independent quadrature: E(c, alpha, f0) = f0 A + (1 - f0) B is the albedo
    of the GGX layer with Schlick's F, so A is a white metal's and B that of
    F = (1 - wo.h)^5 alone (f0 = 0).  Between the nodes, bilinear lookups
    stay within 0.25% for views up to 89.8 degrees."""
    tables = albedo_tables()
    a, b = tables["LAYER_ALBEDO_A"], tables["LAYER_ALBEDO_B"]
    rows, cols = a.shape
    for j in (5, 20, rows - 1):
        alpha = (j / (rows - 1)) ** 4
        for k in (6, 16, cols - 1):
            c = (k / (cols - 1)) ** 2
            assert a[j, k] == pytest.approx(metal_albedo(alpha, c, 1.0, nodes=240), abs=1e-3), (j, k)
            assert b[j, k] == pytest.approx(metal_albedo(alpha, c, 0.0, nodes=240), abs=1e-3), (j, k)
    x, w = np.polynomial.legendre.leggauss(12)
    for j in (12, 40):
        alpha = (j / (rows - 1)) ** 4
        for f0 in (0.0, 1.0):
            average = 2 * sum(wk / 2 * (xk + 1) / 2 * metal_albedo(alpha, (xk + 1) / 2, f0, nodes=96)
                              for xk, wk in zip(x, w))
            assert layer_albedo_average(np.array(alpha), f0, tables) == pytest.approx(average, abs=1e-3)
    rng = np.random.default_rng(14)
    for _ in range(12):
        alpha, c = rng.uniform(0.0316, 1) ** 2, rng.uniform(0.05, 1) ** 2
        for f0 in (0.04, 1.0):
            assert layer_albedo(np.array(c), np.array(alpha), f0, tables) == pytest.approx(
                metal_albedo(alpha, c, f0, nodes=240), abs=2.5e-3), (alpha, c, f0)


def test_specular_weight_zero_is_pure_lambert(probe):
    rng = np.random.default_rng(9)
    count = 5000
    mats = random_materials(rng, count, transmissive=False)
    mats[:, 3] = 0
    mats[:, 8] = 0
    ng = np.tile([0.0, 0, 1], (count, 1))
    wo, wi = random_directions(rng, count), random_directions(rng, count)
    wo[:, 2], wi[:, 2] = np.abs(wo[:, 2]), np.abs(wi[:, 2])
    f, pdf = probe.eval(mats, ng, ng, wo, wi)
    np.testing.assert_allclose(f, mats[:, :3] * wi[:, 2:3] / np.pi, rtol=1e-5, atol=1e-9)
    np.testing.assert_allclose(pdf, wi[:, 2] / np.pi, rtol=1e-5, atol=1e-9)


def test_eval_matches_the_float64_reference(probe):
    rng = np.random.default_rng(10)
    count = 40_000
    mats = random_materials(rng, count)
    mats[:, 4] = np.where(mats[:, 4] == 0, 0, np.maximum(mats[:, 4], 0.05**2))
    n, ng, wo = random_points(rng, count, tilt_deg=25)
    # a third of wi at random, a third near the mirror direction about n, a third near the refracted one
    side = np.sign(np.sum(wo * ng, axis=1))[:, None]
    ns = n * side
    c = np.sum(ns * wo, axis=1)[:, None]
    eta = np.where(side > 0, mats[:, 10:11], 1 / mats[:, 10:11])
    ct = np.sqrt(np.clip(1 - (1 - c**2) / eta**2, 0, None))
    near = [2 * c * ns - wo, -wo / eta + (c / eta - ct) * ns]
    pick = rng.integers(0, 3, count)[:, None]
    wi = np.where(pick == 0, random_directions(rng, count),
                  unit(np.where(pick == 1, near[0], near[1]) + 0.25 * random_directions(rng, count)))
    inputs = [np.asarray(a, np.float32) for a in (n, ng, wo, wi)]      # both see the same float32 vectors
    f, _ = probe.eval(mats, *inputs)
    ref = bsdf_times_cos(mats, *inputs, delta_alpha=probe.delta_alpha)
    assert (ref > 0).any(axis=1).mean() > 0.35
    crossing = np.sum(inputs[1] * inputs[2], axis=1) * np.sum(inputs[1] * inputs[3], axis=1) < 0
    assert (ref[crossing] > 0).any(axis=1).sum() > 2000          # refraction is compared, not only reflection
    # float32 against float64: typically 1e-7 relative; the narrowest lobes and
    # refraction's denominator (eta wi.h + wo.h, which cancels near grazing
    # refraction) reach a few 1e-3 on a handful of pairs
    error = np.abs(f - ref)
    relative = error[ref > 1e-12] / ref[ref > 1e-12]
    assert np.median(relative) < 1e-6 and np.quantile(relative, 0.999) < 2e-4
    tolerance = 5e-3 * np.abs(ref) + 1e-6 * np.abs(ref).max(axis=1, keepdims=True) + 1e-9
    worst = np.unravel_index(np.argmax(error / tolerance), error.shape)[0]
    assert (error <= tolerance).all(), (mats[worst], f[worst], ref[worst], [a[worst] for a in inputs])


def test_frames_are_orthonormal_at_and_near_the_poles(probe):
    rng = np.random.default_rng(12)
    normals = np.concatenate([[[0, 0, 1], [0, 0, -1], [1e-20, 0, -1], [0, 1e-8, -1], [0, -1e-8, 1], [1, 0, 0]],
                              random_directions(rng, 1000)])
    normals = unit(normals).astype(np.float32)
    frames = probe.frames(normals).astype(np.float64)
    gram = frames @ frames.transpose(0, 2, 1)
    np.testing.assert_allclose(gram, np.broadcast_to(np.eye(3), gram.shape), atol=2e-6)
    np.testing.assert_allclose(np.cross(frames[:, 0], frames[:, 1]), frames[:, 2], atol=2e-6)
    np.testing.assert_array_equal(frames[:, 2], normals)


def test_delta_lobes_below_the_threshold_only(probe):
    d = probe.delta_alpha
    n, ng, wo = _shading_point(30, False, 0)
    u = np.random.default_rng(13).random((2000, 3), dtype=np.float32)
    for alpha, delta in ((0.0, True), (0.99 * d, True), (d, False), (1.5 * d, False)):
        mat = material(base=(1, 1, 1), metallic=1)
        mat[4] = alpha
        _, _, _, flag = probe.sample(mat, n, ng, wo, u)
        assert (flag == (2 if delta else 1)).mean() > 0.95, alpha


def test_the_kernels_use_no_double():
    """float32 throughout: no double type and no unsuffixed floating literal
    (which C reads as double) in the BSDF's files."""
    literal = re.compile(r"(?<![\w.])(\d+\.\d*|\.\d+|\d+[eE][-+]?\d+|\d+\.\d*[eE][-+]?\d+)(?![\w.])")
    for name in ("bsdf.cl", "sampling.cl", "bsdf_albedo.cl"):
        code = re.sub(r"//[^\n]*", "", (KERNELS / name).read_text())
        assert "double" not in code, name
        assert not literal.findall(code), (name, literal.findall(code))
