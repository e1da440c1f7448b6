"""Film: pass table, Blackman-Harris filter, filter importance sampling, per-pixel sums."""
from __future__ import annotations

import numpy as np
import pytest

from stpm_core.film import (DEPTH_BACKGROUND, PASS_NAMES, PASSES, Film, blackman_harris, blackman_harris_cdf,
                            filter_offsets, pass_channels)
from oracles.integrator_numpy import camera_samples
from stpm_core.shutter import Shutter


def _values(n, fill):
    """Pass dict with every channel of every pass = fill (n,) or scalar."""
    f = np.broadcast_to(np.asarray(fill, float), (n,))
    return {name: np.repeat(f[:, None], c, axis=1) for name, c, _ in PASSES}


def test_pass_table_is_consistent():
    assert PASS_NAMES == ("Combined", "Depth", "Normal", "Emit", "Direct", "Indirect", "Caustic")
    for name, c, ids in PASSES:
        assert len(ids) == c and pass_channels(name) == c
    assert dict((n, i) for n, _, i in PASSES)["Combined"] == "RGBA"


def test_blackman_harris_shape():
    r = 1.5
    x = np.linspace(-2, 2, 401)
    w = blackman_harris(x, r)
    assert w[200] == pytest.approx(1.0)
    np.testing.assert_allclose(w, w[::-1], atol=1e-12)
    assert np.all(w[np.abs(x) >= r] == 0) and np.all(w >= 0)
    assert blackman_harris(np.array([r - 1e-9]), r)[0] < 1e-4  # continuous at the edge


def _image_samples(W, H, spp, r, seed=0):
    """Camera samples of a whole W x H image as one tile: pixel indices, film positions (n,)."""
    gy, gx = np.mgrid[0:H, 0:W]
    px, py, _ = camera_samples(gx.ravel(), gy.ravel(), spp, Shutter(), np.random.default_rng(seed), filter_width=r)
    return np.repeat(gx.ravel(), spp), np.repeat(gy.ravel(), spp), px, py


@pytest.mark.parametrize("width", [0.0, 1.5, 3.0])
def test_constant_signal_is_reproduced_exactly(width):
    W, H, spp = 12, 9, 7
    ix, iy, px, py = _image_samples(W, H, spp, width)
    n = ix.size
    film = Film(W, H, width)
    film.add_samples(ix[: n // 2], iy[: n // 2], _values(n // 2, 0.25))
    film.add_samples(ix[n // 2:], iy[n // 2:], _values(n - n // 2, 0.25))
    out = film.resolve()
    tiled = Film(W, H, width)
    tiled.add_window(tiled.tile_sums(0, 0, W, H, _values(n, 0.25)))
    for name, c, _ in PASSES:
        assert out[name].shape == (H, W, c) and out[name].dtype == np.float32
        np.testing.assert_allclose(out[name], 0.25, rtol=1e-6)
        np.testing.assert_allclose(tiled.resolve()[name], 0.25, rtol=1e-6)


def test_box_filter_keeps_samples_in_their_pixel():
    film = Film(4, 3, 0.0)
    film.add_samples(np.array([0, 0, 3]), np.array([0, 0, 2]), _values(3, np.array([1.0, 3.0, 5.0])))
    out = film.resolve()["Emit"][..., 0]
    assert out[0, 0] == pytest.approx(2.0) and out[2, 3] == pytest.approx(5.0)
    assert np.count_nonzero(out) == 2
    assert film.resolve()["Depth"][1, 1, 0] == DEPTH_BACKGROUND  # no sample reached it
    # and the camera places box-filter samples inside their own pixel
    ix, iy, px, py = _image_samples(5, 3, 16, 0.0)
    assert np.array_equal(np.floor(px).astype(int), ix) and np.array_equal(np.floor(py).astype(int), iy)


def test_filter_offsets_follow_the_window():
    """filter_offsets inverts the Blackman-Harris CDF: F(offset / r) = u, and a histogram of
    offsets from uniforms matches w / integral w."""
    r = 1.5
    u = np.linspace(0.0, 1.0, 20001)[:-1]
    off = filter_offsets(u, r)
    assert np.all(np.abs(off) <= r) and np.all(np.diff(off) >= 0)
    np.testing.assert_allclose(blackman_harris_cdf(off / r), u, atol=2e-4)
    assert filter_offsets(np.array([0.5]), r)[0] == pytest.approx(0.0, abs=1e-9)
    # Density: bins of 0.1 px against the window's integral over each bin
    off = filter_offsets(np.random.default_rng(3).random(400_000), r)
    edges = np.linspace(-r, r, 31)
    hist = np.histogram(off, edges)[0] / off.size
    want = np.diff(blackman_harris_cdf(edges / r))
    assert np.abs(hist - want).max() < 4 * np.sqrt(want.max() / off.size)
    # The box filter: uniform over the pixel
    np.testing.assert_allclose(filter_offsets(np.array([0.0, 0.25, 0.999]), 0.0), [-0.5, -0.25, 0.499])


def test_moving_edge_gives_the_filtered_coverage_ramp():
    """A step at x = 5.3: each pixel = integral of the filter over the covered part / filter integral
    (filter importance sampling: samples placed by the window, each counts for its own pixel)."""
    W, H, r, edge, spp = 10, 4, 1.5, 5.3, 1024
    ix, iy, px, py = _image_samples(W, H, spp, r, seed=5)
    film = Film(W, H, r)
    film.add_window(film.tile_sums(0, 0, W, H, _values(px.size, (px < edge).astype(float))))
    got = film.resolve()["Direct"][..., 0]
    # Independent answer: 1D quadrature of the window (separable filter, y integrates out)
    x = np.linspace(-r, r, 200001)
    w = blackman_harris(x, r)
    centres = np.arange(W) + 0.5
    want = np.array([np.trapz(w * (c + x < edge), x) / np.trapz(w, x) for c in centres])
    # Stratified 32 x 32 per pixel: the ramp within 0.4 %; borders are not truncated
    np.testing.assert_allclose(got, np.broadcast_to(want, got.shape), atol=4e-3)
    assert np.all(np.diff(got, axis=1) <= 1e-9)  # a monotone ramp
    assert np.all((got[:, 4:6] > 0.01) & (got[:, 4:6] < 0.99)) and got[:, 6].mean() > 0  # spans three pixels
