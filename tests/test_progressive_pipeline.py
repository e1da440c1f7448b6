"""A progressive pass's cost cuts give the same images bit for bit (docs/photon-mapping.md, section 8,
"What a pass costs").

* pass i + 1's photons traced on a second thread while pass i traces its image (``threads`` > 1,
  passes of at most ``PIPELINE_PHOTONS`` photons) give the images, noise estimates and stats of the
  passes traced one after the other (``threads = 1``), also when the render stops inside a round
  with a pass traced ahead, and leave no thread behind;
* the noise estimate, now recomputed only when a round joins the image, is the one recomputed after
  every pass;
* range queries, no longer sorted into Morton order, give each query's sum and count whatever the
  order of the queries.
"""
from __future__ import annotations

import threading

import numpy as np
import pytest

import stpm_core.progressive as progressive
from stpm_core.photons.kdtree import FlatTree
from stpm_core.progressive import noise_estimate
from stpm_core.render import render
from stpm_core.settings import RenderSettings
from test_compare import moving_caustic_scene

COMMON = dict(photons_global=0, seed=3, effects="MANUAL", caustics=True, indirect=False, method="PROGRESSIVE",
              photons_caustic=3000, samples=1, k_nearest=12)
THREAD = "stpm-pass-photons"


def _run(scene, settings, cancel_after=None):
    """(result, per-pass (preview Combined, noise_p95) list, names of the threads that traced pass photons)."""
    shown, threads = [], []          # (thread names: the pass-photon thread's without its "_0")
    build = progressive.build_photon_maps

    def spy(*a, **k):
        threads.append(threading.current_thread().name.rsplit("_", 1)[0])
        return build(*a, **k)

    progressive.build_photon_maps = spy
    try:
        r = render(scene, settings, on_pass=lambda img, info: shown.append((img["Combined"].copy(), info["noise_p95"])),
                   cancel=None if cancel_after is None else (lambda: len(shown) >= cancel_after))
    finally:
        progressive.build_photon_maps = build
    return r, shown, threads


def _same(a, b):
    (ra, sa, _), (rb, sb, _) = a, b
    assert sorted(ra.passes) == sorted(rb.passes)
    for k in ra.passes:
        np.testing.assert_array_equal(ra.passes[k], rb.passes[k], err_msg=k)
    assert len(sa) == len(sb)
    for (ia, na), (ib, nb) in zip(sa, sb):
        np.testing.assert_array_equal(ia, ib)
        assert na == nb or (na is None and nb is None) or (np.isinf(na) and np.isinf(nb))
    pa, pb = ra.stats["progressive"], rb.stats["progressive"]
    for key in ("passes", "passes_rendered", "left_out", "stopped_by", "noise_p95", "noise_mean",
                "caustic_photons_per_estimate", "caustic_median_radius", "kernel_radius_scale"):
        assert pa.get(key) == pb.get(key), key


@pytest.mark.parametrize("estimator", ["TEMPORAL", "KD4D"])
def test_passes_traced_ahead_give_the_sequential_images(estimator):
    scene = moving_caustic_scene((32, 24), mirror=(-0.25, 0.25))
    st = RenderSettings(**COMMON, passes=16, estimator=estimator)
    ahead = _run(scene, st.replace(threads=2))
    one = _run(scene, st.replace(threads=1))
    # the pipeline ran: passes inside a round were traced on the second thread, none with threads = 1
    assert ahead[2].count(THREAD) == 10, ahead[2]     # passes 6-8 and 10-16: inside a round
    assert THREAD not in one[2]
    _same(ahead, one)
    assert not any(t.name.startswith(THREAD) for t in threading.enumerate())


def test_a_stop_inside_a_round_drops_the_pass_traced_ahead():
    scene = moving_caustic_scene((32, 24), mirror=(-0.25, 0.25))
    st = RenderSettings(**COMMON, passes=16)
    # cancelled after pass 6 (round 5-8): pass 7 was being traced ahead; passes 5-6 are left out
    ahead = _run(scene, st.replace(threads=2), cancel_after=6)
    one = _run(scene, st.replace(threads=1), cancel_after=6)
    assert ahead[0].stats["progressive"]["stopped_by"] == "cancelled"
    assert ahead[0].stats["progressive"]["passes"] == 4 and ahead[0].stats["progressive"]["passes_rendered"] == 6
    # pass 6 traced ahead (and taken), pass 7 traced ahead unless dropped before it began
    assert ahead[2].count(THREAD) in (1, 2) and ahead[2][:6].count(THREAD) == 1, ahead[2]
    _same(ahead, one)
    assert not any(t.name.startswith(THREAD) for t in threading.enumerate())


