"""Blender's Principled Coat at the kernel level (``kernels.bsdf`` lobe CLEARCOAT; the closure's
``C_CC_*`` columns): energy, the layering of what lies below, the tint, and the rough lobe's
sampling against its evaluation.  The Cycles comparison is ``test_cycles_coat.py``.

A closure row gets the coat as the node interpreter writes it (``kernels.svm._closure``): Coat
Weight, Roughness, IOR and Tint in C_CC_*, then ``closure.finish_closure``.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from stpm_core.kernels import bsdf as kb
from stpm_core.kernels import closure as kc
from stpm_core.scene import Material


def coated_rows(base, weight=1.0, rough=0.0, ior=1.5, tint=(1.0, 1.0, 1.0), specular=0.0, base_rough=0.5,
                metallic=0.0):
    """Closure rows (2, N_CLOSURE): a Principled-like closure of this base under a coat layer."""
    m = Material(base_color=np.asarray(base, float), specular=specular, roughness=base_rough, metallic=metallic)
    C = kc.pack_materials([m])
    C[0, kc.C_CC_WEIGHT] = weight
    C[0, kc.C_CC_ROUGH] = rough
    C[0, kc.C_CC_IOR] = ior
    C[0, kc.C_CC_TINT:kc.C_CC_TINT + 3] = tint
    kc.finish_closure(C[0])
    return C


def _wo(mu):
    return np.array([math.sqrt(1.0 - mu * mu), 0.0, mu])


def sampled(C, mu, n_side=300, seed=0):
    """(weights (n, 3), wi (n, 3), delta (n,)) of ``bsdf_sample`` at wo of cosine mu over a
    stratified n_side^2 grid of (u1, u2) and a stratified, shuffled u0."""
    n = n_side * n_side
    rng = np.random.default_rng(seed)
    g = (np.arange(n_side) + rng.random(n_side)) / n_side
    u = np.empty((n, 3))
    u[:, 0] = rng.permutation((np.arange(n) + rng.random(n)) / n)
    u[:, 1] = np.repeat(g, n_side)
    u[:, 2] = np.tile(g, n_side)
    E, E_avg = kb.ggx_albedo_tables()
    wo = np.tile(_wo(mu), (n, 1))
    nz = np.tile([0.0, 0.0, 1.0], (n, 1))
    wi, w, dl = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n, bool)
    kb.sample_batch(C, E, E_avg, np.zeros(n, np.int64), wo, nz, nz, u, wi, w, dl)
    return w, wi, dl


@pytest.mark.parametrize("mu", [1.0, 0.7, 0.3, 0.08])
def test_smooth_coat_over_white_gains_no_energy(mu):
    """White furnace: a smooth coat (roughness 0) over a white diffuse base reflects F + (1 - F) = 1,
    every sample exactly (the delta coat's weight and the diffuse pick's are both 1): none above 1."""
    C = coated_rows((1.0, 1.0, 1.0), rough=0.0)
    w, _, dl = sampled(C, mu, n_side=100)
    assert dl.any() and (~dl).any()                       # both the coat's mirror and the diffuse base
    assert w.max() <= 1.0 + 1e-12, w.max()
    assert abs(w.mean() - 1.0) < 1e-9, w.mean()


@pytest.mark.parametrize("mu", [0.9, 0.4])
def test_rough_coat_over_white_keeps_energy_within_its_table(mu):
    """A rough coat (0.3) over white: the coat reflects its albedo, the base gets the rest, so the sum
    is 1 within the coat table's interpolation and the noise (measured 0.2 %)."""
    C = coated_rows((1.0, 1.0, 1.0), rough=0.3)
    w, _, _ = sampled(C, mu)
    assert abs(w.mean() - 1.0) < 0.01, w.mean(axis=0)


@pytest.mark.parametrize("mu", [0.9, 0.5, 0.2])
def test_smooth_coat_layers_the_base_by_its_fresnel(mu):
    """Grey base 0.5, smooth coat of ior 1.5 (Coat Weight 1, no specular layer): the albedo is
    F + (1 - F) 0.5 with F = F_diel(mu, 1.5) (0.5 without the coat: main before 2026-12-07);
    the coat's mirror carries F of it."""
    C = coated_rows((0.5, 0.5, 0.5), rough=0.0)
    w, _, dl = sampled(C, mu, n_side=100)
    F = kb.fresnel_dielectric(mu, 1.5)
    assert abs(w.mean() - (F + 0.5 * (1.0 - F))) < 1e-9, (w.mean(), F)
    assert abs(w[dl, 0].sum() / len(w) - F) < 5e-3, (w[dl, 0].sum() / len(w), F)


