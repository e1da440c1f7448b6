"""The compiled camera-path kernels against the numpy tracer they replaced (tests/oracles).

Every scene of ``kernel_scenes`` (each light type and shape, each lobe, motion,
photon maps with each estimator, a transparent film) is traced twice with the
same random numbers: by ``integrator.trace_image`` (the kernels) and by
``oracles.integrator_numpy.trace_image_numpy`` (whole-array numpy on the numpy
BSDF and light oracles).  Both must give the same image up to float rounding:
the kernels use other orders of float operations (a normalisation multiplies by
1 / |v| where numpy divides), so a shadow ray grazing an edge may decide
differently in a rare sample.  The test bounds that: per pass, at most 0.5 % of
pixels may differ by more than 1e-6 relative, and the mean may move by at most
1e-6 relative.
"""
from __future__ import annotations

import numpy as np
import pytest

from kernel_scenes import kernel_scenes
from oracles.integrator_numpy import trace_image_numpy
from stpm_core import integrator
from stpm_core.integrator import trace_image
from stpm_core.lights import LightSet
from stpm_core.photons import build_photon_maps, sharing
from stpm_core.raycast import make_caster

SCENES = {name: (scene, settings) for name, scene, settings in kernel_scenes()
          if not name.startswith("accumulation")}


def _compare(a: np.ndarray, b: np.ndarray, name: str) -> None:
    scale = max(float(np.abs(b).max()), 1e-30)
    diff = np.abs(a.astype(np.float64) - b.astype(np.float64))
    bad = diff > 1e-6 * np.maximum(np.abs(b), scale * 1e-3)
    assert bad.mean() <= 0.005, f"{name}: {bad.mean():.2%} of values differ (max {diff.max():.3g})"
    assert abs(float(a.mean()) - float(b.mean())) <= 1e-6 * scale + 1e-5 * abs(float(b.mean())), name


@pytest.mark.parametrize("name", sorted(SCENES))
def test_kernels_match_the_numpy_tracer(name, monkeypatch):
    # the oracle estimates every query: compare with look-up sharing off (tests/test_sharing.py tests it)
    monkeypatch.setattr(sharing, "SHARE_RADIUS_FRACTION", 0.0)
    # ... and with the render's estimator at every query (static views: tests/test_static_view.py)
    monkeypatch.setattr(integrator, "STATIC_VIEW", False)
    scene, settings = SCENES[name]
    caster, lights = make_caster(scene), LightSet(scene)
    maps = None
    if settings.photons_caustic or settings.photons_global:
        maps = build_photon_maps(scene, settings, caster, lights)
    got, stats_k = trace_image(scene, settings, caster, lights, maps)
    want, stats_n = trace_image_numpy(scene, settings, caster, lights, maps)
    assert set(got) == set(want)
    for p in want:
        _compare(got[p], want[p], f"{name}/{p}")
    assert stats_k.camera_rays == stats_n.camera_rays
    # Shadow rays: the kernels cast them only where the unshadowed contribution is positive, as numpy does
    assert abs(stats_k.shadow_rays - stats_n.shadow_rays) <= 1e-3 * max(stats_n.shadow_rays, 1)
    assert stats_k.photon_lookups == stats_n.photon_lookups or maps is None


def test_every_scene_reaches_its_feature():
    """The scene set really exercises what it claims: each render has light in its passes."""
    scene, settings = SCENES["photons_temporal"]
    caster, lights = make_caster(scene), LightSet(scene)
    maps = build_photon_maps(scene, settings, caster, lights)
    got, _ = trace_image(scene, settings, caster, lights, maps)
    for p in ("Direct", "Caustic", "Indirect"):
        assert got[p].max() > 0, p
    scene, settings = SCENES["point_radius"]
    got, _ = trace_image(scene, settings, make_caster(scene), LightSet(scene))
    assert got["Emit"].max() > 0                      # the sphere light seen by the camera and in the mirror
