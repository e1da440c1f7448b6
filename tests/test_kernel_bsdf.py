"""The compiled BSDF (stpm_core.kernels.bsdf) agrees with the numpy oracle (tests/oracles/bsdf_numpy.py).

Random materials of every kind (diffuse, coated, metal, glass, mixtures; glass with Cycles'
reflection and transmission tints: a Glass BSDF's, a Principled BSDF's, unrelated ones) at
roughness 0, 1e-3, 0.3 and 1, random directions and normals (ns tilted from
ng, either side, grazing wo / wi, wi near the mirror direction), the same
uniforms: eval, pdf, sample (wi, weight, is_delta) and the diffuse albedo.

Tolerance: rtol 1e-9, atol 1e-12, except near the peak of a GGX lobe with
alpha at its floor 1e-4 (roughness 1e-3): D's denominator
cos_h^2 (alpha^2 - 1) + 1 cancels down to alpha^2 there, so a rounding
difference in cos_h (dot products are summed x + y + z in the kernels, x + z
+ y by numpy's einsum) is amplified by about 1 / alpha^2; rows get
rtol = max(1e-9, 5e-15 / alpha^2) (5e-7 at alpha = 1e-4, where 8e-8 was
measured; 1e-9 from alpha 2.2e-3 up).  With einsum's order of the dot
products the kernels reproduce the oracle bit for bit (checked once by hand).
Near-horizon samples (a cosine sample with u close to a corner) are kept: f
cos / pdf there is relative-ill-conditioned but tiny, inside atol.
"""
import numpy as np
import pytest

from oracles import bsdf_numpy as oracle
from stpm_core import bsdf
from stpm_core.bsdf import MaterialTable
from stpm_core.kernels import bsdf as kb
from stpm_core.kernels import closure as kc
from stpm_core.sampling import uniform_sphere
from stpm_core.scene import Material

ROUGHNESS = (0.0, 1e-3, 0.3, 1.0)
RTOL, ATOL = 1e-9, 1e-12


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _glass_bsdf(color, ior, roughness) -> Material:
    """Cycles' Glass BSDF of this colour: reflection and refraction tinted by it (svm/closure.h)."""
    color = np.asarray(color, float)
    return Material(base_color=color, transmission=1.0, ior=ior, roughness=roughness, reflection_tint=color.copy())


def _materials(rng) -> list:
    """Every lobe combination at every test roughness, random colours / weights / ior."""
    col = lambda: rng.uniform(0.05, 1.0, 3)
    ior = lambda: float(rng.choice([1.0, 1.33, 1.5, 2.4]))
    mats = []
    for r in ROUGHNESS:
        mats += [
            Material(base_color=col(), roughness=r),                                      # diffuse
            Material(base_color=col(), specular=rng.uniform(0.2, 1.0), roughness=r, ior=ior()),  # coated
            Material.mirror(col(), roughness=r),                                          # metal
            Material.glass(ior(), color=col(), roughness=r),                              # glass
            Material.glass(1.0, color=col(), roughness=r),                                # index-matched glass
            Material(base_color=col(), metallic=rng.uniform(0.1, 0.9), transmission=rng.uniform(0.1, 0.9),
                     specular=rng.uniform(0.0, 1.0), roughness=r, ior=ior()),             # mixture of all
            Material(base_color=col(), metallic=rng.uniform(0.1, 0.9), specular=rng.uniform(0.2, 1.0),
                     roughness=r, ior=ior()),                                             # metal + coat
            Material(base_color=col(), transmission=rng.uniform(0.1, 0.9), roughness=r, ior=ior()),  # glass + diffuse
            _glass_bsdf(col(), ior(), r),                                                 # Cycles' Glass BSDF
            Material(base_color=(c := col()), transmission=1.0, roughness=r, ior=ior(),
                     transmission_tint=np.sqrt(c)),                                       # Principled glass
            Material(base_color=col(), metallic=rng.uniform(0.1, 0.9), transmission=rng.uniform(0.1, 0.9),
                     specular=rng.uniform(0.0, 1.0), roughness=r, ior=ior(), transmission_tint=col(),
                     reflection_tint=col()),                                              # unrelated tints
            Material(base_color=col(), transmission=1.0, roughness=r, ior=ior(),
                     reflection_tint=np.zeros(3)),                                        # no reflection at all
        ]
    mats += [Material.emitter((2.0, 3.0, 4.0)), Material(base_color=np.zeros(3), specular=0.5, roughness=0.3)]
    return mats


