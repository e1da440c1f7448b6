"""Stratified light samples (``kernels.paths.light_strata``): each pixel's samples of a light are
the first points of an Owen-scrambled (0, 2)-sequence (a (0, m, 2)-net for 2^m samples, placed by an
orthogonal array against the film's cells for 4^k), each sample stays uniform, and the image is the
one the independent uniforms gave, with less noise (docs/rendering.md, "Stratified light samples").

The light densities themselves are unchanged (tests/test_light_mis.py checks that they integrate to 1
and match the oracle); the numpy tracer draws the same strata independently
(tests/test_kernel_paths.py).
"""
from __future__ import annotations

import numpy as np
import pytest

import stpm_core.integrator as integrator
from scenes import box_mesh, make_scene, persp_camera, plane_mesh, translate
from stpm_core.kernels.paths import light_strata
from stpm_core.motion import MotionTransform
from stpm_core.render import render
from stpm_core.scene import Light, Material
from stpm_core.settings import RenderSettings
from stpm_core.shutter import Shutter


def _strata(S, P, rng, samples=None):
    keys, n = rng.random((P, S)), P * S
    samples = np.arange(n) if samples is None else samples
    U = np.empty((samples.size, 2))
    light_strata(samples, S, keys, rng.random((samples.size, 2)), U)
    return U


@pytest.mark.parametrize("S", [1, 5, 16, 49, 64, 70, 100])
def test_each_pixel_takes_the_start_of_a_scrambled_sequence(S):
    """Any S: a pixel's points are the first S of an Owen-scrambled (0, 2)-sequence, so along each
    axis no two of them share a 1 / 2^ceil(log2 S) interval (each coordinate is a (0, 1)-sequence)."""
    L = int(np.ceil(np.log2(S))) if S > 1 else 0
    U = _strata(S, 7, np.random.default_rng(S)).reshape(7, S, 2)
    assert np.all((U >= 0) & (U < 1))
    for p in range(7):
        for axis in (0, 1):
            assert len(set(np.floor(U[p, :, axis] * 2 ** L).astype(int).tolist())) == S, (p, axis)


