"""Path splitting at a path's first rough vertex (``RenderSettings.rough_splits``), STPM against itself.

A dark coated floor (roughness 0.3: most of what it shows is its coat's reflection) seen directly
and through a clear glass sphere, under a bright grey world (no light that a path through the glass
could reach as a caustic firefly).  Where the camera sees the floor through the glass the path first
meets a rough lobe after two refractions: it splits there (``integrator.shade_paths``), not at the
camera's first hit.  Splitting keeps every pixel's mean: a block z-test against the render
without splitting over 6 seeds, the sphere's pixels included (forgetting a copy's 1 / N, or a copy
drawing its neighbour's direction, fails it).  ``test_cycles_rough_splits`` checks the mean against
Cycles and the noise it removes.
"""
from __future__ import annotations

import numpy as np

from cycles_ref import block_ztest
from scenes import make_scene, persp_camera, plane_mesh, sphere_mesh, translate
from stpm_core.render import render
from stpm_core.scene import Material
from stpm_core.settings import RenderSettings

SEEDS = tuple(range(6))
SPP = 8
Z_MAX = 4.5


def _scene():
    mats = [Material(base_color=np.array([0.05, 0.045, 0.04]), roughness=0.3, specular=1.0),  # coated floor
            Material(base_color=np.ones(3), transmission=1.0, roughness=0.0, ior=1.5)]      # clear glass
    objects = [plane_mesh(8.0, material=0), (sphere_mesh(0.6, 24, 48, material=1), translate(0.0, 0.0, 0.6))]
    cam = persp_camera((0.0, -4.0, 1.6), (0.0, 0.0, 0.45), lens=40.0)
    return make_scene(objects, mats, cam, [], world=(0.8, 0.8, 0.9), resolution=(40, 30))


def _renders(splits: int) -> np.ndarray:
    sc = _scene()
    out = []
    for s in SEEDS:
        st = RenderSettings(samples=SPP, seed=s, photons_global=0, photons_caustic=0, threads=1,
                            rough_splits=splits)
        out.append(np.asarray(render(sc, st).passes["Combined"][..., :3], np.float64))
    return np.stack(out)


def test_rough_splits_keep_the_mean():
    a, b = _renders(4), _renders(1)
    r = block_ztest(a, b, floor=0.005)
    print(r.summary())
    assert abs(r.mean_ratio - 1.0) < 0.005, r.summary()
    assert r.z_abs_max < Z_MAX, (r.summary(), np.round(r.z, 1))
