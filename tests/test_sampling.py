"""Sampling primitives: reproducible streams, frames, warps and their densities."""
import numpy as np
import pytest

from stpm_core.sampling import (concentric_disk, cosine_hemisphere, orthonormal_basis, rng_for,
                                stratified_1d, stratified_2d, to_world, uniform_cone,
                                uniform_cone_pdf, uniform_sphere)


def test_rng_for_same_stream_same_numbers_and_streams_differ():
    a = rng_for(7, 3, 1).random(5)
    b = rng_for(7, 3, 1).random(5)
    c = rng_for(7, 3, 2).random(5)
    d = rng_for(8, 3, 1).random(5)
    assert np.array_equal(a, b)
    assert not np.allclose(a, c) and not np.allclose(a, d)
    # Matches SeedSequence([seed, *stream]) as the contract says
    ref = np.random.Generator(np.random.PCG64(np.random.SeedSequence([7, 3, 1]))).random(5)
    assert np.array_equal(a, ref)


def test_orthonormal_basis_at_poles_and_random():
    rng = np.random.default_rng(0)
    n = uniform_sphere(rng.random((1000, 2)))
    n = np.concatenate([n, [[0, 0, 1.0], [0, 0, -1.0], [0, 0, -1.0 + 1e-17], [1.0, 0, 0], [0, -1.0, 0]]])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    t, b = orthonormal_basis(n)
    assert np.all(np.isfinite(t)) and np.all(np.isfinite(b))
    for x in (t, b):
        assert np.allclose(np.linalg.norm(x, axis=1), 1.0, atol=1e-12)
    assert np.allclose(np.sum(t * b, 1), 0, atol=1e-12)
    assert np.allclose(np.sum(t * n, 1), 0, atol=1e-12)
    assert np.allclose(np.sum(b * n, 1), 0, atol=1e-12)
    # Right-handed: t x b = n
    assert np.allclose(np.cross(t, b), n, atol=1e-12)


def test_cosine_hemisphere_density():
    rng = np.random.default_rng(1)
    w = cosine_hemisphere(rng.random((200_000, 2)))
    assert np.allclose(np.linalg.norm(w, axis=1), 1.0)
    assert np.all(w[:, 2] >= 0)
    # pdf cos/pi => cos^2 is uniform on [0, 1] and E[cos] = 2/3
    assert abs(w[:, 2].mean() - 2 / 3) < 3e-3
    hist, _ = np.histogram(w[:, 2] ** 2, bins=10, range=(0, 1))
    assert np.all(np.abs(hist / len(w) - 0.1) < 0.005)
    # Azimuth uniform
    phi = np.arctan2(w[:, 1], w[:, 0])
    hist, _ = np.histogram(phi, bins=8, range=(-np.pi, np.pi))
    assert np.all(np.abs(hist / len(w) - 0.125) < 0.005)


def test_uniform_sphere_and_cone():
    rng = np.random.default_rng(2)
    w = uniform_sphere(rng.random((200_000, 2)))
    assert np.allclose(np.linalg.norm(w, axis=1), 1.0)
    assert np.all(np.abs(w.mean(0)) < 6e-3)
    hist, _ = np.histogram(w[:, 2], bins=10, range=(-1, 1))
    assert np.all(np.abs(hist / len(w) - 0.1) < 0.005)
    cos_max = 0.8
    c = uniform_cone(rng.random((200_000, 2)), cos_max)
    assert np.allclose(np.linalg.norm(c, axis=1), 1.0)
    assert c[:, 2].min() >= cos_max - 1e-12
    hist, _ = np.histogram(c[:, 2], bins=10, range=(cos_max, 1))
    assert np.all(np.abs(hist / len(c) - 0.1) < 0.005)
    assert np.isclose(uniform_cone_pdf(cos_max), 1 / (2 * np.pi * 0.2))
    # Degenerate cone gives the axis exactly
    assert np.allclose(uniform_cone(rng.random((4, 2)), 1.0), [0, 0, 1])


def test_concentric_disk_uniform_area():
    rng = np.random.default_rng(3)
    d = concentric_disk(rng.random((200_000, 2)))
    r2 = np.sum(d * d, 1)
    assert r2.max() <= 1 + 1e-12
    hist, _ = np.histogram(r2, bins=10, range=(0, 1))          # r^2 uniform for uniform area
    assert np.all(np.abs(hist / len(d) - 0.1) < 0.005)
    q = np.histogram2d(d[:, 0], d[:, 1], bins=2, range=[[-1, 1], [-1, 1]])[0] / len(d)
    assert np.allclose(q, 0.25, atol=0.005)
    assert np.allclose(concentric_disk(np.array([[0.5, 0.5]])), 0.0)


def test_to_world_maps_z_to_normal():
    n = np.array([[0, 0, -1.0], [1.0, 0, 0]])
    assert np.allclose(to_world(np.array([[0, 0, 1.0], [0, 0, 1.0]]), n), n)


@pytest.mark.parametrize("n", [1, 4, 16, 7, 12])
def test_stratified_one_sample_per_stratum(n):
    rng = np.random.default_rng(n)
    s1 = stratified_1d(n, rng)
    assert s1.shape == (n,)
    assert np.array_equal(np.sort(np.floor(s1 * n).astype(int)), np.arange(n))
    s2 = stratified_2d(n, rng)
    assert s2.shape == (n, 2) and s2.min() >= 0 and s2.max() < 1
    k = int(np.sqrt(n))
    if k * k == n:
        cells = np.floor(s2[:, 0] * k).astype(int) * k + np.floor(s2[:, 1] * k).astype(int)
        assert np.array_equal(np.sort(cells), np.arange(n))