def _geometry(rng, n):
    """(wo, wi, ns, ng) (n, 3): ns tilted from ng, normals facing either way, some grazing and mirror-near directions."""
    ng = uniform_sphere(rng.random((n, 2)))
    ns = _unit(ng + rng.uniform(0.0, 0.6, (n, 1)) * uniform_sphere(rng.random((n, 2))))
    ns *= rng.choice([-1.0, 1.0], (n, 1))                                    # shading normal on either side
    wo = uniform_sphere(rng.random((n, 2)))
    wi = uniform_sphere(rng.random((n, 2)))
    # Grazing wo / wi: a tangent of ng tipped by +-1e-2 or +-1e-4
    t = _unit(np.cross(ng, uniform_sphere(rng.random((n, 2)))))
    tip = rng.choice([-1e-2, -1e-4, 1e-4, 1e-2], (n, 1))
    g = rng.random(n) < 0.15
    wo[g] = _unit(t + tip * ng)[g]
    g = rng.random(n) < 0.15
    wi[g] = _unit(np.cross(ng, t) + tip * ng)[g]
    # wi near the mirror direction of wo about ns (the GGX peak), spread 1e-2 or 1e-4
    mirror = 2.0 * np.sum(wo * ns, axis=1, keepdims=True) * ns - wo
    spread = rng.choice([1e-4, 1e-2], (n, 1))
    g = rng.random(n) < 0.35
    wi[g] = _unit(mirror + spread * uniform_sphere(rng.random((n, 2))))[g]
    return wo, wi, ns, ng


@pytest.fixture(scope="module")
def case():
    rng = np.random.default_rng(2024)
    mats = _materials(rng)
    table = MaterialTable(mats)
    n = 60_000
    mat = rng.integers(-1, len(mats), n)
    wo, wi, ns, ng = _geometry(rng, n)
    u = rng.random((n, 3))
    # Near the corners and at the centre of the square (not at u = 0: a cosine sample lands exactly on
    # ns's horizon there, where the sign of cos_i is rounding)
    u[:200, 1:] = rng.choice([2.0 ** -40, 0.5, 1.0 - 2.0 ** -53], (200, 2))
    alpha = np.maximum(table.alpha[np.where(mat < 0, len(mats), mat)], 1e-4)
    rtol = np.maximum(RTOL, 5e-15 / alpha ** 2)
    return table, mat, wo, wi, ns, ng, u, rtol


def _assert_close(got, want, rtol, what):
    got, want = np.asarray(got), np.asarray(want)
    r = rtol if np.ndim(rtol) == 0 or want.ndim == 1 else np.asarray(rtol)[:, None]
    bad = ~(np.abs(got - want) <= ATOL + r * np.abs(want))
    assert not bad.any(), f"{what}: {bad.any(axis=-1).sum() if bad.ndim > 1 else bad.sum()} rows differ, " \
                          f"max |diff| {np.max(np.abs(got - want)):.3g}"


# ----------------------------------------------------------------------------
# Kernels vs oracle
# ----------------------------------------------------------------------------
def test_eval_and_pdf_match_the_oracle(case):
    table, mat, wo, wi, ns, ng, _, rtol = case
    f = bsdf.bsdf_eval(table, mat, wo, wi, ns, ng)
    pdf = bsdf.bsdf_pdf(table, mat, wo, wi, ns, ng)
    assert f.shape == (len(mat), 3) and f.dtype == np.float64 and pdf.shape == (len(mat),)
    f_o = oracle.bsdf_eval(table, mat, wo, wi, ns, ng)
    pdf_o = oracle.bsdf_pdf(table, mat, wo, wi, ns, ng)
    assert (f_o > 0).any(axis=1).mean() > 0.2 and (pdf_o > 0).mean() > 0.2     # the case tests something
    _assert_close(f, f_o, rtol, "f")
    _assert_close(pdf, pdf_o, rtol, "pdf")
    # eval_batch with and without the pdf gives the same f
    E, E_avg = kb.ggx_albedo_tables()
    f2, pdf2 = np.empty_like(f), np.empty_like(pdf)
    kb.eval_batch(table.closures, E, E_avg, mat, wo, wi, ns, ng, f2, pdf2)
    assert np.array_equal(f2, f) and np.array_equal(pdf2, pdf)


