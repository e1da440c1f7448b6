"""Film: pass table, Blackman-Harris filter, splatting normalisation."""
from __future__ import annotations

import numpy as np
import pytest

from stpm_core.film import DEPTH_BACKGROUND, PASS_NAMES, PASSES, Film, blackman_harris, pass_channels


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


@pytest.mark.parametrize("width", [0.0, 1.5, 3.0])
def test_constant_signal_is_reproduced_exactly(width):
    rng = np.random.default_rng(1)
    W, H, n = 12, 9, 20000
    px, py = rng.random(n) * W, rng.random(n) * H
    film = Film(W, H, width)
    film.add_samples(px[: n // 2], py[: n // 2], _values(n // 2, 0.25))
    film.add_samples(px[n // 2:], py[n // 2:], _values(n - n // 2, 0.25))
    out = film.resolve()
    for name, c, _ in PASSES:
        assert out[name].shape == (H, W, c) and out[name].dtype == np.float32
        np.testing.assert_allclose(out[name], 0.25, rtol=1e-6)


def test_box_filter_keeps_samples_in_their_pixel():
    film = Film(4, 3, 0.0)
    film.add_samples(np.array([0.2, 0.7, 3.9]), np.array([0.1, 0.9, 2.5]), _values(3, np.array([1.0, 3.0, 5.0])))
    out = film.resolve()["Emit"][..., 0]
    assert out[0, 0] == pytest.approx(2.0) and out[2, 3] == pytest.approx(5.0)
    assert np.count_nonzero(out) == 2
    assert film.resolve()["Depth"][1, 1, 0] == DEPTH_BACKGROUND  # no sample reached it


def test_moving_edge_gives_the_filtered_coverage_ramp():
    """A step at x = 5.3: each pixel = integral of the filter over the covered part / filter integral."""
    W, H, r, edge = 10, 4, 1.5, 5.3
    # Dense stratified samples: exact-enough integrals
    g = (np.arange(400) + 0.5) / 40.0
    px, py = np.meshgrid(g, (np.arange(160) + 0.5) / 40.0)
    px, py = px.ravel(), py.ravel()
    film = Film(W, H, r)
    film.add_samples(px, py, _values(px.size, (px < edge).astype(float)))
    got = film.resolve()["Direct"][2, :, 0]
    # Independent answer: 1D quadrature of the window (separable filter, y integrates out)
    x = np.linspace(-r, r, 200001)
    w = blackman_harris(x, r)
    centres = np.arange(W) + 0.5
    want = np.array([np.trapz(w * (c + x < edge), x) / np.trapz(w, x) for c in centres])
    # Image borders truncate the window: compare interior pixels
    np.testing.assert_allclose(got[2:8], want[2:8], atol=2e-3)
    assert np.all(np.diff(got) <= 1e-9)  # a monotone ramp
    assert np.all((got[4:6] > 0.01) & (got[4:6] < 0.99)) and got[6] > 0  # the ramp spans three pixels