def test_half_coat_weight_mixes():
    """Coat Weight 0.5: the coat reflects 0.5 F and the base keeps 1 - 0.5 F (Cycles'
    closure_layering_weight)."""
    mu = 0.5
    C = coated_rows((0.5, 0.5, 0.5), weight=0.5, rough=0.0)
    w, _, _ = sampled(C, mu, n_side=100)
    F = kb.fresnel_dielectric(mu, 1.5)
    assert abs(w.mean() - (0.5 * F + 0.5 * (1.0 - 0.5 * F))) < 1e-9


@pytest.mark.parametrize("mu", [1.0, 0.5])
def test_coat_tint_is_beer_through_the_refracted_path(mu):
    """White base under a smooth coat tinted t: per channel F + (1 - F) t^(1 / cos_t), cos_t the
    cosine of wo refracted into the coat (Cycles' optical depth), F = F_diel(mu, 1.5)."""
    t = np.array([0.8, 0.5, 0.2])
    C = coated_rows((1.0, 1.0, 1.0), rough=0.0, tint=t)
    w, _, _ = sampled(C, mu, n_side=200)
    F = kb.fresnel_dielectric(mu, 1.5)
    cos_t = math.sqrt(1.0 - (1.0 - mu * mu) / 1.5 ** 2)
    want = F + (1.0 - F) * t ** (1.0 / cos_t)
    assert np.allclose(w.mean(axis=0), want, atol=2e-3), (w.mean(axis=0), want)


def test_rough_coat_sampling_matches_its_evaluation():
    """Everything non-delta (base roughness 0.5 under a coat of roughness 0.3 over a red base with a
    specular layer): the mixture pdf the sampler reports integrates to 1 over what it samples
    (E[1 / pdf] over the upper hemisphere = 2 pi) and the sampled albedo equals a quadrature of
    f |cos| over the hemisphere."""
    C = coated_rows((0.5, 0.05, 0.05), rough=0.3, specular=1.0)
    mu = 0.6
    w, wi, dl = sampled(C, mu)
    assert not dl.any()
    E, E_avg = kb.ggx_albedo_tables()
    n = len(wi)
    wo = np.tile(_wo(mu), (n, 1))
    nz = np.tile([0.0, 0.0, 1.0], (n, 1))
    f, pdf = np.zeros((n, 3)), np.zeros(n)
    kb.eval_batch(C, E, E_avg, np.zeros(n, np.int64), wo, wi, nz, nz, f, pdf)
    up = (wi[:, 2] > 0) & (pdf > 0)
    assert abs((1.0 / pdf[up]).sum() / n / (2 * math.pi) - 1.0) < 0.02
    # quadrature of f cos over the hemisphere (uniform in cos theta and phi, 400 x 400 midpoints)
    k = 400
    ct = (np.arange(k) + 0.5) / k
    ph = (np.arange(k) + 0.5) / k * 2 * math.pi
    CT, PH = np.meshgrid(ct, ph, indexing="ij")
    st = np.sqrt(1 - CT ** 2)
    d = np.stack([st * np.cos(PH), st * np.sin(PH), CT], axis=-1).reshape(-1, 3)
    m = len(d)
    fq, pq = np.zeros((m, 3)), np.zeros(0)
    kb.eval_batch(C, E, E_avg, np.zeros(m, np.int64), np.tile(_wo(mu), (m, 1)), d, np.tile([0.0, 0.0, 1.0], (m, 1)),
                  np.tile([0.0, 0.0, 1.0], (m, 1)), fq, pq)
    quad = (fq * d[:, 2:3]).mean(axis=0) * 2 * math.pi
    assert np.allclose(w.mean(axis=0), quad, rtol=0.02), (w.mean(axis=0), quad)
    # the coat's highlight is in there: the same row without the coat is darker in green and blue
    C0 = coated_rows((0.5, 0.05, 0.05), weight=0.0, specular=1.0)
    w0, _, _ = sampled(C0, mu)
    assert w.mean(axis=0)[1] > 1.5 * w0.mean(axis=0)[1]


def test_coat_flags():
    """A smooth coat is a delta lobe (caustics, specular chains), a rough one a glossy lobe."""
    C = coated_rows((0.5, 0.5, 0.5), rough=0.0, base_rough=1.0)
    assert C[0, kc.C_HAS_DELTA] == 1.0 and C[0, kc.C_ROUGH_LOBE] == 0.0
    assert kb.lobe_is_delta(C, 0, kb.CLEARCOAT)
    C = coated_rows((0.5, 0.5, 0.5), rough=0.2, base_rough=0.0)
    assert C[0, kc.C_HAS_DELTA] == 0.0 and C[0, kc.C_ROUGH_LOBE] == 1.0
    assert not kb.lobe_is_delta(C, 0, kb.CLEARCOAT)
    assert kb.needs_bsdf_call(coated_rows((0.5, 0.5, 0.5), rough=0.0), 0)