def test_eval_shortcut_matches_the_full_lobe_sum(case):
    """Rows without a rough lobe take bsdf_eval's short form; it equals the oracle's general lobe sum."""
    table, mat, wo, wi, ns, ng, _, _ = case
    f = bsdf.bsdf_eval(table, mat, wo, wi, ns, ng)
    f_full, _ = oracle._eval_pdf(oracle._Hit(table, mat, wo, ns, ng), wi)
    smooth = ~table.rough_lobe[np.where(mat < 0, len(table), mat)]
    assert smooth.sum() > 1000
    assert np.allclose(f[smooth], f_full[smooth], rtol=1e-12, atol=1e-15)


def test_sample_matches_the_oracle(case):
    table, mat, wo, _, ns, ng, u, rtol = case
    wi, w, delta = bsdf.bsdf_sample(table, mat, wo, ns, ng, u)
    assert wi.shape == w.shape == (len(mat), 3) and delta.dtype == bool and delta.shape == (len(mat),)
    wi_o, w_o, delta_o = oracle.bsdf_sample(table, mat, wo, ns, ng, u)
    assert 0.1 < delta_o.mean() < 0.9 and (w_o > 0).any(axis=1).mean() > 0.4
    assert np.array_equal(delta, delta_o)
    _assert_close(wi, wi_o, RTOL, "wi")
    _assert_close(w, w_o, rtol, "weight")


def test_diffuse_albedo_matches_the_oracle(case):
    table, mat, wo, _, ns, _, _, _ = case
    a = bsdf.diffuse_albedo(table, mat, wo, ns)
    assert a.shape == (len(mat), 3)
    _assert_close(a, oracle.diffuse_albedo(table, mat, wo, ns), RTOL, "albedo")


def test_scalar_fresnel_and_albedo_lookups_match_the_oracle():
    rng = np.random.default_rng(7)
    cos = np.concatenate([rng.uniform(-0.1, 1.1, 300), [0.0, 1.0, 1e-12]])
    eta = np.concatenate([rng.choice([1.0, 1.5, 1 / 1.5, 2.4, 1 / 2.4], 300), [1.5, 1 / 1.5, 1 / 1.5]])
    F = np.array([kb.fresnel_dielectric(c, e) for c, e in zip(cos, eta)])
    F_o = oracle.fresnel_dielectric(cos, eta)
    assert np.allclose(F, F_o, rtol=RTOL, atol=ATOL) and (F == 1.0).any()            # TIR included
    E, E_avg = kb.ggx_albedo_tables()
    mu = np.concatenate([rng.random(300), [0.0, 1.0, 1 / 64, 0.5]])
    alpha = np.concatenate([rng.random(300), [0.0, 1.0, 1e-4, 3 / 31]])
    got = np.array([kb.ggx_albedo(E, m, a) for m, a in zip(mu, alpha)])
    assert np.array_equal(got, oracle._ggx_albedo(mu, alpha))
    a = np.concatenate([rng.random(300), np.arange(32) / 31, [1e-4, 1.0, 1.2]])
    got = np.array([kb.ggx_albedo_avg(E_avg, x) for x in a])
    assert np.array_equal(got, oracle._ggx_albedo_avg(a))


def test_ggx_albedo_tables_are_the_numpy_construction():
    E, E_avg = kb.ggx_albedo_tables()
    assert E.shape == (65, 32, 32) and E_avg.shape == (32 + 2 * 16 * 32,)
    assert E.dtype == E_avg.dtype == np.float64 and E.flags.c_contiguous and E_avg.flags.c_contiguous
    E_o, E_avg_o = oracle._ggx_albedo_table_numpy()
    assert np.array_equal(E[0], E_o) and np.array_equal(E_avg[:32], E_avg_o)
    assert kb.ggx_albedo_tables()[0] is E                                           # built once


