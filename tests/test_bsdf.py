"""The layered material: energy, reciprocity, sampling vs evaluation, Fresnel and refraction."""
import numpy as np
import pytest

from oracles.bsdf_numpy import fresnel_dielectric
from stpm_core.bsdf import MaterialTable, bsdf_eval, bsdf_pdf, bsdf_sample, diffuse_albedo, emission, has_nondelta
from stpm_core.sampling import uniform_sphere
from stpm_core.scene import Material

Z = np.array([0.0, 0.0, 1.0])


def _wo(theta, n):
    return np.tile([np.sin(theta), 0.0, np.cos(theta)], (n, 1))


def _sample(mat, theta, n=100_000, seed=0, ns=Z, ng=Z):
    table = MaterialTable([mat])
    rng = np.random.default_rng(seed)
    wo = _wo(theta, n)
    wi, w, delta = bsdf_sample(table, np.zeros(n, int), wo, np.tile(ns, (n, 1)), np.tile(ng, (n, 1)), rng.random((n, 3)))
    return table, wo, wi, w, delta


@pytest.mark.parametrize("theta", [0.0, 0.7, 1.4])
def test_white_furnace_diffuse(theta):
    _, _, wi, w, delta = _sample(Material.diffuse((1, 1, 1)), theta, n=20_000)
    assert not delta.any()
    assert np.allclose(w, 1.0)                    # cosine sampling of albedo 1: every weight is 1
    assert np.all(wi[:, 2] > 0)


@pytest.mark.parametrize("theta", [0.0, 0.6, 1.2])
def test_white_furnace_smooth_coat_over_white_base(theta):
    # Coat reflects F, diffuse gets (1 - F): total albedo exactly 1
    mat = Material(base_color=np.ones(3), specular=1.0, roughness=0.0, ior=1.5)
    _, _, _, w, delta = _sample(mat, theta)
    assert 0 < delta.mean() < 1
    assert abs(w[:, 0].mean() - 1.0) < 4 * w[:, 0].std() / np.sqrt(len(w)) + 1e-12


@pytest.mark.parametrize("roughness,theta", [(0.2, 0.0), (0.2, 1.4), (0.5, 0.7), (0.9, 0.0), (0.9, 1.4)])
def test_rough_metal_furnace(theta, roughness):
    """White rough metal keeps its energy: single-scattering GGX times Cycles' compensation 1 / E(mu_o)."""
    mat = Material.mirror((1, 1, 1), roughness=roughness)
    _, _, wi, w, delta = _sample(mat, theta, n=60_000)
    assert not delta.any()
    assert np.all(wi[w[:, 0] > 0, 2] > 0)
    mean, se = w[:, 0].mean(), w[:, 0].std() / np.sqrt(len(w))
    assert mean <= 1.0 + 4 * se + 0.01          # tabulated albedo: within 1 %
    assert mean > 0.985


def test_single_scattering_ggx_albedo_table_against_quadrature():
    """The tabulated GGX albedo E(mu, alpha) equals an independent quadrature of D G2 / (4 cos_o) over wi."""
    from oracles.bsdf_numpy import _ggx_D, _ggx_albedo, _ggx_lambda
    alpha, mu = 0.36, 0.6
    wo = np.array([np.sqrt(1 - mu * mu), 0, mu])
    th, ph = np.meshgrid((np.arange(400) + 0.5) / 400 * np.pi / 2, (np.arange(400) + 0.5) / 400 * 2 * np.pi, indexing="ij")
    wi = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1).reshape(-1, 3)
    h = wi + wo
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    a = np.full(len(wi), alpha)
    G2 = 1 / (1 + _ggx_lambda(np.full(len(wi), mu), a) + _ggx_lambda(wi[:, 2], a))
    f_cos = _ggx_D(h[:, 2], a) * G2 / (4 * mu)
    E_quad = np.sum(f_cos * np.sin(th).ravel()) * (np.pi / 2 / 400) * (2 * np.pi / 400)
    assert abs(_ggx_albedo(np.array([mu]), np.array([alpha]))[0] - E_quad) < 0.01


def _uniform_f_cos(table, wo, n=300_000, seed=1):
    """Uniform sphere directions and f(wo, wi) |cos| / p_uniform from bsdf_eval (independent of bsdf_sample)."""
    rng = np.random.default_rng(seed)
    wi = uniform_sphere(rng.random((n, 2)))
    N = np.tile(Z, (n, 1))
    f = bsdf_eval(table, np.zeros(n, int), np.tile(wo[0], (n, 1)), wi, N, N)
    return wi, f[:, 0] * np.abs(wi[:, 2]) * 4 * np.pi


