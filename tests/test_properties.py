"""Property-based tests (hypothesis) over the estimators' inputs and the effects plan.

The scene-file loader's own fuzzing lives in tests/test_scenefile.py; here:

* photon maps from random photon sets -- duplicates, zero power, all photons at
  one time, k beyond the photon count -- and random query points / times give
  finite, non-negative irradiance of the right shape;
* the estimators agree where they must: all photons at one time ->
  STANDARD = TEMPORAL = KD4D; the estimate is linear in photon power; the two
  sides of a surface split the photons; duplicated photons at half power give
  the STANDARD estimate of the originals (k' = 2k - 1);
* random valid scenes round-trip through the scene file with the same plan,
  and the plan's booleans are consistent with each other and its details.
"""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings as hsettings, strategies as st

from stpm_core.photons.estimators import PhotonMap
from stpm_core.photons.record import make_records
from stpm_core.shutter import Shutter

ESTIMATORS = ("STANDARD", "TEMPORAL", "KD4D")
FAST = hsettings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])

SHUTTERS = st.sampled_from([Shutter(1.0, 2.0), Shutter(0.5, 0.75, curve=np.array([0.0, 1.0, 0.2])),
                            Shutter(1.0, 1.0)])


@st.composite
def photon_sets(draw, max_n=120):
    """(positions (n,3), wi (n,3), power (n,3), times (n,)) with duplicates, zero powers, shared times."""
    n = draw(st.integers(0, max_n))
    seed = draw(st.integers(0, 2**31 - 1))
    rng = np.random.default_rng(seed)
    pos = rng.uniform(-1, 1, (n, 3)) * [1, 1, draw(st.sampled_from([0.0, 0.05, 1.0]))]
    if n and draw(st.booleans()):                    # duplicates: copy a random subset onto others
        src = rng.integers(0, n, n // 2)
        pos[rng.integers(0, n, n // 2)] = pos[src]
    if n and draw(st.booleans()):                    # a cluster of coincident photons
        pos[: max(1, n // 3)] = pos[0]
    wi = rng.normal(size=(n, 3))
    wi[:, 2] = np.abs(wi[:, 2]) * draw(st.sampled_from([1.0, -1.0]))
    wi /= np.maximum(np.linalg.norm(wi, axis=1, keepdims=True), 1e-12)
    power = rng.uniform(0, 1, (n, 3)) * draw(st.sampled_from([0.0, 1e-6, 1.0, 1e6]))
    if n and draw(st.booleans()):
        power[rng.random(n) < 0.3] = 0.0             # zero-power photons
    times = np.full(n, draw(st.floats(0, 1))) if draw(st.booleans()) else rng.random(n)
    return pos, wi, power, times


def _map(photons, shutter, time_scale=1.0):
    pos, wi, power, times = photons
    return PhotonMap(make_records(pos, wi, power, times), shutter, time_scale=time_scale)


def _queries(seed, m=17):
    rng = np.random.default_rng(seed)
    p = rng.uniform(-1.2, 1.2, (m, 3)) * [1, 1, 0.1]
    ns = np.tile([0.0, 0.0, 1.0], (m, 1))
    return p, ns, rng.random(m)


@FAST
@given(photons=photon_sets(), shutter=SHUTTERS, k=st.integers(1, 300), seed=st.integers(0, 1000),
       estimator=st.sampled_from(ESTIMATORS), kernel=st.sampled_from(["BOX", "CONE"]),
       s=st.sampled_from([1e-3, 1.0, 1e3]))
def test_estimates_are_finite_non_negative(photons, shutter, k, seed, estimator, kernel, s):
    m = _map(photons, shutter, time_scale=s)
    p, ns, t = _queries(seed)
    E = m.estimate(p, ns, t, estimator=estimator, k=k, kernel=kernel)
    assert E.shape == (p.shape[0], 3)
    assert np.all(np.isfinite(E)) and np.all(E >= 0)
    if photons[2].sum() == 0:                         # no power anywhere: no light anywhere
        assert np.all(E == 0)


@FAST
@given(photons=photon_sets(), shutter=SHUTTERS, k=st.integers(2, 60), seed=st.integers(0, 1000),
       t0=st.floats(0, 1))
def test_one_shared_time_makes_the_three_estimators_equal(photons, shutter, k, seed, t0):
    pos, wi, power, _ = photons
    m = _map((pos, wi, power, np.full(len(pos), t0)), shutter)
    p, ns, t = _queries(seed)
    E = [m.estimate(p, ns, t, estimator=e, k=k) for e in ESTIMATORS]
    np.testing.assert_array_equal(E[0], E[1])
    np.testing.assert_array_equal(E[0], E[2])


@FAST
@given(photons=photon_sets(), shutter=SHUTTERS, k=st.integers(2, 60), seed=st.integers(0, 1000),
       estimator=st.sampled_from(ESTIMATORS), c=st.sampled_from([0.5, 2.0, 1024.0]))
def test_estimate_is_linear_in_photon_power(photons, shutter, k, seed, estimator, c):
    pos, wi, power, times = photons
    p, ns, t = _queries(seed)
    E1 = _map(photons, shutter).estimate(p, ns, t, estimator=estimator, k=k)
    Ec = _map((pos, wi, power * c, times), shutter).estimate(p, ns, t, estimator=estimator, k=k)
    np.testing.assert_allclose(Ec, c * E1, rtol=1e-5, atol=1e-30)


@FAST
@given(photons=photon_sets(), shutter=SHUTTERS, k=st.integers(2, 60), seed=st.integers(0, 1000),
       estimator=st.sampled_from(ESTIMATORS))
def test_the_two_sides_split_the_photons(photons, shutter, k, seed, estimator):
    """E(ns) + E(-ns) = the estimate with every photon turned to the ns side (same neighbours)."""
    pos, wi, power, times = photons
    wi = wi.copy()
    wi[:, 2] = np.where(np.abs(wi[:, 2]) < 1e-3, 0.5, wi[:, 2])     # no photon exactly in the plane
    wi /= np.linalg.norm(wi, axis=1, keepdims=True) if len(wi) else 1.0
    p, ns, t = _queries(seed)
    m = _map((pos, wi, power, times), shutter)
    both = m.estimate(p, ns, t, estimator=estimator, k=k) + m.estimate(p, -ns, t, estimator=estimator, k=k)
    up = np.abs(wi)
    all_up = _map((pos, up / np.maximum(np.linalg.norm(up, axis=1, keepdims=True), 1e-12), power, times), shutter)
    np.testing.assert_allclose(both, all_up.estimate(p, ns, t, estimator=estimator, k=k), rtol=1e-5, atol=1e-30)


@FAST
@given(n=st.integers(3, 150), k=st.integers(2, 40), seed=st.integers(0, 10_000))
@example(n=138, k=2, seed=0)        # found by hypothesis: the compiled k-d tree missed the nearest photon
def test_duplicated_photons_at_half_power_give_the_same_standard_estimate(n, k, seed):
    """Each photon twice at half power, k' = 2k - 1: the same k-th radius and the same inner power."""
    rng = np.random.default_rng(seed)
    pos = rng.uniform(-1, 1, (n, 3)) * [1, 1, 0]
    wi = np.tile([0.0, 0.0, 1.0], (n, 1))
    power = rng.uniform(0.1, 1, (n, 3))
    t = rng.random(n)
    sh = Shutter(1.0, 2.0)
    k = min(k, n)
    p, ns, tq = _queries(seed)
    E = _map((pos, wi, power, t), sh).estimate(p, ns, tq, estimator="STANDARD", k=k)
    twice = _map((np.repeat(pos, 2, 0), np.repeat(wi, 2, 0), np.repeat(power / 2, 2, 0), np.repeat(t, 2)), sh)
    np.testing.assert_allclose(twice.estimate(p, ns, tq, estimator="STANDARD", k=2 * k - 1), E, rtol=1e-5)


# ----------------------------------------------------------------------------
# Random scenes: file round trip and plan consistency
# ----------------------------------------------------------------------------
@st.composite
def random_scenes(draw):
    from scenes import box_mesh, make_scene, moving, persp_camera, plane_mesh, point_light, sphere_mesh, translate
    from stpm_core.scene import Light, Material
    from stpm_core.motion import MotionTransform
    mats = [Material.diffuse((0.7, 0.7, 0.7)), Material.glass(draw(st.floats(1.0, 2.5))), Material.mirror(),
            Material.mirror(roughness=0.3), Material(base_color=np.array([0.5, 0.5, 0.5]), specular=0.5, roughness=0.0)]
    objs = []
    if draw(st.booleans()):
        objs.append(plane_mesh(6.0, material=0, name="floor"))
    for j in range(draw(st.integers(0, 3))):
        mat = draw(st.integers(0, len(mats) - 1))
        mesh = sphere_mesh(0.4, 6, 12, material=mat, name=f"s{j}") if draw(st.booleans()) \
            else box_mesh(material=mat, name=f"b{j}")
        x, y, z = (draw(st.floats(-2, 2)) for _ in range(3))
        objs.append((mesh, moving((x, y, z + 1), (x + 0.5, y, z + 1)) if draw(st.booleans()) else translate(x, y, z + 1)))
    lights = [point_light((draw(st.floats(-2, 2)), 0, 3), draw(st.sampled_from([0.0, 100.0])))
              for _ in range(draw(st.integers(0, 2)))]
    if draw(st.booleans()):
        lights.append(Light(type="SPOT", power=200.0, spot_size=draw(st.floats(0.1, 3.0)),
                            transform=moving((0, 0, 3), (1, 0, 3)) if draw(st.booleans())
                            else MotionTransform.static(translate(0, 0, 3))))
    shutter = draw(st.sampled_from([Shutter(1.0, 1.0), Shutter(0.75, 1.25)]))
    return make_scene(objs, mats, persp_camera((0, -6, 3), (0, 0, 0.5)), lights, shutter=shutter)


@hsettings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                  HealthCheck.function_scoped_fixture])
@given(scene=random_scenes(), manual=st.booleans(), caustics=st.booleans(), indirect=st.booleans())
def test_plan_is_consistent_and_survives_the_scene_file(tmp_path, scene, manual, caustics, indirect):
    from stpm_core.plan import apply_plan, make_plan
    from stpm_core.scenefile import load_scene, save_scene
    from stpm_core.settings import RenderSettings
    settings = RenderSettings(effects="MANUAL" if manual else "AUTO", caustics=caustics, indirect=indirect)
    plan = make_plan(scene, settings)
    d = plan["details"]
    # Consistency of the booleans with each other and with the details
    assert plan["time_dependent"] <= plan["motion_blur"]
    assert plan["time_dependent"] <= (plan["caustics"] or plan["indirect"])
    assert plan["motion_blur"] == (scene.shutter.length > 0 and bool(d["moving_objects"] or d["deforming_objects"]
                                                                   or d["camera_moves"] or d["moving_lights"]))
    if manual:
        assert (plan["caustics"], plan["indirect"]) == (caustics, indirect)
    else:
        assert plan["caustics"] <= bool(d["specular_objects"] and d["lights"] and d["diffuse_objects"])
        assert plan["indirect"] <= bool(d["lit_diffuse_objects"])
    assert (plan["estimator"] == "STANDARD") >= (not plan["time_dependent"])
    r = apply_plan(settings, plan)
    assert (r.photons_caustic > 0) == plan["caustics"] and (r.photons_global > 0) == plan["indirect"]
    # The same plan after a round trip through the scene file
    path = tmp_path / "s.stpm"
    save_scene(scene, path)
    assert make_plan(load_scene(path), settings) == plan