def _ggx_albedo_quadrature(mu: float, alpha: float, nt: int = 1500, nph: int = 512) -> float:
    """E(mu, alpha) = int D G2 (wo . h) / mu dw_h over the half-vectors whose reflection stays above
    the surface: a midpoint rule in x = atan(tan(theta_h) / alpha) (dense where D is) and phi."""
    x = (np.arange(nt) + 0.5) / nt * (np.pi / 2)
    th = np.arctan(alpha * np.tan(x))
    dth = alpha / np.cos(x) ** 2 / (1 + (alpha * np.tan(x)) ** 2) * (np.pi / 2 / nt)
    ph = (np.arange(nph) + 0.5) / nph * 2 * np.pi
    T, Pp = np.meshgrid(th, ph, indexing="ij")
    h = np.stack([np.sin(T) * np.cos(Pp), np.sin(T) * np.sin(Pp), np.cos(T)], -1)
    wo = np.array([np.sqrt(1 - mu * mu), 0.0, mu])
    woh = h @ wo
    ci = 2 * woh * h[..., 2] - mu
    lam = lambda c: 0.5 * (np.sqrt(1 + alpha ** 2 * (1 - c * c) / np.maximum(c * c, 1e-24)) - 1)   # noqa: E731
    D = alpha ** 2 / (np.pi * (h[..., 2] ** 2 * (alpha ** 2 - 1) + 1) ** 2)
    f = np.where((ci > 0) & (woh > 0), D * woh / mu / (1 + lam(mu) + lam(np.clip(ci, 1e-12, 1))), 0.0)
    return float(np.sum(f * np.sin(T) * dth[:, None]) * (2 * np.pi / nph))


@pytest.mark.parametrize("i, j", [(28, 1), (28, 3), (15, 2), (10, 8), (28, 8), (5, 2), (2, 1)])
def test_ggx_albedo_table_is_the_integral(i, j):
    """E[0] at grid points = an independent quadrature of the GGX albedo (F = 1).  A uniform
    midpoint grid of visible-normal samples (K = 24, until 2026-12-06) missed GGX's tail and read
    up to 1.1 % high at small alpha (i 28, j 3: 0.998 for 0.987), which left rough metals' energy
    compensation short: a roughness-0.25 metal glint 0.35 % dark against Cycles."""
    E, _ = kb.ggx_albedo_tables()
    mu, alpha = (i + 0.5) / 32, j / 31
    q = _ggx_albedo_quadrature(mu, alpha)
    assert abs(E[0, i, j] - q) < 5e-4 * q, (E[0, i, j], q)


def test_shipped_coat_table_is_its_construction():
    """kernels/coat_albedo.npy (loaded by ggx_albedo_tables) = build_coat_table, on three slices."""
    E, E_avg = kb.ggx_albedo_tables()
    ks = [0, 7, 31]
    np.testing.assert_allclose(E[1 + np.array(ks)], kb.build_coat_table(E[0], E_avg, ks), rtol=0, atol=1e-12)
    assert np.all(E[1] < 1e-20)                                  # ior 1: no reflection at all


@pytest.mark.parametrize("mu, roughness, ior", [(0.95, 1.0, 1.5), (0.5, 0.7, 1.45), (0.2, 0.5, 2.0),
                                                (0.8, 0.3, 1.33), (0.6, 0.02, 1.5)])
def test_coat_albedo_table_is_the_integral_of_the_coat(mu, roughness, ior):
    """The rough-coat albedo slices E[1:] = the integral of the (energy-compensated) coat lobe's
    f cos over the hemisphere, by quadrature of the numpy oracle's eval (black base, specular 1);
    roughness -> 0: the smooth Fresnel F_diel(mu)."""
    E, _ = kb.ggx_albedo_tables()
    table = MaterialTable([Material(base_color=np.zeros(3), specular=1.0, roughness=roughness, ior=ior)])
    nt, nph = 400, 400
    th = (np.arange(nt) + 0.5) / nt * (np.pi / 2)
    ph = (np.arange(nph) + 0.5) / nph * (2 * np.pi)
    T, Pp = np.meshgrid(th, ph, indexing="ij")
    wi = np.stack([np.sin(T) * np.cos(Pp), np.sin(T) * np.sin(Pp), np.cos(T)], -1).reshape(-1, 3)
    dw = (np.pi / 2 / nt) * (2 * np.pi / nph) * np.sin(T).ravel()
    wo = np.tile([np.sqrt(1 - mu * mu), 0.0, mu], (wi.shape[0], 1))
    N = np.tile([0.0, 0.0, 1.0], (wi.shape[0], 1))
    f = oracle.bsdf_eval(table, np.zeros(wi.shape[0], np.int64), wo, wi, N, N)[:, 0]
    integral = float(np.sum(f * wi[:, 2] * dw))
    got = kb.coat_albedo(E, mu, max(roughness * roughness, 1e-4), ior)
    if roughness < 0.05:        # a near-delta lobe: the quadrature cannot resolve it; the smooth limit
        assert abs(got - kb.fresnel_dielectric(mu, ior)) < 0.02 * got
    else:
        assert abs(got - integral) < 0.03 * integral + 2e-4, (got, integral)   # table interpolation