@pytest.mark.parametrize("mat", [
    Material(base_color=np.array([0.7, 0.7, 0.7]), specular=1.0, roughness=0.4, ior=1.5),
    Material(base_color=np.array([0.9, 0.9, 0.9]), metallic=0.5, roughness=0.6),
    Material.mirror((0.9, 0.9, 0.9), roughness=0.5),
])
@pytest.mark.parametrize("theta", [0.3, 1.1])
def test_sample_weight_matches_eval_integral(mat, theta):
    """E[weight * g(wi)] from bsdf_sample equals the integral of f cos g from bsdf_eval (uniform sampling)."""
    table, wo, wi, w, delta = _sample(mat, theta, n=150_000)
    assert not delta.any()
    wu, fu = _uniform_f_cos(table, wo)
    for g in (lambda d: np.ones(len(d)), lambda d: (d[:, 0] > 0.2).astype(float), lambda d: d[:, 2] ** 2):
        v, vu = w[:, 0] * g(wi), fu * g(wu)
        se = np.hypot(v.std() / np.sqrt(len(v)), vu.std() / np.sqrt(len(vu)))
        assert abs(v.mean() - vu.mean()) < 4 * se + 1e-3


def test_pdf_matches_sample_histogram():
    """bsdf_pdf integrated over a region equals the fraction of samples landing there."""
    mat = Material(base_color=np.array([0.5, 0.5, 0.5]), specular=1.0, roughness=0.3)
    table, wo, wi, w, _ = _sample(mat, 0.8, n=200_000)
    region = lambda d: (d[:, 0] < -0.3) & (d[:, 2] > 0)       # around the mirror direction
    frac = np.mean(region(wi) & (w[:, 0] > 0))
    rng = np.random.default_rng(3)
    n = 400_000
    u = uniform_sphere(rng.random((n, 2)))
    N = np.tile(Z, (n, 1))
    p = bsdf_pdf(table, np.zeros(n, int), np.tile(wo[0], (n, 1)), u, N, N)
    integral = np.mean(p * region(u)) * 4 * np.pi
    assert abs(frac - integral) < 0.01


@pytest.mark.parametrize("mat", [Material.diffuse((0.3, 0.6, 0.9)), Material.mirror((0.9, 0.5, 0.2), roughness=0.4),
                                 Material.glass(1.5, roughness=0.5)])
def test_eval_reciprocity(mat):
    table = MaterialTable([mat])
    rng = np.random.default_rng(4)
    n = 2000
    a = uniform_sphere(rng.random((n, 2)))
    b = uniform_sphere(rng.random((n, 2)))
    a[:, 2], b[:, 2] = np.abs(a[:, 2]), np.abs(b[:, 2])
    N = np.tile(Z, (n, 1))
    f_ab = bsdf_eval(table, np.zeros(n, int), a, b, N, N)
    f_ba = bsdf_eval(table, np.zeros(n, int), b, a, N, N)
    if (mat.metallic > 0 or mat.transmission > 0) and mat.roughness > 0:
        # Cycles' Multiscatter GGX energy compensation k_metal(mu_o) (k_glass(mu_o)) scales the
        # reciprocal single scattering by a function of wo alone: f(a, b) / k(a) = f(b, a) / k(b)
        from oracles.bsdf_numpy import _Hit
        h_a, h_b = _Hit(table, np.zeros(n, int), a, N, N), _Hit(table, np.zeros(n, int), b, N, N)
        k_a, k_b = h_a.ms_scale * h_a.k_glass, h_b.ms_scale * h_b.k_glass
        f_ab, f_ba = f_ab / k_a, f_ba / k_b
    assert np.allclose(f_ab, f_ba, rtol=1e-9, atol=1e-12)
    assert f_ab.max() > 0


@pytest.mark.parametrize("ior", [1.33, 1.5, 2.4])
def test_fresnel_normal_incidence_and_smooth_glass_split(ior):
    assert np.isclose(fresnel_dielectric(np.array([1.0]), np.array([ior]))[0], ((ior - 1) / (ior + 1)) ** 2)
    # Leaving the medium gives the same reflectance at normal incidence
    assert np.isclose(fresnel_dielectric(np.array([1.0]), np.array([1 / ior]))[0], ((ior - 1) / (ior + 1)) ** 2)
    _, _, wi, w, delta = _sample(Material.glass(ior), 0.0, n=100_000)
    assert delta.all() and np.allclose(w, 1.0)
    reflected = wi[:, 2] > 0
    F = ((ior - 1) / (ior + 1)) ** 2
    assert abs(reflected.mean() - F) < 4 * np.sqrt(F * (1 - F) / len(w))


