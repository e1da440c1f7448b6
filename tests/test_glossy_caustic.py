"""Rough lobes read the caustic map (docs/rendering.md, "Path partition"), STPM against itself.

A clear glass sphere over a dark coated floor (roughness 0.6: most of what the floor shows of the
caustic is its coat's reflection) under a sun of 0.5 rad (wide enough that paths traced from the
camera find it through the glass often), black world.  The camera sees only the floor around the
caustic, never the sphere, so no camera ray reaches the sun through the glass directly.

* With the rule (``integrator.GLOSSY_CAUSTIC_MIN_ROUGHNESS`` <= 0.6) the coat's reflection of the
  caustic comes from the caustic map (each delta-only photon weighed by f_c(wo, wi_p)) and the
  paths that leave the coat drop the sun they reach through the glass: Emit is about 0.
* Without it (inf) those paths carry it (Emit) and the caustic map gives the diffuse part only.

Both count each light path once, so the images agree: a block z-test over seeds (dropping the
paths without the glossy reading loses the coat's caustic: mean ratio 0.755, |z| 26; keeping both
counts it twice: 1.246, |z| 7.3).  The caustic map must carry what the paths no longer do: its
Caustic pass matches Caustic + Emit without the rule (without the glossy reading it is the diffuse
part alone, 0.41 of that; on main's code, which has no such rule, the first test fails at its Emit
check).

The progressive method reads its maps through fixed regions (``kdtree._range``); there the rule holds
as well (``ProgressiveMaps.estimate(..., glossy=...)``): the same checks with 32 passes of 1 sample
against 16 passes of 8 samples without the rule (2026-12-07: Emit 0.0002 against 0.036, Caustic ratio
1.024, block |z| max 3.65, mean ratio 1.012; with 8 / 16 passes |z| 5.25 / 4.00 and mean 1.017 / 1.013,
the regions' blur shrinking with the passes).  On main's code (the rule off in PROGRESSIVE) the
Emit check fails (0.036 both).
"""
from __future__ import annotations

import numpy as np
import pytest

import stpm_core.integrator as integrator
from cycles_ref import block_ztest
from scenes import look_at, make_scene, persp_camera, plane_mesh, sphere_mesh, translate
from stpm_core.motion import MotionTransform
from stpm_core.render import render
from stpm_core.scene import Light, Material
from stpm_core.settings import RenderSettings

SEEDS = tuple(range(6))
Z_MAX = 4.0


def _scene():
    mats = [Material(base_color=np.full(3, 0.1), roughness=0.6, specular=1.0),          # coated floor
            Material(base_color=np.ones(3), transmission=1.0, roughness=0.0, ior=1.5)]  # clear glass
    objects = [plane_mesh(8.0, material=0), (sphere_mesh(0.5, 24, 48, material=1), translate(0.0, 0.0, 0.8))]
    # the floor around the caustic, the sphere just above the frame
    cam = persp_camera((0.0, -3.0, 0.8), (0.0, -0.6, 0.0), lens=100.0)
    sun = Light(type="SUN", color=np.ones(3), power=3.0, angle=0.5,
                transform=MotionTransform.static(look_at((0.0, 1.0, 2.0), (0.0, 0.0, 0.0))))
    return make_scene(objects, mats, cam, [sun], resolution=(48, 32))


def _renders(monkeypatch, floor: float, spp: int, seed0: int, passes: int = 0) -> dict:
    """The passes over SEEDS; passes > 0: the progressive method with that many passes of spp samples
    (50 000 caustic photons each)."""
    # (raising=False: on code without the rule the test runs, and fails on what it checks)
    monkeypatch.setattr(integrator, "GLOSSY_CAUSTIC_MIN_ROUGHNESS", floor, raising=False)
    sc = _scene()
    out = {"Combined": [], "Emit": [], "Caustic": []}
    for s in SEEDS:
        if passes:
            st = RenderSettings(method="PROGRESSIVE", passes=passes, samples=spp, seed=seed0 + s, photons_global=0,
                                photons_caustic=50_000, threads=1)
        else:
            st = RenderSettings(samples=spp, seed=seed0 + s, photons_global=0, photons_caustic=200_000, threads=1)
        r = render(sc, st)
        for k in out:
            out[k].append(np.asarray(r.passes[k][..., :3], np.float64))
    return {k: np.stack(v) for k, v in out.items()}


@pytest.fixture(scope="module")
def both():
    mp = pytest.MonkeyPatch()
    try:
        yield _renders(mp, 0.5, 16, 0), _renders(mp, np.inf, 64, 100)
    finally:
        mp.undo()


@pytest.fixture(scope="module")
def both_progressive():
    mp = pytest.MonkeyPatch()
    try:
        yield _renders(mp, 0.5, 1, 0, passes=32), _renders(mp, np.inf, 8, 100, passes=16)
    finally:
        mp.undo()


@pytest.fixture(params=["k_nearest", "progressive"])
def renders(request):
    return request.getfixturevalue("both" if request.param == "k_nearest" else "both_progressive")


def test_rough_lobe_reads_the_caustic_map_and_its_paths_drop_it(renders):
    on, off = renders
    # the paths that leave the coat no longer reach the sun through the glass
    assert on["Emit"].mean() < 0.02 * off["Emit"].mean(), (on["Emit"].mean(), off["Emit"].mean())
    # the caustic map carries that light instead (without the glossy reading: the diffuse part, 0.41)
    ratio = on["Caustic"].mean() / (off["Caustic"] + off["Emit"]).mean()
    assert ratio == pytest.approx(1.0, abs=0.06), ratio


def test_partition_counts_each_path_once(renders):
    on, off = renders
    r = block_ztest(on["Combined"], off["Combined"], floor=0.01)
    print(r.summary())
    assert abs(r.mean_ratio - 1.0) < 0.04, r.summary()
    assert r.z_abs_max < Z_MAX, (r.summary(), np.round(r.z, 1))
