"""Indirect light of a soft-falloff point light 0.2 m under a ceiling against Cycles 5.0.

The Cornell-like box of tests/gather_scenes.py with its point light (radius 0.1 m, Blender's
default soft falloff) 0.2 m under the ceiling: the ceiling right above the light is the box's
brightest indirect source, and there Cycles' disc facing each receiver gives ``I cos / (r^2 +
D^2)`` where a sphere light gives ``I cos / D^2`` (+25 % straight above).  STPM's photons carried
the sphere's field until 2026-12-06 (tests/test_soft_falloff_photons.py): the Indirect pass read
+5.5 % of Cycles' (direct visualisation and final gathering alike) while Direct matched.

Cycles' indirect light is its full render (4 diffuse bounces) minus its direct-only render, seed by
seed; STPM's the Indirect pass (direct visualisation of the global map).  Block Z-test over 4
seeds (6 x 6 pixel blocks) with a 1 % floor, as tests/test_cycles_final_gather.py.
"""
from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
pytest.importorskip("OpenImageIO")

from cycles_ref import block_ztest, render_cycles, render_cycles_paths  # noqa: E402

SEEDS = (0, 1, 2, 3)
STPM = dict(samples=16, photons_caustic=0, photons_global=100_000, k_nearest=50)
FLOOR = 0.01
LIGHT_Z, LIGHT_R = 1.8, 0.1          # 0.2 m under the ceiling (z = 2), radius 0.1 m


def stpm_indirect(final_gather: int = 0, seeds=SEEDS):
    """(K, H, W, 3) STPM Indirect passes of the exported box (bpy's current scene), one per seed."""
    from addon.export import export_scene
    from stpm_core.render import render
    from stpm_core.settings import RenderSettings
    bl = bpy.context.scene
    core = export_scene(bpy.context.evaluated_depsgraph_get(), lambda f, sub: bl.frame_set(f, subframe=sub))[0]
    out = []
    for s in seeds:
        res = render(core, RenderSettings(seed=s, final_gather_samples=final_gather, **STPM))
        out.append(np.asarray(res.passes["Indirect"][..., :3], np.float64))
    return np.stack(out)


def cycles_indirect(tmp, seeds=SEEDS):
    """(K, H, W, 3) Cycles' indirect light of the box (full minus direct-only), built here."""
    import gather_scenes
    scene = gather_scenes.cornell(light_z=LIGHT_Z, light_radius=LIGHT_R)
    assert scene.objects["Lamp"].data.use_soft_falloff                       # Blender's default
    full = render_cycles_paths(scene, tmp, samples=128, seeds=seeds, diffuse_bounces=4, glossy_bounces=4,
                               transmission_bounces=4)
    direct = render_cycles(scene, tmp, samples=128, seeds=seeds, max_bounces=0)
    return full - direct


def test_soft_falloff_light_near_the_ceiling_gives_cycles_indirect_light(tmp_path):
    cyc = cycles_indirect(tmp_path)
    stpm = stpm_indirect(0)
    z = block_ztest(stpm, cyc, block=6, floor=FLOOR)
    print("soft falloff 0.2 m under the ceiling, direct visualisation vs Cycles:", z.summary())
    assert abs(z.mean_ratio - 1.0) < 0.02, z.summary()
    assert z.z_abs_max < 4.5, z.summary()