# ----------------------------------------------------------------------------
# Energy: sampled weights against the integral of the evaluated f
# ----------------------------------------------------------------------------
@pytest.mark.parametrize("mat", [
    Material(base_color=np.array([0.7, 0.6, 0.5]), specular=0.8, roughness=0.3, ior=1.5),
    Material.mirror((0.9, 0.7, 0.4), roughness=1.0),
    Material(base_color=np.array([0.8, 0.8, 0.3]), metallic=0.5, transmission=0.3, specular=0.5, roughness=0.6),
    Material.glass(1.5, roughness=1.0),
    Material(base_color=np.array([0.9, 0.5, 0.3]), transmission=1.0, roughness=0.4, ior=1.5,
             reflection_tint=np.array([0.3, 0.6, 0.9])),                  # the reflect / refract split tinted
])
@pytest.mark.parametrize("theta", [0.3, 1.2])
def test_sampled_weights_reproduce_the_eval_integral(mat, theta):
    """E[weight; non-delta lobe] from sample_batch = integral of f |cos| over the sphere from eval_batch."""
    table = MaterialTable([mat])
    E, E_avg = kb.ggx_albedo_tables()
    rng = np.random.default_rng(11)
    n = 200_000
    ids = np.zeros(n, np.int64)
    N = np.tile([0.0, 0.0, 1.0], (n, 1))
    wo = np.tile([np.sin(theta), 0.0, np.cos(theta)], (n, 1))
    wi, w, delta = np.empty((n, 3)), np.empty((n, 3)), np.empty(n, bool)
    kb.sample_batch(table.closures, E, E_avg, ids, wo, N, N, rng.random((n, 3)), wi, w, delta)
    v = np.where(delta, 0.0, w[:, 0])
    d = uniform_sphere(rng.random((n, 2)))
    f = np.empty((n, 3))
    kb.eval_batch(table.closures, E, E_avg, ids, wo, d, N, N, f, np.empty(0))
    vu = f[:, 0] * np.abs(d[:, 2]) * 4 * np.pi
    se = np.hypot(v.std(), vu.std()) / np.sqrt(n)
    assert abs(v.mean() - vu.mean()) < 4 * se + 1e-3
    assert v.mean() > 0.01                                                    # (rough glass: ~1.3 %)


# ----------------------------------------------------------------------------
# Closures
# ----------------------------------------------------------------------------
def test_material_table_closures_match_its_arrays():
    mats = _materials(np.random.default_rng(3))
    t = MaterialTable(mats)
    c = t.closures
    assert c.shape == (len(mats) + 1, kc.N_CLOSURE) and c.dtype == np.float64 and c.flags.c_contiguous
    assert np.array_equal(c, kc.pack_materials(mats))
    assert np.array_equal(c[:, kc.C_BASE:kc.C_BASE + 3], t.base_color)
    assert np.array_equal(c[:, kc.C_EMIT:kc.C_EMIT + 3], t.emission)
    for col, arr in [(kc.C_METALLIC, t.metallic), (kc.C_TRANSMISSION, t.transmission), (kc.C_ROUGHNESS, t.roughness),
                     (kc.C_SPECULAR, t.specular), (kc.C_IOR, t.ior), (kc.C_ALPHA, t.alpha), (kc.C_W_BASE, t.w_base),
                     (kc.C_W_METAL, t.w_metal), (kc.C_W_GLASS, t.w_glass)]:
        assert np.array_equal(c[:, col], arr), col
    assert np.array_equal(c[:, kc.C_TINT_T:kc.C_TINT_T + 3], t.tint_t)
    assert np.array_equal(c[:, kc.C_TINT_R:kc.C_TINT_R + 3], t.tint_r)
    assert np.all(t.tint_r[[i for i, m in enumerate(mats) if m.reflection_tint is None]] == 1.0)  # None: white
    for col, arr in [(kc.C_ROUGH_LOBE, t.rough_lobe), (kc.C_NONDELTA, t.nondelta), (kc.C_COAT, t.coat),
                     (kc.C_EMISSIVE, t.emission.max(axis=1) > 0)]:
        assert np.array_equal(c[:, col] > 0, arr), col
    assert np.all(c[:, kc.C_PROGRAM] == -1.0)


