"""The path tracer's light tables (lights.cl), built on the host.

Every light of a scene is one row of a table that the kernels sample by
Walker's alias method (Vose's construction) in proportion to its power
(luminance, Rec. 709 weights):

=================  ==============================================================
light              power
=================  ==============================================================
point light        4 pi I
spot light         2 pi (1 - (cos_beam + cos_cutoff) / 2) I  (pbrt-v4's estimate)
emissive triangle  pi L area, twice for a double-sided material
background         pi L_mean x pi R^2, R the radius of the scene's bounding sphere
=================  ==============================================================

A triangle emits when its material's emission factor is above 0 (its texture,
if any, multiplies the radiance, not the power: the choice stays a function of
the material alone, so that lights.cl's triangle_light_area_pdf can compute
the same probability where a BSDF-sampled ray hits it).  The environment map
is sampled texel by texel in proportion to luminance x sin(theta): a marginal
CDF over its rows and a conditional CDF over each row's texels (float32, each
ending at exactly 1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from clrt.config import LIGHT_KINDS, MATERIAL_DOUBLE_SIDED
from clrt.layouts import LIGHT_ENTRY, MATERIAL

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


@dataclass
class LightTables:
    """What the path tracer's launches need of a scene's lights: the rows for
    the `tables` buffer and the values of PathLaunch (layouts.py)."""

    entries: np.ndarray          # (N,) LIGHT_ENTRY, at least one row (num_entries says how many are lights)
    num_entries: int
    inv_power: float             # 1 / the power of every light (0: no light)
    background_probability: float
    texels: np.ndarray           # (H * W, 4) float32 of the environment map, one zero row without one
    marginal: np.ndarray         # (H + 1,) float32
    conditional: np.ndarray      # (H * (W + 1),) float32
    env_size: tuple[int, int]    # (W, H); (0, 0): the constant background


def alias_table(weights) -> tuple[np.ndarray, np.ndarray]:
    """Walker's alias table of ``weights`` (Vose's construction, float64):
    (threshold, alias) with entry i kept when a uniform u in [0, 1) below
    threshold[i] and alias[i] taken otherwise, so that entry i is chosen with
    probability weights[i] / sum(weights)."""
    w = np.asarray(weights, np.float64)
    n = len(w)
    scaled = w * (n / w.sum())
    threshold = np.ones(n)
    alias = np.arange(n)
    small = [i for i in range(n) if scaled[i] < 1.0]
    large = [i for i in range(n) if scaled[i] >= 1.0]
    while small and large:
        s, g = small.pop(), large.pop()
        threshold[s], alias[s] = scaled[s], g
        scaled[g] -= 1.0 - scaled[s]
        (small if scaled[g] < 1.0 else large).append(g)
    return threshold, alias   # what is left in either list keeps itself (threshold 1)


def triangle_powers(corners: np.ndarray, material_of: np.ndarray, materials: np.ndarray) -> np.ndarray:
    """(F,) float64 power of each triangle (0 for those that do not emit)."""
    emission = materials["emission"][:, :3].astype(np.float64) @ LUMINANCE
    sides = np.where(materials["flags"] & MATERIAL_DOUBLE_SIDED, 2.0, 1.0)
    per_material = math.pi * emission * sides
    c = corners.astype(np.float64)
    area = 0.5 * np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1)
    return per_material[material_of] * area


def light_power(light) -> float:
    intensity = float(np.asarray(light.color, np.float64) @ LUMINANCE)
    if light.direction is None:
        return 4.0 * math.pi * intensity
    cos_outer, cos_inner = math.cos(math.radians(light.cutoff)), math.cos(math.radians(light.beam))
    return 2.0 * math.pi * (1.0 - 0.5 * (cos_inner + cos_outer)) * intensity


def environment_cdfs(image: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """The marginal (H + 1) and conditional (H x (W + 1)) CDFs of an (H, W, 3)
    map, float32, and its mean luminance over the sphere (float64)."""
    h, w = image.shape[:2]
    sin_theta = np.sin(math.pi * (np.arange(h) + 0.5) / h)
    weight = (image.astype(np.float64) @ LUMINANCE) * sin_theta[:, None]
    rows = weight.sum(axis=1)
    conditional = np.empty((h, w + 1))
    conditional[:, 0] = 0.0
    np.cumsum(weight, axis=1, out=conditional[:, 1:])
    empty = rows <= 0.0
    conditional[empty, 1:] = np.arange(1, w + 1)   # never chosen (its row has no weight): any CDF
    conditional /= conditional[:, -1:]
    total = rows.sum()
    marginal = np.concatenate([[0.0], np.cumsum(rows)])
    marginal = marginal / total if total > 0 else np.linspace(0.0, 1.0, h + 1)
    # The mean over the sphere: sum of L sin(theta) dtheta dphi / 4 pi.
    mean = total * (math.pi / h) * (2.0 * math.pi / w) / (4.0 * math.pi)
    return _cdf32(marginal), _cdf32(conditional).ravel(), mean


def _cdf32(cdf: np.ndarray) -> np.ndarray:
    """A float64 CDF (last axis) as float32, non-decreasing, from exactly 0 to exactly 1."""
    out = np.maximum.accumulate(cdf.astype(np.float32), axis=-1)
    out[..., 0], out[..., -1] = 0.0, 1.0
    return np.minimum(out, np.float32(1.0))


def emitting_triangles(arrays, order: np.ndarray) -> tuple:
    """The triangles :func:`light_tables` weighs, of a scene's SceneArrays
    (clrt.scene.arrays) uploaded in slot order ``order`` (the input row each
    slot holds: Acceleration.slot_order): ``(corners, material_of, slots,
    instances)``.  A one-level scene: every triangle in slot order, ``slots``
    and ``instances`` None.  An instanced one: each placement of each
    triangle whose material emits (Instance.material, its object's, counted
    in), its corners as placed (float64, for its area), its material row, its
    slot and its instance -- one light per placed emitter, so that a mesh
    placed K times emits K times."""
    if arrays.instances is None:
        return arrays.corners[order], arrays.triangle_materials[order], None, None
    placed = arrays.instances
    emits = materials_emit(arrays.materials)
    slot_of = np.empty(len(order), np.int64)
    slot_of[order] = np.arange(len(order))
    first = np.cumsum([0] + [len(m.faces) for m in placed.meshes])
    local = arrays.triangle_materials.astype(np.int64)
    corners, material_of, slots, instances = [], [], [], []
    pairs = np.stack([placed.mesh_of, arrays.material_base.astype(np.int64)], axis=1)
    for k, base in np.unique(pairs, axis=0):
        rows = first[k] + np.flatnonzero(emits[base + local[first[k]:first[k + 1]]])
        if not len(rows):
            continue
        which = np.flatnonzero((pairs[:, 0] == k) & (pairs[:, 1] == base))
        mesh = placed.meshes[k]
        own = mesh.vertices[mesh.faces[rows - first[k]]].astype(np.float64)            # (E, 3, 3)
        m = placed.transforms[which]
        corners.append((np.einsum("nij,ecj->neci", m[:, :3, :3], own) + m[:, None, None, :3, 3]).reshape(-1, 3, 3))
        material_of.append(np.tile(base + local[rows], len(which)))
        slots.append(np.tile(slot_of[rows], len(which)))
        instances.append(np.repeat(which, len(rows)))
    if not corners:
        return np.zeros((0, 3, 3)), np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64)
    return tuple(np.concatenate(x) for x in (corners, material_of, slots, instances))


def materials_emit(materials: np.ndarray) -> np.ndarray:
    """(M,) bool: which MATERIAL rows emit (an emission factor of luminance above 0)."""
    return materials["emission"][:, :3].astype(np.float64) @ LUMINANCE > 0.0


def light_tables(corners: np.ndarray, material_of: np.ndarray, materials: np.ndarray, lights, background,
                 environment, bounds, slots=None, instances=None) -> LightTables:
    """The light table of a scene.  ``corners`` (F, 3, 3) and ``material_of``
    (F,): the triangles in slot order (the rows the kernels index) -- or,
    with ``slots`` and ``instances`` (F,) (:func:`emitting_triangles` of a
    two-level scene), each triangle's slot and instance, its corners as placed;
    ``materials``: MATERIAL rows; ``lights``: clrt Lights; ``background``: the
    constant radiance (used without an ``environment``, an Environment or
    None); ``bounds``: the scene's (2, 3) box."""
    assert materials.dtype == MATERIAL
    bounds = np.asarray(bounds, np.float64)
    radius = 0.5 * float(np.linalg.norm(bounds[1] - bounds[0])) or 1.0
    kinds, indices, powers = [], [], []
    for i, light in enumerate(lights):
        kinds.append(LIGHT_KINDS["point"])
        indices.append(i)
        powers.append(light_power(light))
    placed = [0] * len(kinds)   # each entry's instance
    tri_power = triangle_powers(corners, material_of, materials)
    emitting = np.nonzero(tri_power > 0.0)[0]
    kinds += [LIGHT_KINDS["triangle"]] * len(emitting)
    indices += (emitting if slots is None else np.asarray(slots)[emitting]).tolist()
    placed += [0] * len(emitting) if instances is None else np.asarray(instances)[emitting].tolist()
    powers += tri_power[emitting].tolist()
    if environment is not None:
        marginal, conditional, mean = environment_cdfs(environment.image)
        mean *= environment.strength
        h, w = environment.image.shape[:2]
        texels = np.zeros((h * w, 4), np.float32)
        texels[:, :3] = environment.image.reshape(-1, 3)
        env_size = (w, h)
    else:
        marginal, conditional = np.array([0.0, 1.0], np.float32), np.array([0.0, 1.0], np.float32)
        mean = float(np.asarray(background, np.float64) @ LUMINANCE)
        texels, env_size = np.zeros((1, 4), np.float32), (0, 0)
    background_power = math.pi * mean * math.pi * radius * radius
    if background_power > 0.0:
        kinds.append(LIGHT_KINDS["background"])
        indices.append(-1)
        placed.append(0)
        powers.append(background_power)
    powers = np.asarray(powers, np.float64)
    keep = powers > 0.0
    entries = np.zeros(max(int(keep.sum()), 1), LIGHT_ENTRY)
    total = float(powers[keep].sum())
    background_probability = 0.0
    if total > 0.0:
        threshold, alias = alias_table(powers[keep])
        entries["threshold"][:len(threshold)] = threshold
        entries["alias"][:len(alias)] = alias
        entries["kind"][:len(alias)] = np.asarray(kinds)[keep]
        entries["index"][:len(alias)] = np.asarray(indices)[keep]
        entries["instance"][:len(alias)] = np.asarray(placed)[keep]
        entries["probability"][:len(alias)] = powers[keep] / total
        if background_power > 0.0:
            background_probability = background_power / total
    return LightTables(entries, int(keep.sum()), 1.0 / total if total > 0.0 else 0.0, background_probability,
                       texels, marginal, conditional, env_size)