def test_a_pass_above_the_pipeline_bound_is_traced_in_turn(monkeypatch):
    monkeypatch.setattr(progressive, "PIPELINE_PHOTONS", COMMON["photons_caustic"] - 1)
    scene = moving_caustic_scene((16, 12), mirror=(-0.25, 0.25))
    r, _, threads = _run(scene, RenderSettings(**COMMON, passes=8, threads=2))
    assert THREAD not in threads and r.stats["progressive"]["passes"] == 8


def test_the_noise_after_each_pass_is_that_of_its_sums():
    """render_passes estimates the noise only when a round joins the image: the same value as after every pass."""
    from stpm_core.lights import LightSet
    from stpm_core.bsdf import MaterialTable
    from stpm_core.raycast import make_caster
    scene = moving_caustic_scene((16, 12), mirror=(-0.25, 0.25))
    st = RenderSettings(**COMMON, passes=10, threads=1)
    seen = []

    def on_pass(sums, info):
        seen.append((info["pass"], info["noise_p95"], noise_estimate(sums)["noise_p95"]))

    progressive.render_passes(scene, st, st, make_caster(scene), LightSet(scene), MaterialTable(scene.materials),
                              on_pass=on_pass)
    assert [p for p, _, _ in seen] == list(range(1, 11))
    for p, told, now in seen:
        assert told == now or (np.isinf(told) and np.isinf(now)), (p, told, now)
    assert np.isfinite(seen[-1][1])


@pytest.mark.parametrize("dims, cyl", [(3, False), (4, False), (4, True)])
def test_range_sums_do_not_depend_on_the_order_of_the_queries(dims, cyl):
    rng = np.random.default_rng(7)
    N, n = 3000, 700
    pos = rng.random((N, 3)).astype(np.float32)
    t = rng.random(N).astype(np.float32)
    packed = np.zeros((N, 8), np.float32)
    wi = rng.normal(size=(N, 3))
    packed[:, :3] = wi / np.linalg.norm(wi, axis=1, keepdims=True)
    packed[:, 4:7] = rng.random((N, 3))
    tree = FlatTree(pos, t, packed, dims=dims, s=0.7)
    q = np.empty((n, 4))
    q[:, :3] = rng.random((n, 3))
    q[:, 3] = 0.7 * rng.random(n)
    ns = rng.normal(size=(n, 3)).astype(np.float32)
    rad = 0.1 + 0.15 * rng.random(n)
    half = 0.2 * rng.random(n) if cyl else None
    phi, cnt = tree.range_sum(q, ns, rad, half, True, 1.1, 1)
    assert cnt.sum() > 3 * n
    perm = rng.permutation(n)
    phi_p, cnt_p = tree.range_sum(q[perm], ns[perm], rad[perm], None if half is None else half[perm], True, 1.1, 1)
    np.testing.assert_array_equal(phi_p, phi[perm])
    np.testing.assert_array_equal(cnt_p, cnt[perm])
    # and one query at a time (no neighbour before it at all)
    for i in range(0, n, 97):
        p1, c1 = tree.range_sum(q[i:i + 1], ns[i:i + 1], rad[i:i + 1], None if half is None else half[i:i + 1],
                                True, 1.1, 1)
        np.testing.assert_array_equal(p1[0], phi[i])
        assert c1[0] == cnt[i]


def test_an_error_during_a_pass_leaves_no_pass_traced_ahead():
    scene = moving_caustic_scene((16, 12), mirror=(-0.25, 0.25))
    seen = []

    def on_pass(img, info):
        seen.append(info["pass"])
        if info["pass"] == 6:                       # pass 7 is being traced ahead
            raise RuntimeError("viewer closed")

    with pytest.raises(RuntimeError, match="viewer closed"):
        render(scene, RenderSettings(**COMMON, passes=16, threads=2), on_pass=on_pass)
    assert seen == [1, 2, 3, 4, 5, 6]
    assert not any(t.name.startswith(THREAD) for t in threading.enumerate())


def test_one_slow_pass_does_not_abandon_a_round_under_a_time_limit(monkeypatch):
    """A time limit finishes a round begun unless its remaining passes would overrun the limit; one pass
    slowed by a hiccup (here a 0.3 s sleep in pass 70 of the round 65-128) must not make every remaining
    pass look that slow (until 2026-12-07 the last pass's time alone could stop the round, leaving
    its passes out; cheap passes made this frequent on a loaded machine)."""
    import time
    scene = moving_caustic_scene((8, 6), mirror=(-0.25, 0.25))
    trace = progressive.trace_image

    def slow_once(*a, **k):
        if k.get("stream") == 70:
            time.sleep(0.3)
        return trace(*a, **k)

    monkeypatch.setattr(progressive, "trace_image", slow_once)
    st = RenderSettings(**{**COMMON, "photons_caustic": 0}, passes=0, time_limit=3.0, threads=1)
    pr = render(scene, st).stats["progressive"]
    assert pr["passes_rendered"] > 70, pr                     # (the hiccup was inside the render)
    assert pr["left_out"] is None, pr