# ----------------------------------------------------------------------------
# Cycles' glass reflection tint (a Glass BSDF's Color)
# ----------------------------------------------------------------------------
@pytest.mark.parametrize("roughness", [0.0, 0.3])
def test_glass_bsdf_reflection_is_tinted_by_its_colour(roughness):
    """A Glass BSDF (Cycles: reflection_tint = transmission_tint = Color) and the same glass with an
    untinted reflection: kernels = oracle (eval, pdf, sample); rough: the reflected f is the
    untinted one times the colour, the refracted f the same; smooth: with equal tints the mirror is
    chosen with probability F and every sample (mirror or refraction) weighs the colour; the
    denoising albedo is w_glass (F tint_r + (1 - F) tint_t)."""
    color = np.array([0.8, 0.3, 0.2])
    tinted = _glass_bsdf(color, 1.5, roughness)
    plain = Material(base_color=color.copy(), transmission=1.0, ior=1.5, roughness=roughness)
    table = MaterialTable([tinted, plain])
    E, E_avg = kb.ggx_albedo_tables()
    rng = np.random.default_rng(31)
    # kernels against the oracle, both materials, random geometry
    n = 20_000
    mat = rng.integers(0, 2, n)
    wo, wi, ns, ng = _geometry(rng, n)
    u = rng.random((n, 3))
    _assert_close(bsdf.bsdf_eval(table, mat, wo, wi, ns, ng), oracle.bsdf_eval(table, mat, wo, wi, ns, ng), RTOL, "f")
    _assert_close(bsdf.bsdf_pdf(table, mat, wo, wi, ns, ng), oracle.bsdf_pdf(table, mat, wo, wi, ns, ng), RTOL, "pdf")
    wi_k, w_k, d_k = bsdf.bsdf_sample(table, mat, wo, ns, ng, u)
    wi_o, w_o, d_o = oracle.bsdf_sample(table, mat, wo, ns, ng, u)
    assert np.array_equal(d_k, d_o) and (d_k.mean() > 0.5 if roughness == 0.0 else not d_k.any())
    _assert_close(wi_k, wi_o, RTOL, "wi")
    _assert_close(w_k, w_o, RTOL, "weight")
    # one view direction, flat normals
    theta = 1.1
    m = 100_000
    N = np.tile([0.0, 0.0, 1.0], (m, 1))
    wo1 = np.tile([np.sin(theta), 0.0, np.cos(theta)], (m, 1))
    F = kb.fresnel_dielectric(np.cos(theta), 1.5)
    if roughness > 0:
        d = uniform_sphere(rng.random((m, 2)))
        f_t = bsdf.bsdf_eval(table, np.zeros(m, int), wo1, d, N, N)
        f_p = bsdf.bsdf_eval(table, np.ones(m, int), wo1, d, N, N)
        up = d[:, 2] > 0
        assert (f_p[up] > 0).all(axis=1).mean() > 0.5 and (f_p[~up] > 0).all(axis=1).mean() > 0.1
        np.testing.assert_allclose(f_t[up], f_p[up] * color, rtol=1e-12, atol=0)
        np.testing.assert_allclose(f_t[~up], f_p[~up], rtol=1e-12, atol=0)
    else:
        wi1, w1, delta = bsdf.bsdf_sample(table, np.zeros(m, int), wo1, N, N, rng.random((m, 3)))
        assert delta.all()
        np.testing.assert_allclose(w1, np.tile(color, (m, 1)), rtol=1e-12)
        refl = wi1[:, 2] > 0
        assert abs(refl.mean() - F) < 4 * np.sqrt(F * (1 - F) / m)
        # the untinted mirror: weight F / p_R with p_R = F / (F + (1 - F) mean(color))
        wi1, w1, _ = bsdf.bsdf_sample(table, np.ones(m, int), wo1, N, N, rng.random((m, 3)))
        refl = wi1[:, 2] > 0
        np.testing.assert_allclose(w1[refl], F + (1 - F) * color.mean(), rtol=1e-12)
    o = (float(np.sin(theta)), 0.0, float(np.cos(theta)))
    z = (0.0, 0.0, 1.0)
    for row, tint_r in ((0, color), (1, np.ones(3))):
        diff, spec, _, _ = kb.denoising_features(table.closures, row, E, E_avg, o, z, z)
        albedo = np.add(diff, spec)
        np.testing.assert_allclose(albedo, F * tint_r + (1 - F) * color, rtol=1e-12)