@pytest.mark.parametrize("theta", [0.2, 0.6, 1.0, 1.45])
def test_snell_law_entering_and_leaving(theta):
    ior = 1.5
    # Entering: wo on the ng side
    _, wo, wi, w, delta = _sample(Material.glass(ior), theta, n=2000)
    t = wi[:, 2] < 0
    assert t.any() and delta.all()
    sin_t = np.linalg.norm(np.cross(wi[t], Z), axis=1)
    assert np.allclose(sin_t, np.sin(theta) / ior)
    assert np.allclose(wi[t, 1], 0) and np.all(wi[t, 0] < 0)    # in the plane, on the far side
    # Leaving: wo below ng (inside the glass), below the critical angle
    theta_in = np.arcsin(np.sin(theta) / ior)
    wo_in = np.array([np.sin(theta_in), 0, -np.cos(theta_in)])
    table = MaterialTable([Material.glass(ior)])
    n = 2000
    wi2, w2, _ = bsdf_sample(table, np.zeros(n, int), np.tile(wo_in, (n, 1)), np.tile(Z, (n, 1)),
                             np.tile(Z, (n, 1)), np.random.default_rng(1).random((n, 3)))
    out = wi2[:, 2] > 0
    assert out.any()
    assert np.allclose(np.linalg.norm(np.cross(wi2[out], Z), axis=1), np.sin(theta))


def test_total_internal_reflection_beyond_critical_angle():
    ior = 1.5
    critical = np.arcsin(1 / ior)
    table = MaterialTable([Material.glass(ior)])
    n = 5000
    for theta in (critical + 0.01, 1.2):
        wo = np.tile([np.sin(theta), 0, -np.cos(theta)], (n, 1))   # inside the glass
        wi, w, delta = bsdf_sample(table, np.zeros(n, int), wo, np.tile(Z, (n, 1)), np.tile(Z, (n, 1)),
                                   np.random.default_rng(2).random((n, 3)))
        assert delta.all() and np.allclose(w, 1.0)
        assert np.allclose(wi, [[-np.sin(theta), 0, -np.cos(theta)]])     # mirrored, stays inside
    assert fresnel_dielectric(np.array([np.cos(critical + 1e-6)]), np.array([1 / ior]))[0] == 1.0


def test_ior_one_passes_straight_through():
    _, wo, wi, w, delta = _sample(Material.glass(1.0, color=(0.9, 0.8, 0.7)), 0.9, n=1000)
    assert delta.all()
    assert np.allclose(wi, -wo)
    assert np.allclose(w, [0.9, 0.8, 0.7])


def test_smooth_metal_schlick_and_delta():
    base = np.array([0.9, 0.6, 0.3])
    theta = 1.0
    _, wo, wi, w, delta = _sample(Material.mirror(base), theta, n=100)
    assert delta.all()
    assert np.allclose(wi, wo * [-1, -1, 1])
    assert np.allclose(w, base + (1 - base) * (1 - np.cos(theta)) ** 5)