def test_node_inputs_fill_the_coat_columns():
    """The node interpreter fills C_CC_* from the Principled BSDF's Coat inputs, linked ones too (a
    Math node into Coat Weight, an RGB node into Coat Tint), and the compiler no longer says the
    coat is not rendered."""
    from test_kernel_svm import L, N, make_hits, make_scene, run_kernel, surface
    nodes = {"w": N("ShaderNodeMath", {"Value": 0.25, "Value_001": 0.5}, {"operation": "ADD"}),
             "tint": N("ShaderNodeRGB", props={"value": (0.9, 0.5, 0.25)}),
             "p": N("ShaderNodeBsdfPrincipled", {"Base Color": (0.3, 0.02, 0.02), "Coat Weight": L("w", "Value"),
                                                 "Coat Roughness": 0.2, "Coat IOR": 1.6,
                                                 "Coat Tint": L("tint", "Color")})}
    scene = make_scene([surface(nodes, "p")])
    hits = make_hits(4, np.random.default_rng(0))
    C, sd = run_kernel(scene, hits, np.zeros(4, np.int32))
    assert not any("Coat" in m for m in sd.unsupported), sd.unsupported
    assert np.allclose(C[:, kc.C_CC_WEIGHT], 0.75)
    assert np.allclose(C[:, kc.C_CC_ROUGH], 0.2) and np.allclose(C[:, kc.C_CC_ALPHA], 0.04)
    assert np.allclose(C[:, kc.C_CC_IOR], 1.6)
    assert np.allclose(C[:, kc.C_CC_TINT:kc.C_CC_TINT + 3], (0.9, 0.5, 0.25))
    assert (C[:, kc.C_ROUGH_LOBE] == 1.0).all()
    # a Diffuse BSDF has no coat
    scene = make_scene([surface({"d": N("ShaderNodeBsdfDiffuse", {"Color": (0.5, 0.5, 0.5)})}, "d")])
    C, _ = run_kernel(scene, hits, np.zeros(4, np.int32))
    assert (C[:, kc.C_CC_WEIGHT] == 0.0).all()


def test_linked_coat_normal_tilts_the_coat_alone():
    """A linked Coat Normal (a Combine XYZ here) becomes the coat layer's normal (C_CC_N, C_CC_HAS_N)
    without touching the shading normal; the smooth coat's mirror reflects about it."""
    from test_kernel_svm import L, N, make_hits, make_scene, run_kernel, surface
    nodes = {"n": N("ShaderNodeCombineXYZ", {"X": 0.3, "Y": 0.0, "Z": 1.0}),
             "p": N("ShaderNodeBsdfPrincipled", {"Base Color": (0.5, 0.5, 0.5), "Coat Weight": 1.0,
                                                 "Coat Roughness": 0.0, "Coat Normal": L("n", "Vector")})}
    scene = make_scene([surface(nodes, "p")])
    hits = make_hits(3, np.random.default_rng(1))
    ns_before = hits["NS"].copy()
    C, sd = run_kernel(scene, hits, np.zeros(3, np.int32))
    assert not any("Coat Normal" in m for m in sd.unsupported), sd.unsupported
    want = np.array([0.3, 0.0, 1.0]) / math.hypot(0.3, 1.0)
    assert np.allclose(C[:, kc.C_CC_N:kc.C_CC_N + 3], want) and (C[:, kc.C_CC_HAS_N] == 1.0).all()
    assert (C[:, kc.C_BUMPED] == 0.0).all() and np.array_equal(hits["NS"], ns_before)
    # the delta coat's mirror about the tilted normal, the base's lobes about the surface's
    R = coated_rows((0.5, 0.5, 0.5), rough=0.0)
    R[0, kc.C_CC_N:kc.C_CC_N + 3] = want
    R[0, kc.C_CC_HAS_N] = 1.0
    E, E_avg = kb.ggx_albedo_tables()
    wo = (0.0, 0.0, 1.0)
    n = (0.0, 0.0, 1.0)
    wi0, wi1, wi2, *_, lobe = kb.bsdf_sample_lobe(R, 0, E, E_avg, wo, n, n, 0.9999, 0.5, 0.5)
    assert lobe == kb.CLEARCOAT
    mirror = 2.0 * want[2] * want - np.array(wo)
    assert np.allclose((wi0, wi1, wi2), mirror / np.linalg.norm(mirror), atol=1e-9)