@pytest.mark.parametrize("S", [16, 64, 256, 1024])
def test_square_counts_stratify_the_light_against_the_film(S):
    """S = s^2, s = 2^k >= 4: (film cell x, film cell y, light cell x, light cell y) is an orthogonal
    array of strength 2: any two of the four take each of the s^2 pairs once per pixel."""
    s = int(round(np.sqrt(S)))
    U = _strata(S, 5, np.random.default_rng(S)).reshape(5, S, 2)
    j = np.arange(S)
    for p in range(5):
        cols = [j % s, j // s, np.floor(U[p, :, 0] * s).astype(int), np.floor(U[p, :, 1] * s).astype(int)]
        for a in range(4):
            for b in range(a + 1, 4):
                assert len(set(zip(cols[a].tolist(), cols[b].tolist()))) == S, (a, b)


@pytest.mark.parametrize("S", [2, 8, 32, 64, 128])
def test_powers_of_two_take_the_points_of_a_net(S):
    """S = 2^m: each pixel's points form a (0, m, 2)-net (every 2^a x 2^b cut, a + b = m, holds one
    point), the Owen-scrambled (0, 2)-sequence, whether S is a square (each point placed in its
    film-stratified cell) or not (points by a permutation of their index)."""
    m = int(np.log2(S))
    U = _strata(S, 4, np.random.default_rng(S)).reshape(4, S, 2)
    for p in range(4):
        for a in range(m + 1):
            ix = np.floor(U[p, :, 0] * 2 ** a).astype(int) * 2 ** (m - a) + np.floor(U[p, :, 1] * 2 ** (m - a)).astype(int)
            assert np.array_equal(np.sort(ix), np.arange(S)), (p, a)


@pytest.mark.parametrize("S", [1, 4, 5, 16, 32, 49, 64, 70, 81])
def test_kernel_matches_the_numpy_oracle(S):
    """The same stream gives the same uniforms as the numpy tracer's (an independent implementation),
    for every rows of a tile and for a subset of them."""
    from types import SimpleNamespace
    from oracles.integrator_numpy import _light_uniforms as oracle
    P = 6
    for samples in (np.arange(P * S), np.sort(np.random.default_rng(S).choice(P * S, size=max(1, P * S // 3),
                                                                              replace=False))):
        want = oracle(SimpleNamespace(type="AREA"), samples, (P * S, S), np.random.default_rng(7))
        rng = np.random.default_rng(7)
        keys = rng.random((P, S))
        got = np.empty((samples.size, 2))
        light_strata(samples, S, keys, rng.random((samples.size, 2)), got)
        assert np.array_equal(got, want)


@pytest.mark.parametrize("S", [32, 64, 70])
def test_a_rows_point_does_not_depend_on_the_other_rows(S):
    """A row's uniforms depend on its pixel's keys, its sample and its jitter only: a few rows of
    a pixel in any order (later bounces; split paths' strata) get what the full set of rows gives
    them.  (The kernel computes only the rows' own points where no orthogonal array is used: S =
    32 and 70 here; 64 takes the array.  docs/rendering.md, "Where a product-shot camera sample's
    time goes".)"""
    P = 9
    rng = np.random.default_rng(S + 1)
    keys, jit = rng.random((P, S)), rng.random((P * S, 2))
    full = np.empty((P * S, 2))
    light_strata(np.arange(P * S), S, keys, jit, full)
    for frac in (0.02, 0.3):
        sub = rng.permutation(np.sort(rng.choice(P * S, size=max(1, int(P * S * frac)), replace=False)))
        part = np.empty((sub.size, 2))
        light_strata(sub, S, keys, jit[sub], part)
        assert np.array_equal(part, full[sub]), (S, frac)


def test_each_sample_is_uniform_and_the_film_strata_are_not_followed():
    """The j-th sample of a pixel, over many pixels, is uniform on the square (chi-square on 4 x 4
    bins), for a square power of two (net points in the array's cells), another power of two (net
    points by index) and another count (the sequence's first points by index): every light sampler
    keeps its density."""
    for S in (16, 32, 25):
        _uniform_per_sample(S, 4000)
    S = 16
    # a subset of the rows (later bounces shade fewer samples) reads the same pixel permutations
    rng = np.random.default_rng(2)
    keys, jit = rng.random((3, S)), rng.random((3 * S, 2))
    full, part = np.empty((3 * S, 2)), np.empty((5, 2))
    light_strata(np.arange(3 * S), S, keys, jit, full)
    sub = np.array([1, 17, 18, 40, 47])
    light_strata(sub, S, keys, jit[sub], part)
    assert np.array_equal(part, full[sub])


def _uniform_per_sample(S, P):
    U = _strata(S, P, np.random.default_rng(S)).reshape(P, S, 2)
    for j in (0, 5, S - 1):
        b = np.floor(U[:, j, 0] * 4).astype(int) * 4 + np.floor(U[:, j, 1] * 4).astype(int)
        counts = np.bincount(b, minlength=16)
        chi2 = float(np.sum((counts - P / 16) ** 2 / (P / 16)))
        assert chi2 < 45.0, (S, j, chi2)         # 15 degrees of freedom: p ~ 1e-4


def _rot_x(a):
    c, s = np.cos(a), np.sin(a)
    M = np.eye(4)
    M[1:3, 1:3] = [[c, -s], [s, c]]
    return M


def _lit_corner():
    """A diffuse corner (floor, back wall) lit by a rectangle close to the wall, a disc, a sphere
    light of radius 0.3 and an emissive box (a MESH light) that moves during the shutter."""
    mats = [Material.diffuse((0.8, 0.8, 0.8)), Material.emitter((3.0, 2.5, 2.0))]
    wall = plane_mesh(6.0)
    moving_box = MotionTransform(np.array([0.0, 1.0]), np.stack([translate(0.0, 0.0, 0.0), translate(0.2, 0.0, 0.1)]))
    objects = [wall, (plane_mesh(6.0), translate(0.0, 2.0, 0.0) @ _rot_x(np.pi / 2)),
               (box_mesh((0.6, 0.8, 0.3), (0.9, 1.0, 0.5), material=1), moving_box)]
    lights = [Light(type="AREA", power=60.0, shape="RECTANGLE", size=1.0, size_y=0.4,
                    transform=MotionTransform.static(translate(-0.6, 1.75, 1.4) @ _rot_x(-0.5))),
              Light(type="AREA", power=30.0, shape="DISK", size=0.6,
                    transform=MotionTransform.static(translate(0.8, 0.5, 1.2))),
              Light(type="POINT", power=30.0, radius=0.3, use_soft_falloff=False,
                    transform=MotionTransform.static(translate(-1.2, 0.6, 0.6)))]
    return make_scene(objects, mats, persp_camera((0.5, -2.5, 1.4), (0, 1.2, 0.5), lens=28), lights,
                      resolution=(32, 24), shutter=Shutter(1.0, 1.5))


def _independent_uniforms(light, samples, strata, rng, out):
    """The sampler before stratification: independent uniforms (k, 2) per light."""
    if integrator._is_delta_light(light):
        out[...] = 0.0
        return out
    return rng.random(out=out)


def test_stratified_image_is_the_independent_one_with_less_noise(monkeypatch):
    """The same scene with stratified and with independent light uniforms: the same image (block Z-test
    over 6 seeds, 4 x 4 px blocks) and a per-pixel variance far lower (measured 0.12x at 16 spp)."""
    scene = _lit_corner()

    def images():
        return np.stack([render(scene, RenderSettings(samples=16, seed=s, photons_caustic=0, photons_global=0,
                                                      max_depth=1)).passes["Combined"][..., :3]
                         for s in range(6)]).astype(np.float64).mean(axis=-1)

    a = images()
    with monkeypatch.context() as m:
        m.setattr(integrator, "_light_uniforms", _independent_uniforms)
        b = images()
    assert np.all(np.isfinite(a)) and a.min() >= 0.0
    blocks = lambda x: x.reshape(x.shape[0], 6, 4, 8, 4).mean(axis=(2, 4))
    A, B = blocks(a), blocks(b)
    se = np.sqrt(A.var(0, ddof=1) / 6 + B.var(0, ddof=1) / 6 + (0.002 * B.mean(0)) ** 2 + 1e-12)
    z = (A.mean(0) - B.mean(0)) / se
    print(f"stratified vs independent: |z| max {np.abs(z).max():.2f}, mean ratio {a.mean() / b.mean():.4f}")
    assert np.abs(z).max() < 4.5, np.round(z, 1)
    assert abs(a.mean() / b.mean() - 1.0) < 0.01, (a.mean(), b.mean())
    lit = b.mean(0) > 0.05 * b.mean(0).max()
    ratio = float(np.median(a.var(0, ddof=1)[lit] / np.maximum(b.var(0, ddof=1)[lit], 1e-12)))
    print(f"per-pixel variance, stratified / independent: {ratio:.3f} over {int(lit.sum())} px")
    assert ratio < 0.4, ratio