def test_shading_normal_does_not_leak_light():
    # Shading normal tilted 0.5 rad away from wo (at 0.7 rad): the mirror direction about ns is below
    # ng, so the specular normal is raised toward ng until the reflection leaves min(0.9 wo.ng, 0.01)
    # above the surface (Cycles' ensure_valid_specular_reflection), with the mirror's full weight
    ns = np.array([-np.sin(0.5), 0, np.cos(0.5)])
    _, wo, wi, w, delta = _sample(Material.mirror(), 0.7, n=10, ns=ns)
    assert delta.all() and np.allclose(wi[:, 2], 0.01, rtol=0, atol=1e-12)
    assert np.allclose(np.linalg.norm(wi, axis=1), 1.0) and np.all(wi[:, 0] < 0)
    assert np.all(w > 0.99)
    # Eval: wi below ng but above ns gives nothing for a glossy reflection lobe; the DIFFUSE lobe
    # gives base / pi there, as Cycles' bsdf_diffuse_eval (the shadow ray decides: docs/rendering.md,
    # "Shadow terminator"; before 2026-12-06 it gave 0 too, the dark smooth-shading terminator)
    table = MaterialTable([Material.diffuse((1, 1, 1)), Material(base_color=(0.9, 0.9, 0.9), metallic=1.0,
                                                                 roughness=0.5)])
    wi_below = np.array([[-0.9, 0.0, -0.1]]) / np.linalg.norm([0.9, 0, -0.1])
    assert wi_below @ ns > 0
    f = bsdf_eval(table, np.array([0, 1]), np.array([[0, 0, 1.0]] * 2), np.repeat(wi_below, 2, 0),
                  np.repeat(ns[None], 2, 0), np.repeat(Z[None], 2, 0))
    assert np.allclose(f[0], 1 / np.pi) and np.all(f[1] == 0)
    # Flipped normals (back face) behave like the front face
    wo1, wi1 = np.array([[0.3, 0, 0.954]]), np.array([[-0.5, 0, 0.866]])
    f_front = bsdf_eval(table, np.zeros(1, int), wo1, wi1, Z[None], Z[None])
    f_back = bsdf_eval(table, np.zeros(1, int), wo1, wi1, -Z[None], -Z[None])
    assert np.allclose(f_front, 1 / np.pi) and np.allclose(f_back, f_front)


def test_normals_as_they_come():
    """As Cycles (issue 14, item 5): the face (ng) alone says front or back, the shading normal turns
    with it.  A glass hit on its back face is leaving the glass (eta = 1 / ior); a shading normal
    on the other side of its face than the face's own normal is not turned back: its specular lobes
    give nothing (Cycles' microfacet closures have no lobe for a view under N)."""
    glass = Material.glass(1.5)
    theta = 0.3
    # Back face (ns, ng = -Z, seen from +Z): leaving, so refraction bends away from the normal
    _, wo, wi, w, delta = _sample(glass, theta, n=2000, ns=-Z, ng=-Z)
    t = delta & (wi[:, 2] < 0)
    assert t.any()
    sin_t = np.hypot(wi[t, 0], wi[t, 1])
    assert np.allclose(sin_t, 1.5 * np.sin(theta))
    # Front face with the shading normal pointing into the object: nothing (and no mirror either)
    _, wo, wi, w, delta = _sample(glass, theta, n=2000, ns=-Z, ng=Z)
    assert np.all(w == 0)
    # ... and the diffuse lobe gets no light from the face's side
    table = MaterialTable([Material.diffuse((1, 1, 1))])
    wo1, wi1 = np.array([[0.3, 0, 0.954]]), np.array([[-0.5, 0, 0.866]])
    assert np.all(bsdf_eval(table, np.zeros(1, int), wo1, wi1, -Z[None], Z[None]) == 0)


def test_diffuse_albedo_is_the_diffuse_eval_times_pi():
    mats = [Material.diffuse((0.2, 0.4, 0.8)),
            Material(base_color=np.array([0.5, 0.6, 0.7]), specular=0.7, roughness=0.0, ior=1.45),
            Material(base_color=np.array([0.5, 0.6, 0.7]), metallic=0.3, transmission=0.5, roughness=0.0)]
    table = MaterialTable(mats)
    n = 3
    mat = np.arange(n)
    wo = np.tile([np.sin(0.8), 0, np.cos(0.8)], (n, 1))
    wi = np.tile([0, np.sin(0.3), np.cos(0.3)], (n, 1))
    N = np.tile(Z, (n, 1))
    a = diffuse_albedo(table, mat, wo, N)
    assert np.allclose(bsdf_eval(table, mat, wo, wi, N, N), a / np.pi)   # smooth lobes are deltas
    assert np.allclose(a[0], [0.2, 0.4, 0.8])
    F = fresnel_dielectric(np.array([np.cos(0.8)]), np.array([1.45]))[0]
    assert np.allclose(a[1], (1 - 0.7 * F) * np.array([0.5, 0.6, 0.7]))
    assert np.allclose(a[2], 0.7 * 0.5 * np.array([0.5, 0.6, 0.7]))


def test_has_nondelta_and_emission():
    mats = [Material.diffuse(), Material.mirror(), Material.glass(), Material.mirror(roughness=0.3),
            Material.emitter((2.0, 3.0, 4.0))]
    table = MaterialTable(mats)
    ids = np.array([0, 1, 2, 3, 4, -1])
    assert has_nondelta(table, ids).tolist() == [True, False, False, True, False, False]
    e = emission(table, ids)
    assert np.allclose(e[4], [2, 3, 4]) and np.allclose(e[[0, 5]], 0)
